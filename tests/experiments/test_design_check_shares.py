"""The shares check of design_check: the radius σ of a moved gauge split into the image's noise,
the §4.4 compensation's and the calibration's, simulated and beside the model."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from lts360.cli import main as cli_main
from lts360.experiments.design_check import _oriented_uncertainty, sigma_with_interval
from lts360.recon.calibration.uncertainty import perturb_plane

# --- bad input: one line, exit 2, nothing rendered ----------------------------------------------


def main(argv):
    """``lts360 design check ARGV``."""
    return cli_main(["design", "check", *argv])


@pytest.mark.parametrize("argv, field", [
    (["--draws", "2"], "draws"),
    (["--placement-mm", "-0.5"], "placement_mm"),
    (["--placement-mm", "10.5"], "placement_mm"),
    (["--calibration", "/nonexistent/calibration.json"], "calibration"),
])
def test_bad_share_arguments_exit_2_with_one_line(argv, field, capsys):
    assert main(["paper", "--shares", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err


def test_a_calibration_without_uncertainty_is_refused(tmp_path, capsys):
    path = tmp_path / "cal.json"
    path.write_text(json.dumps({"format": "lts360-calibration"}))
    assert main(["paper", "--shares", "--calibration", str(path)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_share_options_need_shares(capsys):
    assert main(["paper", "--placement-mm", "1"]) == 2
    assert "--shares" in capsys.readouterr().err


# --- the statistics -----------------------------------------------------------------------------


def test_sigma_interval_skips_failed_draws():
    s = sigma_with_interval([0.001, -0.002, np.nan, 0.0015, 0.0])
    assert s["draws"] == 4 and s["failed"] == 1
    assert s["sigma_um"] == pytest.approx(np.std([1.0, -2.0, 1.5, 0.0], ddof=1))
    assert s["mean_um"] == pytest.approx(0.125)


def test_sigma_interval_covers_the_true_sigma_95_percent_of_the_time():
    """The interval is checked by what it claims, not by holding its own σ: over 4000 seeded
    sets of 4 normal draws (σ = 3 µm) it holds the true σ in 95 % of them."""
    rng = np.random.default_rng(35)
    errors_mm = rng.normal(0.0, 0.003, size=(4000, 4))
    held = [lo < 3.0 < hi for lo, hi in (sigma_with_interval(e)["sigma_95_um"]
                                          for e in errors_mm)]
    # binomial standard error sqrt(0.95 * 0.05 / 4000) = 0.0034: ±0.015 is 4.4 of them
    assert abs(np.mean(held) - 0.95) < 0.015, np.mean(held)


def test_the_model_shares_are_computed_not_skipped():
    """The design model's shares for the shares run's case (no render): the model's API works,
    so the comparison below can never be skipped; the figures are the paper rig's (Ø20 mm,
    2 mm off the axis; deterministic, 2 % for numerics: n_theta 96 → 360 moves them < 1 %)."""
    from lts360.experiments.design_check import _model_shares
    from lts360.scenes.rig_io import load_rig

    m = _model_shares(load_rig("paper"), 2.0, None, None)
    assert "error" not in m, m.get("error")
    assert m["noise_um"] == pytest.approx(1.81, rel=0.02)  # STUDIES.md: model 1.81 µm
    assert m["compensation_um"] == pytest.approx(5.75, rel=0.02)  # STUDIES.md: model 5.75 µm
    assert m["calibration_um"] is None  # no covariance given
    assert m["total_um"] == pytest.approx(math.hypot(m["noise_um"], m["compensation_um"]),
                                          rel=1e-6)


def test_covariance_follows_a_flipped_normal():
    """A plane stored with the opposite normal: the drawn plane is the same plane (first order),
    whichever orientation the covariance was written in (a rank-1 covariance: one direction)."""
    n = np.array([0.70710678, 0.45451948, -0.54167522])
    d = -125.8
    v = np.array([2e-4, -1e-4, 0.01])
    unc = {"mirrors": {"left": {"cov_abd": np.outer(v, v).tolist()}}}
    file_cal = SimpleNamespace(mirrors=[SimpleNamespace(name="left", n=n)],
                               laser_plane=(np.array([0.0, 0.0, 1.0]), 0.0))
    true_cal = SimpleNamespace(mirrors=[SimpleNamespace(name="left", n=-n)],
                               laser_plane=(np.array([0.0, 0.0, 1.0]), 0.0))
    C = np.asarray(_oriented_uncertainty(unc, file_cal, true_cal)["mirrors"]["left"]["cov_abd"])
    w = np.sqrt(np.diag(C)) * np.sign(C[0])  # the rank-1 factor, up to its sign
    n1, d1 = perturb_plane(n, d, v)
    for sign in (1.0, -1.0):
        n2, d2 = perturb_plane(-n, -d, sign * w)
        if np.allclose(-n2, n1, atol=1e-7) and math.isclose(-d2, d1, abs_tol=1e-9):
            break
    else:
        pytest.fail(f"the re-oriented draw is another plane: {n1, d1} vs {-n2, -d2}")


# --- a small run end to end ---------------------------------------------------------------------


# (mean, σ) of the radius errors measured 2026-12-05 by the run below (µm; half-size images at
# 4 spp, so the means hold the line-centre bias at that sampling, not the model's figures).
# One realisation: the render of seed 5 (pixel-support frames, the support's exact-disk
# dilation and the speckle's row groups of c950c4d) and four draws of the keyed speckle and the
# sensor noise. At 2026-12-04 (the support's earlier pixel lists: another realisation) the run
# read -2.67 ± 1.71, -16.67 ± 2.80, -3.14 ± 1.81 and -23.40 ± 6.41. Another render realisation moves the noise-free error by
# σ 2.2 µm at this sampling (render seeds 5-24: support -6.41, full frames -5.86 µm, paired
# difference -0.55 ± 0.65 µm), so any change of the chain (renderer, support, speckle) moves
# these means beyond the bounds below and they are measured again.
MEASURED = {"noise": (-6.90, 2.24), "compensation": (-5.06, 2.96),
            "compensation_paired_uncompensated": (-6.84, 1.46), "calibration": (-11.07, 6.25)}


@pytest.fixture(scope="module")
def shares_run(tmp_path_factory, truth_calibration):
    from lts360.scenes.rig_io import load_rig

    rig = load_rig("paper")
    path = truth_calibration
    out = tmp_path_factory.mktemp("shares") / "shares.json"
    # half-size images, 4 spp, 4 draws: structure, not accuracy (~30 s on 2 cores)
    from lts360.experiments.design_check import check_shares

    return check_shares(rig, draws=4, spp=4, seed=5, placement_mm=2.0, calibration=path,
                        scale=0.5), path, out


@pytest.mark.slow
def test_shares_run_reports_every_share(shares_run):
    r, _, _ = shares_run
    assert r["draws"] == 4 and r["placement_mm"] == 2.0
    for key, (mean_um, sigma_um) in MEASURED.items():
        s = r["simulated"][key]
        assert s["draws"] == 4 and s["failed"] == 0, key
        # seeded renders and draws: the mean within 3 standard errors of 4 draws (3σ/2) of
        # the value measured (2026-12-04), so a lost view or a wrong scale (tens of µm) fails
        assert abs(s["mean_um"] - mean_um) < 1.5 * sigma_um, (key, s["mean_um"])
        # σ of 4 draws within a factor 2 of the value measured (its 95 % χ² range is
        # 0.57–3.73; seeded, so only a changed chain moves it)
        assert 0.5 * sigma_um < s["sigma_um"] < 2.0 * sigma_um, (key, s["sigma_um"])
    assert r["shares"]["calibration"]["sigma_um"] == r["simulated"]["calibration"]["sigma_um"]
    comp = r["shares"]["compensation"]
    assert comp["resolved"] == (comp["sigma_um"] is not None)
    # the model ran: a broken model API is a failure here, not a skipped comparison
    assert "error" not in r["model"], r["model"]
    for share in ("noise", "compensation", "calibration"):
        assert math.isfinite(r["comparison"][share]["model_um"]), share
        assert r["comparison"][share]["model_um"] > 0, share
    json.dumps(r)  # plain JSON


@pytest.mark.slow
def test_compensation_does_not_lower_the_scatter(shares_run):
    """The compensation adds its reference image's noise. Paired (the same test images with
    and without the offsets): the offsets' own σ (model 5.7 µm) exceeds the images' (model
    1.8 µm), and σ with them exceeds σ without."""
    r = shares_run[0]
    sim = r["simulated"]
    s_u = sim["compensation_paired_uncompensated"]["sigma_um"]
    s_d = r["shares"]["compensation_paired"]["sigma_um"]
    # Four draws do not resolve the model's ratio (3.2): s_d / s_u measured 1.55, 1.18, 16.1
    # at seeds 5, 6, 7 (support frames) and 2.26, 1.89, 8.56 (full frames). The offsets add
    # scatter (s_d > s_u) ...
    assert s_d > s_u, (s_d, s_u)  # measured: 3.85 against 1.46 µm (2026-12-05)
    # ... and σ with them exceeds σ without, in every one of those six runs
    assert sim["compensation"]["sigma_um"] > s_u  # measured: 2.96 against 1.46 µm


@pytest.mark.parametrize("argv, message", [
    (["paper", "--calibrations", "a.json", "b.json"], "need at least 3 files"),
    (["paper", "paper-f8", "--calibrations", "a", "b", "c"], "give exactly one rig"),
    (["paper", "--calibrations", "a.json", "b.json", "c.json"], "no file 'a.json'"),
    (["paper", "--placement-mm", "12", "--calibrations", "a", "b", "c"], "--placement-mm"),
])
def test_bad_calibrations_arguments_exit_2_with_one_line(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err

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


def test_sigma_interval_brackets_sigma_and_skips_failed_draws():
    s = sigma_with_interval([0.001, -0.002, np.nan, 0.0015, 0.0])
    assert s["draws"] == 4 and s["failed"] == 1
    assert s["sigma_95_um"][0] < s["sigma_um"] < s["sigma_95_um"][1]
    assert s["sigma_um"] == pytest.approx(np.std([1.0, -2.0, 1.5, 0.0], ddof=1))


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
    for key in ("noise", "compensation", "compensation_paired_uncompensated", "calibration"):
        s = r["simulated"][key]
        assert s["draws"] == 4 and s["failed"] == 0, key
        lo, hi = s["sigma_95_um"]
        assert 0 < lo < s["sigma_um"] < hi, key
        # µm-level noise of a Ø20 mm gauge, not a broken measurement
        assert abs(s["mean_um"]) < 30 and s["sigma_um"] < 30, key
    assert r["shares"]["calibration"]["sigma_um"] == r["simulated"]["calibration"]["sigma_um"]
    comp = r["shares"]["compensation"]
    assert comp["resolved"] == (comp["sigma_um"] is not None)
    assert r["shares"]["compensation_paired"]["sigma_um"] > 0
    if "error" not in r["model"]:
        for share in ("noise", "compensation", "calibration"):
            assert math.isfinite(r["comparison"][share]["model_um"]), share
    json.dumps(r)  # plain JSON


@pytest.mark.slow
def test_compensation_does_not_lower_the_scatter(shares_run):
    """The compensation adds its reference image's noise: σ with it is not below σ without,
    within the 95 % intervals of 4 draws (independent images, so no tighter test is fair)."""
    sim = shares_run[0]["simulated"]
    assert sim["compensation"]["sigma_95_um"][1] >= sim["noise"]["sigma_95_um"][0]
    # paired: the same images with and without the offsets
    assert sim["compensation"]["sigma_95_um"][1] >= \
        sim["compensation_paired_uncompensated"]["sigma_95_um"][0]


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

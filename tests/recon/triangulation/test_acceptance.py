"""A measurement says what it could not measure: coverage against what the views predict, and
`lts360 measure` refuses (exit 3, one line) a section with no valid point or too little
coverage, on synthetic images made for it (no stripe; a stripe in the direct view only)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from lts360.cli import main
from lts360.recon.triangulation.acceptance import refusal, section_coverage
from lts360.recon.triangulation.cloud import VIEW_CODES, Cloud
from lts360.recon.triangulation.grid import CylGrid

GRID = CylGrid.from_ranges((8.0, 12.0), theta_step_deg=1.0, r_step_mm=0.05)


def _rows(section, view, theta_deg, r):
    th = np.radians(np.asarray(theta_deg, float))
    r = np.broadcast_to(np.asarray(r, float), th.shape)
    n = th.size
    pts = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(n)])
    return Cloud(pts, th, r.copy(), np.full(n, VIEW_CODES[view], np.uint8), np.zeros(n, np.uint8),
                 np.full(n, section, np.int32), np.ones(n, np.float32))


def test_coverage_counts_distinct_theta_over_views():
    # Section 0: direct 0..179° valid, left 150..299° valid (overlap 150..179 counted once),
    # right 300..359° searched but nothing found.
    cloud = Cloud.concatenate([_rows(0, "direct", np.arange(0, 180), 10.0),
                               _rows(0, "left", np.arange(150, 300), 10.0),
                               _rows(0, "right", np.arange(300, 360), np.nan)])
    (c,) = section_coverage(cloud, GRID, n_sections=1)
    assert c.predicted_deg == pytest.approx(360.0) and c.measured_deg == pytest.approx(300.0)
    assert c.n_valid == 180 + 150 and set(c.views) == {"direct", "left", "right"}
    assert c.fraction == pytest.approx(300 / 360)
    assert refusal([c], GRID, min_fraction=0.8) is None
    line = refusal([c], GRID, min_fraction=0.9)
    assert "300.0° of 360.0°" in line and "section 0" in line and "\n" not in line


def test_a_section_without_a_valid_point_is_refused_and_names_views_and_band():
    cloud = Cloud.concatenate([_rows(0, "direct", np.arange(0, 180), 10.0),
                               _rows(1, "direct", np.arange(0, 180), np.nan),
                               _rows(1, "left", np.arange(150, 300), np.nan)])
    cov = section_coverage(cloud, GRID, n_sections=2)
    assert [c.n_valid for c in cov] == [180, 0]
    line = refusal(cov, GRID, min_fraction=0.0)
    assert line.startswith("no valid point in 1 of 2 sections")
    assert "views direct, left" in line and "r = 8.000–12.000 mm" in line and "--radius-mm" in line


def test_a_classic_cloud_has_no_predicted_coverage():
    (c,) = section_coverage(_rows(0, "direct", np.arange(0, 90), 10.0), GRID, n_sections=1,
                            windows_in_cloud=False)
    assert c.predicted_deg is None and c.fraction is None
    assert refusal([c], GRID, min_fraction=1.0) is None


# ---- the command on synthetic images ----------------------------------------------------------

@pytest.fixture(scope="module")
def true_calibration(tmp_path_factory):
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth, write_json

    rig = load_rig("paper")
    path = tmp_path_factory.mktemp("cal") / "frame.json"
    write_json(path, rig_truth(rig, rig.camera.K, (rig.camera.width_px, rig.camera.height_px)))
    return path, (rig.camera.height_px, rig.camera.width_px)


def _write_png(path, img):
    import cv2

    assert cv2.imwrite(str(path), img)


def _stripe_in(view: str, cal_path, shape, radius_mm=10.0) -> np.ndarray:
    """An 8-bit image with the laser line of a Ø2r section in one view only (σ ≈ 1.2 px)."""
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.inverse import plan_inverse

    grid = CylGrid.from_ranges((radius_mm - 0.01, radius_mm + 0.01), theta_step_deg=0.02,
                               r_step_mm=0.01)
    uv = plan_inverse(load_calibration(cal_path), grid, precompute=False).views[view].uv[:, 1]
    acc = np.zeros(shape)
    u, v = uv[:, 0], uv[:, 1]
    inside = (u >= 0) & (v >= 0) & (u < shape[1] - 1) & (v < shape[0] - 1)
    np.add.at(acc, (np.rint(v[inside]).astype(int), np.rint(u[inside]).astype(int)), 1.0)
    img = gaussian_filter(acc, 1.2)
    return np.clip(200.0 * img / img.max(), 0, 255).astype(np.uint8)


def test_an_image_without_a_stripe_exits_3_naming_views_and_radii(true_calibration, tmp_path,
                                                                    capsys):
    cal, shape = true_calibration
    _write_png(tmp_path / "dark.png", np.zeros(shape, np.uint8))
    out = tmp_path / "cloud.ply"
    args = ["measure", str(tmp_path / "dark.png"), "--pitch-mm", "1", "--calibration",
            str(cal), "--out", str(out), "--theta-step-deg", "0.5"]
    # A fixed band.
    code = main(args + ["--radius-mm", "10"])
    err = capsys.readouterr().err.strip()
    assert code == 3 and not out.exists()
    assert len(err.splitlines()) == 1
    assert "no valid point" in err and "views direct, left, right" in err
    assert "r = 8.000–12.000 mm" in err and "nothing written" in err
    # The band searched from the image: every radius the rig can image.
    code = main(args)
    err = capsys.readouterr().err.strip()
    assert code == 3 and not out.exists() and len(err.splitlines()) == 1
    assert "no valid point" in err and "views direct, left, right" in err
    assert "r = 0.10–40.31 mm searched" in err and "no stripe was found" in err


def test_a_stripe_in_one_view_only_is_refused_for_its_coverage(true_calibration, tmp_path,
                                                               capsys):
    cal, shape = true_calibration
    _write_png(tmp_path / "direct.png", _stripe_in("direct", cal, shape))
    out = tmp_path / "cloud.ply"
    args = ["measure", str(tmp_path / "direct.png"), "--pitch-mm", "1", "--calibration", str(cal),
            "--out", str(out), "--theta-step-deg", "0.5"]
    assert main(args) == 3
    err = capsys.readouterr().err.strip()
    assert "less than 50% of the coverage" in err and out.exists()
    # The direct view alone covers ~142° of the predicted 360°: enough at --min-coverage 0.3.
    assert main(args + ["--min-coverage", "0.3"]) == 0
    from lts360.recon.triangulation.cloud import read_cloud

    cloud = read_cloud(out)
    direct = cloud.valid & (cloud.view == VIEW_CODES["direct"])
    assert direct.sum() > 200 and np.all(cloud.view[cloud.valid] == VIEW_CODES["direct"])
    assert np.median(np.abs(cloud.radius_mm[direct] - 10.0)) < 0.01


def test_min_coverage_outside_0_1_is_a_usage_error(true_calibration, tmp_path, capsys):
    cal, _ = true_calibration
    assert main(["measure", str(tmp_path), "--calibration", str(cal), "--out",
                 str(tmp_path / "c.ply"), "--min-coverage", "1.5"]) == 2
    assert "--min-coverage" in capsys.readouterr().err


@pytest.mark.parametrize("extra,name", [(["--band-mm", "-1"], "--band-mm"),
                                        (["--band-mm", "11"], "--band-mm"),
                                        (["--radius-mm", "1", "--band-mm", "2"], "--radius-mm"),
                                        (["--r-step-mm", "0"], "--r-step-mm"),
                                        (["--theta-step-deg", "20"], "--theta-step-deg"),
                                        (["--radius-mm", "ten"], "--radius-mm"),
                                        (["--band-search"], "unrecognized")])
def test_bad_band_values_are_one_line_usage_errors(true_calibration, tmp_path, capsys, extra,
                                                   name):
    cal, _ = true_calibration
    code = main(["measure", str(tmp_path), "--calibration", str(cal), "--out",
                 str(tmp_path / "c.ply")] + extra)
    err = capsys.readouterr().err.strip()
    assert code == 2 and name in err and len(err.splitlines()) == 1, err


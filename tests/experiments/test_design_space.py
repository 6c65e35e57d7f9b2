"""The design-space study (issue 6): ranges, geometry metrics, invalid rigs, a tiny study.

The end-to-end study renders at half scale (640×512; the true calibration follows the scaled
K) with 2 draws: ~3 s per rig on 2 cores.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lts360.experiments.design_space import (
    PAPER_DESIGN,
    STATUS,
    design_rig,
    design_space_trial,
    format_design_space,
    geometry_metrics,
    parse_range,
    rig_status,
    run_design_space_study,
)
from lts360.experiments.runner import Trial, trial_path
from lts360.scenes.coverage import coverage
from lts360.scenes.rig import RigError
from lts360.scenes.rig_io import load_rig

#: β below RigDesign's range [60, 150]°: the rig validation rejects it.
INVALID_BETA_DEG = 50.0


# --- parse_range --------------------------------------------------------------------------------

@pytest.mark.parametrize("text,expected", [
    ("20:70:5", np.arange(20.0, 71.0, 5.0)),
    ("60:120:5", np.arange(60.0, 121.0, 5.0)),
    ("40", [40.0]),
    (" 42.5 ", [42.5]),
    ("40:40:5", [40.0]),
    ("20:70:7", [20.0, 27.0, 34.0, 41.0, 48.0, 55.0, 62.0, 69.0]),  # stops before STOP
    ("0.1:0.3:0.1", [0.1, 0.2, 0.3]),  # STOP kept despite float rounding of the steps
])
def test_parse_range(text, expected):
    np.testing.assert_allclose(parse_range(text), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("text,match", [
    ("", "START:STOP:STEP"),
    ("20:70", "START:STOP:STEP"),
    ("20:70:5:1", "START:STOP:STEP"),
    ("a:b:c", "START:STOP:STEP"),
    ("20:70:0", "STEP must be > 0"),
    ("20:70:-5", "STEP must be > 0"),
    ("70:20:5", "STOP"),
    ("nan", "START:STOP:STEP"),
    ("0:1:1e-9", "more than"),
])
def test_parse_range_rejects(text, match):
    with pytest.raises(ValueError, match=match):
        parse_range(text)


def test_parse_range_rejects_a_non_string():
    with pytest.raises(ValueError, match="string"):
        parse_range(40)


# --- rigs and geometry --------------------------------------------------------------------------

def test_the_paper_design_is_the_paper_rig():
    paper, rig = load_rig("paper"), design_rig(*PAPER_DESIGN)
    np.testing.assert_allclose(rig.camera.R, paper.camera.R, atol=1e-12)
    np.testing.assert_allclose(rig.camera.t_mm, paper.camera.t_mm, atol=1e-12)
    np.testing.assert_allclose(rig.camera.K, paper.camera.K, atol=1e-12)
    for a, b in zip(rig.mirrors, paper.mirrors):
        np.testing.assert_allclose(a.T, b.T, atol=1e-12)
    assert rig.sensor.to_dict() == paper.sensor.to_dict()


def test_only_alpha_and_beta_change():
    rig, paper = design_rig(55.0, 105.0), load_rig("paper")
    assert (rig.design.alpha_deg, rig.design.beta_deg) == (55.0, 105.0)
    for field in ("camera_distance_mm", "laser_distance_mm", "mirror_width_mm",
                  "mirror_corner_distance_mm"):
        assert getattr(rig.design, field) == getattr(paper.design, field)
    assert rig.camera.focus_distance_mm == paper.camera.focus_distance_mm
    assert rig.laser.fan_angle_deg == paper.laser.fan_angle_deg


def test_paper_geometry_metrics_are_those_of_coverage():
    out = design_space_trial(Trial(0, {"alpha_deg": 40.0, "beta_deg": 90.0, "draws": 0}, 7))
    v = {k: float(x) for k, x in out.values.items() if x.ndim == 0}
    paper = load_rig("paper")
    cov = coverage(paper, 10.0)
    assert v["status"] == 0
    assert v["coverage_deg"] == cov.coverage_deg == pytest.approx(360.0, abs=1e-9)
    assert v["coverage_single_deg"] == pytest.approx(360.0, abs=1e-9)
    assert v["overlap_direct_left_deg"] == cov.overlap_deg("direct", "left")
    assert v["overlap_direct_right_deg"] == cov.overlap_deg("direct", "right")
    assert v["overlap_direct_mirror_deg"] == min(cov.overlap_deg("direct", "left"),
                                                 cov.overlap_deg("direct", "right"))
    assert v["overlap_mirror_mirror_deg"] == cov.overlap_deg("left", "right")
    assert v["image_margin_px"] == cov.image_margin_px(paper.camera.image_size)
    # At β = 90° the corner image lies behind the object: no second image of a measured point.
    assert v["multi_reflection_pct"] == 0.0 and v["ghost_in_band_pct"] == 0.0
    # Geometry only: the Monte Carlo metrics are NaN, no draws.
    assert math.isnan(v["radius_std_mm"]) and out.values["radius_error_mm"].shape == (0,)


def test_multiple_reflection_share_from_the_coverage_masks():
    # β = 75°: both double reflections are seen and lit over part of the section.
    rig = design_rig(40.0, 75.0)
    m = geometry_metrics(rig)
    cov = coverage(rig, 10.0)
    single = cov.measured["direct"] | cov.measured["left"] | cov.measured["right"]
    double = cov.measured["left-right"] | cov.measured["right-left"]
    assert m["multi_reflection_pct"] == pytest.approx(100.0 * np.mean(single & double))
    assert m["multi_reflection_pct"] > 10.0
    assert m["coverage_single_deg"] < 360.0 <= m["coverage_deg"] + 1e-9
    # The second images lie in the top of the frame, >= 250 px from every single-view stripe
    # (measured): none reaches a ±1 mm search band.
    assert m["ghost_in_band_pct"] == 0.0


@pytest.mark.parametrize("shift_px,disturbed", [(1.0, True), (50.0, False)])
def test_a_ghost_stripe_on_a_search_segment_is_found(shift_px, disturbed):
    """Put a fake double-reflection stripe ``shift_px`` below the direct view's stripe."""
    import dataclasses

    from lts360.experiments.design_space.trial import GHOST_TOLERANCE_PX, _ghost_in_band

    assert (shift_px < GHOST_TOLERANCE_PX) == disturbed
    rig = load_rig("paper")
    cov = coverage(rig, 10.0)
    fake = dataclasses.replace(
        cov, measured={**cov.measured, "left-right": cov.measured["direct"]},
        image_uv={**cov.image_uv, "left-right": cov.image_uv["direct"] + [0.0, shift_px]})
    mask = _ghost_in_band(rig, fake, [(), (0,), (1,)], [(0, 1), (1, 0)], 1.0)
    if disturbed:
        assert mask[cov.measured["direct"]].all()
    else:
        assert not mask.any()


def test_an_invalid_rig_gives_nan_and_a_status():
    with pytest.raises(RigError):
        design_rig(40.0, INVALID_BETA_DEG)
    out = design_space_trial(Trial(3, {"alpha_deg": 40.0, "beta_deg": INVALID_BETA_DEG,
                                       "draws": 2}, 7))
    assert int(out.values["status"]) == 1
    for name in ("coverage_deg", "overlap_mirror_mirror_deg", "multi_reflection_pct",
                 "radius_std_mm", "point_rms_mm"):
        assert math.isnan(float(out.values[name])), name
    assert out.values["radius_error_mm"].shape == (2,)
    assert np.isnan(out.values["radius_error_mm"]).all()
    assert rig_status(40.0, INVALID_BETA_DEG).startswith(STATUS[1] + ": design.beta_deg")
    assert rig_status(*PAPER_DESIGN) == "ok"


@pytest.mark.parametrize("params,match", [({"draws": 1}, "draws"), ({"draws": -2}, "draws"),
                                          ({"spp": 0}, "spp"), ({"scale": 1.5}, "scale")])
def test_bad_trial_settings_are_rejected(params, match):
    with pytest.raises(ValueError, match=match):
        design_space_trial(Trial(0, {"alpha_deg": 40.0, "beta_deg": 90.0, **params}, 1))


def test_study_arguments_are_checked(tmp_path):
    with pytest.raises(ValueError, match="unique"):
        run_design_space_study(tmp_path, alpha_deg=[40, 40], beta_deg="90", draws=0)
    with pytest.raises(ValueError, match="START:STOP:STEP"):
        run_design_space_study(tmp_path, alpha_deg="40:50", beta_deg="90", draws=0)


# --- the study end to end -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def study(tmp_path_factory):
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    out = tmp_path_factory.mktemp("design-space")
    kwargs = dict(alpha_deg="40", beta_deg=[90.0, 100.0], seed=3, draws=2, scale=0.5,
                  say=lambda *_: None)
    summary = run_design_space_study(out, **kwargs)
    return out, kwargs, summary


@pytest.mark.slow
def test_study_writes_results_figures_and_readme(study):
    import xarray as xr

    out, _, summary = study
    ds = xr.load_dataset(out / "trials" / "results.nc")
    assert ds.sizes["trial"] == 2 and ds.sizes["draw"] == 2
    assert (ds["status"].values == 0).all()
    # Every draw measured the gauge; radius noise of a few µm, not a broken measurement.
    err = ds["radius_error_mm"].values
    assert np.isfinite(err).all() and np.abs(err).max() < 0.02
    assert (ds["radius_std_mm"].values > 0).all() and (ds["radius_std_mm"].values < 0.02).all()
    assert (ds["measured_coverage_deg"].values > 300.0).all()
    for name in ("grid.nc", "summary.json", "README.md", "design-space-coverage.png",
                 "design-space-overlap.png", "design-space-multiple-reflections.png",
                 "design-space-radius-uncertainty.png"):
        assert (out / name).is_file(), name
    readme = (out / "README.md").read_text()
    assert "lts360 study design-space --alpha-deg 40 --beta-deg 90:100:10" in readme
    assert "root seed 3" in readme and "optimum" in readme
    g = summary["grid"]
    assert g["alpha_deg"] == [40.0] and g["beta_deg"] == [90.0, 100.0]
    assert np.shape(g["radius_std_mm"]) == (1, 2)
    assert summary["paper"]["coverage_single_deg"] == pytest.approx(360.0)
    opt = summary["optimum"]
    assert opt is not None and opt["beta_deg"] in (90.0, 100.0)
    assert opt["radius_std_mm"] == min(v for v in g["radius_std_mm"][0] if v is not None)
    text = format_design_space(summary)
    assert "radius standard deviation" in text and "optimum: α = 40°" in text


@pytest.mark.slow
def test_rerunning_the_study_resumes(study):
    out, kwargs, first = study
    files = sorted((out / "trials" / "trials").glob("trial_*.nc"))
    stamps = [f.stat().st_mtime_ns for f in files]
    again = run_design_space_study(out, **kwargs)
    assert again["n_run"] == 0 and first["n_run"] == 2
    assert sorted((out / "trials" / "trials").glob("trial_*.nc")) == files
    assert [f.stat().st_mtime_ns for f in files] == stamps
    assert again["grid"]["radius_std_mm"] == first["grid"]["radius_std_mm"]
    assert trial_path(out / "trials", 1) in files


def test_a_study_with_an_invalid_rig_finishes(tmp_path):
    summary = run_design_space_study(tmp_path, alpha_deg="40", beta_deg=[INVALID_BETA_DEG, 90.0],
                                     draws=0, say=lambda *_: None)
    assert summary["grid"]["status"] == [[1.0, 0.0]]
    assert summary["grid"]["coverage_deg"][0][0] is None
    assert summary["invalid"][0]["status"].startswith("invalid rig: design.beta_deg")
    # Geometry only: no radius uncertainty, so no optimum; the figures are still written.
    assert summary["optimum"] is None
    assert (tmp_path / "design-space-overlap.png").is_file()
    assert "invalid rig" in (tmp_path / "README.md").read_text()

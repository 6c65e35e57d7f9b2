"""The studies of issue 6: closed forms of their statistics, and each study end to end on a
tiny configuration (the real runs and their numbers are in STUDIES.md)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import xarray as xr

from lts360.experiments.gauge_study import (
    GAUGE_DIAMETER_MM,
    PAPER_TABLE,
    gauge_placements,
    gauge_table,
)
from lts360.experiments.monte_carlo import (
    _tolerance,
    adaptive_stable,
    coverage_interval,
    dorsch_speckle_limit_um,
)


def test_placements_are_seeded_and_within_the_tolerance():
    a, b = gauge_placements(20, 3), gauge_placements(20, 3)
    assert a == b and a != gauge_placements(20, 4)
    from lts360.scenes.objects import build_object

    for p in a:
        pl = build_object(p["spec"]).placement
        assert math.hypot(pl.x_mm, pl.y_mm) <= 0.3 + 1e-9 and 0 <= pl.tilt_deg <= 0.3


def test_the_paper_recipe_reproduces_the_paper_table():
    """With the paper's mean error and worst-case std, the paper's U and maximum error."""
    ds = xr.Dataset({"radius_error_mm": ("trial", [0.015] * 10),
                     "point_std_mm": ("trial", [0.020] * 9 + [0.025]),
                     "coverage_deg": ("trial", [360.0] * 10)})
    t = gauge_table(ds)
    assert t["worst_std_mm"] == 0.025
    assert t["expanded_uncertainty_mm"] == pytest.approx(PAPER_TABLE["expanded_uncertainty_mm"],
                                                         abs=0.0005)
    assert t["max_error_mm"] == pytest.approx(0.065, abs=0.001)  # the paper rounds to 0.067
    assert t["temperature_mm"] == pytest.approx(11.5e-6 * GAUGE_DIAMETER_MM * 5.0)


def test_coverage_interval_of_a_known_distribution():
    y = np.random.default_rng(0).uniform(0.0, 1.0, 100_000)
    lo, hi = coverage_interval(y, 0.95)
    assert lo == pytest.approx(0.025, abs=0.003) and hi == pytest.approx(0.975, abs=0.003)
    z = np.random.default_rng(1).normal(0.0, 1.0, 100_000)
    lo, hi = coverage_interval(z, 0.95)
    assert lo == pytest.approx(-1.96, abs=0.03) and hi == pytest.approx(1.96, abs=0.03)


def test_adaptive_tolerance_and_stopping_rule():
    assert _tolerance(0.0234, 2) == pytest.approx(0.0005)  # JCGM 101 §7.9.2 example style
    assert _tolerance(23.4, 2) == pytest.approx(0.5)
    rng = np.random.default_rng(2)
    few = [rng.normal(0, 10, 10) for _ in range(3)]
    many = [rng.normal(0, 10, 20_000) for _ in range(20)]
    assert not adaptive_stable(few, n_dig=2)[0]
    stable, info = adaptive_stable(many, n_dig=1)
    assert stable and info["h"] == 20


def test_dorsch_speckle_limit_for_the_paper_optics():
    from lts360.scenes.rig_io import load_rig

    rig = load_rig("paper")
    d = dorsch_speckle_limit_um(rig)
    cam = rig.camera
    sin_u = (cam.focal_length_mm / cam.f_number) / (2 * np.linalg.norm(cam.center_mm))
    expect = 0.66 / (2 * math.pi * sin_u * math.sin(math.radians(40.0)))  # C = 1
    assert d["contrast"] == 1.0
    assert d["delta_z_um"] == pytest.approx(expect)
    assert 0.2 < d["pixel_contrast"] < 0.5


mi = pytest.importorskip("mitsuba", reason="the study runs render")


@pytest.mark.slow
def test_plug_gauge_study_end_to_end(tmp_path, truth_calibration):
    """The study as a user measures by default (§4.4, mastered with the gauge's diameter, each
    placement corrected by its twin), with each step on and off on the same images."""
    from lts360.experiments.gauge_study import STEPS, format_gauge_table, run_plug_gauge_study

    table = run_plug_gauge_study(tmp_path, trials=2, calibration=truth_calibration, noise="none",
                                 say=lambda *_: None)
    assert table["n_measurements"] == 2 and table["mean_coverage_deg"] > 355.0
    # True calibration, no noise, master and twin: within 3 µm (see STUDIES.md).
    assert table["ours"] == "c44_master_twin"
    assert abs(table["mean_radius_error_mm"]) < 0.003 and table["worst_std_mm"] < 0.015
    steps = table["steps"]
    assert list(steps) == [k for k, _, _ in STEPS]
    # ours is one of the steps, measured once: the same numbers
    assert steps["c44_master_twin"]["mean_radius_error_mm"] == table["mean_radius_error_mm"]
    # §4.4 alone fits the radius freely: its size error is the sheet's bias, several µm
    assert abs(steps["c44"]["mean_radius_error_mm"]) > abs(table["mean_radius_error_mm"])
    text = format_gauge_table(table)
    assert "§4.4 + master + twin" in text and "<- lts360" in text
    for name in ("table.txt", "plug-gauge.png", "calibration-compensated.json",
                 "calibration-compensated-master.json", "calibration-compensated-master-twin.json"):
        assert (tmp_path / name).is_file(), name
    assert len(list((tmp_path / "clouds").glob("*.ply"))) == 2


@pytest.mark.slow
def test_monte_carlo_study_end_to_end(tmp_path, truth_calibration):
    from lts360.experiments.monte_carlo import INPUTS, PLACEMENT_SPP, run_monte_carlo_study

    s = run_monte_carlo_study(tmp_path, calibration=truth_calibration, trials=4, batch=2,
                              sensitivity_trials=2, placements=2, workers=1, say=lambda *_: None)
    assert s["M"] == 4 and s["interval95_um"][0] <= s["mean_um"] <= s["interval95_um"][1]
    assert set(s["budget"]) == set(INPUTS) and len(s["ranking"]) == len(INPUTS)
    assert s["gum_u_um"] == pytest.approx(math.sqrt(sum(b["u_um"] ** 2 for b in s["budget"].values())))
    assert (tmp_path / "monte-carlo.png").is_file()
    again = run_monte_carlo_study(tmp_path, calibration=truth_calibration, trials=4, batch=2,
                                  sensitivity_trials=2, placements=2, workers=1,
                                  say=lambda *_: None)
    assert again["mean_um"] == s["mean_um"]  # resumed from disk: same numbers
    # each trial records the sample count of the renders it measured: trials of renders made
    # at another count are another study, not resumed
    plan = json.loads((tmp_path / "mc" / "batch_000" / "plan.json").read_text())
    assert {t["params"]["spp"] for t in plan["trials"]} == {PLACEMENT_SPP}
    import shutil

    shutil.rmtree(tmp_path / "renders")
    with pytest.raises(ValueError, match="different study"):
        run_monte_carlo_study(tmp_path, calibration=truth_calibration, trials=4, batch=2,
                              sensitivity_trials=2, placements=2, workers=1, spp=4,
                              say=lambda *_: None)


def test_monte_carlo_compensates_nominal_and_drawn_calibrations_alike(tmp_path,
                                                                     truth_calibration):
    """A calibration drawn with no uncertainty is the nominal one: the calibration-only trial
    and a trial with nothing drawn (the placement input with one placement) must read the same
    radius.  Before the fix the drawn calibration was compensated at the reference placement
    and the nominal one used the file's offsets (none here): the two differed."""
    from lts360.experiments.monte_carlo import _render_placements, mc_trial
    from lts360.experiments.runner import Trial
    from lts360.recon.model import load_calibration, save_calibration

    path = tmp_path / "calibration.json"
    save_calibration(path, dataclasses.replace(load_calibration(truth_calibration),
                                               uncertainty={}))
    renders = _render_placements(tmp_path, 1, rig="paper", seed=3, spp=4, say=lambda *_: None)
    base = {"calibration": str(path), "renders": str(renders), "placements": 1, "rig": "paper",
            "theta_step_deg": 2.0}
    drawn = mc_trial(Trial(0, dict(base, vary="calibration"), 11)).values["y_um"]
    nominal = mc_trial(Trial(1, dict(base, vary="placement"), 12)).values["y_um"]
    assert np.isfinite(drawn) and drawn == pytest.approx(nominal, abs=1e-6)
    # A compensation measured on a noisy reference image moves the result.
    noisy = mc_trial(Trial(2, dict(base, vary="compensation"), 13)).values["y_um"]
    assert np.isfinite(noisy) and abs(noisy - nominal) > 1e-3
    # Without the compensation (--no-compensate) the same image reads otherwise.
    plain = mc_trial(Trial(3, dict(base, vary="placement", compensate=False), 14)).values["y_um"]
    assert np.isfinite(plain) and abs(plain - nominal) > 1e-3
    # And the compensation is applied: the file's own (zero) offsets would read otherwise.
    from lts360.experiments.monte_carlo import _nominal_calibration

    cal = _nominal_calibration(str(path), str(renders), "paper", 2.0)
    assert set(cal.view_offsets_mm) == {"left", "right"}
    assert max(np.abs(v).max() for v in cal.view_offsets_mm.values()) > 0
    # Mastered with the gauge's known diameter on the same (noise-free) reference image: the
    # size is set by the master, where §4.4 alone fits the radius freely.
    mastered = mc_trial(Trial(1, dict(base, vary="placement", master=True), 12)).values["y_um"]
    assert abs(mastered) < 1.0 and abs(mastered) < abs(nominal) - 1.0
    # Several reference shots: the same first shot and more, so another compensation.
    four = mc_trial(Trial(2, dict(base, vary="compensation", compensation_shots=4), 13))
    assert np.isfinite(four.values["y_um"]) and abs(four.values["y_um"] - noisy) > 1e-4


def test_the_gauge_study_compensates_from_several_shots(tmp_path, truth_calibration):
    from lts360.experiments.gauge_study import _compensated_calibration
    from lts360.recon.model import load_calibration

    path = _compensated_calibration(truth_calibration, tmp_path, rig="paper", noise="none",
                                    spp=2, seed=0, shots=2)
    assert path.name == "calibration-compensated-2shots.json"
    off = load_calibration(path).view_offsets_mm
    assert set(off) == {"left", "right"} and all(np.all(np.isfinite(v)) for v in off.values())
    with pytest.raises(ValueError, match="shots"):
        _compensated_calibration(truth_calibration, tmp_path, rig="paper", noise="none",
                                 spp=2, seed=0, shots=0)


def test_the_gauge_study_masters_with_the_gauge_diameter(tmp_path, truth_calibration):
    from lts360.experiments.gauge_study import GAUGE_DIAMETER_MM, _compensated_calibration
    from lts360.recon.model import load_calibration

    path = _compensated_calibration(truth_calibration, tmp_path, rig="paper", noise="none",
                                    spp=2, seed=0, shots=1, master=True)
    assert path.name == "calibration-compensated-master.json"
    cal = load_calibration(path)
    assert set(cal.view_radial_offsets_mm) == {"direct", "left", "right"}
    assert cal.master["diameters_mm"] == [GAUGE_DIAMETER_MM]


@pytest.mark.slow
def test_plug_gauge_study_the_papers_method_alone(tmp_path, truth_calibration):
    """Each step switches off: §4.4 alone (the paper's method), no steps measured."""
    from lts360.experiments.gauge_study import run_plug_gauge_study

    table = run_plug_gauge_study(tmp_path, trials=2, calibration=truth_calibration, noise="none",
                                 master=False, bias_model="none", steps=False,
                                 say=lambda *_: None)
    assert table["n_measurements"] == 2 and table["ours"] == "c44" and "steps" not in table
    # True calibration, no noise: a few µm (sheet bias and the §4.4 compensation).
    assert abs(table["mean_radius_error_mm"]) < 0.015 and table["worst_std_mm"] < 0.015
    assert (tmp_path / "calibration-compensated.json").is_file()
    assert not list(tmp_path.glob("calibration-compensated-master*.json"))


def test_examples_and_algorithms_studies_end_to_end(tmp_path):
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.algorithms import METHODS, run_algorithms_study
    from lts360.experiments.examples_study import run_examples_study

    ex = run_examples_study(tmp_path / "ex", objects=["alu-pipe"], section_scale=0.04,
                            noise="none")
    assert ex["alu-pipe"]["sections"] == 1 and ex["alu-pipe"]["coverage_deg"] > 340.0
    assert ex["alu-pipe"]["rms_mm"] < 0.1
    assert (tmp_path / "ex" / "clouds" / "alu-pipe.ply").is_file()
    report = json.loads((tmp_path / "ex" / "inspection" / "alu-pipe" / "inspection.json")
                        .read_text())
    # the true section's 3 lobes of 30 µm (0.5° bins take 3e-5 of them off: 0.9 nm)
    assert report["sections"][0]["truth"]["a3_mm"] == pytest.approx(0.03, abs=5e-6)
    al = run_algorithms_study(tmp_path / "al", objects=["plug-gauge"], noises=("none",),
                              repeats=1, theta_step_deg=0.5, say=lambda *_: None)
    rows = al["plug-gauge"]["none"]
    assert set(rows) == set(METHODS)
    for method, r in rows.items():
        assert abs(r["bias_um"]) < 15 and r["rms_um"] < 30, (method, r)


def test_examples_study_with_interreflections_and_the_polished_shaft(tmp_path):
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    import xarray as xr

    from lts360.experiments.examples_study import run_examples_study

    ex = run_examples_study(tmp_path / "ex", objects=["polished-shaft"], section_scale=0.04,
                            noise="none", max_scatter=1)
    row = ex["polished-shaft"]
    assert row["sections"] == 1 and row["figure"] == 0 and row["coverage_deg"] > 200.0  # measured
    ds = xr.open_dataset(tmp_path / "ex" / "trials" / "results.nc")
    assert int(ds["max_scatter"].values[0]) == 1  # the trial rendered with interreflections
    with pytest.raises(ValueError, match="polished-shaft"):
        run_examples_study(tmp_path / "ex2", objects=["teapot"])


def test_a_calibration_rewritten_under_the_same_name_is_read_again(tmp_path, truth_calibration):
    """The per-process plan cache is keyed on the file's version, not only its name."""
    import os
    import shutil

    from lts360.experiments.gauge_study import _plan
    from lts360.recon.model import load_calibration, save_calibration

    path = tmp_path / "calibration.json"
    shutil.copy(truth_calibration, path)
    first = _plan(path, 10.0, 0.2, 1.0, 0.05)[0]
    assert first.view_offsets_mm in (None, {}) or not any(np.any(v) for v in first.view_offsets_mm.values())
    cal = dataclasses.replace(load_calibration(path), view_offsets_mm={"left": np.array([0.01, 0.0])})
    save_calibration(path, cal)
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10**9))
    second = _plan(path, 10.0, 0.2, 1.0, 0.05)[0]
    np.testing.assert_allclose(second.view_offsets_mm["left"], [0.01, 0.0])
    assert _plan(path, 10.0, 0.2, 1.0, 0.05)[0] is second  # unchanged file: cached


def test_gauge_results_against_the_distance_from_the_axis():
    import xarray as xr

    from lts360.experiments.gauge_study import by_offset, gauge_placements, placement_band_mm

    off = np.array([0.1, 0.2, 1.1, 2.9, 3.0])
    ds = xr.Dataset({"offset_mm": ("trial", off),
                     "radius_error_mm": ("trial", np.array([-4, -4, -5, -6, -6]) * 1e-3),
                     "view_mean_mm": (("trial", "view"), np.array([[-5, -3, -4]] * 5) * 1e-3)})
    rows = by_offset(ds, bins=3)
    assert [r["n"] for r in rows] == [2, 1, 2]
    assert rows[-1]["mean_radius_error_mm"] == pytest.approx(-6e-3)
    assert rows[0]["view_spread_mm"] == pytest.approx(2e-3)
    assert placement_band_mm(0.3) == 1.0 and placement_band_mm(3.3) == pytest.approx(4.0)
    specs = gauge_placements(50, 0, offset_mm=3.0)
    r = [float(np.hypot(*[float(kv.split("=")[1]) for kv in s["spec"].split(",")[1:3]]))
         for s in specs]
    assert max(r) <= 3.0 and max(r) > 2.0


def test_format_mc_prints_the_speckle_figures():
    from lts360.experiments.monte_carlo import format_mc

    s = {"M": 10, "mean_um": -6.4, "u_um": 6.3, "interval95_um": [-18.7, 6.0], "gum_u_um": 6.0,
         "ranking": ["speckle"], "budget": {"speckle": {"u_um": 1.9, "mean_um": -7.3, "M": 50}},
         "dorsch": {"contrast": 1.0, "pixel_contrast": 0.34, "sin_u_obs": 0.0086,
                    "triangulation_deg": 40.0, "delta_z_um": 18.9},
         "speckle_model_point_um": {"pixel": 34.4, "dorsch": 20.5}, "speckle_point_std_um": 33.0}
    text = format_mc(s)
    assert "δz = 18.9 µm (C = 1" in text
    assert "34.4 µm (the simulator's pixel speckle, contrast 0.340" in text
    assert "simulated speckle-only point scatter 33.0 µm" in text


def test_bias_study_end_to_end(tmp_path):
    """One gauge, measured as it comes and twin-corrected: the table, the trials, and a bias
    the twin reduces (Ø12 mm: −6 µm as measured at 16 spp)."""
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.bias_study import format_bias_table, run_bias_study

    table = run_bias_study(tmp_path, diameters_mm=(12.0,), placements_mm=((0.0, 0.0),),
                           spp=4, twin_spp=16)
    (row,) = table["rows"]
    assert row["n_valid"] > 4000
    assert row["bias_plain_um"] < -3.0
    assert abs(row["bias_twin_um"]) < 0.5 * abs(row["bias_plain_um"])
    assert len(row["views_twin_um"]) == 3
    assert "twin-corrected" in format_bias_table(table)
    for name in ("table.json", "table.txt", "trials/results.nc"):
        assert (tmp_path / name).is_file()


def test_a_gauge_study_names_what_its_column_measured():
    """Every configuration's column says what it did, also one that is not a step of the table
    (no §4.4 but the twin): the study's column was unlabelled there."""
    from lts360.experiments.gauge_study import STEPS, _config_label, format_gauge_table

    assert [_config_label(*conf) for _, _, conf in STEPS] == [
        "no compensation", "§4.4", "§4.4 + master", "§4.4 + twin", "§4.4 + master + twin"]
    assert _config_label(False, True, "twin") == "no compensation + twin"  # a master needs §4.4
    row = {"mean_radius_error_mm": 0.001, "worst_std_mm": 0.03, "temperature_mm": 0.001,
           "resolution_mm": 0.001, "expanded_uncertainty_mm": 0.06, "max_error_mm": 0.061,
           "n_measurements": 10, "mean_coverage_deg": 360.0}
    text = format_gauge_table(dict(row, ours="", ours_label="no compensation + twin"))
    assert "(lts360: no compensation + twin)" in text


def test_a_study_refuses_a_calibration_of_another_rig(tmp_path, truth_calibration):
    """A calibration records the rig it was made with; a study that would render with another
    (the f/8 lens against the paper rig's f/2.8) refuses it in one line before rendering — it
    ran before, silently measuring f/2.8 images with an f/8 twin.  The same rig under another
    name (a lab's copy of the TOML) and a calibration without a record pass."""
    import dataclasses

    from lts360.experiments.gauge_study import check_calibration_rig
    from lts360.experiments.monte_carlo import run_monte_carlo_study
    from lts360.recon.model import load_calibration, save_calibration
    from lts360.scenes.rig_io import load_rig, rig_to_toml

    f8 = tmp_path / "f8.json"
    cal = load_calibration(truth_calibration)
    save_calibration(f8, dataclasses.replace(cal, optics={
        "rig": "paper-f8", "rig_toml": rig_to_toml(load_rig("paper-f8"))}))
    with pytest.raises(ValueError, match="not the rig the calibration .* made with .'paper-f8'"):
        run_monte_carlo_study(tmp_path / "mc", calibration=f8, rig="paper", trials=2)
    assert not (tmp_path / "mc" / "renders").exists()
    copy = tmp_path / "lab.toml"
    copy.write_text(rig_to_toml(load_rig("paper-f8")).replace('"paper-f8"', '"lab"'))
    check_calibration_rig(f8, str(copy))
    check_calibration_rig(f8, "paper-f8")
    none = tmp_path / "none.json"
    save_calibration(none, dataclasses.replace(cal, optics={}))
    check_calibration_rig(none, "paper")

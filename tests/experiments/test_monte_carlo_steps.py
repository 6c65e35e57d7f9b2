"""The Monte Carlo measures as a user does: §4.4 + master + twin by default, each switchable,
and the paper's method measured on the same draws (issue 29)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from lts360.cli import build_parser


def test_the_monte_carlo_defaults_are_master_and_twin():
    from lts360.experiments.monte_carlo import MC_STEPS, run_monte_carlo_study

    sig = inspect.signature(run_monte_carlo_study).parameters
    assert sig["master"].default is True and sig["bias_model"].default == "twin"
    assert sig["steps"].default is True
    assert [k for k, _, _ in MC_STEPS] == ["c44", "c44_master", "c44_master_twin"]
    parse = build_parser().parse_args
    a = parse(["study", "monte-carlo", "--out", "s"])
    assert a.master is None and a.bias_model == "twin" and a.steps  # None: on unless --no-master
    assert a.twin_per == "trial" and sig["twin_per"].default == "trial"
    assert parse(["study", "monte-carlo", "--out", "s", "--twin-per", "placement"]).twin_per \
        == "placement"
    a = parse(["study", "monte-carlo", "--out", "s", "--no-master", "--bias-model", "none",
               "--no-steps"])
    assert a.master is False and a.bias_model == "none" and not a.steps


def test_the_monte_carlo_refuses_an_unknown_bias_model(tmp_path):
    from lts360.experiments.monte_carlo import run_monte_carlo_study

    with pytest.raises(ValueError, match="bias_model"):
        run_monte_carlo_study(tmp_path, calibration="unused.json", bias_model="lsq")
    assert not (tmp_path / "renders").exists()  # refused before anything was rendered


def test_each_full_trial_draws_its_own_twin_render_noise():
    """The twin's samples are keyed to the pixel and the seed: a trial whose every input
    varies renders its twin with a seed of its own (different between trials, the same for
    the same trial), a one-at-a-time run with the twin's default."""
    from lts360.experiments.monte_carlo import INPUTS, _twin_seed

    all_inputs = set(INPUTS)
    a = [_twin_seed(all_inputs, np.random.default_rng(t).integers(0, 2**31, size=5))
         for t in range(50)]
    assert len(set(a)) == 50 and all(0 <= x < 2**32 for x in a)
    seeds = np.random.default_rng(3).integers(0, 2**31, size=5)
    assert _twin_seed(all_inputs, seeds) == _twin_seed(all_inputs, seeds.copy())
    assert all(_twin_seed({name}, seeds) is None for name in INPUTS)


def test_the_monte_carlo_twin_needs_the_calibrations_optics(tmp_path, truth_calibration):
    import dataclasses

    from lts360.experiments.monte_carlo import run_monte_carlo_study
    from lts360.recon.model import load_calibration, save_calibration

    old = tmp_path / "old.json"
    save_calibration(old, dataclasses.replace(load_calibration(truth_calibration), optics={}))
    with pytest.raises(ValueError, match="records no optics"):
        run_monte_carlo_study(tmp_path / "mc", calibration=old, placements=1,
                              say=lambda *_: None, spp=1)
    assert not (tmp_path / "mc" / "renders").exists()  # refused before any render


def test_a_twin_corrected_trial_differs_from_the_plain_one_by_the_twins_correction(
        tmp_path, truth_calibration):
    """The same draw measured with and without the twin: the twin-corrected radius error is
    the plain one less the mean bias the twin removed (the circle fit of points each moved
    by −b(θ) moves its radius by −mean b, to first order), and, without the master (whose
    shots the twin corrects too), the plain measurement is the §4.4-only trial itself."""
    from lts360.experiments.monte_carlo import _render_placements, mc_trial
    from lts360.experiments.runner import Trial

    renders = _render_placements(tmp_path, 1, rig="paper", seed=3, spp=4, say=lambda *_: None)
    base = {"calibration": str(truth_calibration), "renders": str(renders), "placements": 1,
            "rig": "paper", "theta_step_deg": 2.0, "vary": "sensor_noise"}
    plain = mc_trial(Trial(0, base, 21)).values
    twin = mc_trial(Trial(0, dict(base, bias_model="twin"), 21)).values
    assert "y_no_twin_um" not in plain
    assert float(twin["y_no_twin_um"]) == pytest.approx(float(plain["y_um"]), abs=1e-9)
    b = float(twin["twin_bias_um"])
    assert np.isfinite(b) and abs(b) > 1.0  # the paper rig's line-centre bias: µm, not zero
    moved = float(twin["y_um"]) - float(twin["y_no_twin_um"])
    assert moved == pytest.approx(-b, abs=0.3 * abs(b))
    # With the steps: the configuration's own y among them, the paper's method the plain one.
    steps = mc_trial(Trial(0, dict(base, bias_model="twin", master=True, steps=True), 21)).values
    assert float(steps["y_c44_master_twin_um"]) == float(steps["y_um"])
    assert float(steps["y_c44_um"]) == pytest.approx(float(plain["y_um"]), abs=1e-9)
    assert abs(float(steps["y_c44_master_um"]) - float(steps["y_c44_um"])) > 1e-3


def test_a_trials_configurations_share_one_plan_and_measure_as_with_their_own(
        tmp_path, truth_calibration):
    """The configurations of a draw differ only by their compensation (§4.4 offsets,
    mastering), which moves the measured points afterwards: they share one inverse plan, and
    each measures bit for bit as with a plan of its own; another geometry gets its own plan."""
    import dataclasses
    from types import SimpleNamespace

    from lts360.experiments.mc_measure import _grid, _placement, _plan, _uncompensated
    from lts360.experiments.monte_carlo import _render_placements
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    renders = _render_placements(tmp_path, 1, rig="paper", seed=3, spp=4, say=lambda *_: None)
    Y, L, _ = _placement(str(renders / "placement_00"))
    image, _, _ = sensor_image(load_rig("paper"),
                               SimpleNamespace(radiance_W_m2_sr=Y, laser_W_m2_sr=L), noise="none")
    base = _uncompensated(str(truth_calibration))
    names = base.mirror_names
    comp = dataclasses.replace(base, view_offsets_mm={n: np.array([0.01, -0.02]) for n in names},
                               view_radial_offsets_mm={n: 0.003 for n in names})
    grid, memo = _grid(2.0), {}
    for cal, flag in ((base, False), (comp, True)):
        shared = inverse_triangulate(image, cal, grid, compensate=flag, plan=_plan(cal, grid, memo))
        own = inverse_triangulate(image, cal, grid, compensate=flag)
        for n, v in own.views.items():
            assert np.array_equal(shared.views[n].r_mm, v.r_mm, equal_nan=True)
            assert np.array_equal(shared.views[n].valid, v.valid)
    assert np.any(np.isfinite(own.views[names[0]].r_mm))
    plans = [v for k, v in memo.items() if k[0] == "plan"]
    assert len(plans) == 1 and plans[0].cal is base
    other = dataclasses.replace(comp, K=comp.K * np.array([[1.001], [1.0], [1.0]]))
    p = _plan(other, grid, memo)
    assert p.cal is other and memo[("plan", id(grid))].cal is other  # made anew for it


def test_a_draws_image_is_sampled_once_and_each_compensation_applied_as_measured(
        tmp_path, truth_calibration):
    """The configurations of a draw read the same image: it is sampled once (its raw peaks)
    and each calibration's compensation applied afterwards (``recompensated``), bit for bit
    the measurement ``inverse_triangulate`` makes with that calibration."""
    import dataclasses
    from types import SimpleNamespace

    from lts360.experiments.mc_measure import _grid, _placement, _uncompensated, measure
    from lts360.experiments.monte_carlo import _render_placements
    from lts360.recon.triangulation.inverse import inverse_triangulate, recompensated
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    renders = _render_placements(tmp_path, 1, rig="paper", seed=3, spp=4, say=lambda *_: None)
    Y, L, _ = _placement(str(renders / "placement_00"))
    image, _, _ = sensor_image(load_rig("paper"),
                               SimpleNamespace(radiance_W_m2_sr=Y, laser_W_m2_sr=L),
                               noise="realistic", seed=5)
    base = _uncompensated(str(truth_calibration))
    names = base.mirror_names
    comp = dataclasses.replace(base, view_offsets_mm={n: np.array([0.01, -0.02]) for n in names},
                               view_radial_offsets_mm={n: 0.003 for n in names},
                               view_scales={n: 1.0004 for n in names})
    grid, memo = _grid(2.0), {}
    for cal in (base, comp, base):
        flag = bool(cal.view_offsets_mm)
        got = measure(image, cal, grid, "none", memo)[0]
        own = inverse_triangulate(image, cal, grid, compensate=flag)
        assert got.compensated is flag
        for n, v in own.views.items():
            assert np.array_equal(got.views[n].r_mm, v.r_mm, equal_nan=True)
            assert np.array_equal(got.views[n].r_raw_mm, v.r_raw_mm, equal_nan=True)
            assert np.array_equal(got.views[n].offset_mm, v.offset_mm)
    assert sum(k[0] == "raw" for k in memo) == 1  # one sampling of the image for all three
    moved = recompensated(own, comp)
    assert not np.array_equal(moved.views[names[0]].r_mm, own.views[names[0]].r_mm,
                              equal_nan=True)


def test_the_frozen_twin_is_the_twin_of_the_noise_free_placement(tmp_path, truth_calibration):
    """``twin_per="placement"``: each placement's twin correction made once, from its
    noise-free image and the nominal calibration.  A draw that is that very image (only the
    placement varies) measures as with its own twin; a noisy draw gets the same correction
    subtracted (its mean over the draw's points moves y by about minus it), and the
    configurations without the twin are those of the per-trial twin, value for value."""
    from lts360.experiments.monte_carlo import _render_placements, mc_trial
    from lts360.experiments.runner import Trial

    renders = _render_placements(tmp_path, 1, rig="paper", seed=3, spp=4, say=lambda *_: None)
    base = {"calibration": str(truth_calibration), "renders": str(renders), "placements": 1,
            "rig": "paper", "theta_step_deg": 2.0, "vary": "placement", "master": True,
            "bias_model": "twin", "steps": True}
    own = mc_trial(Trial(0, base, 4)).values
    frozen = mc_trial(Trial(0, dict(base, twin_per="placement"), 4)).values
    for key in ("y_um", "twin_bias_um", "y_no_twin_um", "y_c44_um", "y_c44_master_um"):
        assert float(frozen[key]) == pytest.approx(float(own[key]), abs=1e-6), key
    noisy = dict(base, vary="sensor_noise")
    a = mc_trial(Trial(0, dict(noisy, twin_per="placement"), 8)).values
    b = mc_trial(Trial(0, dict(noisy, twin_per="placement"), 9)).values
    for v in (a, b):
        moved = float(v["y_um"]) - float(v["y_no_twin_um"])
        b_um = float(v["twin_bias_um"])
        assert abs(b_um) > 1.0 and moved == pytest.approx(-b_um, abs=0.3 * abs(b_um))
        # the same correction; its mean differs only by which points the draw found
        assert b_um == pytest.approx(float(own["twin_bias_um"]), abs=0.3)
    assert float(a["y_um"]) != float(b["y_um"])
    trial = mc_trial(Trial(0, noisy, 8)).values
    assert float(trial["y_c44_um"]) == float(a["y_c44_um"])  # no twin in it: the same
    with pytest.raises(ValueError, match="twin_per"):
        mc_trial(Trial(0, dict(base, twin_per="scan"), 4))


def test_inputs_varied_together_add_up_where_they_do_not_interact(tmp_path, truth_calibration):
    """``vary`` may name several inputs (``a+b``) or ``none``: the nominal measurement is the
    same for every seed; ``sensor_noise+temperature`` moves y by the sum of what each moves
    it by alone on the same seed (the temperature only adds the gauge's thermal growth); an
    unknown name is refused."""
    from lts360.experiments.monte_carlo import INPUTS, mc_trial, vary_set
    from lts360.experiments.runner import Trial

    assert vary_set("all") == set(INPUTS) and vary_set("none") == set()
    assert vary_set("speckle+placement") == {"speckle", "placement"}
    with pytest.raises(ValueError, match="unknown input"):
        vary_set("speckle+wind")
    renders = _render_placements_once(tmp_path)
    base = {"calibration": str(truth_calibration), "renders": str(renders), "placements": 1,
            "rig": "paper", "theta_step_deg": 2.0, "master": False, "bias_model": "none"}

    def y(vary, seed):
        return float(mc_trial(Trial(0, dict(base, vary=vary), seed)).values["y_um"])

    y0 = y("none", 1)
    assert y("none", 2) == y0
    for seed in (5, 6):
        both = y("sensor_noise+temperature", seed)
        alone = (y("sensor_noise", seed) - y0) + (y("temperature", seed) - y0)
        assert both - y0 == pytest.approx(alone, abs=1e-9)
        assert abs(both - y0) > 0.01  # each moved it
    with pytest.raises(ValueError, match="unknown input"):
        mc_trial(Trial(0, dict(base, vary="speckle+wind"), 1))


def _render_placements_once(tmp_path):
    from lts360.experiments.monte_carlo import _render_placements

    return _render_placements(tmp_path, 1, rig="paper", seed=3, spp=4, say=lambda *_: None)


def test_a_trials_images_are_drawn_on_the_pixels_its_plan_reads(tmp_path, truth_calibration):
    """The read set holds every tap of the nominal plan, and of a plan whose points moved by
    less than its check margin: an image with speckle drawn on it alone measures bit for bit
    as the full frame's.  A plan that reads outside it (a calibration far from the nominal)
    gets the full frame."""
    import dataclasses

    from lts360.experiments.mc_measure import (
        _grid,
        _plan,
        _read,
        _uncompensated,
        read_set,
        reads_within,
        stored_render,
    )
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_pixels
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    renders = _render_placements_once(tmp_path)
    res = stored_render(str(renders / "placement_00"))
    read, check = read_set(str(truth_calibration), 2.0)
    base = _uncompensated(str(truth_calibration))
    w = base.image_size[0]
    grid = _grid(2.0)
    near = dataclasses.replace(base, K=base.K + np.array([[0, 0, 0.6], [0, 0, -0.4], [0, 0, 0]]))
    far = dataclasses.replace(base, K=base.K + np.array([[0, 0, 6.0], [0, 0, 0], [0, 0, 0]]))
    for cal, inside in ((base, True), (near, True), (far, False)):
        memo = {"read_set": (read, check)}
        plan = _plan(cal, grid, memo)
        taps = plan_pixels(plan, margin_px=0)
        assert bool(np.isin(taps[:, 1] * w + taps[:, 0], read).all()) is inside
        assert reads_within(plan, check) is inside
        assert (_read(memo, plan) is read) is inside
    rig = load_rig("paper")
    kw = dict(noise="none", speckle=True, speckle_seed=9)
    full = sensor_image(rig, res, **kw)[0]
    part = sensor_image(rig, res, read=read, **kw)[0]
    assert not np.array_equal(full, part)               # the unread pixels are noise-free
    for cal in (base, near):
        a = inverse_triangulate(full, cal, grid, compensate=False)
        b = inverse_triangulate(part, cal, grid, compensate=False)
        for n, v in a.views.items():
            assert np.array_equal(b.views[n].r_raw_mm, v.r_raw_mm, equal_nan=True)
        assert np.isfinite(a.views["direct"].r_raw_mm).sum() > 20

"""Residual compensation (paper §4.4): the joint circle against the paper's per-view circles."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lts360.recon.calibration.compensation import joint_view_offsets
from lts360.recon.triangulation.inverse import estimate_view_offsets
from lts360.recon.triangulation.peaks import Quality

ARCS = {"direct": (-160.0, -20.0), "left": (85.0, 235.0), "right": (-55.0, 95.0)}


def _result(shifts: dict, radius_errors: dict | None = None, r=10.0, n=600, seed=0,
            noise_mm=1e-5):
    """Three arcs of one circle (the views' θ windows of the paper rig), each translated by
    ``shifts[view]`` (a mirror miscalibration) and with its own radius error."""
    rng = np.random.default_rng(seed)
    views = {}
    for name, (a, b) in ARCS.items():
        th = np.radians(np.linspace(a, b, n))
        rr = r + (radius_errors or {}).get(name, 0.0) + rng.normal(0, noise_mm, n)
        xy = np.column_stack([rr * np.cos(th), rr * np.sin(th)]) + np.asarray(shifts.get(name, (0, 0)))
        pts = np.column_stack([xy, np.zeros(n)])
        views[name] = SimpleNamespace(name=name, r_raw_mm=np.hypot(*xy.T), raw_points_meas_mm=pts,
                                      quality=np.full(n, int(Quality.FOUND), np.uint8))
    return SimpleNamespace(views=views, accept=(Quality.FOUND,))


def test_both_recover_pure_translations():
    shifts = {"left": (0.020, -0.010), "right": (-0.030, 0.005)}
    for fn in (joint_view_offsets, estimate_view_offsets):
        off = fn(_result(shifts))
        for name, s in shifts.items():
            np.testing.assert_allclose(off[name], -np.asarray(s), atol=1e-5)


def test_the_trade_off_between_the_two():
    """The paper's free-radius circle per view ignores a view's own radius error (its centre
    stays) but its centre is poorly conditioned on a ~150° arc; the joint circle is better
    conditioned but turns a view's radius error into a translation."""
    res = _result({}, {"left": 0.005})
    assert np.linalg.norm(estimate_view_offsets(res)["left"]) < 1e-5
    assert np.linalg.norm(joint_view_offsets(res)["left"]) > 0.002
    spread = {"paper": [], "joint": []}
    for seed in range(20):
        noisy = _result({}, seed=seed, noise_mm=0.005)
        spread["paper"].append(estimate_view_offsets(noisy)["left"])
        spread["joint"].append(joint_view_offsets(noisy)["left"])
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in spread.items()}
    assert rms["joint"] < 0.85 * rms["paper"], rms  # measured 0.74 (20 seeds)


def test_too_few_points_is_a_clear_error():
    res = _result({})
    res.views["left"].quality[:] = int(Quality.NO_PEAK)
    with pytest.raises(ValueError, match="'left': 0 valid points"):
        joint_view_offsets(res)
    with pytest.raises(ValueError, match="no view 'front'"):
        joint_view_offsets(res, reference="front")


def _shot(centre, shifts, r, seed, noise_mm):
    c = np.asarray(centre, float)
    moved = {v: c + np.asarray(shifts.get(v, (0.0, 0.0))) for v in ARCS}
    return _result(moved, r=r, seed=seed, noise_mm=noise_mm)


def test_several_shots_share_the_offsets_and_average_their_noise():
    """Each shot its own circle (the reference moved between shots), one offset per view."""
    shifts = {"left": (0.020, -0.010), "right": (-0.030, 0.005)}
    shots = [_shot((0.3 * k, -0.2 * k), shifts, 10.0 + 0.01 * k, seed=k, noise_mm=1e-5)
             for k in range(3)]
    off = joint_view_offsets(shots)
    for name, s in shifts.items():
        np.testing.assert_allclose(off[name], -np.asarray(s), atol=1e-5)
    err = {1: [], 4: []}
    for seed in range(16):
        for k in err:
            res = [_shot((0.1 * j, 0.0), {}, 10.0, seed=100 * seed + j, noise_mm=0.005)
                   for j in range(k)]
            err[k].append(joint_view_offsets(res if k > 1 else res[0])["left"])
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in err.items()}
    assert rms[4] < 0.65 * rms[1], rms  # 1/√4 = 0.5 expected


def test_shots_with_different_views_are_refused():
    a = _result({})
    b = _result({})
    del b.views["right"]
    with pytest.raises(ValueError, match="different views"):
        joint_view_offsets([a, b])
    with pytest.raises(ValueError, match="no measurement"):
        joint_view_offsets([])


# -- mastering ---------------------------------------------------------------------------------

TRUE_T = {"left": (0.020, -0.010), "right": (-0.030, 0.005)}
TRUE_DR = {"direct": -0.004, "left": 0.006, "right": -0.009}
TRUE_S = {"direct": 1.0003, "left": 0.9995, "right": 1.0008}


def _master_shot(centre, diameter, *, scales=True, seed=0, noise_mm=0.0, n=600):
    """Raw points of a master of ``diameter`` at ``centre`` whose correction
    ``r' = s·r + δ`` along the ray, then the translation ``t``, gives the true circle."""
    rng = np.random.default_rng(seed)
    views = {}
    c = np.asarray(centre, float)
    for name, (a, b) in ARCS.items():
        th = np.radians(np.linspace(a, b, n))
        q = c + 0.5 * diameter * np.column_stack([np.cos(th), np.sin(th)])
        q = q - np.asarray(TRUE_T.get(name, (0.0, 0.0)))
        rc = np.hypot(*q.T)
        u = q / rc[:, None]
        s = TRUE_S[name] if scales else 1.0
        r_raw = (rc - TRUE_DR[name]) / s + rng.normal(0, noise_mm, n)
        xy = r_raw[:, None] * u
        views[name] = SimpleNamespace(name=name, r_raw_mm=np.hypot(*xy.T),
                                      raw_points_meas_mm=np.column_stack([xy, np.zeros(n)]),
                                      quality=np.full(n, int(Quality.FOUND), np.uint8))
    return SimpleNamespace(views=views, accept=(Quality.FOUND,))


def test_one_master_recovers_translations_and_radial_offsets_exactly():
    from lts360.recon.calibration.compensation import master_fit

    shots = [_master_shot((0.3 * k, -0.2 * k), 20.0, scales=False, seed=k) for k in range(3)]
    fit = master_fit(shots, 20.0)
    assert not fit.fitted_scale and fit.scale == {"direct": 1.0, "left": 1.0, "right": 1.0}
    for name, t in TRUE_T.items():
        np.testing.assert_allclose(fit.offsets_mm[name], t, atol=1e-9)  # noise-free: round-off
    for name, d in TRUE_DR.items():
        assert fit.radial_offset_mm[name] == pytest.approx(d, abs=1e-9)
    assert fit.rms_mm < 1e-9


def test_two_masters_recover_scales_too():
    from lts360.recon.calibration.compensation import master_fit

    shots = [_master_shot((0.2 * k, 0.1 * k), d, seed=k)
             for k, d in enumerate((12.0, 12.0, 28.0, 28.0))]
    fit = master_fit(shots, [12.0, 12.0, 28.0, 28.0], u_diameters_mm=[0.001] * 2 + [0.002] * 2)
    assert fit.fitted_scale and fit.diameters_mm == (12.0, 28.0)
    assert fit.shots_per_master == (2, 2)
    for name in ARCS:
        np.testing.assert_allclose(fit.offsets_mm.get(name, TRUE_T.get(name, (0, 0))),
                                   TRUE_T.get(name, (0, 0)), atol=1e-9)
        assert fit.radial_offset_mm[name] == pytest.approx(TRUE_DR[name], abs=1e-9)
        assert fit.scale[name] == pytest.approx(TRUE_S[name], abs=1e-11)
    # noise-free: the uncertainty is the masters' (their radii move by u/2 together)
    assert all(v > 0 for v in fit.u_master_radial_offset_mm.values())
    assert all(v < 1e-9 for v in fit.u_fit_radial_offset_mm.values())


def test_one_master_u_is_its_diameter_u_and_the_fit_covers_the_noise():
    """Over many noisy draws the radial offsets scatter as the fit predicts (σ within 30 %),
    and a master's diameter u moves every view's radial offset by u/2."""
    from lts360.recon.calibration.compensation import master_fit

    est, pred = [], []
    for seed in range(50):
        shots = [_master_shot((0.3 * k, -0.2 * k), 20.0, scales=False, seed=100 * seed + k,
                              noise_mm=0.003, n=150) for k in range(2)]
        fit = master_fit(shots, 20.0, u_diameters_mm=0.002)
        est.append([fit.radial_offset_mm[n] for n in ARCS])
        pred.append([fit.u_fit_radial_offset_mm[n] for n in ARCS])
        assert all(v == pytest.approx(0.001, rel=1e-3) for v in
                   fit.u_master_radial_offset_mm.values())
    est, pred = np.array(est), np.array(pred)
    sd = est.std(axis=0, ddof=1)
    ratio = sd / pred.mean(axis=0)
    # 50 draws: the sample σ is within −25/+30 % of the true σ with > 99 % probability
    # (χ², 49 dof)
    assert np.all((ratio > 0.75) & (ratio < 1.3)), ratio
    assert np.all(np.abs(est.mean(axis=0) - [TRUE_DR[n] for n in ARCS]) < 3 * sd / np.sqrt(50))


def test_master_bad_input_is_named():
    from lts360.recon.calibration.compensation import master_fit

    shots = [_master_shot((0, 0), 20.0, scales=False)]
    with pytest.raises(ValueError, match="must be > 0"):
        master_fit(shots, 0.0)
    with pytest.raises(ValueError, match="less than 1 mm apart"):
        master_fit(shots * 2, [20.0, 20.5])
    with pytest.raises(ValueError, match="different u"):
        master_fit(shots * 2, 20.0, u_diameters_mm=[0.001, 0.002])


def _central_jacobian(f, x, h=1e-6):
    return np.column_stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)])


@pytest.mark.parametrize("fit_scale", [False, True])
def test_the_masters_jacobian_is_the_residuals_derivative(fit_scale):
    """The exact Jacobian the mastering fit hands Levenberg–Marquardt equals central
    differences of its residuals at a point away from the solution (every column: centres,
    translations, radial offsets, scales), on every point and on a selection."""
    from lts360.recon.calibration.compensation import _master_problem, _shot_views

    shots = [_master_shot((0.3, -0.2), 20.0, seed=1, noise_mm=0.002),
             _master_shot((-0.1, 0.4), 28.0, seed=2, noise_mm=0.002)]
    views, names, col = _shot_views(shots, reference="direct", min_points=10, what="test")
    problem = _master_problem(views, names, col, fit_scale)
    n_par = 2 * problem.m + 2 * problem.no + problem.nv * (2 if fit_scale else 1)
    x = np.random.default_rng(3).normal(0.0, 0.05, n_par)
    R = np.array([10.0, 14.0])
    keep = np.random.default_rng(4).random(problem.r0.size) < 0.7
    for sel in (None, keep):
        J = problem.jacobian(sel)(x)
        assert J.shape == ((problem.r0.size if sel is None else keep.sum()), n_par)
        np.testing.assert_allclose(J, _central_jacobian(problem.residual(R, sel), x),
                                   atol=1e-8, rtol=1e-6)


def test_the_joint_fit_with_its_exact_jacobian_finds_the_offsets_from_any_start():
    """joint_view_offsets (exact Jacobian) recovers noise-free pure translations to round-off
    (a wrong Jacobian stalls Levenberg–Marquardt short of it), whatever the shots' centres."""
    for seed in range(3):
        shots = [_shot((0.2 * k - 0.1, 0.1 * seed), TRUE_T, 10.0 + k, seed + 10 * k, 0.0)
                 for k in range(2)]
        off = joint_view_offsets(shots)
        for name, t in TRUE_T.items():
            np.testing.assert_allclose(off[name], -np.asarray(t), atol=1e-9)

"""The compensation's and the calibration's shares of the radius: the closed forms of
:mod:`lts360.design.shares` against the real §4.4 fit and circle fit (recon), and the model's
per-point calibration sensitivities against a numerical reconstruction."""

from __future__ import annotations

import json
import math
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import least_squares

from lts360.design import model as M
from lts360.design.params import DesignSpace
from lts360.design.shares import (
    CAMERA_NAMES,
    PLANE_NAMES,
    CalibrationCovariance,
    compensation_shares,
    tangent_basis_np,
)
from lts360.design.smallmat import spd_inverse_ridged as spd_inverse
from lts360.geometry.camera import project_points
from lts360.geometry.fit import fit_circle
from lts360.geometry.mirror import mirror_matrix
from lts360.scenes.rig_io import rig_from_dict, rig_to_toml

#: Three views' arcs of a centred section (deg): the direct view in front (−y), the mirror
#: views behind, overlapping it and each other.
ARCS = {"direct": (-160.0, -20.0), "left": (60.0, 200.0), "right": (-20.0, 120.0)}
STEP_DEG = 1.0


def _arc_theta(view):
    lo, hi = ARCS[view]
    return np.deg2rad(np.arange(lo, hi, STEP_DEG))


def _sums(weight_of):
    """Per view, the six moment sums of ``weight_of(view, θ)`` as 1-element arrays."""
    out = {}
    for v in ARCS:
        th = _arc_theta(v)
        w = weight_of(v, th)
        c, s = np.cos(th), np.sin(th)
        out[v] = [np.array([np.sum(w * b)]) for b in (1.0 + 0 * c, c, s, c * c, c * s, s * s)]
    return out


def _fake_result(points: dict):
    """A stand-in for InverseResult with the attributes the §4.4 fit reads."""
    views = {v: SimpleNamespace(r_raw_mm=np.hypot(*p.T), quality=np.zeros(len(p), int),
                                raw_points_meas_mm=np.column_stack([p, np.zeros(len(p))]))
             for v, p in points.items()}
    return SimpleNamespace(views=views, accept=(0,))


def _points(radius, centre, dr_of=None):
    out = {}
    for v in ARCS:
        th = _arc_theta(v)
        r = radius + (dr_of(v, th) if dr_of is not None else 0.0)
        out[v] = np.column_stack([centre[0] + r * np.cos(th), centre[1] + r * np.sin(th)])
    return out


def _compensated_radius(ref_pts, case_pts):
    from lts360.recon.calibration.compensation import joint_view_offsets

    off = joint_view_offsets(_fake_result(ref_pts))
    pts = [case_pts[v] + off.get(v, 0.0) for v in ARCS]
    return fit_circle(np.concatenate(pts)).radius_mm


def test_spd_inverse_matches_numpy():
    rng = np.random.default_rng(3)
    for n in (1, 3, 7):
        a = rng.normal(size=(n, n + 2))
        A = a @ a.T
        rows = [[np.array([A[i, j]]) for j in range(n)] for i in range(n)]
        inv = spd_inverse(rows, np.sqrt, ridge=0.0)
        got = np.array([[inv[i][j][0] for j in range(n)] for i in range(n)])
        np.testing.assert_allclose(got, np.linalg.inv(A), rtol=1e-9, atol=1e-12)


def test_calibration_share_equals_the_real_fits():
    """A deterministic point error (a calibration's δr^k) through the real §4.4 joint fit and
    circle fit equals the closed form, with and without compensation."""
    R0, R1, c1 = 10.0, 6.0, (2.0, -1.0)
    eps = 1e-4  # mm: small enough that the fits are linear

    def pattern(v, th):  # view-dependent: a radius error, a translation and a wobble
        k = {"direct": 0.0, "left": 1.0, "right": -0.5}[v]
        return eps * (0.3 + k * np.cos(th) + 0.7 * k * np.sin(th) + 0.2 * np.cos(3 * th))

    ones = _sums(lambda v, th: np.ones_like(th))
    case_A = ones  # the moment sums do not depend on the radius or the centre

    def dr_sums(v_th_fun):
        return {v: [[np.array([np.sum(v_th_fun(v, _arc_theta(v)) * b)])
                     for b in (1.0, np.cos(_arc_theta(v)), np.sin(_arc_theta(v)))]]
                for v in ARCS}

    d = dr_sums(pattern)
    mirrors = ["left", "right"]
    for compensate in (False, True):
        _, var = compensation_shares(case_A, ones, ones, d, d, np.eye(1), mirrors, np.sqrt,
                                     shots=1, compensate=compensate)
        ref = _points(R0, (0.0, 0.0), pattern)
        case = _points(R1, c1, pattern)
        if compensate:
            got = _compensated_radius(ref, case) - R1
        else:
            got = fit_circle(np.concatenate(list(case.values()))).radius_mm - R1
        assert math.sqrt(var[0]) == pytest.approx(abs(got), rel=1e-3), compensate


def test_compensation_share_against_monte_carlo_of_the_real_fit():
    """Noisy reference images through the real joint fit, offsets applied to noise-free case
    points: the radius scatter equals the closed-form compensation share (within the 400
    draws' interval)."""
    sigma = 0.02  # mm per point, independent
    ones = _sums(lambda v, th: np.ones_like(th))
    var_B = _sums(lambda v, th: np.full_like(th, sigma ** 2))
    var_comp, _ = compensation_shares(ones, ones, var_B, {}, {}, None, ["left", "right"],
                                      np.sqrt, shots=1, compensate=True)
    rng = np.random.default_rng(11)
    case = _points(8.0, (1.5, 0.5))
    err = []
    for _ in range(400):
        ref = _points(10.0, (0.0, 0.0), lambda v, th: rng.normal(0.0, sigma, len(th)))
        err.append(_compensated_radius(ref, case) - 8.0)
    s = float(np.std(err, ddof=1))
    assert s == pytest.approx(math.sqrt(var_comp[0]), rel=0.12)
    # two shots: half the variance
    v2, _ = compensation_shares(ones, ones, var_B, {}, {}, None, ["left", "right"], np.sqrt,
                                shots=2, compensate=True)
    assert v2[0] == pytest.approx(var_comp[0] / 2, rel=1e-12)


# --- the model's per-point calibration sensitivities --------------------------------------

CAL_NAMES = ([f"camera.{n}" for n in CAMERA_NAMES] + [f"left.{p}" for p in PLANE_NAMES]
             + [f"right.{p}" for p in PLANE_NAMES] + [f"laser.{p}" for p in PLANE_NAMES])


def _identity_cov():
    n = len(CAL_NAMES)
    return CalibrationCovariance(names=tuple(CAL_NAMES),
                                 cov=tuple(map(tuple, (np.eye(n) * 1e-8).tolist())))


def _perturbed(cam_R, pos, n_w, d_w, which, h):
    """A world plane moved by ``h`` of its camera-frame (a, b, δ)."""
    n_c = cam_R @ n_w
    d_c = d_w - n_w @ pos
    e1, e2 = tangent_basis_np(n_c)
    if which == "a":
        n_c = n_c + h * e1
    elif which == "b":
        n_c = n_c + h * e2
    else:
        d_c = d_c + h
    n_c = n_c / np.linalg.norm(n_c)
    n2 = cam_R.T @ n_c
    return n2, d_c + n2 @ pos


def _reconstructed(X, u, K, dist, R, t, T, plane):
    """The point of ``plane`` whose projection through ``T`` is ``u`` (Gauss-Newton)."""
    n, d = plane
    p0 = X - (X @ n - d) * n
    b1 = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(n, b1)

    def res(s):
        Y = p0 + s[0] * b1 + s[1] * b2
        return project_points(Y[None], K, dist, R, t, T_mirror=T)[0] - u

    sol = least_squares(res, np.zeros(2), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return p0 + sol.x[0] * b1 + sol.x[1] * b2


def _distorted_space():
    data = tomllib.loads(rig_to_toml(DesignSpace.create("paper").base))
    data["camera"]["distortion"] = [-0.12, 0.05, 0.0008, -0.0005, 0.01]
    return DesignSpace.create(rig_from_dict(data))


@pytest.mark.parametrize("distorted", [False, True])
def test_point_sensitivities_match_a_numerical_reconstruction(distorted):
    """Every calibration parameter: the model's δr^k against re-solving the stripe's pixel with
    the perturbed calibration (central differences), on a few points of each single view."""
    space = _distorted_space() if distorted else DesignSpace.create("paper")
    cond = M.Conditions(diameters_mm=(16.0,), n_theta=48, compensate=False,
                        calibration=_identity_cov())
    e = M.evaluate(space, None, cond, gradient=False, detail=True)
    rig = space.rig()
    cam = rig.camera
    K, dist, R, t = cam.K, np.asarray(cam.distortion, float), cam.R, cam.t_mm
    pos = -R.T @ t
    theta = e.detail["theta_rad"]
    planes = {m.name: m.plane for m in rig.mirrors}
    planes["laser"] = (np.array([0.0, 0.0, 1.0]), 0.0)
    checked = 0
    for view in ("direct", "left", "right"):
        det = e.detail[view]
        idx = np.flatnonzero(det["detected"][0] > 0.999)[::5]
        assert len(idx) >= 3, view
        T = np.eye(4) if view == "direct" else rig.mirror(view).T
        for i in idx:
            X = np.array([8.0 * math.cos(theta[i]), 8.0 * math.sin(theta[i]), 0.0])
            rhat = X / 8.0
            u = project_points(X[None], K, dist, R, t, T_mirror=T)[0]
            for k, name in enumerate(CAL_NAMES):
                plane, _, p = name.partition(".")
                got = det["cal_dr_mm"][k][0, i]
                vals = []
                for h in (1e-6, -1e-6):
                    K2, d2, T2, lp = K.copy(), dist.copy(), T, planes["laser"]
                    if plane == "camera":
                        hh = h * 1e3 if p in ("fx", "fy", "cx", "cy") else h
                        j = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}.get(p)
                        if j is not None:
                            K2[j] += hh
                        else:
                            d2[("k1", "k2", "p1", "p2", "k3").index(p)] += hh
                    elif plane == "laser":
                        hh = h
                        lp = _perturbed(R, pos, *planes["laser"], p, h)
                    else:
                        hh = h
                        if plane == view:
                            T2 = mirror_matrix(*_perturbed(R, pos, *planes[plane], p, h))
                    X2 = _reconstructed(X, u, K2, d2, R, t, T2, lp)
                    vals.append((rhat @ (X2 - X)) / hh)
                fd = 0.5 * (vals[0] + vals[1])
                assert got == pytest.approx(fd, rel=2e-3, abs=1e-6 * max(1.0, abs(fd))), \
                    (view, name, got, fd)
                checked += 1
    assert checked > 50


def _assert_gradient_at_three_designs(space, cond):
    """Every parameter's ∂objective against central differences (h = 1e-5 of the bounds'
    width), ≤ 1e-3 relative, at the base design and two others; a calibration share present."""
    x0 = space.base_x()
    designs = [x0, space.from_scaled(np.linspace(0.35, 0.65, len(x0))),
               space.from_scaled(np.roll(np.linspace(0.35, 0.65, len(x0)), 5))]
    for x in designs:
        e = M.evaluate(space, x, cond)
        assert e.sigma_R_cal_um.max() > 0.1
        for i, name in enumerate(space.free):
            h = 1e-5 * (space.hi[i] - space.lo[i])
            xp, xm = x.copy(), x.copy()
            xp[i] += h
            xm[i] -= h
            fd = (M.evaluate(space, xp, cond).objective
                  - M.evaluate(space, xm, cond).objective) / (2 * h)
            assert abs(e.gradient[i] - fd) <= 1e-3 * max(abs(fd), 1e-4), (name, e.gradient[i], fd)


def test_gradient_with_calibration_matches_central_differences():
    """The objective with the compensation and a calibration covariance (the demo's scale):
    every parameter at three designs, ≤ 1e-3 relative.  The floor 1e-7 µm/unit is the
    differences' round-off for parameters without effect there (mirror width): the sums'
    parallel order changes the objective's last bits, ~1e-13 of it, over h."""
    space = DesignSpace.create("paper")
    rng = np.random.default_rng(5)
    n = len(CAL_NAMES)
    a = rng.normal(size=(n, n)) * 1e-2
    cov = (a @ a.T + np.eye(n)) * np.array([0.05] * 9 + [1e-4, 1e-4, 0.02] * 3)[:, None] ** 0.5 \
        * np.array([0.05] * 9 + [1e-4, 1e-4, 0.02] * 3)[None, :] ** 0.5
    cond = M.Conditions(diameters_mm=(12.0, 24.0), n_theta=96, margin_px=20.0,
                        calibration=CalibrationCovariance(names=tuple(CAL_NAMES),
                                                          cov=tuple(map(tuple, cov.tolist()))))
    _assert_gradient_at_three_designs(space, cond)


def test_covariance_from_a_calibration_file(tmp_path):
    unc = {"camera": {"std": {"fx": 0.2, "fy": 0.1, "cx": 0.3, "cy": 0.3, "k1": 1e-3,
                              "k2": 0.0, "p1": 0.0, "p2": 0.0, "k3": 0.0}},
           "mirrors": {"left": {"cov_abd": np.diag([1e-8, 2e-8, 1e-4]).tolist()}},
           "laser_plane": {"cov_abd": np.diag([4e-8, 1e-8, 4e-4]).tolist()}}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps({"uncertainty": unc, "mirrors": [{"name": "left",
                                                                 "n": [0.7, -0.7, 0.0]}],
                                "laser_plane": {"n": [0.0, 0.6, 0.8], "d_mm": 150.0}}))
    c = CalibrationCovariance.from_file(path)
    assert c.names[:2] == ("camera.fx", "camera.fy") and c.names[-1] == "laser.delta"
    C = c.matrix
    assert C[0, 0] == pytest.approx(0.04) and C[-1, -1] == pytest.approx(4e-4)
    # a plane stored with the opposite normal: a and δ change sign (their covariances too)
    c2 = CalibrationCovariance.from_uncertainty(
        {"laser_plane": {"cov_abd": [[1.0, 0.5, 0.2], [0.5, 1.0, 0.1], [0.2, 0.1, 1.0]]}},
        {"laser": [0.0, 0.6, 0.8]})
    flipped = c2.oriented({"laser": np.array([0.0, -0.6, -0.8])})
    np.testing.assert_allclose(flipped, [[1.0, -0.5, 0.2], [-0.5, 1.0, -0.1], [0.2, -0.1, 1.0]])
    with pytest.raises(ValueError, match="no uncertainty"):
        (tmp_path / "bare.json").write_text("{}")
        CalibrationCovariance.from_file(tmp_path / "bare.json")
    with pytest.raises(ValueError, match="3×3"):
        CalibrationCovariance.from_uncertainty({"laser_plane": {"cov_abd": [[1.0]]}})


@pytest.mark.slow  # ~60 s: records the model with the per-design plan covariance
def test_gradient_with_the_plan_covariance_matches_central_differences():
    """The calibration's covariance predicted per design from the plan: the objective's
    gradient, every parameter at three designs, ≤ 1e-3 relative."""
    from lts360.design.calib_covariance import CalibrationPlan

    space = DesignSpace.create("paper")
    cond = M.Conditions(diameters_mm=(12.0, 24.0), n_theta=96, margin_px=20.0,
                        calibration=CalibrationPlan.from_rig(space.base))
    _assert_gradient_at_three_designs(space, cond)


def _mastered_radius(ref_pts, case_pts, diameter_mm):
    """The case's fitted radius after the real mastering fit on ``ref_pts``: each view's
    points moved along their ray by its radial offset, then by its translation."""
    from lts360.recon.calibration.compensation import master_fit

    fit = master_fit(_fake_result(ref_pts), diameter_mm)
    pts = []
    for v in ARCS:
        p = case_pts[v]
        rr = np.hypot(*p.T)
        p = p * ((fit.scale.get(v, 1.0) * rr + fit.radial_offset_mm.get(v, 0.0)) / rr)[:, None]
        pts.append(p + fit.offsets_mm.get(v, 0.0))
    return fit_circle(np.concatenate(pts)).radius_mm


def test_mastered_compensation_share_against_monte_carlo_of_the_real_fit():
    """A master (radius known; a radial offset per view, a translation per mirror view):
    noisy reference images through :func:`master_fit`, the offsets applied to a noise-free
    case: the radius scatter equals the closed form's ``master=True`` share (400 draws: the
    σ's 95 % interval is ±7 %; 12 % allowed, as the §4.4 test), and it is below §4.4's."""
    sigma = 0.02
    ones = _sums(lambda v, th: np.ones_like(th))
    var_B = _sums(lambda v, th: np.full_like(th, sigma ** 2))
    var_m, _ = compensation_shares(ones, ones, var_B, {}, {}, None, ["left", "right"],
                                   np.sqrt, shots=1, compensate=True, master=True)
    var_free, _ = compensation_shares(ones, ones, var_B, {}, {}, None, ["left", "right"],
                                      np.sqrt, shots=1, compensate=True)
    rng = np.random.default_rng(12)
    case = _points(10.0, (0.2, -0.1))
    err = []
    for _ in range(400):
        ref = _points(10.0, (0.0, 0.0), lambda v, th: rng.normal(0.0, sigma, len(th)))
        err.append(_mastered_radius(ref, case, 20.0) - 10.0)
    s = float(np.std(err, ddof=1))
    assert s == pytest.approx(math.sqrt(var_m[0]), rel=0.12)
    assert var_m[0] < var_free[0]

"""The design model: gradients against finite differences, closed forms, the stripe against the
geometry's projection, the smooth coverage against the hard one."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from lts360.design import model as M
from lts360.design.params import DesignSpace
from lts360.geometry.camera import project_points
from lts360.scenes.coverage import coverage, mirror_sequences, view_name
from lts360.scenes.rig_io import rig_from_dict, rig_to_toml

#: A small grid keeps the recording of the frozen model short.
COND = M.Conditions(diameters_mm=(12.0, 24.0), n_theta=96, margin_px=20.0)


@pytest.fixture(scope="module")
def space():
    return DesignSpace.create("paper")


def _designs(space):
    x0 = space.base_x()
    s1 = np.linspace(0.35, 0.65, len(x0))
    s2 = np.roll(s1, 5)
    return [x0, space.from_scaled(s1), space.from_scaled(s2)]


def test_gradient_matches_central_differences(space):
    """Every parameter at three designs, ≤ 1e-3 relative.  Differences of the same recorded
    model (float64); h = 1e-5 of the bounds' width; the floor 1e-9 µm/unit is the differences'
    round-off (ε·J/h ≈ 1e-12) for parameters without effect there (mirror width, fan)."""
    for x in _designs(space):
        e = M.evaluate(space, x, COND)
        assert np.isfinite(e.objective)
        for i, name in enumerate(space.free):
            h = 1e-5 * (space.hi[i] - space.lo[i])
            xp, xm = x.copy(), x.copy()
            xp[i] += h
            xm[i] -= h
            fd = (M.evaluate(space, xp, COND).objective
                  - M.evaluate(space, xm, COND).objective) / (2 * h)
            assert abs(e.gradient[i] - fd) <= 1e-3 * max(abs(fd), 1e-6), (name, e.gradient[i], fd)


def _aimed(space, r_mm):
    """The paper rig aimed at the section's front point (0, −r, 0): it lies on the optical axis."""
    x = space.base_x()
    x[space.free.index("camera_target_y_mm")] = -r_mm
    return x


@pytest.mark.parametrize("speckle", ["dorsch"])
def test_direct_view_sensitivity_and_speckle_floor_closed_forms(space, speckle):
    r = 10.0
    cond = M.Conditions(diameters_mm=(2 * r,), n_theta=96, speckle=speckle)
    x = _aimed(space, r)
    e = M.evaluate(space, x, cond, gradient=False, detail=True)
    j = int(np.argmin(np.abs(e.detail["theta_rad"] + math.pi / 2)))
    assert e.detail["theta_rad"][j] == pytest.approx(-math.pi / 2, abs=1e-12)
    v = space.values(x)
    a = math.radians(v["alpha_deg"])
    D = v["camera_distance_mm"]
    f_px = v["focal_length_mm"] / (space.base.camera.pixel_pitch_um * 1e-3)
    d = e.detail["direct"]
    # Sensitivity: δr = δn · D / (f_px sin α) on the optical axis (exact).
    assert d["sensitivity_mm_per_px"][0, j] == pytest.approx(D / (f_px * math.sin(a)), rel=1e-12)
    # Dorsch et al. (1994): δz = C λ / (2π sin u sin θ), C = 1, sin u = (f/N) / (2 D) (paraxial).
    lam = space.base.laser.wavelength_nm * 1e-6
    sin_u = v["focal_length_mm"] / v["f_number"] / (2 * D)
    dorsch_um = lam / (2 * math.pi * sin_u * math.sin(a)) * 1e3
    speckle_um = d["noise_px"]["speckle"][0, j] * d["sensitivity_mm_per_px"][0, j] * 1e3
    assert speckle_um == pytest.approx(dorsch_um, rel=1e-12)
    assert 15.0 < dorsch_um < 25.0  # paper rig: f/2.8 at 180 mm, α = 40°


def test_pixel_speckle_contrast_against_goodman():
    """The Gaussian-correlation closed form against the simulator's exact integral: within
    6 % over f/1.4–f/8 (measured: +3.7 % at f/1.4, +4.9 % at f/2.8, 0 at f/8 — the Airy
    correlation is not a Gaussian of the same area)."""
    from lts360.simulator.speckle import speckle_contrast_theory

    for N in (1.4, 2.8, 5.6, 8.0):
        exact = speckle_contrast_theory(5.3, 660.0, N)
        assert M.pixel_speckle_contrast(5.3, 660.0, N) == pytest.approx(exact, rel=0.06)


def _distorted_space():
    data = tomllib.loads(rig_to_toml(DesignSpace.create("paper").base))
    data["camera"]["distortion"] = [-0.12, 0.05, 0.0008, -0.0005, 0.01]
    return DesignSpace.create(rig_from_dict(data))


@pytest.mark.slow  # ~5 s: its own recording of the model (distortion)
def test_stripe_position_equals_geometry_projection():
    """Every view (double reflections too), a perturbed design with Brown distortion: the model's
    image positions are lts360.geometry's projection of the same rig (float64 round-off)."""
    sp = _distorted_space()
    x = sp.from_scaled(np.linspace(0.3, 0.7, len(sp.free)))
    cond = M.Conditions(diameters_mm=(18.0,), placement_mm=0.4, n_theta=64)
    e = M.evaluate(sp, x, cond, gradient=False, detail=True)
    rig = sp.rig(x)
    cam = rig.camera
    th = e.detail["theta_rad"]
    for k, (r, cx, cy) in enumerate(cond.cases()):
        pts = np.stack([cx + r * np.cos(th), cy + r * np.sin(th), np.zeros_like(th)], -1)
        for seq in mirror_sequences(rig.mirrors, 2):
            T = np.eye(4)
            for m in seq:
                T = rig.mirrors[m].T @ T
            uv = project_points(pts, cam.K, cam.distortion, cam.R, cam.t_mm, T_mirror=T)
            ok = np.all(np.isfinite(uv), axis=1)
            got = e.detail[view_name(seq, rig.mirrors)]["uv"][k]
            assert np.max(np.abs(got[ok] - uv[ok])) < 1e-8


@pytest.mark.slow  # ~8 s: two recordings of the model
def test_smooth_coverage_tends_to_the_hard_coverage(space):
    """Per view, the smooth measured angle approaches coverage()'s as the sharpness grows."""
    x = space.from_scaled(np.full(len(space.free), 0.45))
    rig = space.rig(x)
    r = 11.0
    hard = coverage(rig, r, theta_step_deg=1.0, max_bounces=2, margin_px=20.0)
    errs = []
    for k in (0.5, 50.0):
        cond = M.Conditions(diameters_mm=(2 * r,), n_theta=360, sharpness=k, margin_px=20.0)
        e = M.evaluate(space, x, cond, gradient=False, detail=True)
        err = 0.0
        for seq in mirror_sequences(rig.mirrors, 2):
            name = view_name(seq, rig.mirrors)
            err += abs(e.detail[name]["measured"][0].sum() - hard.measured[name].sum())
            if k == 50.0:  # thresholded at 1/2: the same samples
                assert np.sum((e.detail[name]["measured"][0] > 0.5)
                              != hard.measured[name]) <= 1, name
        errs.append(err)
    assert errs[1] < errs[0]
    assert errs[1] <= 2.0  # degrees, over all five views


def test_batch_equals_single(space):
    X = np.array(_designs(space))
    b = M.evaluate_batch(space, X, COND)
    for i, x in enumerate(X):
        e = M.evaluate(space, x, COND)
        assert b["objective"][i] == pytest.approx(e.objective, rel=1e-12)
        np.testing.assert_allclose(b["U_um"][i], e.U_um, rtol=1e-12)


def test_paper_rig_values():
    """The paper rig's model figures (recorded here; STUDIES.md compares them with the
    simulation): per-point σ_r 34.5 µm, the image's own radius σ 1.81 µm for Ø20 mm, the
    §4.4 compensation's 5.71 µm (n_theta = 96; the simulation measured 34.6, 1.78 and
    6.16 µm), full coverage; the total is the quadrature sum of the shares (with the
    line-centre bias the twin leaves)."""
    sp = DesignSpace.create("paper")
    e = M.evaluate(sp, None, M.Conditions(diameters_mm=(20.0,), n_theta=96), gradient=False)
    # The model is deterministic: each figure to 2 % of its value measured on 2026-12-04
    # (34.54, 1.813, 5.706 µm); 2 % is the numerics' room (n_theta 96 → 360 moves them by
    # 0.06 %, 0.1 % and 0.7 %), well inside the ±20 % the model claims against simulation.
    assert e.point_rms_um[0] == pytest.approx(34.54, rel=0.02)
    assert e.sigma_R_noise_um[0] == pytest.approx(1.813, rel=0.02)
    assert e.sigma_R_comp_um[0] == pytest.approx(5.706, rel=0.02)
    assert e.sigma_R_cal_um[0] < 1e-5  # the floor that keeps the square root smooth
    # the line-centre bias the twin leaves (lts360.design.bias) is the fourth share
    assert 0.0 < e.sigma_R_bias_um[0] < 0.5
    assert e.sigma_R_um[0] == pytest.approx(math.hypot(e.sigma_R_noise_um[0],
                                                       e.sigma_R_comp_um[0],
                                                       e.sigma_R_bias_um[0]), rel=1e-6)
    assert e.U_um[0] == pytest.approx(2 * e.sigma_R_um[0], rel=1e-12)
    assert e.coverage_deg[0] > 359.0

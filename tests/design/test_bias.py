"""The design model's line-centre bias (lts360.design.bias): the closed form, what a master
and the twin leave, and the model against the bias measured on rendered gauges."""

from __future__ import annotations

import numpy as np
import pytest

from lts360.design import model as M
from lts360.design.bias import TWIN_RESIDUAL_FRACTION, plane_covariance, point_bias_mm
from lts360.design.params import DesignError, DesignSpace

#: Measured at the paper rig, noise-free 64 spp, the true calibration, no correction, the
#: gauge centred (STUDIES.md "Line-centre bias and the digital twin", commit 1676999):
#: diameter -> (radius bias, direct, left, right) in µm.
MEASURED_PAPER = {6.0: (-12.66, -13.3, -11.6, -12.3), 12.0: (-6.10, -6.7, -5.7, -5.6),
                  20.0: (-4.33, -5.7, -3.7, -3.5), 28.0: (-3.61, -5.2, -2.8, -3.0)}


@pytest.fixture(scope="module")
def paper():
    space = DesignSpace.create("paper")
    cond = M.Conditions(diameters_mm=tuple(MEASURED_PAPER), n_theta=360, compensate=False,
                        bias_model="none")
    return M.evaluate(space, None, cond, gradient=False)


class _NP:
    """The few Dr.Jit calls of the closed form, on numpy."""

    maximum = staticmethod(np.maximum)


def test_closed_form_on_orthogonal_jacobians():
    """Tangent and radius imaged orthogonally, b px per mm along the tangent: the tangential
    variance in the plane is σ²/b² + σ_z² (jz along the tangent, 1 px/mm), the shift
    −σ_t²/(2r), exactly."""
    r, a, b, sig2, sz = 7.0, 6.0, 9.0, 1.7, 0.2
    jr, jt, jz = (0.0, a), (r * b, 0.0), (b, 0.0)
    got = point_bias_mm(_NP, r, jr, jt, jz, sig2, sz)
    want = -(sig2 / b ** 2 + sz ** 2) / (2.0 * r)
    assert got == pytest.approx(want, rel=1e-12)
    # the sheet seen across the line (jz along jr) widens the line and moves nothing
    assert point_bias_mm(_NP, r, jr, jt, (0.0, 5.0), 0.0, sz) == pytest.approx(0.0, abs=1e-15)


def _blurred_section_shift(A, r, s, th0, weight):
    """The exact centroid shift (mm, along the radial line at ``th0``) of the section's circle
    of radius ``r`` imaged by the affine map ``A`` (px/mm), blurred in the image by an
    isotropic Gaussian of σ ``s`` px, its light per unit of arc ``weight(φ)``: the line
    integral of the kernel over the circle, sampled along the radial line (no threshold)."""
    phi = th0 + np.linspace(-1.2, 1.2, 24001)
    uq = (r * np.stack([np.cos(phi), np.sin(phi)], 1)) @ A.T
    w = weight(phi)
    x = np.linspace(-2.0, 2.0, 801)
    up = ((r + x)[:, None] * np.array([np.cos(th0), np.sin(th0)])) @ A.T
    d2 = ((up[:, None, :] - uq[None, :, :]) ** 2).sum(-1)
    intensity = (w[None, :] * np.exp(-d2 / (2.0 * s * s))).sum(1)
    return float(np.sum(x * intensity) / np.sum(intensity))


@pytest.mark.parametrize("th0", [0.0, 0.7, 1.5708])
def test_closed_form_with_the_light_gradient_is_the_exact_blurred_section(th0):
    """An oblique (sheared) affine image of a Ø20 mm section blurred by σ = 2 px, its light
    per unit of arc ∝ 1 + 0.4 sin φ + the map's own |A t̂(φ)| (a stripe brighter on one
    side): the closed form −C_tt/(2r) − g C_rt is the exact blurred section's shift within
    2 %; without the gradient term (``g = 0``) it is off by up to 2×."""
    A = np.array([[12.0, 6.0], [1.2, 8.4]])
    r, s = 10.0, 2.0

    def weight(phi):
        t = np.stack([-np.sin(phi), np.cos(phi)], 1) @ A.T
        return (1.0 + 0.4 * np.sin(phi)) * np.hypot(*t.T)

    exact = _blurred_section_shift(A, r, s, th0, weight)
    e_r = np.array([np.cos(th0), np.sin(th0)])
    e_t = np.array([-np.sin(th0), np.cos(th0)])
    jr, jt = A @ e_r, A @ e_t * r
    h = 1e-6
    g = (np.log(weight(np.array([th0 + h]))[0]) - np.log(weight(np.array([th0 - h]))[0])) \
        / (2 * h) / r
    got = point_bias_mm(_NP, r, jr, jt, (0.0, 0.0), s * s, 0.0, g)
    assert got == pytest.approx(exact, rel=0.02)
    c_tt, c_rt = plane_covariance(_NP, r, jr, jt, (0.0, 0.0), s * s, 0.0)
    assert -c_tt / (2 * r) == pytest.approx(point_bias_mm(_NP, r, jr, jt, (0.0, 0.0), s * s,
                                                          0.0), rel=1e-12)
    # the term matters here: without it the closed form misses the exact shift by > 15 %
    # at two of the three angles (the radial line's own angle decides C_rt's sign and size)
    if th0 != 0.7:
        assert abs(-c_tt / (2 * r) - exact) > 0.15 * abs(exact)


def test_sheet_covariance_is_the_pulled_back_height():
    """The sheet's part of C: the image move ``jz`` per mm of height pulled back through
    J = [jr, jt/r] is v with J v = jz; C_sheet = σ_z² v vᵀ (here v = (0.5, 2.0) mm per mm)."""
    r = 5.0
    jr, jt = np.array([4.0, 1.0]), np.array([-1.0, 3.0]) * r
    v = np.array([0.5, 2.0])
    jz = jr * v[0] + jt / r * v[1]
    c_tt, c_rt = plane_covariance(_NP, r, jr, jt, jz, 0.0, 0.3)
    assert c_tt == pytest.approx(0.09 * v[1] ** 2, rel=1e-12)
    assert c_rt == pytest.approx(0.09 * v[0] * v[1], rel=1e-12)


def test_bias_is_inverse_to_the_radius(paper):
    """The closed form scales as 1/R at a fixed rig: R × bias constant within 7 % over
    Ø6–28 mm (46.4–49.0 µm·mm; the measured R × bias spreads by 38 %, 36.6–50.5 µm·mm)."""
    rb = np.array([c[0] * b for c, b in zip(paper.cases, paper.bias_um)])
    assert np.all(paper.bias_um < 0)
    assert np.ptp(rb) / abs(np.mean(rb)) < 0.07


def test_bias_against_the_measured_table(paper):
    """The model against the rendered gauges' bias (the stripe's light gradient included):
    the fitted radius at 0.97–1.28 of the measured, the direct view 0.62–0.96, the mirror
    views 1.16–1.45 (docs/design.md, "How far the closed form holds"); without the gradient
    term the radius was at 0.33–0.47."""
    for k, (d, meas) in enumerate(MEASURED_PAPER.items()):
        ratio = paper.bias_um[k] / meas[0]
        assert 0.9 <= ratio <= 1.35, (d, ratio)
        r_direct = paper.bias_view_um["direct"][k] / meas[1]
        assert 0.55 <= r_direct <= 1.05, (d, r_direct)
        for view, m in zip(("left", "right"), meas[2:]):
            r_view = paper.bias_view_um[view][k] / m
            assert 1.1 <= r_view <= 1.55, (d, view, r_view)


def test_master_removes_the_bias_at_its_diameter_and_the_twin_leaves_a_tenth():
    space = DesignSpace.create("paper")
    base = dict(n_theta=180, compensate=True, compensation_diameter_mm=20.0)
    at20 = M.evaluate(space, None, M.Conditions(diameters_mm=(20.0,), master=True,
                                                bias_model="none", **base), gradient=False)
    # each view's mean removed; what varies along θ within a view (the light gradient's
    # term) is left, weighed by the circle fit: 0.11 µm of the whole −4.8 µm
    assert abs(at20.bias_left_um[0]) < 0.15
    assert at20.bias_um[0] < -1.0  # the whole bias is still reported
    d10 = dict(diameters_mm=(10.0,), **base)
    none = M.evaluate(space, None, M.Conditions(bias_model="none", **d10), gradient=False)
    master = M.evaluate(space, None, M.Conditions(master=True, bias_model="none", **d10),
                        gradient=False)
    twin = M.evaluate(space, None, M.Conditions(master=True, bias_model="twin", **d10),
                      gradient=False)
    # §4.4 alone leaves it all; the Ø20 master the difference of 1/R; the twin a tenth of that
    assert none.bias_left_um[0] == pytest.approx(none.bias_um[0], rel=1e-9)
    assert none.bias_um[0] < master.bias_left_um[0] < 0
    assert master.bias_left_um[0] == pytest.approx(none.bias_um[0] / 2, rel=0.15)
    assert twin.bias_left_um[0] == pytest.approx(TWIN_RESIDUAL_FRACTION
                                                 * master.bias_left_um[0], rel=1e-9)
    # the share in U: |left| in quadrature
    for e in (none, master, twin):
        assert e.sigma_R_bias_um[0] == pytest.approx(abs(e.bias_left_um[0]), rel=1e-12)
        s2 = (e.sigma_R_noise_um[0] ** 2 + e.sigma_R_comp_um[0] ** 2
              + e.sigma_R_cal_um[0] ** 2 + e.sigma_R_bias_um[0] ** 2)
        assert e.sigma_R_um[0] == pytest.approx(np.sqrt(s2), rel=1e-6)


def test_bad_conditions_are_refused():
    with pytest.raises(DesignError, match="bias_model"):
        M.Conditions(bias_model="ai")
    with pytest.raises(DesignError, match="master"):
        M.Conditions(master=True, compensate=False)


#: The default optimum of ``lts360 design optimize`` on 2026-12-04 (its rig.toml, rounded;
#: every other value the paper rig's) and its bias measured by ``lts360 study bias`` (64 spp,
#: true calibration, centred): diameter -> (direct, left, right) µm (STUDIES.md, "The design
#: model's line-centre bias").
OPTIMUM = dict(alpha_deg=64.212, beta_deg=101.417, camera_distance_mm=226.169,
               camera_target_y_mm=1.578, laser_distance_mm=83.522,
               mirror_corner_distance_mm=40.0, mirror_width_mm=105.0, focal_length_mm=15.606,
               f_number=1.4, focus_distance_mm=239.187, waist_um=408.416, fan_angle_deg=74.802)
MEASURED_OPTIMUM = {6.0: (-17.6, -3.5, -4.0), 12.0: (-14.2, -1.7, -1.7),
                    20.0: (-13.5, -1.1, -1.1), 28.0: (-16.7, -0.9, -0.7)}


def test_bias_at_the_optimum_in_focus_views_near_the_defocused_direct_view_not():
    """At the f/1.4 optimum the in-focus mirror views are at 1.17–1.60 of the measured bias
    (over, as at the paper rig); the direct view, 23 mm before the focus plane, reads 1.9–5.7×
    the closed form (and not ∝ 1/R): a mechanism of strong defocus the model lacks
    (docs/design.md)."""
    space = DesignSpace.create("paper")
    x = np.array([OPTIMUM[name] for name in space.free])
    e = M.evaluate(space, x,
                   M.Conditions(diameters_mm=tuple(MEASURED_OPTIMUM), n_theta=360,
                                compensate=False, bias_model="none"), gradient=False)
    for k, (d, (direct, left, right)) in enumerate(MEASURED_OPTIMUM.items()):
        for view, m in (("left", left), ("right", right)):
            assert 1.1 <= e.bias_view_um[view][k] / m <= 1.7, (d, view)
        assert e.bias_view_um["direct"][k] / direct < 0.55, d

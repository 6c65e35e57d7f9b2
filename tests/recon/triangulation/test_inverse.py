"""End-to-end inverse triangulation on analytically synthesised images (no renderer)."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lts360.geometry import fit_circle, project_points
from lts360.recon.model import calibration_from_dict
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import (
    _shift_on_rays,
    estimate_view_offsets,
    inverse_triangulate,
    plan_inverse,
)
from lts360.recon.triangulation.peaks import Quality
from lts360.scenes.coverage import coverage
from lts360.scenes.rig_io import load_rig
from lts360.simulator.io import rig_truth

R_GAUGE_MM = 9.99935     # plug gauge Ø19.9987 mm (paper §4.5)
SIGMA_PX = 0.8           # line half-width in the synthetic image
AMP = 200.0


def synthesize_section(rig, radius_mm, *, centre_xy_mm=(0.0, 0.0), sigma_px=SIGMA_PX,
                       amp=AMP, step_deg=0.01, views=("direct", "left", "right")):
    """Image of a circular section: ``amp · exp(−d² / 2σ²)`` with ``d`` the distance (px) from
    each pixel centre to the projected section curve of each view, drawn only where the view
    measures the section (scenes.coverage: seen through the mirror and lit).

    Returns the float image and the coverage used.
    """
    cam = rig.camera
    cov = coverage(rig, radius_mm, theta_step_deg=step_deg, max_bounces=1,
                   center_xy_mm=centre_xy_mm)
    th = cov.theta_rad
    pts = np.column_stack([radius_mm * np.cos(th) + centre_xy_mm[0],
                           radius_mm * np.sin(th) + centre_xy_mm[1], np.zeros_like(th)])
    w, h = cam.image_size
    img = np.zeros(h * w)
    cut = 5.0 * sigma_px
    n = th.size
    nxt = (np.arange(n) + 1) % n
    for name in views:
        seen = cov.measured[name]
        T = None if name == "direct" else rig.mirror(name).T
        uv = project_points(pts, cam.K, cam.distortion, cam.R, cam.t_mm, T_mirror=T)
        ids = np.flatnonzero(seen)
        lo = np.floor(uv[ids].min(0) - cut).astype(int)
        hi = np.ceil(uv[ids].max(0) + cut).astype(int)
        vv, uu = np.mgrid[max(lo[1], 0):min(hi[1], h - 1) + 1, max(lo[0], 0):min(hi[0], w - 1) + 1]
        pix = np.column_stack([uu.ravel(), vv.ravel()]).astype(float)
        dist, j = cKDTree(uv[ids]).query(pix, distance_upper_bound=cut + 0.1)
        ok = np.isfinite(dist)
        pix, k = pix[ok], ids[j[ok]]
        best = np.full(len(pix), np.inf)
        for s in (k, (k - 1) % n):  # the two segments at the nearest vertex: exact distance
            a, e = uv[s], uv[nxt[s]] - uv[s]
            t = np.clip(np.einsum("ij,ij->i", pix - a, e) / np.einsum("ij,ij->i", e, e), 0, 1)
            d = np.linalg.norm(pix - (a + t[:, None] * e), axis=1)
            best = np.minimum(best, np.where(seen[s] & seen[nxt[s]], d, np.inf))
        best = np.minimum(best, np.linalg.norm(pix - uv[k], axis=1))
        flat = pix[:, 1].astype(int) * w + pix[:, 0].astype(int)
        np.add.at(img, flat, amp * np.exp(-0.5 * (best / sigma_px) ** 2))
    return img.reshape(h, w), cov


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


@pytest.fixture(scope="module")
def cal(paper):
    return calibration_from_dict(rig_truth(paper, paper.camera.K, paper.camera.image_size))


@pytest.fixture(scope="module")
def gauge_image(paper):
    return synthesize_section(paper, R_GAUGE_MM)


@pytest.fixture(scope="module")
def grid():
    # 0.25° keeps the test fast; the radial step is the standard 5 µm over ±2 mm.
    return CylGrid.from_ranges((R_GAUGE_MM - 2.0, R_GAUGE_MM + 2.0), theta_step_deg=0.25)


@pytest.mark.parametrize("peak", ["centroid", "gauss", "steger"])
def test_recovers_the_gauge_radius_in_every_view(cal, grid, gauge_image, peak):
    img, cov = gauge_image
    opts = {"line_width_mm": 0.5} if peak == "steger" else None
    res = inverse_triangulate(img, cal, grid, peak=peak, peak_options=opts)
    for name, v in res.views.items():
        ok = v.valid
        # Every θ of the window where the image has a line gives a point.
        assert ok.sum() >= 0.99 * v.window.sum(), name
        fit = fit_circle(v.points_meas_mm[ok, :2])
        # Circle-fit radius within 3 µm (measured: ≤ 0.3 µm direct, ≤ 1.5 µm mirrors).
        # What remains is (a) Keys interpolation of a σ = 0.8 px line, whose error depends on
        # the sub-pixel phase (±8 µm per point, averaging out over the circle), and (b) the
        # radial search crossing a curved line obliquely (≈ σ²/2ρ ≈ 0.01 px, mirror views).
        assert abs(fit.radius_mm - R_GAUGE_MM) < 3e-3, (name, fit.radius_mm)
        assert np.linalg.norm(fit.center_mm) < 3e-3, (name, fit.center_mm)
        err = v.r_mm[ok] - R_GAUGE_MM
        assert np.sqrt(np.mean(err**2)) < (4e-3 if peak == "centroid" else 1e-2), name
        assert np.max(np.abs(err)) < (1.5e-2 if peak == "centroid" else 3e-2), name


def test_covers_360_degrees_with_overlaps(cal, grid, gauge_image):
    img, _ = gauge_image
    res = inverse_triangulate(img, cal, grid)
    assert res.coverage_deg == pytest.approx(360.0, abs=1e-6)
    assert res.overlap_deg("direct", "left") > 20.0 and res.overlap_deg("direct", "right") > 20.0
    assert res.overlap_deg("left", "right") > 2.0
    fused = res.fused_r_mm
    assert np.all(np.isfinite(fused)) and np.max(np.abs(fused - R_GAUGE_MM)) < 1.5e-2
    cloud = res.cloud
    assert len(cloud.r_mm) == sum(v.valid.sum() for v in res.views.values())
    assert set(np.unique(cloud.view)) == {0, 1, 2}
    assert cloud.view_names == ("direct", "left", "right")
    assert np.allclose(np.hypot(*cloud.points_meas_mm[:, :2].T), cloud.r_mm)
    q = res.views["direct"].quality
    assert np.all(q[~res.views["direct"].window] == Quality.OUTSIDE_WINDOW)


def test_precomputed_plan_gives_the_same_result(cal, grid, gauge_image):
    img, _ = gauge_image
    img8 = np.clip(np.round(img), 0, 255).astype(np.uint8)
    plan = plan_inverse(cal, grid, weights_dtype=np.float64)
    a = inverse_triangulate(img8, cal, grid)
    b = inverse_triangulate(img8, cal, grid, plan=plan)
    for name in a.views:
        assert np.array_equal(a.views[name].quality, b.views[name].quality)
        assert np.allclose(a.views[name].r_mm, b.views[name].r_mm, atol=1e-12, equal_nan=True)
    assert a.threshold == 25.5 and a.saturation == 255.0  # 8-bit defaults
    with pytest.raises(ValueError, match="plan"):
        inverse_triangulate(img8, cal, CylGrid.from_ranges((8.0, 12.0)), plan=plan)
    with pytest.raises(ValueError, match="interpolation"):
        inverse_triangulate(img8, cal, grid, plan=plan, interpolation="bspline")


def test_bspline_interpolation_recovers_the_gauge_too(cal, grid, gauge_image):
    """The optional B-spline sampling, with and without a precomputed plan."""
    img, _ = gauge_image
    plan = plan_inverse(cal, grid, interpolation="bspline", weights_dtype=np.float64)
    a = inverse_triangulate(img, cal, grid, interpolation="bspline")
    b = inverse_triangulate(img, cal, grid, plan=plan)
    for name, v in a.views.items():
        assert np.array_equal(v.quality, b.views[name].quality)
        assert np.allclose(v.r_mm, b.views[name].r_mm, atol=1e-12, equal_nan=True)
        assert v.valid.sum() > 100
        assert np.nanmax(np.abs(v.r_mm - R_GAUGE_MM)) < 0.01
    with pytest.raises(ValueError, match="interpolation"):
        plan_inverse(cal, grid, interpolation="cubic")


def test_shift_on_rays_is_exact_for_a_translated_circle():
    theta = np.radians(np.arange(-180.0, 180.0, 0.2))
    r = np.full(theta.size, 10.0)
    r[(theta > 0.5) & (theta < 1.0)] = np.nan  # a gap
    off = np.array([0.03, -0.05])
    got = _shift_on_rays(theta, r, off, periodic=True)
    u = np.stack([np.cos(theta), np.sin(theta)], -1)
    want = u @ off + np.sqrt(100.0 - (u[:, 0] * off[1] - u[:, 1] * off[0]) ** 2)
    ok = np.isfinite(got)
    # Chords of the 0.2° polyline lie inside the circle by at most R·Δθ²/8 = 0.015 µm.
    assert np.max(np.abs(got[ok] - want[ok])) < 2e-5
    # The shift (58 µm ≈ 1.7 ray spacings) moves the curve's ends by up to 2 rays: the gap
    # stays empty inside, and at most 2 rays per end change between valid and not.
    assert not ok[(theta > 0.52) & (theta < 0.98)].any()
    assert np.sum(ok != np.isfinite(r)) <= 4
    assert np.array_equal(_shift_on_rays(theta, r, np.zeros(2), True), r, equal_nan=True)


def test_residual_compensation_of_a_mirror_calibration_error(paper, cal, grid, gauge_image):
    """A mirror plane calibrated 20 µm off translates that view by 40 µm along its normal
    (Eq. 3: T' T = translation by 2δn); §4.4's circle-centre alignment takes it out."""
    img, _ = gauge_image
    delta = 0.02
    mirrors = tuple(dataclasses.replace(m, d_mm=m.d_mm + delta,
                                        corners_mm=m.corners_mm + delta * m.n)
                    if m.name == "left" else m for m in cal.mirrors)
    bad = dataclasses.replace(cal, mirrors=mirrors)
    raw = inverse_triangulate(img, bad, grid)
    offsets = estimate_view_offsets(raw)
    n_meas = bad.T_cam_meas[:3, :3].T @ bad.mirror("left").n
    # The circle-fit centres carry ≤ 1 µm of the synthetic bias (see the radius test).
    assert np.allclose(offsets["left"], -2 * delta * n_meas[:2], atol=2e-3)
    assert np.linalg.norm(offsets["right"]) < 2e-3
    fixed = inverse_triangulate(img, dataclasses.replace(bad, view_offsets_mm=offsets), grid,
                                compensate=True)
    for res, limit in ((raw, 0.03), (fixed, 0.015)):
        err = res.views["left"].r_mm - R_GAUGE_MM
        assert (np.nanmax(np.abs(err)) > limit) if res is raw else (np.nanmax(np.abs(err)) < limit)
    fit = fit_circle(fixed.views["left"].points_meas_mm[fixed.views["left"].valid, :2])
    assert np.linalg.norm(fit.center_mm) < 3e-3
    assert np.array_equal(fixed.views["left"].offset_mm, offsets["left"])
    # The estimate uses raw radii, so it does not depend on the compensation applied.
    again = estimate_view_offsets(fixed)
    assert np.allclose(again["left"], offsets["left"], atol=1e-9)


def test_plan_pixels_are_all_the_inverse_triangulation_reads(cal, grid, gauge_image):
    # Zero every pixel outside plan_pixels: the profiles, hence the result, do not change.
    from lts360.recon.triangulation.inverse import plan_pixels, sample_profiles

    img, _ = gauge_image
    plan = plan_inverse(cal, grid, precompute=False)
    px = plan_pixels(plan, margin_px=0)
    assert len(np.unique(px[:, 1] * 10_000 + px[:, 0])) == len(px)  # each pixel once
    w, h = cal.image_size
    assert len(px) < 0.5 * w * h  # a band, not the image
    masked = np.zeros_like(img)
    masked[px[:, 1], px[:, 0]] = img[px[:, 1], px[:, 0]]
    for vp in plan.views.values():
        np.testing.assert_array_equal(sample_profiles(masked, vp), sample_profiles(img, vp))
    wider = plan_pixels(plan, margin_px=3)
    assert len(wider) > len(px)
    keys = set((wider[:, 1] * 10_000 + wider[:, 0]).tolist())
    assert keys.issuperset((px[:, 1] * 10_000 + px[:, 0]).tolist())
    with pytest.raises(ValueError, match="margin_px"):
        plan_pixels(plan, margin_px=-1)


def test_bad_inputs(cal, grid):
    with pytest.raises(ValueError, match="image"):
        inverse_triangulate(np.zeros((10, 10)), cal, grid)
    img = np.zeros(cal.image_size[::-1], dtype=np.uint8)
    with pytest.raises(ValueError, match="windows"):
        inverse_triangulate(img, cal, grid, windows={"direct": np.ones(3, bool)})
    with pytest.raises(ValueError, match="peak must be"):
        inverse_triangulate(img, cal, grid, peak="max")
    res = inverse_triangulate(img, cal, grid)  # a dark image: no points, no error
    assert res.coverage_deg == 0.0
    with pytest.raises(ValueError, match="valid points"):
        estimate_view_offsets(res)


def test_recon_imports_no_ground_truth():
    code = ("import sys, lts360.recon.triangulation.inverse, lts360.recon.model, lts360.recon.triangulation.views, "
            "lts360.recon.triangulation.peaks, lts360.recon.triangulation.interp, lts360.recon.triangulation.grid; "
            "print(sorted(m for m in sys.modules if m.startswith(('lts360.simulator', "
            "'lts360.scenes', 'mitsuba'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"

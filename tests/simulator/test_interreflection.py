"""Interreflected laser light (``max_scatter``): closed forms, symmetry, Mitsuba's ``path``.

* ``max_scatter = 0`` is the single-scatter image of 905e28a, bit for bit;
* the integrating sphere (furnace): ``(ρ/π) Σ ρᵏ Φ/(4πR²)`` for 1, 2 and 3 bounces;
* the white inside corner: the irradiance integral over the other face's stripe;
* a symmetric corner gives a symmetric secondary stripe;
* the interreflection-only component against Mitsuba's ``path`` integrator with the sheet
  as an emitter (corner and shiny cylinder), pixel for pixel within the Monte Carlo noise;
* the AOV ``laser`` carries the interreflected light; bad ``max_scatter`` is refused.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the simulator needs Mitsuba 3")
dr = pytest.importorskip("drjit", reason="needs Dr.Jit (installed with Mitsuba 3)")

from lts360.experiments import interreflection as ir

DATA = Path(__file__).with_name("data")


@pytest.fixture(scope="module")
def variant():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    return "llvm_ad_mono"


def _rays_to(eye, points, n):
    """``n`` identical rays from ``eye`` to each point (lanes point-major)."""
    pts = np.repeat(np.asarray(points, float), n, axis=0)
    d = pts - np.asarray(eye, float)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.broadcast_to(np.asarray(eye, float), d.shape), d


def test_max_scatter_0_is_the_single_scatter_image_bit_for_bit(variant):
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec, object_meshes

    ref = np.load(DATA / "single_scatter_alu_pipe.npz")
    if (str(ref["mitsuba"]), str(ref["drjit"])) != (mi.__version__, dr.__version__):
        pytest.skip(f"reference made with Mitsuba {ref['mitsuba']} / Dr.Jit {ref['drjit']}")
    spec = SceneSpec(load_rig("paper"), object_meshes(build_object("alu-pipe")), ambient="dim")
    res = render_radiance(spec, spp=4, seed=3, scale=0.125, max_scatter=0)
    assert np.array_equal(res.radiance_W_m2_sr, ref["radiance"])
    assert np.array_equal(res.laser_W_m2_sr, ref["laser"])
    assert (ref["laser"] > 0).sum() > 100  # the reference holds a stripe


def test_the_laser_aov_carries_the_interreflected_light(variant):
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec, object_meshes

    spec = SceneSpec(load_rig("paper"), object_meshes(build_object("alu-pipe")))
    r0 = render_radiance(spec, spp=4, seed=3, scale=0.125, max_scatter=0)
    r1 = render_radiance(spec, spp=4, seed=3, scale=0.125, max_scatter=1)
    # No ambient light: everything is laser light, the interreflected share included (the
    # film accumulates the two channels with different float32 rounding: 1e-6 relative).
    assert np.allclose(r1.radiance_W_m2_sr, r1.laser_W_m2_sr, rtol=1e-6, atol=1e-6 * r1.laser_W_m2_sr.max())
    extra = r1.laser_W_m2_sr.astype(np.float64) - r0.laser_W_m2_sr
    assert extra.min() >= -1e-6 * r0.laser_W_m2_sr.max()  # float32 rounding of the sum
    assert extra.sum() > 1e-3 * r0.laser_W_m2_sr.sum()
    assert ((r1.laser_W_m2_sr > 0) & (r0.laser_W_m2_sr == 0)).sum() > 0  # new lit pixels


@pytest.mark.parametrize("bad", [-1, 4, 1.5, True])
def test_max_scatter_outside_0_to_3_is_refused(variant, bad):
    from lts360.simulator.integrator import make_integrator

    vs = ir.corner_scene()
    with pytest.raises(ValueError, match=r"max_scatter must be an integer in \[0, 3\]"):
        make_integrator(vs.laser, (), max_scatter=bad)


@pytest.mark.parametrize("bad", [0.0, -0.1])
def test_a_roughness_at_or_below_0_is_refused(bad):
    from lts360.scenes.materials import Material

    with pytest.raises(ValueError, match="roughness_alpha must be in"):
        Material("x", diffuse_reflectance=0.5, specular_weight=0.5, roughness_alpha=bad, eta=1.5, k=1.0)


@pytest.mark.parametrize("max_scatter", [1, 2, 3])
def test_integrating_sphere_against_its_closed_form(variant, max_scatter):
    from lts360.simulator.integrator import make_integrator

    vs = ir.cavity_scene(albedo=0.8, radius_mm=50.0, waist_mm=5.0)
    scene = ir.load(vs, emitter=False)
    o, d = ir.pinhole_rays(vs, 8, 8, 2048, seed=5)  # views 60° about the pole: no direct light
    v = ir.lane_values(scene, make_integrator(vs.laser, (), max_scatter=max_scatter), o, d, 7,
                       laser_aov=True)
    expected = ir.cavity_radiance_W_m2_sr(0.8, 50.0, vs.laser.power_W, max_scatter)
    se = v.std(ddof=1) / math.sqrt(v.size)
    # 4 standard errors (Monte Carlo; ~1 % of the value here); the closed form is exact for a
    # sphere, the Gaussian across the sheet is cut at 1e-7 of its peak (negligible).
    assert abs(v.mean() - expected) < 4 * se, (v.mean(), expected, se)
    assert se < 0.02 * expected


def test_integrating_sphere_mitsuba_path_agrees_with_the_closed_form(variant):
    vs = ir.cavity_scene(albedo=0.8, radius_mm=50.0, waist_mm=5.0)
    scene = ir.load(vs, emitter=True)
    o, d = ir.pinhole_rays(vs, 8, 8, 2048, seed=5)
    v = ir.lane_values(scene, mi.load_dict({"type": "path", "max_depth": 3}), o, d, 7,
                       laser_aov=False)
    expected = ir.cavity_radiance_W_m2_sr(0.8, 50.0, vs.laser.power_W, 1)
    se = v.std(ddof=1) / math.sqrt(v.size)
    assert abs(v.mean() - expected) < 4 * se, (v.mean(), expected, se)  # Monte Carlo


@pytest.mark.parametrize("x_mm", [5.0, 15.0, 30.0])
def test_inside_corner_against_the_irradiance_integral(variant, x_mm):
    from lts360.simulator.integrator import make_integrator

    vs = ir.corner_scene(albedo=0.8, waist_mm=3.0)  # a wide sheet: less Monte Carlo noise
    z_mm = 12.0  # off the stripe: 12 mm = 4 w, the sheet's own light is cut there
    scene = ir.load(vs, emitter=False)
    o, d = _rays_to((40.0, 40.0, 30.0), [(x_mm, 0.0, z_mm)], 1 << 17)
    v = ir.lane_values(scene, make_integrator(vs.laser, (), max_scatter=1), o, d, 11, laser_aov=True)
    v0 = ir.lane_values(scene, make_integrator(vs.laser, (), max_scatter=0), o, d, 11, laser_aov=True)
    assert np.all(v0 == 0.0)
    expected = ir.corner_scatter_radiance_W_m2_sr(vs, x_mm, z_mm, albedo=0.8)
    se = v.std(ddof=1) / math.sqrt(v.size)
    # 4 standard errors (Monte Carlo); the quadrature's error is < 1e-4 relative (4000 × 241
    # nodes on a smooth integrand).
    assert abs(v.mean() - expected) < 4 * se, (v.mean(), expected, se)
    assert se < 0.03 * expected


def test_a_symmetric_corner_gives_a_symmetric_secondary_stripe(variant):
    vs = ir.corner_scene()  # mirror symmetric about the plane x = y, and so is the view
    s = ir.component_samples(vs, "laser", "scatter", width=16, height=12, spp=512, seed=3)
    m, var = s.mean(-1), s.var(-1, ddof=1) / s.shape[-1]
    flip_m, flip_var = m[:, ::-1], var[:, ::-1]
    lit = (var + flip_var) > 0
    z = (m - flip_m)[lit] / np.sqrt((var + flip_var)[lit])
    assert lit.sum() > 60
    # Mirror-image pixels agree within their Monte Carlo noise (each pair enters twice, so
    # the mean of z² is that of the pairs); 1.6: the 99.9 % point of χ²/ν for ν ≈ 90.
    assert np.mean(z ** 2) < 1.6
    left, right = m[:, :8].sum(), m[:, 8:].sum()
    assert abs(left - right) < 4 * math.sqrt(var.sum())
    assert m.sum() > 0


def _batches(vs, renderer, width, height, spp, batches, seed0):
    return np.concatenate([ir.component_samples(vs, renderer, "scatter", width=width,
                                                 height=height, spp=spp, seed=seed0 + k)
                           for k in range(batches)], axis=-1)


def _check_against_path(vs, width, height, spp, total_tol, batches=1):
    a_dir = ir.component_samples(vs, "laser", "direct", width=width, height=height, spp=32, seed=1)
    b_dir = ir.component_samples(vs, "path", "direct", width=width, height=height, spp=32, seed=1)
    # Direct light of a delta sheet is deterministic per ray: lane for lane the same number
    # (float32 rounding; Mitsuba also keeps the Gaussian's far tail that ours cuts at 1e-7).
    assert np.allclose(a_dir, b_dir, rtol=1e-5, atol=1e-7 * a_dir.max())
    a = _batches(vs, "laser", width, height, spp, batches, 100)
    b = _batches(vs, "path", width, height, spp, batches, 200)
    c = ir.compare_components(a, b)
    se = math.hypot(c.se_total_a, c.se_total_b)
    assert c.n_pixels > 0.3 * width * height
    assert abs(c.total_a - c.total_b) < 4 * se, c  # totals agree within 4 σ of their noise
    assert abs(c.rel_diff_total) < total_tol, c
    # Pixel means agree within their noise: mean z² ≈ 1; 1.5 allows for the heavy tails of the
    # per-pixel variance estimates of a thin stripe's few hits.
    assert c.chi2_per_dof < 1.5, c
    assert c.frac_abs_z_over_4 < 0.01, c
    return c


@pytest.mark.parametrize("scene,batches", [("corner", 1), ("cylinder", 4)])
def test_interreflection_agrees_with_mitsuba_path_small(variant, scene, batches):
    vs = ir.corner_scene() if scene == "corner" else ir.shiny_cylinder_scene()
    # 16 × 12 pixels, 512 spp per batch: the totals' combined noise is held below 12 %, so the
    # 4 σ agreement catches any error above ~50 %; the 5 % target is the slow test's.
    c = _check_against_path(vs, 16, 12, 512, total_tol=0.5, batches=batches)
    assert math.hypot(c.se_total_a, c.se_total_b) < 0.12 * c.total_b


@pytest.mark.slow
@pytest.mark.parametrize("scene,batches", [("corner", 12), ("cylinder", 32)])
def test_interreflection_agrees_with_mitsuba_path_within_5_percent(variant, scene, batches):
    vs = ir.corner_scene() if scene == "corner" else ir.shiny_cylinder_scene()
    # 48 × 32 pixels, batches of 512 spp (the glossy cylinder is the noisier one).
    c = _check_against_path(vs, 48, 32, 512, total_tol=0.05, batches=batches)
    assert math.hypot(c.se_total_a, c.se_total_b) < 0.0125 * c.total_b  # 5 % is ≥ 4 σ

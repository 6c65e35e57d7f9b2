"""The pixel support: it holds every pixel with laser light, and a frame rendered on it is the
full frame's (statistics, measured radius); a reused scene renders as a fresh one."""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the simulator needs Mitsuba 3")

from lts360.scenes.objects import build_object, object_types  # noqa: E402
from lts360.scenes.rig_io import load_rig  # noqa: E402

#: Small frames: the support is a geometric statement, it holds at any scale.
SCALE = 0.25


@pytest.fixture(scope="module")
def variant():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")


@pytest.fixture(scope="module")
def rig():
    return load_rig("paper")


def _spec(rig, obj, z_mm=0.0):
    from lts360.simulator.frame import stage_transform
    from lts360.simulator.materials import material_to_bsdf
    from lts360.simulator.scene import SceneSpec

    mesh = obj.mesh_world()
    mesh.apply_transform(stage_transform(z_mm))
    return SceneSpec(rig, (("object", mesh, material_to_bsdf(obj.material)),))


def _object(name, tmp_path):
    """A catalog object, or for a user's part (``mesh``, ``profile``) a hexagonal bar written
    to a file (16 mm across flats)."""
    if not object_types()[name].from_file:
        return build_object(name)
    import trimesh

    if name == "mesh":
        path = tmp_path / "hex.stl"
        trimesh.creation.cylinder(radius=16.0 / np.sqrt(3.0), height=30.0,
                                  sections=6).export(path)
        return build_object(f"mesh:path={path}")
    a = np.radians(np.arange(7) * 60.0 + 30.0)  # closed: the first point repeated
    path = tmp_path / "hex.csv"
    path.write_text("\n".join(f"{x:.9f},{y:.9f}" for x, y in
                              16.0 / np.sqrt(3.0) * np.column_stack([np.cos(a), np.sin(a)])))
    return build_object(f"{name}:path={path},length=30")


@pytest.mark.parametrize("name", list(object_types()))
def test_support_holds_every_pixel_with_laser_light(variant, rig, name, tmp_path):
    """A full render of every catalog object: no pixel outside the geometric support carries
    laser radiance above 1e-4 of the stripe's peak (the integrator's sheet is cut at
    exp(-16.1), so outside the slabs it is exactly 0), and the support is a small part of the
    frame."""
    from lts360.simulator.render import render_radiance
    from lts360.simulator.support import geometric_support

    spec = _spec(rig, _object(name, tmp_path))
    sup = geometric_support(spec, scale=SCALE)
    res = render_radiance(spec, spp=4, seed=3, scale=SCALE)
    laser = res.laser_W_m2_sr
    peak = float(laser.max())
    assert peak > 0
    assert float(laser[~sup.mask].max(initial=0.0)) <= 1e-4 * peak
    # At this scale the 2 px margin and the blur dominate: still far below the whole frame.
    assert 0.005 < sup.fraction < 0.15


@pytest.mark.parametrize("name", list(object_types()))
def test_hull_support_holds_every_pixel_with_interreflected_light(variant, rig, name, tmp_path):
    """With interreflections (one scatter) every laser-lit pixel of a full render, glints and
    light carried by the mirrors included, lies in the hull support (every pixel that can see
    a shape), which is a part of the frame only; frames with interreflections render on it."""
    from lts360.simulator.frame import render_frame
    from lts360.simulator.render import render_radiance
    from lts360.simulator.support import hull_support

    spec = _spec(rig, _object(name, tmp_path))
    sup = hull_support(spec, scale=SCALE)
    laser = render_radiance(spec, spp=4, seed=3, scale=SCALE, max_scatter=1).laser_W_m2_sr
    assert laser.max() > 0
    assert not np.any(laser[~sup.mask] > 0)
    assert sup.fraction < 0.6
    res, used = render_frame(spec, spp=1, seed=3, scale=SCALE, max_scatter=1)
    assert used.method == "hull" and np.array_equal(used.mask, sup.mask)
    assert not np.any(res.laser_W_m2_sr[~sup.mask]) and res.laser_W_m2_sr.max() > 0


def test_hull_support_is_the_full_frame_when_a_shape_reaches_the_camera(variant, rig):
    """A shape reaching behind the camera's plane in some view has no bounded image: the full
    frame; the 400 mm base plate below the object fills the frame through its hull."""
    import trimesh

    from lts360.simulator.scene import SceneSpec
    from lts360.simulator.support import hull_support

    spec = _spec(rig, build_object("plug-gauge"))
    assert hull_support(spec, scale=SCALE).fraction < 0.3
    roof = trimesh.creation.box(extents=(400.0, 400.0, 1.0))
    roof.apply_translation((0.0, 0.0, rig.camera.center_mm[2] + 80.0))   # over the camera
    sup = hull_support(SceneSpec(rig, spec.meshes + (("roof", roof, spec.meshes[0][2]),)),
                       scale=SCALE)
    assert sup.method == "full" and sup.fraction == 1.0
    plate = hull_support(SceneSpec(rig, spec.meshes, background_z_mm=-30.0), scale=SCALE)
    assert plate.method == "hull" and plate.fraction == 1.0


@pytest.mark.parametrize("noise", ["none", "realistic"])
def test_support_frame_has_the_full_frames_statistics(variant, rig, noise):
    """Plug gauge, both noise modes: outside the support the band frame's pixels are the full
    frame's (no light: the sensor's dark signal alone; identical without noise), and on the
    support the laser radiance has the full render's mean and spread (another realisation)."""
    from lts360.simulator.frame import simulate_frame

    obj = build_object("plug-gauge:x=0.4")
    # The exposure auto-exposure picks here (the brightest stripe pixels at 80 % of full scale).
    kw = dict(spp=16, seed=2, noise=noise, scale=0.5, exposure_time_s=2.75e-4)
    band = simulate_frame(rig, obj, support="geometric", **kw)
    full = simulate_frame(rig, obj, support="full", **kw)
    assert band.truth["render"]["support"]["method"] == "geometric"
    assert full.truth["render"]["support"]["method"] == "full"
    from lts360.simulator.support import geometric_support

    mask = geometric_support(_spec(rig, obj), scale=0.5).mask
    assert np.array_equal(band.render.laser_W_m2_sr > 0, (band.render.laser_W_m2_sr > 0) & mask)
    out_b, out_f = band.image[~mask].astype(float), full.image[~mask].astype(float)
    if noise == "none":
        assert np.array_equal(out_b, out_f)
    else:  # ~1e6 dark pixels: the means agree to 0.02 DN, the spreads to 2 %
        assert out_b.mean() == pytest.approx(out_f.mean(), abs=0.02)
        assert out_b.std() == pytest.approx(out_f.std(), rel=0.02)
    lb = band.render.laser_W_m2_sr[mask].astype(float)
    lf = full.render.laser_W_m2_sr[mask].astype(float)
    assert float(full.render.laser_W_m2_sr[~mask].max(initial=0.0)) == 0.0
    # 16 spp on ~900 lit pixels: the summed stripe agrees to 1 % (render noise), the brightest
    # pixels to 5 %.
    assert lb.sum() == pytest.approx(lf.sum(), rel=0.01)
    assert np.percentile(lb, 99.5) == pytest.approx(np.percentile(lf, 99.5), rel=0.05)
    if noise == "realistic":  # speckle and shot noise on the stripe: the same contrast
        lit = lf > 0.2 * lf.max()
        ib, if_ = band.image[mask][lit].astype(float), full.image[mask][lit].astype(float)
        assert ib.mean() == pytest.approx(if_.mean(), rel=0.05)
        assert ib.std() / ib.mean() == pytest.approx(if_.std() / if_.mean(), rel=0.15)


def test_support_and_full_frames_get_the_same_speckle(variant, rig):
    """Speckle is a function of the pixel's position and the seed: the camera image of a
    radiance lit only on some of a support frame's laser pixels (those of the frame's right
    half) equals, on those pixels, the image of the full frame's radiance, bit for bit (the
    same radiance there, the same speckle, whatever else is lit)."""
    import dataclasses

    from lts360.simulator.frame import render_frame, sensor_image

    spec = _spec(rig, build_object("plug-gauge:x=0.4"))
    band, _ = render_frame(spec, spp=4, seed=2, scale=0.5, support="geometric")
    full, _ = render_frame(spec, spp=4, seed=2, scale=0.5, support="full")
    lit = (band.laser_W_m2_sr > 0) & (full.laser_W_m2_sr > 0)
    lit[:, :lit.shape[1] // 2] = False
    assert lit.sum() > 200 and (full.laser_W_m2_sr > 0).sum() > lit.sum()
    part = dataclasses.replace(full, radiance_W_m2_sr=np.where(lit, full.radiance_W_m2_sr, 0),
                               laser_W_m2_sr=np.where(lit, full.laser_W_m2_sr, 0))
    kw = dict(noise="none", speckle=True, seed=5, scale=0.5, exposure_time_s=2.75e-4)
    a, b = sensor_image(rig, full, **kw)[0], sensor_image(rig, part, **kw)[0]
    assert np.array_equal(a[lit], b[lit])
    plain = sensor_image(rig, full, **dict(kw, speckle=False))[0]
    assert np.mean(a[lit] != plain[lit]) > 0.5     # the speckle is there


def test_sensor_image_read_draws_speckle_and_noise_where_it_is_read(variant, rig):
    """``read`` (the pixels a plan reads): there the speckle is the full frame's, bit for
    bit, and the sensor noise is drawn; every other pixel holds the noise-free value."""
    from lts360.simulator.frame import render_frame, sensor_image

    full, _ = render_frame(_spec(rig, build_object("plug-gauge:x=0.4")), spp=4, seed=2,
                           scale=0.5, support="full")
    h, w = full.laser_W_m2_sr.shape
    near = np.zeros((h, w), bool)                      # the right half's stripe and beside it
    near[:, w // 2:] = full.laser_W_m2_sr[:, w // 2:] > 0
    near |= np.roll(near, 5, axis=1)
    read = np.flatnonzero(near)
    assert read.size > 200
    kw = dict(seed=5, scale=0.5, exposure_time_s=2.75e-4)
    clean = sensor_image(rig, full, noise="none", **kw)[0]
    a = sensor_image(rig, full, noise="none", speckle=True, **kw)[0]
    b = sensor_image(rig, full, noise="none", speckle=True, read=read, **kw)[0]
    assert np.array_equal(b[near], a[near]) and np.array_equal(b[~near], clean[~near])
    assert np.mean(a[near] != clean[near]) > 0.2       # the speckle is there
    noisy = sensor_image(rig, full, noise="realistic", read=read, **kw)[0]
    assert np.array_equal(noisy[~near], clean[~near])
    every = sensor_image(rig, full, noise="realistic", **kw)[0]
    moved = np.mean(noisy[near] != clean[near])   # and the noise, as often as a full frame
    assert moved > 0.3 and moved == pytest.approx(np.mean(every[near] != clean[near]), abs=0.05)
    with pytest.raises(ValueError, match="read must be sorted"):   # also with no sensor noise
        sensor_image(rig, full, noise="none", speckle=True, read=read[::-1], **kw)


def test_window_and_support_intersect(variant, rig):
    """A window (a study's band) with the default support renders only their intersection;
    with ``support="full"`` the whole window, as before."""
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.render import window_pixels

    obj = build_object("plug-gauge")
    px = window_pixels([(0, 0, 320, 128)])
    f = simulate_frame(rig, obj, spp=4, seed=1, scale=0.25, pixels_xy=px, support="geometric")
    g = simulate_frame(rig, obj, spp=4, seed=1, scale=0.25, pixels_xy=px, support="full")
    assert 0 < f.truth["render"]["support"]["pixels"] < g.truth["render"]["support"]["pixels"]
    assert g.truth["render"]["support"]["pixels"] == 320 * 128
    assert np.all(f.render.laser_W_m2_sr[128:] == 0) and np.all(g.render.laser_W_m2_sr[128:] == 0)


def test_ambient_fills_the_pixels_outside_the_support(variant, rig):
    """With ambient light on, the pixels outside the support hold the ambient radiance (one
    low-spp ambient render), not black."""
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.support import geometric_support

    obj = build_object("plug-gauge")
    band = simulate_frame(rig, obj, spp=4, seed=1, scale=0.25, ambient="dim", support="geometric",
                          exposure_time_s=2e-3)
    full = simulate_frame(rig, obj, spp=4, seed=1, scale=0.25, ambient="dim", support="full",
                          exposure_time_s=2e-3)
    mask = geometric_support(_spec(rig, obj), scale=0.25).mask
    a, b = band.render.radiance_W_m2_sr[~mask], full.render.radiance_W_m2_sr[~mask]
    assert a.mean() > 0
    # The ambient render (4 spp) and the full render (4 spp) are two realisations of the same
    # image: their means over ~75 000 pixels agree to 1 %.
    assert a.mean() == pytest.approx(b.mean(), rel=0.01)


def test_splat_covers_each_disk_and_no_more_than_its_rounding():
    """Each point marks every pixel centre within its radius of the exact point (whatever its
    sub-pixel position), and none farther than radius + √2/2 from the pixel it rounds to (the
    disk of integer offsets, not a rasterised ellipse a pixel wider)."""
    from lts360.simulator.support import _splat

    rng = np.random.default_rng(5)
    uv = rng.uniform(10, 50, size=(40, 2))
    r = rng.uniform(0.0, 6.0, size=40)
    mask = _splat(uv, r, (64, 64))
    yy, xx = np.mgrid[:64, :64]
    inner = np.zeros_like(mask)
    outer = np.zeros_like(mask)
    for (u, v), ri in zip(uv, r):
        inner |= (xx - u) ** 2 + (yy - v) ** 2 <= ri ** 2
        outer |= (xx - np.rint(u)) ** 2 + (yy - np.rint(v)) ** 2 <= (ri + np.sqrt(0.5)) ** 2 + 1e-9
    assert np.all(mask[inner]) and not np.any(mask & ~outer)
    assert np.array_equal(mask, outer)


def test_support_is_refused_bad_input(variant, rig):
    from lts360.simulator.frame import simulate_frame

    with pytest.raises(ValueError, match="support must be one of"):
        simulate_frame(rig, build_object("plug-gauge"), spp=1, scale=0.25, support="band")


def test_pilot_support_holds_the_laser_light(variant, rig):
    """The pilot support (a 4-spp render of the real integrator) holds every pixel a 16-spp
    render lights above 1e-4 of its peak."""
    from lts360.simulator.render import render_radiance
    from lts360.simulator.support import pilot_support

    spec = _spec(rig, build_object("cube"))
    sup = pilot_support(spec, scale=SCALE, seed=5)
    laser = render_radiance(spec, spp=16, seed=6, scale=SCALE).laser_W_m2_sr
    assert float(laser[~sup.mask].max(initial=0.0)) <= 1e-4 * float(laser.max())
    assert sup.method == "pilot" and sup.fraction < 0.2


def test_reused_scene_renders_as_a_fresh_one(variant, rig):
    """Build once, render many: a cached scene whose object moved (another stage height)
    gives the image a freshly loaded scene gives with the same seed."""
    from lts360.simulator.frame import render_frame
    from lts360.simulator.reuse import SceneCache

    obj = build_object("plug-gauge:x=0.3")
    cache = SceneCache()
    kw = dict(spp=4, seed=9, scale=SCALE)
    render_frame(_spec(rig, obj, z_mm=0.0), scenes=cache, **kw)
    moved = _spec(rig, obj, z_mm=2.0)
    reused, sup_r = render_frame(moved, scenes=cache, **kw)
    fresh, sup_f = render_frame(moved, scenes=SceneCache(), **kw)
    assert (cache.loads, cache.reuses) == (1, 1)
    assert np.array_equal(sup_r.mask, sup_f.mask)
    assert fresh.laser_W_m2_sr.max() > 0
    # float32 vertices written through mi.traverse or read from the PLY: the same numbers.
    np.testing.assert_allclose(reused.radiance_W_m2_sr, fresh.radiance_W_m2_sr, rtol=1e-5,
                               atol=1e-6 * float(fresh.radiance_W_m2_sr.max()))
    # Another object (other faces) is not forced into the cached scene.
    render_frame(_spec(rig, build_object("cube")), scenes=cache, **kw)
    assert cache.loads == 2


def test_a_reused_scene_with_ambient_light_renders_as_a_fresh_one(variant, rig):
    """With ambient light on, a cached scene whose object moved far (its bounding sphere, which
    the ambient light's sampling uses, moved with it) gives the fresh scene's image bit for bit."""
    from lts360.simulator.frame import render_frame
    from lts360.simulator.reuse import SceneCache
    from lts360.simulator.scene import SceneSpec

    def spec(x_mm):
        s = _spec(rig, build_object(f"plug-gauge:x={x_mm}"))
        return SceneSpec(rig, s.meshes, ambient="bright")

    cache = SceneCache()
    kw = dict(spp=4, seed=3, scale=SCALE, support="full")
    render_frame(spec(0.0), scenes=cache, **kw)
    reused, _ = render_frame(spec(6.0), scenes=cache, **kw)
    fresh, _ = render_frame(spec(6.0), scenes=SceneCache(), **kw)
    assert (cache.loads, cache.reuses) == (1, 1)
    np.testing.assert_allclose(reused.radiance_W_m2_sr, fresh.radiance_W_m2_sr, rtol=1e-5,
                               atol=1e-6 * float(fresh.radiance_W_m2_sr.max()))


@pytest.mark.slow
def test_band_frame_and_full_frame_measure_the_same_radius(variant, rig):
    """The plug gauge at full resolution, 16 spp, noise-free: the band-rendered frame and the
    full frame give the same mean radius within the render noise (their difference is below
    3 × the standard error of the two means)."""
    from pathlib import Path

    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.measure import Section, measure_sections
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.io import rig_truth

    obj = build_object("plug-gauge")
    cal = calibration_from_frame_truth(rig_truth(rig, rig.camera.K, rig.camera.image_size))
    grid = CylGrid.from_ranges((9.0, 11.0), theta_step_deg=1.0, r_step_mm=0.01)
    radii = {}
    for support in ("geometric", "full"):
        frame = simulate_frame(rig, obj, spp=16, seed=4, noise="none", support=support)
        cloud = measure_sections([Section(Path("f"), 0.0, image=frame.image)], cal, grid)
        r = cloud.radius_mm[np.isfinite(cloud.radius_mm)]
        assert r.size > 200
        radii[support] = r
    a, b = radii["geometric"], radii["full"]
    se = np.hypot(a.std() / np.sqrt(a.size), b.std() / np.sqrt(b.size))
    assert abs(a.mean() - b.mean()) < 3 * se + 1e-4


def test_cli_renders_the_support_by_default_and_the_full_frame_on_request(variant, tmp_path):
    """``lts360 render`` renders the support; ``--support full`` (``--full-frame``) every pixel; with
    ``--max-scatter`` > 0 the geometric support gives way to the hull support; a scan builds its
    scene once (each section moves the object)."""
    import json

    from lts360.cli import main

    for extra, method in (([], "geometric"), (["--support", "full"], "full"),
                          (["--full-frame"], "full"), (["--max-scatter", "1"], "hull")):
        out = tmp_path / "_".join([method] + extra)
        assert main(["render", "--object", "plug-gauge", "--out", str(out), "--scale", "0.125",
                     "--spp", "1", "--sections", "2", "--pitch-mm", "0.5"] + extra) == 0
        truth = json.loads((out / "section_0001" / "frame.json").read_text())
        assert truth["render"]["support"]["method"] == method

"""The ``opencv_camera`` sensor plugin renders what the OpenCV model of the rig camera sees.

Rays against :func:`lts360.geometry.backproject_pixels` (with distortion) and against Mitsuba's
own ``perspective`` sensor; rendered blobs against :func:`lts360.geometry.project_points`; the
thin lens against the geometric-optics blur circle; the scale and crop conventions; determinism.
Images are small (the paper camera at 1/8 scale, or a 64 x 64 crop of the full frame).

Float32 limits (Dr.Jit ``Float`` in the llvm/cuda variants): a unit direction is rounded to
~6e-8 rad, a world point ~200 mm from the origin to ~1e-5 mm.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lts360.geometry import backproject_pixels, project_points, scale_intrinsics
from lts360.scenes.rig_io import load_rig
from lts360.simulator.camera_plugin import (
    camera_to_mitsuba,
    newton_iterations_needed,
    register,
    undistort_newton,
)

mi = pytest.importorskip("mitsuba", reason="the simulator needs Mitsuba 3")

#: A strongly distorted lens (|k1| at the top of real 8 mm lenses, both tangential terms).
DIST = np.array([-0.2, 0.1, 1e-3, -5e-4, 0.0])
SCALE = 0.125  # the paper's 1280 x 1024 camera at 160 x 128
#: Directions: 1e-6 rad is ~15x the float32 rounding of a unit vector.
ANGLE_TOL_RAD = 1e-6
#: Points on rays ~200 mm from the world origin: float32 rounding is ~1e-5 mm.
POINT_TOL_MM = 1e-4


@pytest.fixture(params=["llvm_ad_mono", "scalar"])
def any_variant(request):
    """The JIT variant and a scalar one (the plugin must run in both)."""
    if request.param == "scalar":
        name = next((v for v in ("scalar_mono", "scalar_rgb") if v in mi.variants()), None)
    else:
        name = request.param if request.param in mi.variants() else None
    if name is None:
        pytest.skip(f"no Mitsuba variant {request.param!r} in this build")
    previous = mi.variant()
    mi.set_variant(name)
    register()
    yield name
    if previous is not None:
        mi.set_variant(previous)


@pytest.fixture
def variant():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    register()
    return "llvm_ad_mono"


@pytest.fixture(scope="module")
def paper_camera():
    return load_rig("paper").camera


@pytest.fixture(scope="module")
def distorted_camera(paper_camera):
    return dataclasses.replace(paper_camera, distortion=DIST)


# -- helpers ----------------------------------------------------------------------------------

def _sample_rays(sensor, film_xy, aperture=(0.5, 0.5)):
    """Rays for film positions ``film_xy`` (n, 2) in pixels of the full film (no crop)."""
    size = np.array(sensor.film().crop_size(), dtype=float)
    offset = np.array(sensor.film().crop_offset(), dtype=float)
    s2 = (np.asarray(film_xy, dtype=float) - offset) / size
    ap = np.broadcast_to(np.asarray(aperture, dtype=float), s2.shape)
    if mi.variant().startswith("scalar"):
        rays = [sensor.sample_ray(0.0, 0.5, mi.Point2f(float(a), float(b)),
                                  mi.Point2f(float(c), float(d)))[0]
                for (a, b), (c, d) in zip(s2, ap)]
        return (np.array([list(r.o) for r in rays], dtype=float),
                np.array([list(r.d) for r in rays], dtype=float))
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(s2[:, 0], s2[:, 1]),
                               mi.Point2f(ap[:, 0], ap[:, 1]))
    return np.array(ray.o, dtype=float).T, np.array(ray.d, dtype=float).T


def _angle(a, b):
    """Angle between rows of ``a`` and ``b`` (atan2 of |a×b| and a·b: exact near 0)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))


def _world_point(camera, K, pixel, depth_mm):
    """World point at depth ``depth_mm`` (camera z) seen at OpenCV ``pixel`` (distortion incl.)."""
    ray = backproject_pixels(np.array([pixel], dtype=float), K, camera.distortion)[0]
    return (ray * depth_mm / ray[2] - camera.t_mm) @ camera.R


def _emissive_disk(center, radius, normal, u_axis):
    """One-sided area emitter (unit radiance) on a disk; front face along ``normal``."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    a = np.asarray(u_axis, dtype=float) - n * (n @ u_axis)
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = a * radius, b * radius, n, center
    return {"type": "disk", "to_world": mi.ScalarTransform4f(T.tolist()),
            "emitter": {"type": "area", "radiance": 1.0}}, a, b


def _moments(img):
    """Flux, centroid (x, y) and per-axis variance (mean of x and y) with pixel centres at integers."""
    yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
    flux = float(img.sum())
    c = np.array([(img * xx).sum(), (img * yy).sum()]) / flux
    var = ((img * (xx - c[0]) ** 2).sum() + (img * (yy - c[1]) ** 2).sum()) / (2.0 * flux)
    return flux, c, var


def _polygon_centroid_area(q):
    x, y = q[:, 0], q[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = cross.sum() / 2.0
    return np.array([((x + x1) * cross).sum(), ((y + y1) * cross).sum()]) / (6.0 * area), abs(area)


def _render(scene, sensor=None, *, spp, seed=0):
    integrator = mi.load_dict({"type": "path", "max_depth": 1})  # emitters seen directly
    kw = {} if sensor is None else {"sensor": sensor}
    img = np.array(mi.render(scene, integrator=integrator, spp=spp, seed=seed, **kw), dtype=float)
    return img[..., 0]


# -- (a) ray geometry -------------------------------------------------------------------------

def test_rays_pass_through_backprojected_points(any_variant, distorted_camera):
    cam = distorted_camera
    sensor = mi.load_dict(camera_to_mitsuba(cam, spp=1, scale=SCALE, thin_lens=False))
    W, H = 160, 128
    K = scale_intrinsics(cam.K, SCALE)
    rng = np.random.default_rng(0)
    film = np.vstack([rng.uniform([0, 0], [W, H], size=(40, 2)),
                      [[0, 0], [W, 0], [0, H], [W, H], [W / 2, H / 2]]])  # corners: most distortion
    o, d = _sample_rays(sensor, film)
    ref = backproject_pixels(film - 0.5, K, cam.distortion) @ cam.R  # camera → world: Rᵀ
    assert np.max(_angle(d, ref)) < ANGLE_TOL_RAD
    # The ray's line passes through the camera centre; its origin sits on the near clip plane.
    C = cam.center_mm
    near = 1.0 / (d @ cam.R[2])  # camera_to_mitsuba puts the near plane at z_cam = 1 mm
    assert np.max(np.linalg.norm(o - (C + d * near[:, None]), axis=1)) < POINT_TOL_MM
    # And through the point the model projects back onto the pixel (depth 200 mm).
    pts = C + d * (200.0 / (d @ cam.R[2]))[:, None]
    err_px = np.linalg.norm(project_points(pts, K, cam.distortion, cam.R, cam.t_mm) - (film - 0.5), axis=1)
    assert np.max(err_px) < ANGLE_TOL_RAD * K[0, 0] * 2.0  # 2: a ray near the corner sees ~1.5x fx


def test_undistortion_converges_below_1e6_px(variant, distorted_camera):
    cam = distorted_camera
    K = cam.K
    n, residual = newton_iterations_needed(K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1], DIST,
                                           cam.width_px, cam.height_px)
    assert 1 <= n <= 10 and residual < 1e-6
    # The Dr.Jit (float64) iteration is the numpy one: compare with the reference inverse.
    from lts360.geometry import distort_normalized, undistort_normalized

    rng = np.random.default_rng(1)
    xy_true = rng.uniform(-0.45, 0.45, size=(200, 2))
    xyd = distort_normalized(xy_true, DIST)
    x, y = undistort_newton(mi.Float64(xyd[:, 0]), mi.Float64(xyd[:, 1]), DIST, n)
    got = np.stack([np.array(x), np.array(y)], axis=1)
    assert np.max(np.abs(got - undistort_normalized(xyd, DIST))) * K[0, 0] < 1e-6


def test_fold_over_distortion_is_rejected(variant, paper_camera):
    cam = dataclasses.replace(paper_camera, distortion=[-1.5, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="opencv_camera: .*(did not converge|folds over)"):
        camera_to_mitsuba(cam, spp=1)


def test_thin_lens_rays_meet_the_pinhole_ray_on_the_focus_plane(any_variant, distorted_camera):
    cam = distorted_camera
    sensor = mi.load_dict(camera_to_mitsuba(cam, spp=1, scale=SCALE, thin_lens=True))
    pin = mi.load_dict(camera_to_mitsuba(cam, spp=1, scale=SCALE, thin_lens=False))
    film = np.array([[10.3, 7.9], [80.0, 64.0], [150.5, 120.25]])
    _, d_pin = _sample_rays(pin, film)
    C, z_axis, s_f = cam.center_mm, cam.R[2], cam.focus_distance_mm
    focus_pts = C + d_pin * (s_f / (d_pin @ z_axis))[:, None]
    r_pupil = cam.aperture_diameter_mm / 2.0
    for ap in [(0.5, 0.5), (0.0, 0.3), (0.9, 0.95), (0.25, 1.0)]:
        o, d = _sample_rays(sensor, film, ap)
        t = (s_f - (o - C) @ z_axis) / (d @ z_axis)
        assert np.max(np.linalg.norm(o + d * t[:, None] - focus_pts, axis=1)) < POINT_TOL_MM
        # Origins lie on the pupil disk (before the shift to the near plane).
        o_pupil = o - d * (((o - C) @ z_axis) / (d @ z_axis))[:, None]
        assert np.all(np.linalg.norm(o_pupil - C, axis=1) <= r_pupil * (1 + 1e-5))
    o, d = _sample_rays(sensor, film, (0.5, 0.5))  # the pupil centre gives the chief ray
    assert np.max(_angle(d, d_pin)) < ANGLE_TOL_RAD


def test_matches_mitsuba_perspective_without_distortion(variant, paper_camera):
    cam = paper_camera  # centred principal point, no distortion: Mitsuba's perspective camera
    ours = camera_to_mitsuba(cam, spp=1, scale=SCALE, thin_lens=False)
    fov_deg = math.degrees(2.0 * math.atan(cam.width_px / (2.0 * cam.K[0, 0])))
    persp = mi.load_dict({"type": "perspective", "fov_axis": "x", "fov": fov_deg,
                          "to_world": ours["to_world"], "near_clip": ours["near_clip"],
                          "far_clip": ours["far_clip"], "film": ours["film"]})
    sensor = mi.load_dict(ours)
    film = np.random.default_rng(2).uniform([0, 0], [160, 128], size=(64, 2))
    o1, d1 = _sample_rays(sensor, film)
    o2, d2 = _sample_rays(persp, film)
    assert np.max(_angle(d1, d2)) < ANGLE_TOL_RAD
    assert np.max(np.linalg.norm(o1 - o2, axis=1)) < POINT_TOL_MM


def test_crop_window_keeps_full_film_coordinates(variant, distorted_camera):
    full = mi.load_dict(camera_to_mitsuba(distorted_camera, spp=1, scale=SCALE, thin_lens=False))
    crop = mi.load_dict(camera_to_mitsuba(distorted_camera, spp=1, scale=SCALE, thin_lens=False,
                                          crop_px=(100, 20, 32, 24)))
    film = np.array([[100.0, 20.0], [116.5, 32.5], [132.0, 44.0]])  # inside the crop window
    _, d_full = _sample_rays(full, film)
    _, d_crop = _sample_rays(crop, film)  # (the helper removes the crop offset and size)
    assert np.max(_angle(d_full, d_crop)) < ANGLE_TOL_RAD


# -- (b) rendered blobs land where project_points puts them ------------------------------------

def test_emitter_centroids_match_projection(variant, distorted_camera):
    """Small emissive disks (image diameter 3-7 px) facing the camera, pinhole, distortion on.

    Reference: the area centroid of the disk's projected outline (4000-gon through
    ``project_points``), which is what a uniform blob integrates to; it differs from the
    projection of the disk centre by < 0.005 px for these sizes.  Tolerance 0.05 px: Monte
    Carlo noise of the centroid at 1024 spp is ~0.005 px (edge pixels are binomial in their
    covered fraction) and the box-pixel sampling (aliasing) bias of a uniform disk of
    radius >= 1.5 px is ~0.01 px at most.
    """
    cam = distorted_camera
    K = scale_intrinsics(cam.K, SCALE)
    C = cam.center_mm
    blobs = [((120.0, 30.0), 170.0, 2.5), ((20.0, 100.0), 200.0, 2.0),
             ((79.5, 63.5), 180.0, 3.0), ((148.0, 117.0), 190.0, 1.6)]
    scene = {"type": "scene", "sensor": camera_to_mitsuba(cam, spp=1024, scale=SCALE, thin_lens=False)}
    geo = []
    for i, (px, depth, radius) in enumerate(blobs):
        P = _world_point(cam, K, px, depth)
        shape, a, b = _emissive_disk(P, radius, C - P, cam.R[0])
        scene[f"disk{i}"] = shape
        ang = np.linspace(0.0, 2.0 * np.pi, 4000, endpoint=False)
        outline = P + radius * (np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * b)
        geo.append((P, _polygon_centroid_area(project_points(outline, K, cam.distortion, cam.R, cam.t_mm))))
    img = _render(mi.load_dict(scene), spp=1024, seed=3)
    assert img.shape == (128, 160)
    for (px, _, _), (P, (poly_c, poly_area)) in zip(blobs, geo):
        proj = project_points(P[None], K, cam.distortion, cam.R, cam.t_mm)[0]
        assert np.allclose(proj, px, atol=1e-9)
        x0, y0 = int(round(px[0])) - 8, int(round(px[1])) - 8
        win = img[max(y0, 0): y0 + 17, max(x0, 0): x0 + 17]
        flux, c, _ = _moments(win)
        c = c + [max(x0, 0), max(y0, 0)]
        assert np.linalg.norm(c - poly_c) < 0.05
        assert np.linalg.norm(c - proj) < 0.05
        # Unit ray weights + box filter: the blob's flux is its image area (radiance 1).
        assert flux == pytest.approx(poly_area, rel=0.02)  # MC noise ~0.4 % at 1024 spp


# -- (c) thin lens: sharp at the focus distance, the geometric blur circle at 1.5x ---------------

def test_thin_lens_blur_circle(variant, paper_camera):
    """Full-resolution paper camera (f = 8 mm, f/1.4, focused on the object axis), 64 x 64 crops.

    A point at depth ``s`` is spread over a disk of diameter ``A·f_x·|s − s_f| / (s·s_f)``
    pixels (``A = f/N``: pupil diameter).  The geometric-optics blur circle on the sensor,
    ``c = A·|s − s_f|/s · f/(s_f − f)``, is the same expression with the sensor at the image
    distance ``v = f·s_f/(s_f − f)`` instead of ``f_x·pitch = f``; the calibrated ``f_x`` of a
    focused lens *is* ``v/pitch``, the rig's ``f_x = f/pitch`` makes ours smaller by
    ``1 − f/s_f`` (≈5 % for the paper preset).  The diameter is measured from the second moment: per axis
    ``σ² = D²/16`` (uniform disk) ``+ ρ²/4`` (the source's own image, radius ρ) ``+ 1/12``
    (pixel box).
    """
    cam = paper_camera
    K = cam.K
    s_f = cam.focus_distance_mm
    A = cam.aperture_diameter_mm
    radius = 0.5
    n_cam = -cam.R[2]  # disks parallel to the focus plane, facing the camera
    sites = {"sharp": ((400.0, 300.0), s_f), "blurred": ((900.0, 700.0), 1.5 * s_f)}
    scene = {"type": "scene", "sensor": camera_to_mitsuba(cam, spp=1, thin_lens=False)}
    for name, (px, depth) in sites.items():
        scene[name] = _emissive_disk(_world_point(cam, K, px, depth), radius, n_cam, cam.R[0])[0]
    scene = mi.load_dict(scene)

    def render(name, thin, spp, seed=0):
        px = sites[name][0]
        crop = (int(px[0]) - 32, int(px[1]) - 32, 64, 64)
        sensor = mi.load_dict(camera_to_mitsuba(cam, spp=spp, thin_lens=thin, crop_px=crop))
        flux, c, var = _moments(_render(scene, sensor, spp=spp, seed=seed))
        return flux, c + crop[:2], var

    # In focus: the thin lens gives the pinhole image (every pupil sample of a pixel sees the
    # same point of the focus plane).
    f_pin, c_pin, v_pin = render("sharp", False, 256)
    f_thin, c_thin, v_thin = render("sharp", True, 256)
    assert f_thin == pytest.approx(f_pin, rel=1e-3)
    assert v_thin == pytest.approx(v_pin, rel=1e-3)
    assert np.linalg.norm(c_thin - c_pin) < 1e-3

    s = sites["blurred"][1]
    rho = radius * K[0, 0] / s
    flux, c, var = render("blurred", True, 1024)
    D = 4.0 * math.sqrt(var - rho ** 2 / 4.0 - 1.0 / 12.0)
    D_model = A * K[0, 0] * abs(s - s_f) / (s * s_f)  # ≈17 px
    D_optics = A * abs(s - s_f) / s * cam.focal_length_mm / (s_f - cam.focal_length_mm) \
        / (cam.pixel_pitch_um * 1e-3)
    assert D == pytest.approx(D_model, rel=0.03)  # MC noise of D ~0.3 % at 1024 spp
    assert D == pytest.approx(D_optics, rel=0.15)
    assert D / D_optics == pytest.approx(1.0 - cam.focal_length_mm / s_f, rel=0.03)
    assert flux == pytest.approx(math.pi * rho ** 2, rel=0.03)  # defocus keeps the flux (noise 0.7 %)
    assert np.linalg.norm(c - sites["blurred"][0]) < 0.15  # centred; noise ~0.03 px per axis


# -- (d) scale ----------------------------------------------------------------------------------

@pytest.mark.parametrize("scale", [0.125, 0.5, 0.3])
def test_scale_keeps_pixel_centre_convention(variant, distorted_camera, scale):
    cam = distorted_camera
    d = camera_to_mitsuba(cam, spp=1, scale=scale, thin_lens=False)
    W, H = round(cam.width_px * scale), round(cam.height_px * scale)
    assert (d["film"]["width"], d["film"]["height"]) == (W, H)
    K = cam.K
    assert d["fx"] == pytest.approx(K[0, 0] * scale, rel=1e-12)
    assert d["cx"] == pytest.approx((K[0, 2] + 0.5) * scale - 0.5, abs=1e-12)
    assert d["cy"] == pytest.approx((K[1, 2] + 0.5) * scale - 0.5, abs=1e-12)
    # The ray through OpenCV pixel u of the full image is the ray through u' = (u + 0.5)s − 0.5.
    full = mi.load_dict(camera_to_mitsuba(cam, spp=1, thin_lens=False))
    scaled = mi.load_dict(d)
    uv = np.array([[0.0, 0.0], [639.5, 511.5], [1000.25, 90.75], [1279.0, 1023.0]])
    _, d_full = _sample_rays(full, uv + 0.5)
    _, d_scaled = _sample_rays(scaled, (uv + 0.5) * scale)
    assert np.max(_angle(d_full, d_scaled)) < ANGLE_TOL_RAD


# -- (e) determinism, film and sampler ----------------------------------------------------------

def test_same_seed_same_image(variant, distorted_camera):
    cam = distorted_camera
    K = scale_intrinsics(cam.K, SCALE)
    P = _world_point(cam, K, (60.0, 50.0), 180.0)
    scene = mi.load_dict({"type": "scene",
                          "sensor": camera_to_mitsuba(cam, spp=16, scale=SCALE, thin_lens=True),
                          "disk": _emissive_disk(P, 4.0, cam.center_mm - P, cam.R[0])[0]})
    a = _render(scene, spp=16, seed=7)
    b = _render(scene, spp=16, seed=7)
    c = _render(scene, spp=16, seed=8)
    assert a.sum() > 0
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_film_and_sampler_dictionary(variant, paper_camera):
    d = camera_to_mitsuba(paper_camera, spp=12, seed=5, scale=SCALE)
    assert d["type"] == "opencv_camera"
    assert d["film"]["pixel_format"] == "luminance" and d["film"]["component_format"] == "float32"
    assert d["film"]["rfilter"] == {"type": "box"}
    assert d["sampler"] == {"type": "independent", "sample_count": 12, "seed": 5}
    assert d["aperture_radius"] == pytest.approx(paper_camera.aperture_diameter_mm / 2)
    assert d["focus_distance"] == pytest.approx(paper_camera.focus_distance_mm)
    assert "aperture_radius" not in camera_to_mitsuba(paper_camera, spp=1, thin_lens=False)
    sensor = mi.load_dict(d)
    assert sensor.needs_aperture_sample()
    assert not mi.load_dict(camera_to_mitsuba(paper_camera, spp=1, thin_lens=False)).needs_aperture_sample()


@pytest.mark.parametrize("kwargs, match", [
    ({"spp": 0}, "spp"), ({"spp": 4, "scale": 0.0}, "scale"), ({"spp": 4, "seed": -1}, "seed"),
    ({"spp": 4, "crop_px": (1270, 0, 32, 32)}, "crop_px"),
])
def test_bad_arguments_are_named(variant, paper_camera, kwargs, match):
    with pytest.raises(ValueError, match=match):
        camera_to_mitsuba(paper_camera, **kwargs)


def test_plugin_checks_its_properties(variant, paper_camera):
    d = camera_to_mitsuba(paper_camera, spp=1, scale=SCALE)
    del d["focus_distance"]
    with pytest.raises(RuntimeError, match="focus_distance is required"):
        mi.load_dict(d)
    d = camera_to_mitsuba(paper_camera, spp=1, scale=SCALE)
    d["fx"] = -1.0
    with pytest.raises(RuntimeError, match="fx and fy must be > 0"):
        mi.load_dict(d)

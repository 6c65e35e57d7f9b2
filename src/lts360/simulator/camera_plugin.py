"""Mitsuba 3 sensor plugin ``opencv_camera``: the OpenCV camera of the rig, ray for ray.

Each film sample is mapped to the exact ray of the OpenCV model (pinhole ``K[R|t]`` with Brown
distortion ``(k1, k2, p1, p2, k3)``, :mod:`lts360.geometry.camera`):

1. film position → OpenCV pixel: Mitsuba's film pixel ``(i, j)`` covers ``[i, i+1) × [j, j+1)``
   and its centre is the OpenCV pixel ``(i, j)``, so ``(u, v) = (film_x − 0.5, film_y − 0.5)``;
2. ``K⁻¹`` → distorted normalised coordinates;
3. undistortion by Newton's method in double precision, unrolled a fixed number of times; the
   count is chosen when the sensor is built: the smallest one that meets ``undistort_tol_px``
   on a dense grid over the whole film, plus one (Newton converges quadratically, so the extra
   iteration squares the residual), and construction fails if ``undistort_iterations`` do not
   suffice (distortion not invertible over the film);
4. ray in the camera frame (x right, y down, z forward) → world.

Pinhole when ``aperture_radius`` is 0; otherwise a thin lens whose entrance pupil (a disk of
radius ``aperture_radius``, sampled with Mitsuba's aperture sample) lies at the projection centre:
each ray leaves a point of the pupil towards the point of the focus plane
``z_cam = focus_distance`` that the pinhole ray through the same film position reaches.
Points off that plane are blurred into a disk of diameter ``2·aperture_radius·f_x·|1/s_f − 1/s|``
pixels (``s``: depth of the point).

Every ray carries unit weight (times the wavelength weight, which is 1 in mono and RGB
variants): with a ``box`` reconstruction filter each pixel's value is the mean radiance
arriving at the pupil over the pixel's area and the pupil's area; radiometry (irradiance,
exposure) is the renderer's business.  Rays carry no differentials, so textures are point-
sampled and the pixel integral is done by the samples alone.

Properties (lengths in scene units, millimetres in this project; pixels of the full film)
------------------------------------------------------------------------------------------
fx, fy : float, > 0            focal lengths in pixels (required)
cx, cy : float                 principal point, OpenCV convention (required)
skew : float                   ``K[0, 1]`` (default 0)
k1, k2, p1, p2, k3 : float     Brown distortion, OpenCV order (default 0)
to_world : transform           camera-to-world in Mitsuba's camera convention (x left, y up,
                               z forward), as for ``perspective``; the OpenCV axes (x right,
                               y down) are the first two negated — :func:`camera_to_mitsuba`
                               builds it from ``R, t``
aperture_radius : float, >= 0  entrance pupil radius (default 0: pinhole)
focus_distance : float, > 0    depth of the plane in focus (required when aperture_radius > 0)
near_clip, far_clip : float    clip planes ``z_cam = near_clip`` / ``far_clip``
                               (default 1e-2 / 1e4, as ``perspective``)
undistort_iterations : int     maximum Newton iterations, [1, 50] (default 10)
undistort_tol_px : float       convergence tolerance of the undistortion in pixels (default 1e-6)

The caller sets the Mitsuba variant, then calls :func:`register`; nothing here runs at import.
``OpenCVCamera`` (module attribute) is the plugin class of the active variant.
"""

from __future__ import annotations

import math

import numpy as np

from lts360.geometry.camera import camera_center, scale_intrinsics

__all__ = ["PLUGIN_NAME", "register", "sensor_class", "camera_to_mitsuba", "undistort_newton",
           "newton_iterations_needed"]

PLUGIN_NAME = "opencv_camera"

#: Defaults of the plugin's properties.
DEFAULT_UNDISTORT_ITERATIONS = 10
DEFAULT_UNDISTORT_TOL_PX = 1e-6
#: Points per film axis on which the undistortion's convergence is verified at construction.
_CHECK_GRID = 65
#: Clip planes written by :func:`camera_to_mitsuba`: nothing of the rig lies within 1 mm of the
#: lens, nothing of a lab beyond 100 m (rays that reach it see the environment).
NEAR_CLIP_MM = 1.0
FAR_CLIP_MM = 1e5

_classes: dict[str, type] = {}
_registered: set[str] = set()


# --------------------------------------------------------------------------------------------
# Undistortion: one implementation for numpy arrays, Dr.Jit arrays and Python floats
# --------------------------------------------------------------------------------------------

def _newton_step(x, y, xd, yd, dist):
    """One Newton step from ``(x, y)`` towards ``distort(x, y) = (xd, yd)``.

    Uses only ``+ − × ÷`` so that the same code runs on numpy arrays (the construction-time
    check), Dr.Jit arrays (the plugin) and Python floats (scalar variants).
    """
    k1, k2, p1, p2, k3 = dist
    x2, y2, xy = x * x, y * y, x * y
    r2 = x2 + y2
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    ex = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2) - xd
    ey = y * radial + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy - yd
    j00 = radial + 2.0 * x2 * dradial + 2.0 * p1 * y + 6.0 * p2 * x
    j01 = 2.0 * xy * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    j11 = radial + 2.0 * y2 * dradial + 6.0 * p1 * y + 2.0 * p2 * x
    inv_det = 1.0 / (j00 * j11 - j01 * j01)
    return x - (j11 * ex - j01 * ey) * inv_det, y - (j00 * ey - j01 * ex) * inv_det


def undistort_newton(xd, yd, dist, iterations: int):
    """Invert Brown distortion by ``iterations`` Newton steps started at the distorted point.

    Parameters
    ----------
    xd, yd : array-like (numpy, Dr.Jit or float)
        Distorted normalised coordinates.
    dist : (5,) float
        ``(k1, k2, p1, p2, k3)``.
    iterations : int, >= 0

    Returns
    -------
    x, y
        Undistorted normalised coordinates, of the type of ``xd``.
    """
    dist = tuple(float(c) for c in dist)  # numpy scalars would not mix with Dr.Jit arrays
    x, y = xd, yd
    for _ in range(int(iterations)):
        x, y = _newton_step(x, y, xd, yd, dist)
    return x, y


def _residual_px(x, y, xd, yd, dist, fx: float, fy: float, skew: float) -> np.ndarray:
    """Pixel distance between ``distort(x, y)`` and the target ``(xd, yd)`` (numpy, float64)."""
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    ex = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
    ey = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
    res = np.hypot(fx * ex + skew * ey, fy * ey)
    return np.where(np.isfinite(res), res, np.inf)


def newton_iterations_needed(fx: float, fy: float, cx: float, cy: float, skew: float, dist,
                             width: int, height: int, *, tol_px: float = DEFAULT_UNDISTORT_TOL_PX,
                             max_iterations: int = DEFAULT_UNDISTORT_ITERATIONS,
                             grid: int = _CHECK_GRID) -> tuple[int, float]:
    """Newton iterations the plugin unrolls for this camera, and the residual they leave.

    The undistortion (:func:`undistort_newton`, float64) is run on a ``grid × grid`` lattice that
    spans the whole film, edges and corners included; ``n`` is the smallest count whose largest
    residual is below ``tol_px``.  The plugin uses one more (quadratic convergence squares the
    residual, which covers the film between the lattice nodes), at most ``max_iterations``.

    Parameters
    ----------
    fx, fy, cx, cy, skew : float
        Intrinsics in pixels (OpenCV convention).
    dist : (5,) float
        ``(k1, k2, p1, p2, k3)``.
    width, height : int
        Film size in pixels.
    tol_px : float, > 0
    max_iterations : int, >= 1

    Returns
    -------
    iterations : int
        ``min(n + 1, max_iterations)``; 0 without distortion.
    residual_px : float
        Largest residual on the lattice after ``iterations`` steps.

    Raises
    ------
    ValueError
        When ``max_iterations`` steps do not reach ``tol_px`` (a distortion that is not invertible
        over the film, or too strong for Newton started at the distorted point).
    """
    dist = tuple(float(c) for c in dist)
    if not any(dist):
        return 0, 0.0
    uu, vv = np.meshgrid(np.linspace(-0.5, width - 0.5, grid), np.linspace(-0.5, height - 0.5, grid))
    yd = (vv - cy) / fy
    xd = (uu - cx - skew * yd) / fx
    x, y = xd, yd
    res = np.inf
    with np.errstate(all="ignore"):
        for n in range(1, max_iterations + 1):
            x, y = _newton_step(x, y, xd, yd, dist)
            res = float(np.max(_residual_px(x, y, xd, yd, dist, fx, fy, skew)))
            if res < tol_px:
                if n < max_iterations:
                    x, y = _newton_step(x, y, xd, yd, dist)
                    res = float(np.max(_residual_px(x, y, xd, yd, dist, fx, fy, skew)))
                    n += 1
                _check_radial_monotonic(dist, float(np.sqrt(np.max(x * x + y * y))))
                return n, res
    raise ValueError(
        f"{PLUGIN_NAME}: undistortion did not converge to undistort_tol_px={tol_px:g} within "
        f"undistort_iterations={max_iterations} over the {width}x{height} film (largest residual "
        f"{res:.3g} px); the distortion (k1, k2, p1, p2, k3)={dist} must be invertible over the "
        "whole image")


def _check_radial_monotonic(dist, r_max: float) -> None:
    """Raise if ``r·(1 + k1 r² + k2 r⁴ + k3 r⁶)`` folds over within the field (``r <= r_max``).

    Beyond a fold the distortion has two preimages and Newton may settle on the wrong one even
    though its residual is tiny.
    """
    k1, k2, _, _, k3 = dist
    r2 = np.linspace(0.0, r_max, 2001) ** 2
    slope = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + 7.0 * k3 * r2))
    if np.min(slope) <= 0:
        raise ValueError(
            f"{PLUGIN_NAME}: the radial distortion (k1, k2, k3)=({k1:g}, {k2:g}, {k3:g}) folds over "
            f"inside the field of view (normalised radius <= {r_max:.3g}); it must be monotonic "
            "over the whole image")


# --------------------------------------------------------------------------------------------
# The plugin class (one per Mitsuba variant, built on demand)
# --------------------------------------------------------------------------------------------

def _get_float(props, name: str, default: float | None = None) -> float:
    if name not in props:
        if default is None:
            raise ValueError(f"{PLUGIN_NAME}: property '{name}' is required")
        return float(default)
    value = props.get(name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{PLUGIN_NAME}: property '{name}' must be a finite number, got {value!r}")
    return float(value)


def _build_class():
    import drjit as dr
    import mitsuba as mi

    class OpenCVCamera(mi.Sensor):
        """OpenCV camera (Brown distortion, pinhole or thin lens) as a Mitsuba sensor."""

        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            self.fx = _get_float(props, "fx")
            self.fy = _get_float(props, "fy")
            self.cx = _get_float(props, "cx")
            self.cy = _get_float(props, "cy")
            self.skew = _get_float(props, "skew", 0.0)
            self.dist = tuple(_get_float(props, k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3"))
            self.aperture_radius = _get_float(props, "aperture_radius", 0.0)
            self.focus_distance = _get_float(props, "focus_distance", 1.0)
            self.near_clip = _get_float(props, "near_clip", 1e-2)
            self.far_clip = _get_float(props, "far_clip", 1e4)
            max_it = props.get("undistort_iterations", DEFAULT_UNDISTORT_ITERATIONS)
            tol = _get_float(props, "undistort_tol_px", DEFAULT_UNDISTORT_TOL_PX)
            if not (self.fx > 0 and self.fy > 0):
                raise ValueError(f"{PLUGIN_NAME}: fx and fy must be > 0 pixels, "
                                 f"got fx={self.fx}, fy={self.fy}")
            if not self.aperture_radius >= 0:
                raise ValueError(f"{PLUGIN_NAME}: aperture_radius must be >= 0, "
                                 f"got {self.aperture_radius}")
            if self.aperture_radius > 0 and "focus_distance" not in props:
                raise ValueError(f"{PLUGIN_NAME}: focus_distance is required when aperture_radius > 0")
            if not self.focus_distance > 0:
                raise ValueError(f"{PLUGIN_NAME}: focus_distance must be > 0, got {self.focus_distance}")
            if not 0 < self.near_clip < self.far_clip:
                raise ValueError(f"{PLUGIN_NAME}: need 0 < near_clip < far_clip, got "
                                 f"near_clip={self.near_clip}, far_clip={self.far_clip}")
            if isinstance(max_it, bool) or not isinstance(max_it, int) or not 1 <= max_it <= 50:
                raise ValueError(f"{PLUGIN_NAME}: undistort_iterations must be an integer in "
                                 f"[1, 50], got {max_it!r}")
            if not tol > 0:
                raise ValueError(f"{PLUGIN_NAME}: undistort_tol_px must be > 0, got {tol}")
            to_world = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=float)
            lin = to_world[:3, :3]
            if not (np.allclose(lin.T @ lin, np.eye(3), atol=1e-5) and np.linalg.det(lin) > 0):
                raise ValueError(f"{PLUGIN_NAME}: to_world must be a rigid motion (rotation and "
                                 "translation, no scale or mirroring)")
            self.center = to_world[:3, 3].copy()
            width, height = (int(c) for c in self.film().size())
            self.undistort_iterations, self.undistort_residual_px = newton_iterations_needed(
                self.fx, self.fy, self.cx, self.cy, self.skew, self.dist, width, height,
                tol_px=tol, max_iterations=max_it)
            self.m_needs_sample_3 = self.aperture_radius > 0

        # -- the mapping film sample → ray ------------------------------------------------
        def _camera_ray(self, sample2, sample3):
            """Origin and unit direction in the OpenCV camera frame (x right, y down, z fwd)."""
            film = self.film()
            size, offset = film.crop_size(), film.crop_offset()
            # Film position → OpenCV pixel (film pixel centres sit at +0.5), in float64.
            u = mi.Float64(sample2.x) * float(size[0]) + (float(offset[0]) - 0.5)
            v = mi.Float64(sample2.y) * float(size[1]) + (float(offset[1]) - 0.5)
            yd = (v - self.cy) * (1.0 / self.fy)
            xd = (u - self.cx - self.skew * yd) * (1.0 / self.fx)
            x, y = undistort_newton(xd, yd, self.dist, self.undistort_iterations)
            x, y = mi.Float(x), mi.Float(y)
            if self.aperture_radius > 0:
                a = mi.warp.square_to_uniform_disk_concentric(sample3) * self.aperture_radius
                s = self.focus_distance
                d = dr.normalize(mi.Vector3f(x * s - a.x, y * s - a.y, s))
                o = mi.Point3f(a.x, a.y, 0.0)
            else:
                d = dr.normalize(mi.Vector3f(x, y, 1.0))
                o = mi.Point3f(0.0, 0.0, 0.0)
            return o, d

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            wavelengths, weight = self.sample_wavelengths(
                dr.zeros(mi.SurfaceInteraction3f), sample1, active)
            o_cv, d_cv = self._camera_ray(sample2, sample3)
            # OpenCV (x right, y down) → Mitsuba camera (x left, y up): negate x and y.
            to_world = self.world_transform()
            o = to_world @ mi.Point3f(-o_cv.x, -o_cv.y, o_cv.z)
            d = dr.normalize(to_world @ mi.Vector3f(-d_cv.x, -d_cv.y, d_cv.z))
            inv_z = dr.rcp(d_cv.z)
            near_t, far_t = self.near_clip * inv_z, self.far_clip * inv_z
            ray = mi.Ray3f(o + d * near_t, d, time, wavelengths)
            ray.maxt = far_t - near_t
            return ray, weight

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            # No differentials: textures are point-sampled and the samples integrate the pixel.
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            return mi.RayDifferential3f(ray), weight

        def bbox(self):
            r = float(self.aperture_radius)
            c = [float(v) for v in self.center]
            return mi.ScalarBoundingBox3f(mi.ScalarPoint3f([v - r for v in c]),
                                          mi.ScalarPoint3f([v + r for v in c]))

        def to_string(self):
            lens = (f"thin lens, aperture_radius={self.aperture_radius:g}, "
                    f"focus_distance={self.focus_distance:g}" if self.aperture_radius > 0 else "pinhole")
            return (f"OpenCVCamera[fx={self.fx:g}, fy={self.fy:g}, cx={self.cx:g}, cy={self.cy:g}, "
                    f"skew={self.skew:g}, dist={self.dist}, {lens}, near_clip={self.near_clip:g}, "
                    f"far_clip={self.far_clip:g}, undistort_iterations={self.undistort_iterations}, "
                    f"film={self.film().size()}]")

    OpenCVCamera.__qualname__ = "OpenCVCamera"
    return OpenCVCamera


def _active_variant() -> str:
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError(f"{PLUGIN_NAME}: no Mitsuba variant is set: call "
                           "mitsuba.set_variant(...) before using the camera plugin")
    return variant


def sensor_class() -> type:
    """The plugin class (a ``mitsuba.Sensor`` subclass) for the active Mitsuba variant."""
    variant = _active_variant()
    if variant not in _classes:
        _classes[variant] = _build_class()
    return _classes[variant]


def register() -> None:
    """Register the sensor as ``opencv_camera`` for the active variant (idempotent).

    Set the variant first (``mitsuba.set_variant``); registering again for the same variant is
    a no-op, switching variants and calling again registers it for the new one.
    """
    import mitsuba as mi

    variant = _active_variant()
    if variant in _registered:
        return
    cls = sensor_class()
    mi.register_sensor(PLUGIN_NAME, lambda props: cls(props))
    _registered.add(variant)


def __getattr__(name: str):
    # ``OpenCVCamera`` resolves to the class of the active variant (none exists at import time).
    if name == "OpenCVCamera":
        return sensor_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --------------------------------------------------------------------------------------------
# Rig camera → Mitsuba dictionary
# --------------------------------------------------------------------------------------------

def camera_to_mitsuba(camera, *, spp: int, thin_lens: bool = True, scale: float = 1.0,
                      seed: int = 0, crop_px: tuple[int, int, int, int] | None = None) -> dict:
    """Mitsuba dictionary of the ``opencv_camera`` sensor for a rig camera.

    Parameters
    ----------
    camera : lts360.scenes.rig.Camera
    spp : int, >= 1
        Samples per pixel of the (independent) sampler.
    thin_lens : bool
        Thin lens with the camera's f-number (pupil diameter ``f/N``) and focus distance;
        otherwise a pinhole.
    scale : float, > 0
        Image scale: the film is ``round(W·s) × round(H·s)`` and the intrinsics follow
        :func:`lts360.geometry.scale_intrinsics` (``f' = s·f``, ``c' = (c + 0.5)·s − 0.5``).
    seed : int, >= 0
        Sampler seed (``mitsuba.render(seed=...)`` overrides it).
    crop_px : (x, y, width, height) int, optional
        Render only this window of the (scaled) film, in pixels.

    Returns
    -------
    dict
        ``{"type": "opencv_camera", ...}`` with an ``hdrfilm`` (float32; ``luminance`` in mono
        variants, ``rgb`` otherwise), a ``box`` reconstruction filter and an ``independent``
        sampler.  Requires an active Mitsuba variant (for the transform); the plugin must be
        registered (:func:`register`) before the dictionary is loaded.
    """
    import mitsuba as mi

    _active_variant()
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise ValueError(f"spp must be an integer >= 1, got {spp!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if not (isinstance(scale, (int, float, np.floating)) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
    scale = float(scale)
    width = max(1, int(round(camera.width_px * scale)))
    height = max(1, int(round(camera.height_px * scale)))
    K = scale_intrinsics(camera.K, scale)
    # Camera-to-world in Mitsuba's camera convention: OpenCV's Rᵀ with x and y negated.
    to_world = np.eye(4)
    to_world[:3, :3] = np.asarray(camera.R, dtype=float).T @ np.diag([-1.0, -1.0, 1.0])
    to_world[:3, 3] = camera_center(camera.R, camera.t_mm)
    film = {
        "type": "hdrfilm",
        "width": width,
        "height": height,
        "pixel_format": "luminance" if mi.is_monochromatic else "rgb",
        "component_format": "float32",
        "sample_border": False,
        "rfilter": {"type": "box"},
    }
    if crop_px is not None:
        cx0, cy0, cw, ch = (int(c) for c in crop_px)
        if not (0 <= cx0 and 0 <= cy0 and cw >= 1 and ch >= 1 and cx0 + cw <= width
                and cy0 + ch <= height):
            raise ValueError(f"crop_px must be (x, y, width, height) inside the {width}x{height} "
                             f"film, got {tuple(crop_px)!r}")
        film.update(crop_offset_x=cx0, crop_offset_y=cy0, crop_width=cw, crop_height=ch)
    dist = [float(c) for c in camera.distortion]
    # Fail here, with a plain ValueError, rather than inside mitsuba.load_dict.
    newton_iterations_needed(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                             float(K[0, 1]), dist, width, height)
    sensor = {
        "type": PLUGIN_NAME,
        "fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
        "skew": float(K[0, 1]),
        "k1": dist[0], "k2": dist[1], "p1": dist[2], "p2": dist[3], "k3": dist[4],
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "near_clip": NEAR_CLIP_MM,
        "far_clip": FAR_CLIP_MM,
        "film": film,
        "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
    }
    if thin_lens:
        sensor["aperture_radius"] = float(camera.aperture_diameter_mm) / 2.0
        sensor["focus_distance"] = float(camera.focus_distance_mm)
    return sensor

"""Render the noise-free expected radiance of a rig + scene with the laser integrator.

The caller sets the Mitsuba variant once (``mi.set_variant``, or :func:`ensure_variant`) before
calling :func:`render_radiance`, which sets none. :func:`default_variant` is the one place that
chooses a variant when nobody names one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from lts360.geometry.camera import scale_intrinsics
from lts360.simulator.scene import LASER_MIRRORS_CLEARANCE_MM, SceneSpec, load_scene

__all__ = ["MAX_SPP", "RenderResult", "render_radiance", "render_pixels", "render_radiance_pixels",
           "prepare_scene",
           "window_pixels", "require_variant",
           "default_variant", "ensure_variant", "cuda_usable"]

VARIANTS = ("llvm_ad_mono", "cuda_ad_mono", "scalar_mono", "scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb")


def cuda_usable() -> bool:
    """Whether Dr.Jit can run on a CUDA device here; ``False`` without a driver or a device.

    Asks Dr.Jit (``drjit.has_backend``), which loads the CUDA driver if there is one and
    answers ``False`` where there is none; never raises.
    """
    try:
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # an old Dr.Jit without has_backend, a broken driver: not usable
        return False


def default_variant() -> str:
    """``cuda_ad_mono`` where that variant is compiled in and a CUDA device is usable, else
    ``llvm_ad_mono``, else the first compiled variant.

    The one place that chooses a variant: the command line (no ``--variant``), the studies'
    trials and the twin all take it from here (see :func:`ensure_variant`).
    """
    import mitsuba as mi

    available = mi.variants()
    if "cuda_ad_mono" in available and cuda_usable():
        return "cuda_ad_mono"
    return "llvm_ad_mono" if "llvm_ad_mono" in available else available[0]


def ensure_variant(name: str | None = None) -> str:
    """The active Mitsuba variant, setting one first if none is set: ``name`` when given (and
    not empty), else :func:`default_variant`. A variant already set is kept, whatever ``name``.
    """
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant(name or default_variant())
    return mi.variant()


def require_variant() -> str:
    """The active Mitsuba variant; raise if the entry point has not set one."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("no Mitsuba variant is set: call mitsuba.set_variant(...) first "
                           "(the CLI does this from --variant)")
    return variant


@dataclass(frozen=True)
class RenderResult:
    """Noise-free expected radiance at the lens, per pixel (mean over the pixel and the pupil).

    Attributes
    ----------
    radiance_W_m2_sr : (H, W) float32
        Everything (laser + ambient).
    laser_W_m2_sr : (H, W) float32
        The laser's share (coherent light: speckle multiplies only this part).
    K : (3, 3) float
        Intrinsics of the rendered image (scaled when ``scale != 1``).
    variant : str
    spp : int
    seed : int
    seconds : float
        Wall time of the render call.
    held_index : (n,) int64, optional
        Sorted flat indices of the pixels rendered (a support frame without ambient light):
        every other pixel holds no light, 0 in both images.  ``None``: not known (any pixel
        may hold light).  Lets the sensor find the lit pixels without scanning the frame.
    """

    radiance_W_m2_sr: np.ndarray
    laser_W_m2_sr: np.ndarray
    K: np.ndarray
    variant: str
    spp: int
    seed: int
    seconds: float
    held_index: np.ndarray | None = None


#: The most samples per pixel a render takes (beyond it a frame costs minutes on a CPU and the
#: noise-free accuracy no longer improves: ~3 µm a point is reached at 256).
MAX_SPP = 4096


#: The samplers a render takes: Mitsuba's, and ``keyed`` (:func:`render_pixels` with the
#: laser integrator only): :class:`~lts360.simulator.keyed_sampler.KeyedSampler`, a pixel's
#: samples a function of the seed and the pixel alone, whatever the other pixels rendered.
SAMPLERS = ("multijitter", "independent", "stratified", "ldsampler", "keyed")


def _check_args(spp, seed, scale, integrator, sampler) -> None:
    if not (isinstance(spp, int) and 1 <= spp <= MAX_SPP):
        raise ValueError(f"spp must be an integer in [1, {MAX_SPP}], got {spp!r}")
    if not (isinstance(seed, int) and seed >= 0):
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if not 0.0 < scale <= 1.0:
        raise ValueError(f"scale must be in (0, 1], got {scale}")
    if integrator not in ("laser", "path"):
        raise ValueError(f"integrator must be 'laser' or 'path', got {integrator!r}")
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}, got {sampler!r}")


def _setup(spec, *, spp, scale, max_bounces, thin_lens, laser_on, integrator, sampler,
           max_scatter=0):
    """Loaded scene (full film) and integrator."""
    import mitsuba as mi

    from lts360.simulator.camera_plugin import camera_to_mitsuba, register
    from lts360.simulator.integrator import laser_params, make_integrator

    register()
    sensor = camera_to_mitsuba(spec.rig.camera, spp=spp, thin_lens=thin_lens, scale=scale)
    # a keyed render draws its own samples; the sensor's sampler then only sets the count
    sensor["sampler"] = {"type": "independent" if sampler == "keyed" else sampler,
                         "sample_count": spp}
    scene = load_scene(spec, sensor)
    if integrator == "laser":
        lp, mps = laser_params(spec.rig, laser_on=laser_on, mirrors=spec.laser_mirrors)
        kw = ({} if spec.laser_mirrors is None
              else {"clearance_mm": LASER_MIRRORS_CLEARANCE_MM})
        integ = make_integrator(lp, mps, max_bounces=max_bounces, ambient=spec.ambient != "off",
                                max_scatter=max_scatter, **kw)
    else:
        integ = mi.load_dict({"type": "path", "max_depth": max_bounces + 2})
    return scene, integ


def prepare_scene(spec: SceneSpec, *, spp: int = 4, scale: float = 1.0, max_bounces: int = 2,
                  thin_lens: bool = True, laser_on: bool = True, integrator: str = "laser",
                  sampler: str = "multijitter", max_scatter: int = 0):
    """The loaded scene and integrator of ``spec`` (see :func:`render_pixels`'s ``prepared``)."""
    _check_args(spp, 0, scale, integrator, sampler)
    require_variant()
    return _setup(spec, spp=spp, scale=scale, max_bounces=max_bounces, thin_lens=thin_lens,
                  laser_on=laser_on, integrator=integrator, sampler=sampler,
                  max_scatter=max_scatter)


def window_pixels(windows) -> np.ndarray:
    """(n, 2) int ``(x, y)`` of every pixel of the windows ``(x, y, width, height)``, window
    by window, row-major (the windows should not overlap: a shared pixel is listed twice)."""
    blocks = [np.stack(np.meshgrid(np.arange(x, x + w), np.arange(y, y + h)), axis=-1).reshape(-1, 2)
              for x, y, w, h in windows]
    return np.concatenate(blocks) if blocks else np.zeros((0, 2), dtype=int)


def render_pixels(spec: SceneSpec, pixels_xy, *, spp: int = 4, seed: int = 0, scale: float = 1.0,
                  max_bounces: int = 2, thin_lens: bool = True, laser_on: bool = True,
                  integrator: str = "laser", sampler: str = "multijitter", prepared=None,
                  max_scatter: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Render only the listed pixels of the (scaled) film, ray for ray as :func:`render_radiance`.

    The camera rays, samples and box reconstruction are those of a full render: each pixel is
    the mean of its ``spp`` samples, the film position of a sample is the pixel plus the
    sampler's 2-D jitter, then (thin lens) the sampler's aperture sample — Mitsuba's order.
    One wavefront is launched for all pixels; the pixel list is kernel data, so Dr.Jit
    compiles one kernel per scene structure and reuses it for any pixel set (a film crop of
    another size or offset would compile anew: its size and offset are kernel constants).
    The noise realisation differs from a full render's (the sampler is seeded per wavefront
    lane), its statistics do not.

    Parameters
    ----------
    spec : SceneSpec
    pixels_xy : (n, 2) int
        Pixel ``(x, y)`` of the full film (OpenCV: pixel ``(x, y)`` covers
        ``[x − 0.5, x + 0.5) × [y − 0.5, y + 0.5)``), inside the film.
    spp, seed, scale, max_bounces, thin_lens, laser_on, integrator, sampler, max_scatter
        As :func:`render_radiance`.
    prepared : (scene, integrator), optional
        From :func:`prepare_scene` with the same arguments (then ``spec`` is not loaded
        again): for many renders of one scene whose shapes move (``mi.traverse``).

    Returns
    -------
    radiance_W_m2_sr : (n,) float32
    laser_W_m2_sr : (n,) float32
        Zero for ``integrator="path"``.
    seconds : float
        Wall time of the wavefront (tracing, compiling and running the kernel).
    """
    import drjit as dr
    import mitsuba as mi

    _check_args(spp, seed, scale, integrator, sampler)
    require_variant()
    px = np.asarray(pixels_xy, dtype=np.int64).reshape(-1, 2)
    scene, integ = prepared if prepared is not None else _setup(
        spec, spp=spp, scale=scale, max_bounces=max_bounces, thin_lens=thin_lens,
        laser_on=laser_on, integrator=integrator, sampler=sampler, max_scatter=max_scatter)
    sensor = scene.sensors()[0]
    width, height = (int(c) for c in sensor.film().size())
    if np.any(px < 0) or np.any(px >= (width, height)):
        raise ValueError(f"pixels_xy must lie inside the {width}x{height} film")
    n = len(px)
    if n == 0:
        z = np.zeros(0, dtype=np.float32)
        return z, z.copy(), 0.0
    t0 = time.perf_counter()
    smp = sensor.sampler()
    spp = int(smp.sample_count())  # as the sampler rounded it (multijitter: 32 -> 35)
    lane = dr.arange(mi.UInt32, n * spp)
    lane_px = lane // spp
    if sampler == "keyed":
        if integrator != "laser":
            raise ValueError("sampler 'keyed' needs the laser integrator")
        from lts360.simulator.keyed_sampler import KeyedSampler

        key = mi.UInt32((px[:, 1] * width + px[:, 0]).astype(np.uint32))
        smp = KeyedSampler(dr.gather(mi.UInt32, key, lane_px), lane - lane_px * spp, spp, seed)
    else:
        smp.set_samples_per_wavefront(spp)
        smp.seed(dr.opaque(mi.UInt32, seed), n * spp)
    pos = mi.Vector2f(dr.gather(mi.Float, mi.Float(px[:, 0].astype(np.float32)), lane_px),
                      dr.gather(mi.Float, mi.Float(px[:, 1].astype(np.float32)), lane_px))
    pos = pos + smp.next_2d()
    aperture = smp.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    ray, weight = sensor.sample_ray_differential(0.0, 0.0, pos / mi.ScalarVector2f(width, height),
                                                 aperture)
    L, _, aovs = integ.sample(scene, smp, ray, None, True)
    L = weight * L
    value = L[0] if dr.size_v(L) != 3 else mi.luminance(L)
    aov = aovs[0] if integrator == "laser" else dr.zeros(mi.Float, n * spp)
    value, aov = dr.block_sum(value, spp) / spp, dr.block_sum(aov, spp) / spp
    dr.eval(value, aov)
    radiance = np.array(value, dtype=np.float32)
    laser = np.array(aov, dtype=np.float32)
    return radiance, laser, time.perf_counter() - t0


def render_radiance(spec: SceneSpec, *, spp: int = 4, seed: int = 0, scale: float = 1.0,
                    max_bounces: int = 2, thin_lens: bool = True, laser_on: bool = True,
                    integrator: str = "laser", sampler: str = "multijitter",
                    max_scatter: int = 0) -> RenderResult:
    """Render the expected radiance of a scene.

    Parameters
    ----------
    spec : SceneSpec
    spp : int, [1, 4096]
        Samples per pixel (pixel area and lens aperture are integrated by these samples).
    seed : int, >= 0
        Sampler seed; same seed and variant → identical image.
    scale : float, (0, 1]
        Image scale (for fast tests); intrinsics scale with it.
    max_bounces : int, [0, 3]
        Mirror reflections followed on the camera side and on the laser side.
    thin_lens : bool
        Depth of field from the camera's f-number and focus distance (else a pinhole).
    laser_on : bool
    sampler : str
        Mitsuba sampler: ``multijitter`` (default: stratified, jittered, and correlated
        across dimensions as little as possible — far less variance than ``independent`` on
        the narrow stripe), ``independent``, ``stratified``, ``ldsampler``.
    integrator : str
        ``laser`` (ours) or ``path`` (Mitsuba's path tracer, as a yardstick: it cannot
        render laser light that reaches the object through a mirror and has no laser at all —
        useful for ambient-only images and timing).
    max_scatter : int, [0, 3]
        Interreflections of the laser light between non-delta surfaces (object onto itself,
        glints carried by a mirror onto the object); ``0`` (default): none, bit for bit the
        single-scatter image.  Ignored by ``integrator="path"``.
    """
    import mitsuba as mi

    _check_args(spp, seed, scale, integrator, sampler)
    variant = require_variant()
    scene, integ = _setup(spec, spp=spp, scale=scale, max_bounces=max_bounces,
                          thin_lens=thin_lens, laser_on=laser_on, integrator=integrator,
                          sampler=sampler, max_scatter=max_scatter)
    t0 = time.perf_counter()
    img = mi.render(scene, integrator=integ, spp=spp, seed=seed)
    arr = np.array(img, dtype=np.float32)
    seconds = time.perf_counter() - t0
    if arr.ndim == 2:
        arr = arr[..., None]
    radiance = arr[..., 0] if arr.shape[-1] in (1, 2) else _luminance(arr[..., :3])
    laser = arr[..., -1] if integrator == "laser" else np.zeros_like(radiance)
    K = scale_intrinsics(spec.rig.camera.K, scale)
    return RenderResult(radiance_W_m2_sr=np.ascontiguousarray(radiance),
                        laser_W_m2_sr=np.ascontiguousarray(laser), K=K, variant=variant, spp=spp,
                        seed=seed, seconds=seconds)


def render_radiance_pixels(spec: SceneSpec, pixels_xy, **kwargs) -> RenderResult:
    """A full-size :class:`RenderResult` of which only ``pixels_xy`` are rendered
    (:func:`render_pixels`); every other pixel is 0 (no light).

    For callers that read a known part of the image only (a study measuring a section in a
    band the calibration predicts): the rendered pixels have the statistics of a full
    render's, at the cost of the pixels listed.  Keyword arguments as :func:`render_pixels`.
    """
    scale = float(kwargs.get("scale", 1.0))
    cam = spec.rig.camera
    w = max(1, int(round(cam.width_px * scale)))  # as the camera plugin's film
    h = max(1, int(round(cam.height_px * scale)))
    px = np.asarray(pixels_xy, dtype=np.int64).reshape(-1, 2)
    if len(px) and (px.min() < 0 or np.any(px.max(axis=0) >= (w, h))):
        raise ValueError(f"pixels_xy must lie inside the {w} x {h} film")
    rad, las, seconds = render_pixels(spec, px, **kwargs)
    radiance = np.zeros((h, w), np.float32)
    laser = np.zeros((h, w), np.float32)
    radiance[px[:, 1], px[:, 0]] = rad
    laser[px[:, 1], px[:, 0]] = las
    return RenderResult(radiance_W_m2_sr=radiance, laser_W_m2_sr=laser,
                        K=scale_intrinsics(cam.K, scale), variant=require_variant(),
                        spp=int(kwargs.get("spp", 4)), seed=int(kwargs.get("seed", 0)),
                        seconds=seconds)


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return (0.212671 * rgb[..., 0] + 0.715160 * rgb[..., 1] + 0.072169 * rgb[..., 2]).astype(np.float32)

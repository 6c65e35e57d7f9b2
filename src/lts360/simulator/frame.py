"""One simulated camera frame: render → sensor → files, with the exact truth beside it.

A frame directory holds ``image.png`` (what the camera outputs), ``radiance.exr`` (the
noise-free expected radiance at the lens: channels ``Y`` = all light, ``laser`` = the
laser's share), ``truth.ply`` (the object mesh in world millimetres, as rendered), for a
part read from a file its byte copy ``part.<suffix>`` (so the folder is self-contained) and
``frame.json`` (the true rig, the object spec and placement, the stage position, and every
render and sensor setting).  Files are written to a temporary directory that is renamed into
place, so an interrupted render leaves nothing half-written.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lts360.folders import frame_file, image_file
from lts360.scenes.objects.base import SceneObject
from lts360.scenes.objects.part import copy_part, part_truth
from lts360.scenes.rig import Rig
from lts360.simulator.io import rig_truth, write_exr, write_json, write_png
from lts360.simulator.materials import material_to_bsdf
from lts360.simulator.render import RenderResult, render_radiance
from lts360.simulator.scene import SceneSpec
from lts360.simulator.support import SUPPORT_METHODS, PixelSupport

__all__ = ["DEFAULT_SPP", "NOISE_MODES", "AMBIENT_SPP", "Frame", "simulate_frame", "render_frame",
           "write_frame", "stage_transform", "sensor_image"]

DEFAULT_SPP = 16
NOISE_MODES = ("none", "realistic")
#: Samples per pixel of the ambient-only full-frame render that fills the pixels outside the
#: laser's support when ambient light is on (ambient light varies slowly over the image).
AMBIENT_SPP = 4


def stage_transform(z_mm: float) -> np.ndarray:
    """World transform of the stage at section height ``z_mm``: the object is moved by
    ``-z_mm`` along world Z, so that the laser plane cuts it at (nominal) height ``z_mm``."""
    T = np.eye(4)
    T[2, 3] = -float(z_mm)
    return T


@dataclass(frozen=True, eq=False)
class Frame:
    """A simulated frame and everything needed to score it."""

    image: np.ndarray
    render: RenderResult
    exposure_time_s: float
    truth: dict
    mesh_world: object
    sensor_info: dict = field(default_factory=dict)


def simulate_frame(rig: Rig, obj: SceneObject, *, spp: int = DEFAULT_SPP, seed: int = 0,
                   noise: str = "none", laser_on: bool = True, ambient: str = "off",
                   scale: float = 1.0, z_mm: float = 0.0, max_bounces: int = 2,
                   thin_lens: bool = True, exposure_time_s: float | None = None,
                   speckle_seed: int | None = None, background_z_mm: float | None = None,
                   exposure_fraction: float = 0.8, extra_meshes: tuple = (),
                   pixels_xy: np.ndarray | None = None, support: str = "geometric",
                   scenes=None, max_scatter: int = 0) -> Frame:
    """Render one frame of ``obj`` in ``rig`` at stage height ``z_mm``.

    Parameters
    ----------
    noise : {"none", "realistic"}
        ``none``: the expected digital value (quantised, clipped, no random noise, no speckle);
        ``realistic``: EMVA 1288 noise (shot, dark/read, DSNU, PRNU, quantisation, saturation)
        and laser speckle on the laser's share of the light.
    exposure_time_s : float, optional
        Fixed exposure; by default auto-exposure puts the brightest stripe pixels at
        ``exposure_fraction`` (default 80 %) of full scale, as the paper adjusts the exposure.
    seed : int
        Seeds the renderer's sampler, the temporal noise and (unless ``speckle_seed`` is
        given) the speckle.  The sensor's fixed pattern (DSNU/PRNU) comes from the rig's
        sensor seed: the same camera in every frame.
    speckle_seed : int, optional
        Seed of the speckle pattern alone.  Speckle is fixed by the surface micro-structure
        under the stripe: repeated frames of a static object share it (same speckle seed),
        a moved or replaced object gets a new one.
    pixels_xy : (n, 2) int, optional
        Render only these pixels ``(x, y)``; the others get no light (0 before the sensor's
        offset and noise).  For a study that reads a band the calibration predicts: the
        pixels it reads have the statistics of a full render's (another noise realisation),
        at the cost of the pixels listed.  ``truth["render"]["pixels"]`` counts them.
        Overrides ``support``.
    support : {"geometric", "hull", "pilot", "full"}
        Which pixels are rendered at ``spp`` (:mod:`lts360.simulator.support`).
        ``geometric`` (default): every pixel that can hold direct laser light, from the
        scene's geometry (the sheet's slab on every shape, seen through every view, widened
        by the defocus blur); ``hull`` when ``max_scatter`` > 0 (interreflected light lies
        off the geometric stripe); ``full`` when the laser is off.  ``hull``: every pixel
        that can see a shape through some view (the shapes' convex hulls, widened by the
        blur): any light that leaves a shape last.  ``pilot``: the pixels a low-spp full
        render of the same integrator lights (misses glints).  ``full``: every pixel.  A support frame is another realisation
        of the full frame's render noise with the same statistics and the same speckle
        (docs/simulator.md).  Outside the
        support a pixel holds no laser light: with ambient light off it gets none, with it on
        the ambient radiance of one full-frame ambient-only render at :data:`AMBIENT_SPP`.
        ``truth["render"]["support"]`` records the method and the pixel count.
    scenes : lts360.simulator.reuse.SceneCache, optional
        Build once, render many: a loop passes one cache to all its frames, and a frame
        whose shapes only moved reuses the loaded scene (same image as a fresh load).
    max_scatter : int, [0, 3]
        Interreflected laser light (the object onto itself, glints via a mirror); ``0``: none.
    """
    if noise not in NOISE_MODES:
        raise ValueError(f"noise must be one of {', '.join(NOISE_MODES)}, got {noise!r}")
    T_stage = stage_transform(z_mm)
    mesh = obj.mesh_world()                         # a copy
    # The stage is a translation: its vertices moved in place, the numbers apply_transform
    # gives (x·1 + y·0 + z·0 + t), without trimesh's copy and bookkeeping (~90 ms for the
    # grooved shaft's 475 529 vertices).
    mesh.vertices += T_stage[:3, 3]
    meshes = (("object", mesh, material_to_bsdf(obj.material)),) + tuple(extra_meshes)
    spec = SceneSpec(rig, meshes, ambient=ambient, background_z_mm=background_z_mm)
    res, sup = render_frame(spec, spp=spp, seed=seed, scale=scale, max_bounces=max_bounces,
                            thin_lens=thin_lens, laser_on=laser_on, pixels_xy=pixels_xy,
                            support=support, scenes=scenes, max_scatter=max_scatter)
    image, exposure_time_s, magnification = sensor_image(
        rig, res, noise=noise, seed=seed, speckle_seed=speckle_seed, scale=scale,
        exposure_time_s=exposure_time_s, exposure_fraction=exposure_fraction)
    sens = rig.sensor
    radiance = res.radiance_W_m2_sr
    truth = rig_truth(rig, res.K, (radiance.shape[1], radiance.shape[0]))
    truth.update({
        "object": {"spec": obj.spec, "name": obj.name, "material": obj.material.name,
                   "T_world_object": T_stage @ obj.T_world_object,
                   "measured_zone_z_mm": list(obj.measured_zone_z_mm), **part_truth(obj)},
        "stage": {"z_mm": float(z_mm), "axis": [0.0, 0.0, 1.0]},
        "render": {"variant": res.variant, "spp": res.spp, "seed": res.seed, "scale": scale,
                   "max_bounces": max_bounces, "max_scatter": max_scatter,
                   "thin_lens": thin_lens, "laser_on": laser_on, "ambient": ambient, "background_z_mm": background_z_mm,
                   "seconds": res.seconds,
                   "pixels": None if pixels_xy is None else int(len(pixels_xy)),
                   "support": sup.to_dict()},
        "sensor": {"noise": noise, "exposure_time_s": float(exposure_time_s),
                   "speckle_seed": speckle_seed, "magnification": magnification,
                   "bit_depth": sens.bit_depth, "model": sens.to_dict()},
    })
    return Frame(image=image, render=res, exposure_time_s=float(exposure_time_s), truth=truth,
                 mesh_world=mesh)


def render_frame(spec: SceneSpec, *, spp: int, seed: int, scale: float = 1.0, max_bounces: int = 2,
                 thin_lens: bool = True, laser_on: bool = True, pixels_xy=None,
                 support: str = "geometric", scenes=None, max_scatter: int = 0
                 ) -> tuple[RenderResult, PixelSupport]:
    """The radiance of a frame, rendered on its pixel support (``simulate_frame``'s render).

    Parameters
    ----------
    spec : SceneSpec
    spp, seed, scale, max_bounces, thin_lens, laser_on
        As :func:`lts360.simulator.render.render_radiance`.
    pixels_xy : (n, 2) int, optional
        A window: only its pixels may be rendered (those of the support among them); the
        rest of the frame is 0.
    support : {"geometric", "hull", "pilot", "full"}
        See :func:`simulate_frame`.  With ``max_scatter`` > 0 a ``geometric`` support becomes
        ``hull``: interreflected light lies off the geometric stripe but on a shape, and a
        low-spp pilot misses its glints (measured on the alu pipe: 485 pixels above 1e-4 of
        the peak outside a 4-spp pilot's support, one at 0.65 of it).
    max_scatter : int, [0, 3]
        Interreflections (:func:`lts360.simulator.integrator.make_integrator`).
    scenes : lts360.simulator.reuse.SceneCache, optional
        Scenes built once for a loop: the scene is reused (vertices moved) when it can be.

    Returns
    -------
    RenderResult
        Full size; ``seconds`` is the whole call (support and ambient render included).
    PixelSupport
        The pixels rendered at ``spp`` (``method`` ``"window"`` when ``pixels_xy`` was given
        with ``support="full"``).
    """
    import time

    from lts360.geometry.camera import scale_intrinsics
    from lts360.simulator import support as support_mod
    from lts360.simulator.render import prepare_scene, render_pixels, require_variant

    if support not in SUPPORT_METHODS:
        raise ValueError(f"support must be one of {', '.join(SUPPORT_METHODS)}, got {support!r}")
    t0 = time.perf_counter()
    if not laser_on:  # no laser light: every pixel holds only what the whole image holds
        support = "full"
    if max_scatter > 0 and support == "geometric":  # light off the stripe, on a shape
        support = "hull"
    kw = dict(spp=spp, scale=scale, max_bounces=max_bounces, thin_lens=thin_lens,
              laser_on=laser_on, max_scatter=max_scatter)
    w, h = support_mod.film_size(spec.rig.camera, scale)
    if support == "full" and pixels_xy is None and scenes is None:
        return render_radiance(spec, seed=seed, **kw), support_mod.full_support(spec.rig.camera, scale)
    geo = dict(scale=scale, max_bounces=max_bounces, thin_lens=thin_lens)

    def load():
        return scenes.prepare(spec, **kw) if scenes is not None else prepare_scene(spec, **kw)

    def make():
        if support == "geometric":
            return support_mod.geometric_support(spec, **geo)
        if support == "hull":
            return support_mod.hull_support(spec, **geo)
        if support == "pilot":
            return support_mod.pilot_support(spec, seed=seed, prepared=prepared,
                                             max_scatter=max_scatter, **geo)
        return support_mod.full_support(spec.rig.camera, scale)

    if support in ("geometric", "hull"):
        # The scene is loaded (or its shapes moved) on a second thread while the geometry gives
        # the support here: both are mostly one core's work (the same scene as loaded here).
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="lts360-scene") as pool:
            pending = pool.submit(_evaluated, load)
            try:
                sup = (make() if scenes is None
                       else scenes.support(spec, make, method=support, **geo))
            finally:
                prepared = pending.result()
    else:  # the pilot renders the prepared scene
        prepared = load()
        sup = make() if scenes is None else scenes.support(spec, make, method=support, **geo)
    window = None
    if pixels_xy is not None:
        px = np.asarray(pixels_xy, dtype=np.int64).reshape(-1, 2)
        if len(px) and (px.min() < 0 or np.any(px.max(axis=0) >= (w, h))):
            raise ValueError(f"pixels_xy must lie inside the {w} x {h} film")
        window = np.zeros((h, w), bool)
        window[px[:, 1], px[:, 0]] = True
        sup = PixelSupport(mask=sup.mask & window,
                           method=sup.method if sup.method != "full" else "window",
                           margin_px=sup.margin_px)
    radiance = np.zeros((h, w), np.float32)
    laser = np.zeros((h, w), np.float32)
    ambient = spec.ambient != "off" and sup.method not in ("full", "window")
    if ambient:
        amb = render_radiance(spec, spp=AMBIENT_SPP, seed=seed, scale=scale,
                              max_bounces=max_bounces, thin_lens=thin_lens, laser_on=False)
        radiance[:] = amb.radiance_W_m2_sr if window is None else amb.radiance_W_m2_sr * window
    index = np.flatnonzero(sup.mask)                # row-major: sorted
    rad, las, _ = render_pixels(spec, np.column_stack([index % w, index // w]), seed=seed,
                                prepared=prepared, **kw)
    radiance.flat[index] = rad
    laser.flat[index] = las
    res = RenderResult(radiance_W_m2_sr=radiance, laser_W_m2_sr=laser,
                       K=scale_intrinsics(spec.rig.camera.K, scale), variant=require_variant(),
                       spp=spp, seed=seed, seconds=time.perf_counter() - t0,
                       held_index=None if ambient or sup.method == "full" else index)
    return res, sup


def _evaluated(fn):
    """``fn()``, with everything Dr.Jit scheduled on this thread evaluated before it returns
    (the result is used on another thread)."""
    import drjit as dr

    out = fn()
    dr.eval()
    dr.sync_thread()
    return out


def sensor_image(rig: Rig, res: RenderResult, *, noise: str = "none", seed: int = 0,
                 speckle_seed: int | None = None, scale: float = 1.0,
                 exposure_time_s: float | None = None, exposure_fraction: float = 0.8,
                 speckle: bool | None = None, read=None) -> tuple[np.ndarray, float, float]:
    """The camera's digital image of a rendered radiance image (speckle + EMVA 1288 sensor).

    Parameters
    ----------
    rig : Rig
        Supplies the optics (f-number, focus, pixel pitch), the laser wavelength and the sensor.
    res : RenderResult
        Radiance at the lens and the laser's share of it.
    noise : {"none", "realistic"}
        ``none``: the expected digital value (quantised, clipped); ``realistic``: temporal and
        fixed-pattern sensor noise and speckle on the laser's share of the light.
    seed, speckle_seed : int
        Temporal noise (and speckle, unless ``speckle_seed`` is given).
    speckle : bool, optional
        Speckle on the laser light; default: with ``noise="realistic"`` only.  ``noise="none",
        speckle=True`` gives speckle without sensor noise (for sensitivity studies).
    exposure_time_s : float, optional
        Fixed exposure; by default the brightest laser-lit pixels (99.9th percentile; all
        pixels when nothing is laser-lit) land at ``exposure_fraction`` of full scale.
    read : (n,) int, optional
        Sorted flat indices of the only pixels the caller will read (an inverse plan's taps,
        :func:`lts360.recon.triangulation.inverse.plan_pixels`): speckle and sensor noise are
        drawn there alone (:func:`lts360.simulator.sensor.expose_held`), every other pixel
        holds its noise-free value.  A read pixel's speckle is the full frame's (position
        keyed); its sensor noise another draw of the same distribution.  The exposure is the
        full frame's.

    Returns
    -------
    image : (h, w) uint8 or uint16
    exposure_time_s : float
    magnification : float
        Lateral magnification at the focus distance (the working f-number is N (1 + m)).
    """
    from lts360.simulator import sensor as sensor_mod

    if noise not in NOISE_MODES:
        raise ValueError(f"noise must be one of {', '.join(NOISE_MODES)}, got {noise!r}")
    cam = rig.camera
    sens = rig.sensor
    pitch_um = cam.pixel_pitch_um / scale
    magnification = cam.focal_length_mm / (cam.focus_distance_mm - cam.focal_length_mm)
    seeds = np.random.SeedSequence([int(seed), 0x1A5E]).spawn(2)
    if speckle_seed is not None:
        seeds[0] = np.random.SeedSequence([int(speckle_seed), 0x5BEC])
    laser = res.laser_W_m2_sr
    flat = np.asarray(res.radiance_W_m2_sr).reshape(-1)
    # The light is carried as the pixels that hold any (a pixel support frame: ~1 % of them):
    # a dark pixel's electrons are 0 whatever the radiometry's factors, so only the lit ones
    # are converted (the same products, pixel by pixel, as over the whole frame).
    # A frame lit nearly everywhere (a board under ambient light) is converted whole: the
    # index of every pixel costs more than it saves (expose and expose_held agree bit for bit).
    rendered = getattr(res, "held_index", None)
    if rendered is not None:  # only the rendered pixels can hold light: no scan of the frame
        las_r = laser.reshape(-1)[rendered]
        on = rendered[las_r != 0]
        held = rendered[(flat[rendered] != 0) | (las_r != 0)]
        lit_index = rendered[las_r > 0]
        lit = np.zeros(laser.shape, bool)
        lit.flat[lit_index] = True
    else:
        lit = laser > 0
        on = np.flatnonzero(laser != 0)
        held = np.flatnonzero(flat)
    if read is not None:  # checked here: the speckle step reads it before the sensor does
        read = sensor_mod._flat_index(read, laser.shape, "read")
    if 2 * held.size > flat.size and read is None:
        held = None
        radiance = flat.astype(np.float64)
    elif 2 * held.size > flat.size:
        held = np.arange(flat.size)
        radiance = flat.astype(np.float64)
    else:
        held = np.union1d(held, on) if rendered is None else held
        radiance = flat[held].astype(np.float64)
    if speckle is None:
        speckle = noise == "realistic"
    if speckle and on.size:
        _add_speckle(radiance, held, on, lit, laser, read, rig=rig, pitch_um=pitch_um,
                     magnification=magnification, rng=np.random.default_rng(seeds[0]))
    if exposure_time_s is None:
        # The statistic over the laser-lit pixels only (the same values as a mask over the
        # whole frame, without converting the dark rest).
        lit_values = res.radiance_W_m2_sr[lit] if rendered is None else \
            flat[lit_index]                                      # the same values, in order
        exposure_time_s = sensor_mod.auto_exposure(
            lit_values if lit_values.size else res.radiance_W_m2_sr, sens,
            wavelength_nm=rig.laser.wavelength_nm, f_number=cam.f_number,
            pixel_pitch_um=pitch_um, target_fraction=exposure_fraction, percentile=99.9,
            magnification=magnification)
    electrons = sensor_mod.radiance_to_electrons_mean(
        radiance, wavelength_nm=rig.laser.wavelength_nm, f_number=cam.f_number,
        pixel_pitch_um=pitch_um, exposure_time_s=exposure_time_s,
        quantum_efficiency=sens.quantum_efficiency, magnification=magnification)
    if held is None:
        image = sensor_mod.expose(electrons.reshape(res.radiance_W_m2_sr.shape), sens,
                                  rng=np.random.default_rng(seeds[1]),
                                  noise=noise == "realistic", exposure_time_s=exposure_time_s)
    else:
        image = sensor_mod.expose_held(res.radiance_W_m2_sr.shape, held, electrons, sens,
                                       rng=np.random.default_rng(seeds[1]),
                                       noise=noise == "realistic",
                                       exposure_time_s=exposure_time_s, read=read)
    return image, float(exposure_time_s), float(magnification)


def _add_speckle(radiance: np.ndarray, held, on: np.ndarray, lit: np.ndarray, laser, read, *,
                 rig: Rig, pitch_um: float, magnification: float, rng) -> None:
    """Speckle on the laser share of ``radiance`` (the values at ``held``, or the whole frame
    where ``held`` is None), in place: position keyed, on the tiles that hold laser light, so
    a pixel's speckle is the same whichever other pixels were rendered (a support frame's
    equals a full frame's); with ``read``, only on the read pixels (the same values there)."""
    from lts360.simulator.speckle import speckle_on_tiles

    if read is not None:
        on = on[_member(on, read)]
        lit = np.zeros(laser.shape, bool)
        lit.flat[on[laser.flat[on] > 0]] = True
    pattern = speckle_on_tiles(lit, pixel_pitch_um=pitch_um,
                               wavelength_nm=rig.laser.wavelength_nm,
                               f_number=rig.camera.f_number, magnification=magnification, rng=rng)
    # Added where the laser share is not 0 only (elsewhere the term is 0: the same sums).
    at = on if held is None else np.searchsorted(held, on)
    radiance[at] += laser.flat[on] * (pattern.flat[on] - 1.0)


def _member(values: np.ndarray, sorted_set: np.ndarray) -> np.ndarray:
    """Whether each of ``values`` is in ``sorted_set`` (sorted, unique)."""
    at = np.searchsorted(sorted_set, values)
    ok = at < sorted_set.size
    ok[ok] = sorted_set[at[ok]] == values[ok]
    return ok


def write_frame(out_dir, frame: Frame) -> Path:
    """Write a frame directory atomically (temporary sibling, then rename)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {str(out)!r} exists and is not a directory")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    write_png(image_file(tmp), frame.image)
    write_exr(tmp / "radiance.exr", {"Y": frame.render.radiance_W_m2_sr,
                                     "laser": frame.render.laser_W_m2_sr})
    frame.mesh_world.export(tmp / "truth.ply")
    copy_part(frame.truth["object"], tmp)
    write_json(frame_file(tmp), frame.truth)
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    return out

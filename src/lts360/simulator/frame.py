"""One simulated camera frame: render → sensor → files, with the exact truth beside it.

A frame directory holds ``image.png`` (what the camera outputs), ``radiance.exr`` (the
noise-free expected radiance at the lens: channels ``Y`` = all light, ``laser`` = the
laser's share), ``truth.ply`` (the object mesh in world millimetres, as rendered) and
``frame.json`` (the true rig, the object spec and placement, the stage position, and every
render and sensor setting).  Files are written to a temporary directory that is renamed into
place, so an interrupted render leaves nothing half-written.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lts360.scenes.objects.base import SceneObject
from lts360.scenes.rig import Rig
from lts360.simulator.io import rig_truth, write_exr, write_json, write_png
from lts360.simulator.render import RenderResult, render_radiance, render_radiance_pixels
from lts360.simulator.scene import SceneSpec
from lts360.simulator.materials import material_to_bsdf

__all__ = ["DEFAULT_SPP", "NOISE_MODES", "Frame", "simulate_frame", "write_frame", "stage_transform",
           "sensor_image"]

DEFAULT_SPP = 16
NOISE_MODES = ("none", "realistic")


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
                   pixels_xy: np.ndarray | None = None, max_scatter: int = 0) -> Frame:
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
    max_scatter : int, [0, 3]
        Interreflected laser light (the object onto itself, glints via a mirror); ``0``: none.
    """
    if noise not in NOISE_MODES:
        raise ValueError(f"noise must be one of {', '.join(NOISE_MODES)}, got {noise!r}")
    T_stage = stage_transform(z_mm)
    mesh = obj.mesh_world()
    mesh.apply_transform(T_stage)
    meshes = (("object", mesh, material_to_bsdf(obj.material)),) + tuple(extra_meshes)
    spec = SceneSpec(rig, meshes, ambient=ambient, background_z_mm=background_z_mm)
    kw = dict(spp=spp, seed=seed, scale=scale, max_bounces=max_bounces, thin_lens=thin_lens,
              laser_on=laser_on, max_scatter=max_scatter)
    res = (render_radiance(spec, **kw) if pixels_xy is None
           else render_radiance_pixels(spec, pixels_xy, **kw))
    image, exposure_time_s, magnification = sensor_image(
        rig, res, noise=noise, seed=seed, speckle_seed=speckle_seed, scale=scale,
        exposure_time_s=exposure_time_s, exposure_fraction=exposure_fraction)
    sens = rig.sensor
    radiance = res.radiance_W_m2_sr
    truth = rig_truth(rig, res.K, (radiance.shape[1], radiance.shape[0]))
    truth.update({
        "object": {"spec": obj.spec, "name": obj.name, "material": obj.material.name,
                   "T_world_object": T_stage @ obj.T_world_object,
                   "measured_zone_z_mm": list(obj.measured_zone_z_mm)},
        "stage": {"z_mm": float(z_mm), "axis": [0.0, 0.0, 1.0]},
        "render": {"variant": res.variant, "spp": res.spp, "seed": res.seed, "scale": scale,
                   "max_bounces": max_bounces, "max_scatter": max_scatter,
                   "thin_lens": thin_lens, "laser_on": laser_on, "ambient": ambient, "background_z_mm": background_z_mm,
                   "seconds": res.seconds,
                   "pixels": None if pixels_xy is None else int(len(pixels_xy))},
        "sensor": {"noise": noise, "exposure_time_s": float(exposure_time_s),
                   "speckle_seed": speckle_seed, "magnification": magnification,
                   "bit_depth": sens.bit_depth, "model": sens.to_dict()},
    })
    return Frame(image=image, render=res, exposure_time_s=float(exposure_time_s), truth=truth,
                 mesh_world=mesh)


def sensor_image(rig: Rig, res: RenderResult, *, noise: str = "none", seed: int = 0,
                 speckle_seed: int | None = None, scale: float = 1.0,
                 exposure_time_s: float | None = None, exposure_fraction: float = 0.8,
                 speckle: bool | None = None) -> tuple[np.ndarray, float, float]:
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

    Returns
    -------
    image : (h, w) uint8 or uint16
    exposure_time_s : float
    magnification : float
        Lateral magnification at the focus distance (the working f-number is N (1 + m)).
    """
    from lts360.simulator import sensor as sensor_mod
    from lts360.simulator.speckle import speckle_pattern

    if noise not in NOISE_MODES:
        raise ValueError(f"noise must be one of {', '.join(NOISE_MODES)}, got {noise!r}")
    cam = rig.camera
    sens = rig.sensor
    pitch_um = cam.pixel_pitch_um / scale
    magnification = cam.focal_length_mm / (cam.focus_distance_mm - cam.focal_length_mm)
    seeds = np.random.SeedSequence([int(seed), 0x1A5E]).spawn(2)
    if speckle_seed is not None:
        seeds[0] = np.random.SeedSequence([int(speckle_seed), 0x5BEC])
    radiance = res.radiance_W_m2_sr.astype(np.float64)
    laser = res.laser_W_m2_sr
    if speckle is None:
        speckle = noise == "realistic"
    lit_rows = np.flatnonzero(laser.any(axis=1))
    if speckle and lit_rows.size:
        # Speckle is stationary: draw it on the laser-lit bounding box only (plus a margin so
        # the field's FFT filtering sees no edge), which is a fraction of the frame.
        lit_cols = np.flatnonzero(laser.any(axis=0))
        pad = 16
        r0, r1 = max(0, lit_rows[0] - pad), min(laser.shape[0], lit_rows[-1] + pad + 1)
        c0, c1 = max(0, lit_cols[0] - pad), min(laser.shape[1], lit_cols[-1] + pad + 1)
        pattern = speckle_pattern((r1 - r0, c1 - c0), pixel_pitch_um=pitch_um,
                                  wavelength_nm=rig.laser.wavelength_nm, f_number=cam.f_number,
                                  magnification=magnification, rng=np.random.default_rng(seeds[0]))
        radiance[r0:r1, c0:c1] += laser[r0:r1, c0:c1] * (pattern - 1.0)
    if exposure_time_s is None:
        lit = laser > 0
        exposure_time_s = sensor_mod.auto_exposure(
            res.radiance_W_m2_sr, sens, wavelength_nm=rig.laser.wavelength_nm,
            f_number=cam.f_number, pixel_pitch_um=pitch_um, target_fraction=exposure_fraction,
            percentile=99.9, mask=lit if lit.any() else None, magnification=magnification)
    electrons = sensor_mod.radiance_to_electrons_mean(
        radiance, wavelength_nm=rig.laser.wavelength_nm, f_number=cam.f_number,
        pixel_pitch_um=pitch_um, exposure_time_s=exposure_time_s,
        quantum_efficiency=sens.quantum_efficiency, magnification=magnification)
    image = sensor_mod.expose(electrons, sens, rng=np.random.default_rng(seeds[1]),
                              noise=noise == "realistic", exposure_time_s=exposure_time_s)
    return image, float(exposure_time_s), float(magnification)


def write_frame(out_dir, frame: Frame) -> Path:
    """Write a frame directory atomically (temporary sibling, then rename)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {str(out)!r} exists and is not a directory")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    write_png(tmp / "image.png", frame.image)
    write_exr(tmp / "radiance.exr", {"Y": frame.render.radiance_W_m2_sr,
                                     "laser": frame.render.laser_W_m2_sr})
    frame.mesh_world.export(tmp / "truth.ply")
    write_json(tmp / "frame.json", frame.truth)
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    return out

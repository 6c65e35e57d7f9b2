"""Frames of a moving object: sub-frame rendering over each row's own exposure.

A pixel of row ``y`` integrates the radiance over its exposure ``[s_y, s_y + E]`` (``s_y``
from the :class:`~lts360.scenes.motion.Shutter`).  The time axis from the first row's start to
the last row's end is cut into sub-intervals of length ``Δ = E / N``; in each, the object is
placed at the interval's middle and only the rows whose exposure overlaps it are rendered
(:func:`~lts360.simulator.render.render_pixels`), weighted by the overlap ÷ ``E``.  The weights
of every row sum to 1; as ``N`` grows the sum converges to the exposure integral (midpoint
rule).  A global shutter is the case ``s_y = 0``: ``N`` renders of the whole film.

``N`` is chosen by a stated error: no object point within the object's radius moves more than
``step_px`` pixel footprints (at the axis's distance) during ``Δ``.  The samples per pixel are
shared among the sub-frames (the square nearest below ``spp / N`` each, at least 1), so a moving frame carries about
the still frame's Monte Carlo noise.  A still object renders exactly as
:func:`~lts360.simulator.frame.simulate_frame`.

Speckle is drawn once per frame, as for a still one (a moving surface would decorrelate it
over the exposure; not modelled).
"""

from __future__ import annotations

import math
import time

import numpy as np

from lts360.geometry import project_points
from lts360.geometry.camera import scale_intrinsics
from lts360.geometry.mirror import mirror_matrix
from lts360.scenes.motion import Acquisition
from lts360.scenes.objects.base import SceneObject
from lts360.scenes.objects.part import part_truth
from lts360.scenes.rig import Rig
from lts360.simulator.frame import Frame, sensor_image, simulate_frame, stage_transform
from lts360.simulator.io import rig_truth
from lts360.simulator.materials import material_to_bsdf
from lts360.simulator.render import RenderResult, prepare_scene, render_pixels, require_variant
from lts360.simulator.scene import SceneSpec

__all__ = ["subframe_count", "exposure_schedule", "simulate_moving_frame", "DEFAULT_STEP_PX"]

#: Largest motion of any object point during one sub-frame, in pixel footprints at the axis.
DEFAULT_STEP_PX = 0.1


def _film(rig: Rig, scale: float) -> tuple[int, int]:
    cam = rig.camera
    return max(1, int(round(cam.width_px * scale))), max(1, int(round(cam.height_px * scale)))


def pixel_footprint_mm(rig: Rig, scale: float = 1.0) -> float:
    """Side of one (scaled) pixel projected to the axis's distance, mm."""
    cam = rig.camera
    f_mm = float(cam.K[0][0]) * cam.pixel_pitch_um * 1e-3
    distance = float(np.linalg.norm(cam.center_mm))
    return cam.pixel_pitch_um * 1e-3 / scale * distance / f_mm


def subframe_count(rig: Rig, acq: Acquisition, radius_mm: float, *, scale: float = 1.0,
                   step_px: float = DEFAULT_STEP_PX) -> int:
    """Sub-frames per exposure so that no point within ``radius_mm`` of the axis moves more
    than ``step_px`` pixel footprints in one (1 for a still object)."""
    if not step_px > 0:
        raise ValueError(f"step_px must be > 0, got {step_px}")
    v = acq.motion.max_point_speed_mm_s(radius_mm)
    if v == 0:
        return 1
    return max(1, math.ceil(v * acq.exposure_time_s / (step_px * pixel_footprint_mm(rig, scale))))


def exposure_schedule(acq: Acquisition, n_rows: int, n_sub: int) -> tuple[np.ndarray, list]:
    """Sub-interval middles (s, from the trigger) and, for each, ``(rows, weights)``: the rows
    whose exposure overlaps it and overlap ÷ exposure.  Every row's weights sum to 1."""
    E = acq.exposure_time_s
    d = E / int(n_sub)
    start = acq.shutter.row_start_s(np.arange(n_rows))
    span = float(start[-1]) + E
    n_int = max(1, math.ceil(span / d - 1e-9))
    mids, parts = [], []
    for j in range(n_int):
        a, b = j * d, min((j + 1) * d, span)
        overlap = np.clip(np.minimum(b, start + E) - np.maximum(a, start), 0.0, None)
        rows = np.flatnonzero(overlap > 0)
        if len(rows):
            mids.append(0.5 * (a + b))
            parts.append((rows, overlap[rows] / E))
    return np.array(mids), parts


def _object_radius_mm(mesh) -> float:
    return float(np.max(np.linalg.norm(np.asarray(mesh.vertices)[:, :2], axis=1)))


def _view_rows(rig: Rig, mesh, K: np.ndarray, size: tuple[int, int]) -> dict:
    """Mean image row of the object's section (the mesh cut by the laser plane) in each view:
    direct and through each mirror (visibility not tested: the rows the view's image of the
    section spans)."""
    n_l, d_l = rig.laser.plane
    sec = mesh.section(plane_origin=np.asarray(n_l, float) * d_l, plane_normal=n_l)
    if sec is None:
        return {}
    pts = np.asarray(sec.vertices, float)
    cam = rig.camera
    out = {}
    mats = {"direct": None} | {m.name: mirror_matrix(m.normal, m.d_mm) for m in rig.mirrors}
    w, h = size
    for name, T in mats.items():
        uv = project_points(pts, K, cam.distortion, cam.R, cam.t_mm, T_mirror=T)
        ok = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] < w) \
            & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        if ok.any():
            out[name] = float(np.mean(uv[ok, 1]))
    return out


def _render_subframes(rig: Rig, obj: SceneObject, acq: Acquisition, mesh0, T_stage, mids,
                      parts, *, t_trigger_s: float, seed: int, freeze: bool, spp: int,
                      scale: float, max_bounces: int, thin_lens: bool, max_scatter: int):
    """The exposure-weighted sum of the sub-frames' radiance (each renders the rows its part
    of the exposure reaches, the object moved to that sub-frame's pose).  Returns
    ``(radiance, laser, seconds)``, full-size float64 arrays."""
    w, h = _film(rig, scale)
    radiance = np.zeros((h, w), np.float64)
    laser = np.zeros((h, w), np.float64)
    xs = np.arange(w)
    t0 = time.perf_counter()
    # The scene is loaded once, with the object at its stage pose; each sub-frame moves its
    # vertices (and turns its normals) in place: no reloading per sub-frame.
    import mitsuba as mi

    mesh = mesh0.copy()
    mesh.apply_transform(T_stage)
    spec = SceneSpec(rig, (("object", mesh, material_to_bsdf(obj.material)),))
    kw = dict(spp=spp, scale=scale, max_bounces=max_bounces, thin_lens=thin_lens,
              max_scatter=max_scatter)
    prepared = prepare_scene(spec, **kw)
    params = mi.traverse(prepared[0])
    P0 = np.array(params["object.vertex_positions"], dtype=np.float64).reshape(-1, 3)
    has_normals = "object.vertex_normals" in params and len(params["object.vertex_normals"]) > 0
    N0 = (np.array(params["object.vertex_normals"], dtype=np.float64).reshape(-1, 3)
          if has_normals else None)
    for j, (tm, (rows, wts)) in enumerate(zip(mids, parts)):
        T = acq.motion.transform(t_trigger_s + (0.0 if freeze else tm))
        params["object.vertex_positions"] = mi.Float((P0 @ T[:3, :3].T + T[:3, 3])
                                                     .astype(np.float32).ravel())
        if has_normals:
            params["object.vertex_normals"] = mi.Float((N0 @ T[:3, :3].T)
                                                       .astype(np.float32).ravel())
        params.update()
        px = np.column_stack([np.tile(xs, len(rows)), np.repeat(rows, w)])
        rad, las, _ = render_pixels(spec, px, seed=(seed * 100_003 + j) % 2**31,
                                    prepared=prepared, **kw)
        wt = np.repeat(wts, w)
        radiance[px[:, 1], px[:, 0]] += wt * rad
        laser[px[:, 1], px[:, 0]] += wt * las
    return radiance, laser, time.perf_counter() - t0


def simulate_moving_frame(rig: Rig, obj: SceneObject, acq: Acquisition, *,
                          t_trigger_s: float = 0.0, z_mm: float = 0.0, spp: int = 16,
                          seed: int = 0, noise: str = "none", scale: float = 1.0,
                          max_bounces: int = 2, thin_lens: bool = True,
                          step_px: float = DEFAULT_STEP_PX, n_subframes: int | None = None,
                          speckle_seed: int | None = None, freeze: bool = False,
                          max_scatter: int = 0) -> Frame:
    """One frame of ``obj`` moving as ``acq.motion`` says, triggered at ``t_trigger_s``
    (the stage at ``z_mm`` then), exposed for ``acq.exposure_time_s`` through ``acq.shutter``.

    ``n_subframes`` overrides the sub-frames per exposure chosen from ``step_px``
    (:func:`subframe_count`).  ``freeze``: the same sub-frames and samples with the object
    held at its pose at the trigger (common random numbers: its difference from the moving
    frame is the motion's alone, without Monte Carlo noise).  ``truth["motion"]`` records the acquisition, the sub-frames, and
    per view the mean row of its image of the section, the middle of that row's exposure, and
    the section's height on the object and the object's pose then.

    Raises
    ------
    ValueError
        A bad acquisition; a frame that takes longer to read out than the trigger period; a
        feed that moves the section off the object's measured zone within the frame.
    """
    w, h = _film(rig, scale)
    acq.check_frame(h)
    mesh0 = obj.mesh_world()
    radius = _object_radius_mm(mesh0)
    # The section stays on the measured zone over the frame (the stage moves the object by
    # -z_mm, the feed by +v t: the laser plane cuts it at height z_mm - v t).
    readout = acq.readout_s(h)
    lo, hi = obj.measured_zone_z_mm
    feed = np.array([0.0, acq.motion.speed_mm_s * readout]) + acq.motion.speed_mm_s * t_trigger_s
    cut = z_mm - feed
    if cut.min() < lo - 1e-9 or cut.max() > hi + 1e-9:
        raise ValueError(f"the feed moves the laser section to z = {cut.min():.3g}…{cut.max():.3g} mm "
                         f"of the object within the frame, off its measured zone "
                         f"[{lo:.3g}, {hi:.3g}] mm")
    if acq.motion.still and n_subframes is None:
        frame = simulate_frame(rig, obj, spp=spp, seed=seed, noise=noise, scale=scale, z_mm=z_mm,
                               max_bounces=max_bounces, thin_lens=thin_lens,
                               exposure_time_s=acq.exposure_time_s, speckle_seed=speckle_seed,
                               max_scatter=max_scatter)
        frame.truth["motion"] = {"acquisition": acq.to_dict(), "t_trigger_s": float(t_trigger_s),
                                 "subframes_per_exposure": 1, "renders": 1}
        return frame
    n_sub = int(n_subframes) if n_subframes is not None else subframe_count(
        rig, acq, radius, scale=scale, step_px=step_px)
    if n_sub < 1:
        raise ValueError(f"n_subframes must be >= 1, got {n_subframes}")
    mids, parts = exposure_schedule(acq, h, n_sub)
    # A square count (what the multijitter sampler stratifies without rounding).
    spp_sub = max(1, math.isqrt(max(1, spp // n_sub))) ** 2
    require_variant()
    T_stage = stage_transform(z_mm)
    radiance, laser, seconds = _render_subframes(
        rig, obj, acq, mesh0, T_stage, mids, parts, t_trigger_s=t_trigger_s, seed=seed,
        freeze=freeze, spp=spp_sub, scale=scale, max_bounces=max_bounces, thin_lens=thin_lens,
        max_scatter=max_scatter)
    K = scale_intrinsics(rig.camera.K, scale)
    res = RenderResult(radiance_W_m2_sr=radiance.astype(np.float32),
                       laser_W_m2_sr=laser.astype(np.float32), K=K, variant=require_variant(),
                       spp=spp_sub * n_sub, seed=seed, seconds=seconds)
    image, exposure_time_s, magnification = sensor_image(
        rig, res, noise=noise, seed=seed, speckle_seed=speckle_seed, scale=scale,
        exposure_time_s=acq.exposure_time_s)
    truth = rig_truth(rig, K, (w, h))
    views = {}
    for name, row in _view_rows(rig, mesh0.copy().apply_transform(
            acq.motion.transform(t_trigger_s) @ T_stage), K, (w, h)).items():
        t_mid = t_trigger_s + float(acq.shutter.row_start_s(row)) + 0.5 * acq.exposure_time_s
        T = acq.motion.transform(t_mid) @ T_stage
        views[name] = {"row_mean_px": row, "t_mid_s": t_mid, "section_z_mm": float(-T[2, 3]),
                       "T_world_object": (T @ obj.T_world_object).tolist()}
    truth.update({
        "object": {"spec": obj.spec, "name": obj.name, "material": obj.material.name,
                   "T_world_object": T_stage @ obj.T_world_object,
                   "measured_zone_z_mm": list(obj.measured_zone_z_mm), **part_truth(obj)},
        "stage": {"z_mm": float(z_mm), "axis": [0.0, 0.0, 1.0]},
        "render": {"variant": res.variant, "spp": res.spp, "seed": seed, "scale": scale,
                   "max_bounces": max_bounces, "thin_lens": thin_lens, "laser_on": True,
                   "ambient": "off", "background_z_mm": None, "seconds": seconds,
                   "pixels": None, "max_scatter": int(max_scatter)},
        "sensor": {"noise": noise, "exposure_time_s": float(exposure_time_s),
                   "speckle_seed": speckle_seed, "magnification": magnification,
                   "bit_depth": rig.sensor.bit_depth, "model": rig.sensor.to_dict()},
        "motion": {"acquisition": acq.to_dict(), "t_trigger_s": float(t_trigger_s),
                   "frozen": bool(freeze), "subframes_per_exposure": n_sub, "spp_per_subframe": spp_sub,
                   "renders": len(mids), "views": views},
    })
    return Frame(image=image, render=res, exposure_time_s=float(exposure_time_s), truth=truth,
                 mesh_world=mesh0.apply_transform(T_stage))

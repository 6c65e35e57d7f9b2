"""Render the planned calibration images (paper §4.2–4.3) and write them as a real rig would
deliver them: PNG files and a small manifest of the board geometry and of what each image
shows — nothing more (the true rig and board poses go to a separate ``truth.json`` that the
calibration never reads).

Camera and mirror shots: the board under bright ambient light, laser off, auto-exposed on
the whole image; camera shots planned with ``mirrors_covered`` are rendered without the
mirrors (the manifest says so).  Laser shots (paper Fig. 9): the board auto-exposed for its corners, and a
laser-on and a laser-off image at one shorter exposure set on the laser-lit pixels, so that
their difference is the laser line.  A laser board planned to be seen in a mirror too
(``shot.mirror``) is pictured with the mirrors for its corners and with the mirrors covered
for the line (``laser_mirrors_covered`` in the manifest).

Rendering is windowed (``windowed=True``): the picture without the board (ambient light, the
mirrors) is rendered once per mirror configuration and sample count (at one sample per pixel
but near the mirrors' edges, where its pixels are not uniform: :func:`_context_picture`), and each shot renders
only the pixels where its board can change the picture — seen directly and through every
mirror sequence, padded by the lens blur (:func:`lts360.simulator.board_window.board_windows`) —
at the same sample count, ray for ray as a full render (:func:`lts360.simulator.render.render_pixels`).
Outside those windows the board changes nothing, so the image is that of a full render
(another noise realisation of the same expected image).  The camera shots (laser off, mirrors
covered: the board is the scene's only shape) are rendered with an estimator of the ambient
light that samples the board's BSDF (:func:`_flat_integrator`), which has no variance where all
of a pixel's rays meet one square of the print: those pixels take one sample, their exact
expected value; the pixels across the squares' edges and the board's outline
(:func:`lts360.simulator.board_window.board_edge_pixels`) a quarter of the sample count, with
less noise than the laser integrator at the full count.  The scene is loaded once per mirror
configuration, sample count, laser state and board print; each next board of that print is
moved into it (``mi.traverse``): the image of a freshly loaded scene to float32 rounding (the
moved board's transform is derived in the JIT's arithmetic; 2.4e-7 W m⁻² sr⁻¹ at most on a
full-size 64-spp camera board).
"""

from __future__ import annotations

import contextlib
import functools
from dataclasses import replace
from pathlib import Path

import numpy as np

from lts360.scenes.calib_plan import BoardShot
from lts360.scenes.rig import Rig
from lts360.simulator.board_window import board_edge_pixels, board_pixels, mirror_edge_pixels
from lts360.simulator.frame import sensor_image
from lts360.simulator.io import rig_truth, write_json, write_png
from lts360.simulator.render import RenderResult, prepare_scene, render_pixels, render_radiance
from lts360.simulator.scene import SceneSpec

__all__ = ["render_calibration_images", "MANIFEST_NAME"]

MANIFEST_NAME = "manifest.json"


#: The camera shots' edge pixels are rendered with :func:`_flat_integrator` at this fraction of
#: the sample count: its noise there comes from the box filter's and the lens's coverage of the
#: squares' edges only (the laser integrator adds that of its ambient estimate).  Measured on
#: the edge pixels of the paper rig's first two camera boards (1280 × 1024; 2026-12-05): noise
#: 0.0168 and 0.0159 W m⁻² sr⁻¹ at 16 spp against 0.0255 and 0.0215 for the laser integrator
#: at 64 (at 8 spp: 0.0256, 0.0238), the means within 1.1 standard errors.
FLAT_EDGE_SPP_DIVISOR = 4
#: Safety margin (px) of the camera shots' edge pixels (:func:`_split_pixels`).  With none, on
#: the 30 camera boards of the demo (1280 × 1024, 2026-12-05), :func:`_flat_integrator` at 1
#: and at 64 spp differed on no pixel outside the edge pixels by more than one sample's rare
#: miss (one sample of value zero, likely a shadow ray meeting the board itself — not traced
#: down: 25 pixels in 8.2 M, by 1/64 of their value); one pixel more is kept.
FLAT_EDGE_MARGIN_PX = 1.0

#: Sampler seed of the pictures without a board (one per mirror configuration and spp).
CONTEXT_SEED = 4_000_000_000


def composite(base: RenderResult, pixels_xy: np.ndarray, radiance: np.ndarray,
              laser: np.ndarray, *, seconds: float, seed: int) -> RenderResult:
    """``base`` with the listed pixels replaced.

    Parameters
    ----------
    base : RenderResult
        Full frame (radiance and laser share, W m⁻² sr⁻¹).
    pixels_xy : (n, 2) int
        Pixel ``(x, y)``.
    radiance, laser : (n,) float
        Their values, W m⁻² sr⁻¹.
    seconds : float
        Wall time to report (s).
    seed : int
        Sampler seed to report.
    """
    px = np.asarray(pixels_xy, dtype=np.intp).reshape(-1, 2)
    rad = base.radiance_W_m2_sr.copy()
    las = base.laser_W_m2_sr.copy()
    rad[px[:, 1], px[:, 0]] = radiance
    las[px[:, 1], px[:, 0]] = laser
    return replace(base, radiance_W_m2_sr=rad, laser_W_m2_sr=las, seed=int(seed),
                   seconds=float(seconds))


def _render(rig, board, *, laser_on, spp, seed, thin_lens, mirrors=True, context=None,
            scale=1.0, flat_interior=False):
    """One picture; ``context`` (a dict, filled here) holds the board-less pictures for
    windowed rendering, ``None`` renders the full frame; ``scale`` for tests.

    ``flat_interior`` (windowed, laser off, no mirrors: the camera shots): the board is
    rendered with :func:`_flat_integrator`, its pixels away from its square edges and outline
    at one sample per pixel (their expected value, exactly), the others
    (:func:`_split_pixels`) at ``spp // FLAT_EDGE_SPP_DIVISOR``."""
    scene_rig = rig if mirrors else replace(rig, mirrors=())
    spec = SceneSpec(scene_rig, (), ambient="bright", targets=(board,))
    if context is None:
        return render_radiance(spec, spp=spp, seed=seed, thin_lens=thin_lens, laser_on=laser_on,
                               scale=scale)
    key = (bool(mirrors), int(spp), bool(thin_lens), float(scale))
    seconds = 0.0
    if key not in context:
        context[key] = _context_picture(scene_rig, spp=spp, thin_lens=thin_lens, scale=scale)
        seconds = context[key].seconds
    px = board_pixels(scene_rig, board, thin_lens=thin_lens, scale=scale)
    scenes = context.setdefault("scenes", {})
    if not flat_interior:
        prepared = _prepared(scenes, spec, board, key=key + (bool(laser_on),))
        rad, las, sec = render_pixels(spec, px, spp=spp, seed=seed, thin_lens=thin_lens,
                                      laser_on=laser_on, scale=scale, prepared=prepared)
        return composite(context[key], px, rad, las, seconds=seconds + sec, seed=seed)
    if laser_on or scene_rig.mirrors:
        raise ValueError("flat_interior: only for a picture with the laser off and no mirrors")
    edge, flat = _split_pixels(scene_rig, board, px, thin_lens=thin_lens, scale=scale)
    rad, las = [], []
    for pixels, n in ((edge, max(1, int(spp) // FLAT_EDGE_SPP_DIVISOR)), (flat, 1)):
        scene = _prepared(scenes, spec, board, key=key[:1] + (n,) + key[2:] + ("flat",))[0]
        r, la, sec = render_pixels(spec, pixels, spp=n, seed=seed, thin_lens=thin_lens,
                                   laser_on=False, scale=scale,
                                   prepared=(scene, _flat_integrator()))
        rad.append(r)
        las.append(la)
        seconds += sec
    return composite(context[key], np.vstack([edge, flat]), np.concatenate(rad),
                     np.concatenate(las), seconds=seconds, seed=seed)


def _split_pixels(scene_rig, board, px, *, thin_lens, scale):
    """The board's pixels ``px`` split into ``(edge, flat)``: ``edge`` those whose rays may
    meet different albedos or the board's outline
    (:func:`lts360.simulator.board_window.board_edge_pixels`), ``flat`` the others, where
    every ray of a pixel meets one square of the print."""
    edges = board_edge_pixels(scene_rig, board, thin_lens=thin_lens, scale=scale,
                              margin_px=FLAT_EDGE_MARGIN_PX)
    px = np.asarray(px, dtype=np.int64).reshape(-1, 2)
    if len(edges) == 0:
        return px[:0], px
    mask = np.zeros((int(px[:, 1].max(initial=0)) + 1, int(px[:, 0].max(initial=0)) + 1), bool)
    e = edges[(edges[:, 0] < mask.shape[1]) & (edges[:, 1] < mask.shape[0])]
    mask[e[:, 1], e[:, 0]] = True
    on_edge = mask[px[:, 1], px[:, 0]]
    return px[on_edge], px[~on_edge]


@functools.lru_cache(maxsize=None)
def _flat_integrator_class(variant: str):
    """The class of :func:`_flat_integrator` for the Mitsuba ``variant`` set now."""
    import drjit as dr
    import mitsuba as mi

    class FlatAmbientIntegrator(mi.SamplingIntegrator):
        """Ambient light on a diffuse surface by BSDF (cosine) sampling: ``A D E`` and ``A E``
        paths, laser off, no mirrors."""

        def __init__(self, props=None):
            super().__init__(props if props is not None else mi.Properties())

        def aov_names(self):
            return ["laser"]

        def sample(self, scene, sampler, ray, medium=None, active=True):
            env = scene.environment()
            ray = mi.Ray3f(ray)
            active = mi.Bool(active)
            si = scene.ray_intersect(ray, active)
            hit = active & si.is_valid()
            L = dr.select(active & ~hit, env.eval(si, active & ~hit), 0.0)
            bsdf = si.bsdf(ray)
            bs, w = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(hit),
                                sampler.next_2d(hit), hit)
            ok = hit & (bs.pdf > 0)
            shadow = si.spawn_ray(si.to_world(bs.wo))
            ok &= ~scene.ray_test(shadow, ok)
            far = dr.zeros(mi.SurfaceInteraction3f)
            far.wi = -shadow.d
            L += dr.select(ok, w * env.eval(far, ok), 0.0)
            return L, mi.Bool(True), [dr.zeros(mi.Float, dr.width(si.t))]

    return FlatAmbientIntegrator


def _flat_integrator():
    """An integrator for the flat part of a board under the ambient light, laser off, no
    mirrors (:func:`_render`'s ``flat_interior``).

    Light paths: ``A E`` (a camera ray that escapes sees the environment) and ``A D E`` — the
    laser integrator's (:mod:`lts360.simulator.integrator`) — but the ambient light on the
    diffuse board is estimated by sampling the BSDF (cosine-weighted) instead of the
    environment (uniform over the sphere): the same expectation, ``ρ L_env`` where nothing
    hides the sky, and no variance at all in a mirror-less scene, where nothing can (the board
    is the only shape, and planar): a sample's weight is the albedo ``ρ`` it meets.  A pixel
    whose rays all meet one square of the print therefore has its exact expected value for
    one sample, which the laser integrator's estimate scatters about (1.2 % of the light
    squares' level at 64 spp on the paper rig's camera board, 2026-12-05)."""
    import mitsuba as mi

    return _flat_integrator_class(mi.variant())()


def _context_picture(scene_rig, *, spp, thin_lens, scale) -> RenderResult:
    """The picture without a board, as a full render at ``spp`` gives it.

    Without a board nothing is lit by the laser (the mirrors are the only other surfaces,
    and they are delta reflectors): one picture serves laser on and off.  Every camera ray
    then ends in the uniform ambient light, through some mirror sequence: a pixel whose
    samples all follow one sequence has the same value for one sample as for ``spp`` (the
    environment times the mirrors' reflectances).  So the picture is rendered at one sample
    per pixel, and at ``spp`` only on the pixels near the mirrors' edges, where the samples
    of a pixel may part (:func:`lts360.simulator.board_window.mirror_edge_pixels`; no mirrors:
    none).  Measured on the paper rig (1280 × 1024, 64 spp): all 15 922 pixels where the
    one-sample picture differs from the full 64-spp render lie among the 100 176 re-rendered
    (7.6 % of the film), the others equal to the bit; 0.85 s instead of 9.8 s (6.5 s of CPU
    against 0.84; 2026-12-04, other work sharing the machine)."""
    spec = SceneSpec(scene_rig, (), ambient="bright")
    one = render_radiance(spec, spp=1, seed=CONTEXT_SEED, thin_lens=thin_lens, laser_on=False,
                          scale=scale)
    px = mirror_edge_pixels(scene_rig, thin_lens=thin_lens, scale=scale)
    rad, las, sec = render_pixels(spec, px, spp=spp, seed=CONTEXT_SEED, thin_lens=thin_lens,
                                  laser_on=False, scale=scale)
    out = composite(one, px, rad, las, seconds=one.seconds + sec, seed=CONTEXT_SEED)
    return replace(out, spp=int(spp))


def _prepared(scenes: dict, spec: SceneSpec, board, *, key: tuple):
    """Build once, render many: the loaded scene of ``spec`` with its one board moved to
    ``board``'s pose (``mi.traverse``), loaded only for a new mirror configuration, sample
    count, lens, scale, laser state or board print (``key`` and the board's print)."""
    import mitsuba as mi

    _, kw_spp, kw_thin, kw_scale = key[:4]
    full_key = key + (board.squares_x, board.squares_y, float(board.square_mm),
                      float(board.margin_mm), float(board.dark_reflectance),
                      float(board.light_reflectance))
    if full_key not in scenes:
        scenes[full_key] = prepare_scene(spec, spp=kw_spp, thin_lens=kw_thin, scale=kw_scale,
                                         laser_on=key[4] is True)
        return scenes[full_key]
    prepared = scenes[full_key]
    params = mi.traverse(prepared[0])
    params["target_0.to_world"] = mi.Transform4f(board.rectangle_transform().tolist())
    params.update()
    env = prepared[0].environment()
    if env is not None:  # the ambient light's bounding sphere follows the moved board
        env.set_scene(prepared[0])
    return prepared


def render_calibration_images(rig: Rig, shots: list[BoardShot], out_dir, *, noise: str = "none",
                              seed: int = 0, spp: int = 16, thin_lens: bool = True,
                              target_spp: int | None = None, windowed: bool = True,
                              progress=None, lock=None) -> dict:
    """Render every shot into ``out_dir`` (PNG + ``manifest.json``) and return the manifest.

    Parameters
    ----------
    noise : {"none", "realistic"}
        As :func:`lts360.simulator.frame.sensor_image` (speckle on the laser line only).
    seed : int
        Shot ``k`` uses sampler/noise seed ``seed * 1000 + k``.
    target_spp : int, optional
        Samples per pixel of the mirror and laser shots (the small target), default ``spp``.
        Their corners and line are where render noise counts: at the rig's f/2.8 the small
        board's edges are blurred over ~5 px by the lens aperture, which the renderer
        integrates by sampling — at 64 spp the edge pixels carry 3 % of the white level of
        Monte Carlo noise (multijitter; independent 7 %), against ~1 % of shot noise.
    windowed : bool
        Render each board's windows only, over one board-less picture per mirror
        configuration (see the module docstring); ``False``: every picture in full.
    progress : callable, optional
        Called with each shot's name after it is written.
    lock : context manager, optional
        Held while a shot renders (its Mitsuba/Dr.Jit work; not its sensor noise, file and
        corners): a caller rendering on another thread shares one with its own Dr.Jit work,
        so that the two never trace or launch kernels at once.

    Returns
    -------
    dict
        ``manifest`` (what was written to ``out_dir/manifest.json``) and ``truth`` (the true
        rig as in a frame's ``frame.json`` plus every board's world pose and corners), which
        is *not* written here: the caller keeps it away from the images.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not shots:
        raise ValueError("render_calibration_images: no shots")
    def geometry(kind):
        b = next((s.board for s in shots if (s.kind == "camera") == (kind == "camera")), None)
        return None if b is None else {"pattern_size": list(b.pattern_size),
                                       "square_mm": b.square_mm}

    design = rig.design
    manifest = {"format": "lts360-calibration-images", "version": 1,
                "board": geometry("target"), "camera_board": geometry("camera"),
                "design": {} if design is None else {
                    "mirror_corner_distance_mm": design.mirror_corner_distance_mm,
                    "mirror_width_mm": design.mirror_width_mm,
                    "mirror_height_mm": design.mirror_height_mm,
                    "mirror_center_z_mm": design.mirror_center_z_mm},
                "mirrors": [m.name for m in rig.mirrors], "shots": []}
    truth_boards = []
    K = None
    guard = contextlib.nullcontext() if lock is None else lock
    context = {} if windowed else None
    for k, shot in enumerate(shots):
        s = int(seed) * 1000 + k
        spp_k = spp if (shot.kind == "camera" or target_spp is None) else int(target_spp)
        entry = {"name": shot.name, "kind": shot.kind}
        if shot.mirror is not None:
            entry["mirror"] = shot.mirror
        if shot.kind == "laser":
            # Three pictures of one pose: the board exposed for the board (corners, pose), and
            # laser on / laser off at one exposure set on the line (their difference is the line).
            # A board also seen in a mirror: the line pictures are taken with the mirrors
            # covered, so that only the direct sheet lights the board (a sheet reflected by a
            # mirror a little off perpendicular to the laser plane would draw a second line
            # beside the first); the board picture with the mirrors, for both views.
            covered = shot.mirror is not None
            with guard:
                on = _render(rig, shot.board, laser_on=True, spp=spp_k, seed=s,
                             thin_lens=thin_lens, mirrors=not covered, context=context)
                off = _render(rig, shot.board, laser_on=False, spp=spp_k, seed=s,
                              thin_lens=thin_lens, mirrors=not covered, context=context)
                lit = off if not covered else _render(rig, shot.board, laser_on=False,
                                                      spp=spp_k, seed=s + 900_000,
                                                      thin_lens=thin_lens, context=context)
            img_board, _, _ = sensor_image(rig, lit, noise=noise, seed=s + 300_000)
            if covered:
                entry["laser_mirrors_covered"] = True
            img_on, t_exp, _ = sensor_image(rig, on, noise=noise, seed=s)
            img_off, _, _ = sensor_image(rig, off, noise=noise, seed=s + 600_000,
                                         exposure_time_s=t_exp)
            for suffix, img in (("board", img_board), ("on", img_on), ("off", img_off)):
                write_png(out / f"{shot.name}-{suffix}.png", img)
                entry[f"image_{suffix}"] = f"{shot.name}-{suffix}.png"
            K, rendered_spp = on.K, on.spp
        else:
            with guard:
                res = _render(rig, shot.board, laser_on=False, spp=spp_k, seed=s,
                              thin_lens=thin_lens, mirrors=not shot.mirrors_covered,
                              context=context, flat_interior=shot.mirrors_covered)
            img, _, _ = sensor_image(rig, res, noise=noise, seed=s)
            if shot.mirrors_covered:
                entry["mirrors_covered"] = True
            write_png(out / f"{shot.name}.png", img)
            entry["image"] = f"{shot.name}.png"
            K, rendered_spp = res.K, res.spp
        manifest["shots"].append(entry)
        truth_boards.append({"name": shot.name, "T_world_board": shot.board.T_world_board,
                             "corners_world_mm": shot.board.corners_world_mm(),
                             "spp": int(rendered_spp)})
        if progress is not None:
            progress(shot.name)
    write_json(out / MANIFEST_NAME, manifest)
    truth = rig_truth(rig, K, (rig.camera.width_px, rig.camera.height_px))
    truth.update({"boards": truth_boards, "render": {"noise": noise, "seed": seed, "spp": spp,
                                                     "target_spp": target_spp or spp,
                                                     "thin_lens": thin_lens,
                                                     "camera_shots_flat": None if not windowed else
                                                     {"edge_spp": max(1, spp // FLAT_EDGE_SPP_DIVISOR),
                                                      "flat_spp": 1}}})
    return {"manifest": manifest, "truth": truth}

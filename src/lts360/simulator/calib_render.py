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
(another noise realisation of the same expected image).  The scene is loaded once per mirror
configuration, sample count, laser state and board print; each next board of that print is
moved into it (``mi.traverse``): the image of a freshly loaded scene to float32 rounding (the
moved board's transform is derived in the JIT's arithmetic; 2.4e-7 W m⁻² sr⁻¹ at most on a
full-size 64-spp camera board).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from lts360.scenes.calib_plan import BoardShot
from lts360.scenes.rig import Rig
from lts360.simulator.board_window import board_pixels, mirror_edge_pixels
from lts360.simulator.frame import sensor_image
from lts360.simulator.io import rig_truth, write_json, write_png
from lts360.simulator.render import RenderResult, prepare_scene, render_pixels, render_radiance
from lts360.simulator.scene import SceneSpec

__all__ = ["render_calibration_images", "MANIFEST_NAME"]

MANIFEST_NAME = "manifest.json"


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
            scale=1.0):
    """One picture; ``context`` (a dict, filled here) holds the board-less pictures for
    windowed rendering, ``None`` renders the full frame; ``scale`` for tests."""
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
    prepared = _prepared(context.setdefault("scenes", {}), spec, board, key=key + (bool(laser_on),))
    rad, las, sec = render_pixels(spec, px, spp=spp, seed=seed, thin_lens=thin_lens,
                                  laser_on=laser_on, scale=scale, prepared=prepared)
    return composite(context[key], px, rad, las, seconds=seconds + sec, seed=seed)


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
                                         laser_on=key[4])
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
                              progress=None) -> dict:
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
            on = _render(rig, shot.board, laser_on=True, spp=spp_k, seed=s, thin_lens=thin_lens,
                         mirrors=not covered, context=context)
            off = _render(rig, shot.board, laser_on=False, spp=spp_k, seed=s, thin_lens=thin_lens,
                          mirrors=not covered, context=context)
            lit = off if not covered else _render(rig, shot.board, laser_on=False, spp=spp_k,
                                                  seed=s + 900_000, thin_lens=thin_lens,
                                                  context=context)
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
            res = _render(rig, shot.board, laser_on=False, spp=spp_k, seed=s, thin_lens=thin_lens,
                          mirrors=not shot.mirrors_covered, context=context)
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
                                                     "thin_lens": thin_lens}})
    return {"manifest": manifest, "truth": truth}

"""Windowed calibration rendering: the board's windows, the pixel-list renderer, the composite.

Small images (the paper camera at 1/8 scale, 160 x 128) so that each test takes seconds.
The decisive check: a render with the board and one without, same seed, are identical
outside the board's windows (a camera ray that never meets the board follows the same
computation with the same samples), even with no safety margin — so the windows hold every
pixel the board (direct, in a mirror, through both, blurred by the lens) can change.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lts360.scenes.calib_plan import plan_calibration
from lts360.scenes.rig_io import load_rig
from lts360.simulator.board_window import (
    blur_radius_norm,
    board_pixels,
    board_windows,
    clip_near,
    merge_boxes,
    view_box,
)

SCALE = 0.125


@pytest.fixture(scope="module")
def rig():
    return load_rig("paper")


@pytest.fixture(scope="module")
def shots(rig):
    return {s.name: s for s in plan_calibration(rig, None, n_camera=4, n_mirror=1, n_laser=2,
                                                seed=0)}


def _mask(windows, shape):
    m = np.zeros(shape, dtype=bool)
    for x, y, w, h in windows:
        m[y:y + h, x:x + w] = True
    return m


# ------------------------------------------------------------------ geometry (numpy only)

def test_clip_near_keeps_front_part():
    square = np.array([[-1.0, -1.0, -2.0], [1.0, -1.0, -2.0], [1.0, 1.0, 4.0], [-1.0, 1.0, 4.0]])
    P = clip_near(square, 1.0)
    assert len(P) == 4 and np.all(P[:, 2] >= 1.0 - 1e-12)
    assert np.isclose(P[:, 1].min(), 0.0)  # z = -2 + 6 (y + 1)/2 = 1 at y = 0
    assert len(clip_near(square, 10.0)) == 0
    assert np.array_equal(clip_near(square + [0, 0, 5.0], 1.0), square + [0, 0, 5.0])


def test_merge_boxes_covers_inputs_and_leaves_no_overlap():
    boxes = [(0, 0, 9, 9), (5, 5, 20, 20), (30, 30, 40, 40), (21, 0, 25, 3), None]
    out = merge_boxes(boxes)
    assert out == [(0, 0, 25, 20), (30, 30, 40, 40)]


def test_blur_radius_matches_thin_lens():
    # r |1/z - 1/s_f|: zero at focus, a/s_f far away.
    assert blur_radius_norm(1.0, 200.0, 200.0) == 0.0
    assert np.isclose(blur_radius_norm(1.0, 200.0, 1e12), 1.0 / 200.0)
    assert np.isclose(blur_radius_norm(2.0, 200.0, 100.0), 2.0 / 200.0)


def test_view_box_of_a_square_pinhole_and_thin_lens():
    K = np.array([[100.0, 0, 49.5], [0, 100.0, 49.5], [0, 0, 1]])
    sq = np.array([[-10.0, -10, 200], [10, -10, 200], [10, 10, 200], [-10, 10, 200]])
    # Pinhole: the square spans 49.5 ± 5 px; padded by sampling + 1 px + margin 0.
    x0, y0, x1, y1 = view_box(sq, K, None, 100, 100, margin_px=0.0)
    assert 42 <= x0 <= 44.5 and 54.5 <= x1 <= 57
    # Thin lens focused at 100 mm: blur radius 5 * |1/200 - 1/100| * 100 = 2.5 px more.
    b = view_box(sq, K, None, 100, 100, margin_px=0.0, aperture_radius_mm=5.0,
                 focus_distance_mm=100.0)
    assert b[0] <= x0 - 2 and b[2] >= x1 + 2
    # Behind the camera or off the film: nothing.
    assert view_box(sq * [1, 1, -1], K, None, 100, 100) is None
    assert view_box(sq + [500.0, 0, 0], K, None, 100, 100) is None
    # A board filling the view: the whole film.
    assert view_box(sq * [100, 100, 1], K, None, 100, 100) == (0, 0, 99, 99)


def test_windows_are_a_small_part_of_mirror_shots(rig, shots):
    s = shots["mirror-left-00"]
    w = board_windows(rig, s.board)
    area = sum(ww * hh for _, _, ww, hh in w)
    assert 2 <= len(w) and area < 0.1 * rig.camera.width_px * rig.camera.height_px


# ------------------------------------------------------------------ rendering

@pytest.mark.parametrize("name, mirrors, laser_on", [("mirror-left-00", True, True),
                                                     ("camera-00", False, False)])
def test_board_changes_nothing_outside_its_windows(variant, rig, shots, name, mirrors, laser_on):
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec

    r = rig if mirrors else replace(rig, mirrors=())
    board = shots[name].board
    kw = dict(spp=4, seed=7, scale=SCALE, laser_on=laser_on)
    with_board = render_radiance(SceneSpec(r, (), ambient="bright", targets=(board,)), **kw)
    without = render_radiance(SceneSpec(r, (), ambient="bright"), **kw)
    inside = _mask(board_windows(r, board, scale=SCALE, margin_px=0.0),
                   with_board.radiance_W_m2_sr.shape)
    changed = (with_board.radiance_W_m2_sr != without.radiance_W_m2_sr) | \
              (with_board.laser_W_m2_sr != without.laser_W_m2_sr)
    assert changed.sum() > 50  # the board is there
    assert not np.any(changed & ~inside)
    assert inside.mean() < (0.35 if mirrors else 0.6)
    # The tighter pixel set (each view's padded outline, not its box) holds them too.
    px = board_pixels(r, board, scale=SCALE, margin_px=0.0)
    tight = np.zeros_like(inside)
    tight[px[:, 1], px[:, 0]] = True
    assert not np.any(changed & ~tight)
    assert not np.any(tight & ~inside) and tight.sum() <= inside.sum()
    if laser_on:
        assert with_board.laser_W_m2_sr.max() > 0


def test_render_pixels_matches_a_full_render(variant, rig, shots):
    from lts360.simulator.render import render_pixels, render_radiance, window_pixels
    from lts360.simulator.scene import SceneSpec

    spec = SceneSpec(rig, (), ambient="bright", targets=(shots["laser-00"].board,))
    full = render_radiance(spec, spp=64, seed=1, scale=SCALE, laser_on=True)
    h, w = full.radiance_W_m2_sr.shape
    px = window_pixels([(0, 0, w, h)])
    rad, las, _ = render_pixels(spec, px, spp=64, seed=2, scale=SCALE, laser_on=True)
    rad, las = rad.reshape(h, w), las.reshape(h, w)
    a = full.radiance_W_m2_sr
    # Where the full render is exactly the environment (no noise), so is this one.
    env = a == 1.0
    assert env.mean() > 0.2 and np.mean(rad[env] == 1.0) > 0.99
    # Elsewhere the same expectation: means agree to the noise, laser power too.
    assert abs(rad.mean() - a.mean()) < 2e-3
    assert np.isclose(las.sum(), full.laser_W_m2_sr.sum(), rtol=0.03)
    assert np.sqrt(np.mean((rad - a) ** 2)) < 0.05
    # A subset of pixels: same values for the same seed and pixel list (deterministic), and
    # the same expectation as the full frame.
    sub = window_pixels([(3, 5, 40, 30), (100, 60, 20, 20)])
    r1, l1, _ = render_pixels(spec, sub, spp=64, seed=3, scale=SCALE, laser_on=True)
    r2, l2, _ = render_pixels(spec, sub, spp=64, seed=3, scale=SCALE, laser_on=True)
    assert np.array_equal(r1, r2) and np.array_equal(l1, l2)
    assert abs(r1.mean() - a[sub[:, 1], sub[:, 0]].mean()) < 5e-3
    with pytest.raises(ValueError):
        render_pixels(spec, [[w, 0]], spp=4, scale=SCALE)


def test_windowed_composite_equals_full_render(variant, rig, shots):
    from lts360.simulator.calib_render import _render

    board = shots["mirror-left-00"].board
    kw = dict(laser_on=True, spp=64, seed=11, thin_lens=True, scale=SCALE)
    context = {}
    win = _render(rig, board, context=context, **kw)
    full = _render(rig, board, context=None, **kw)
    a, b = full.radiance_W_m2_sr, win.radiance_W_m2_sr
    assert a.shape == b.shape == (128, 160)
    inside = _mask(board_windows(rig, board, scale=SCALE), a.shape)
    # Outside the windows: the board-less picture, which is the full render's expectation.
    env = a == 1.0
    assert np.mean(b[env] == 1.0) > 0.99
    assert abs(a[~inside].mean() - b[~inside].mean()) < 2e-3
    # Inside: the board at the same sample count — same expectation and noise.
    assert abs(a[inside].mean() - b[inside].mean()) < 5e-3
    assert np.isclose(a.std(), b.std(), rtol=0.05)
    assert np.isclose(full.laser_W_m2_sr.sum(), win.laser_W_m2_sr.sum(), rtol=0.05)
    # The board-less picture is rendered once and reused, and so is the loaded scene.
    pictures = lambda: [k for k in context if k != "scenes"]  # noqa: E731
    assert len(pictures()) == 1 and len(context["scenes"]) == 1
    again = _render(rig, board, context=context, **kw)
    assert np.array_equal(again.radiance_W_m2_sr, b) and len(pictures()) == 1


@pytest.mark.parametrize("names, mirrors", [(("camera-00", "camera-01"), False),
                                            (("laser-00", "laser-01"), True)])
def test_a_board_moved_in_a_loaded_scene_renders_as_a_fresh_scene(variant, rig, shots, names,
                                                                    mirrors):
    """Build once, render many: the calibration's next board of the same print is moved into
    the scene already loaded (``mi.traverse``), and gives the image a freshly loaded scene gives
    with the same seed, to float32 rounding (the moved board's transform is derived in the JIT's
    arithmetic; ambient light included: its bounding sphere follows the board)."""
    from lts360.simulator.calib_render import _render

    kw = dict(spp=4, seed=5, thin_lens=True, scale=SCALE, mirrors=mirrors)
    context = {}
    for laser_on in (True, False):
        _render(rig, shots[names[0]].board, laser_on=laser_on, context=context, **kw)
        moved = _render(rig, shots[names[1]].board, laser_on=laser_on, context=context, **kw)
        fresh = _render(rig, shots[names[1]].board, laser_on=laser_on, context={}, **kw)
        for a, b in ((moved.radiance_W_m2_sr, fresh.radiance_W_m2_sr),
                     (moved.laser_W_m2_sr, fresh.laser_W_m2_sr)):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6 * float(b.max()))
        assert moved.radiance_W_m2_sr.max() > 0
    assert len(context["scenes"]) == 2  # one per laser state, each loaded once


def test_mirror_edge_pixels_hold_every_pixel_whose_samples_differ(variant, rig):
    """The board-less picture (mirrors under the ambient light) at one sample per pixel and at
    64: they differ only on the pixels :func:`mirror_edge_pixels` lists, even with no safety
    margin (the edges of the mirrors seen directly and through the mirrors), which are a small
    part of the film; without mirrors nothing is listed and the picture is uniform."""
    from lts360.simulator.board_window import mirror_edge_pixels
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec

    spec = SceneSpec(rig, (), ambient="bright")
    one = render_radiance(spec, spp=1, seed=9, scale=SCALE, laser_on=False).radiance_W_m2_sr
    many = render_radiance(spec, spp=64, seed=9, scale=SCALE, laser_on=False).radiance_W_m2_sr
    px = mirror_edge_pixels(rig, scale=SCALE, margin_px=0.0)
    listed = np.zeros(one.shape, bool)
    listed[px[:, 1], px[:, 0]] = True
    differ = one != many
    assert differ.sum() > 20  # the mirrors' edges are in the picture
    assert not np.any(differ & ~listed)
    assert listed.mean() < 0.3
    assert len(mirror_edge_pixels(replace(rig, mirrors=()), scale=SCALE)) == 0


def test_the_context_picture_equals_a_full_render_but_on_the_mirror_edges(variant, rig):
    """The board-less picture of the windowed calibration render: outside the mirrors' edges
    the full 64-spp render to the bit, on them the same expectation."""
    from lts360.simulator.board_window import mirror_edge_pixels
    from lts360.simulator.calib_render import CONTEXT_SEED, _context_picture
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec

    for r in (rig, replace(rig, mirrors=())):
        pic = _context_picture(r, spp=64, thin_lens=True, scale=SCALE)
        full = render_radiance(SceneSpec(r, (), ambient="bright"), spp=64, seed=CONTEXT_SEED,
                               scale=SCALE, laser_on=False)
        a, b = full.radiance_W_m2_sr, pic.radiance_W_m2_sr
        px = mirror_edge_pixels(r, scale=SCALE)
        edge = np.zeros(a.shape, bool)
        edge[px[:, 1], px[:, 0]] = True
        assert np.array_equal(a[~edge], b[~edge]) and pic.spp == 64
        assert not pic.laser_W_m2_sr.any()
        if edge.any():
            assert abs(a[edge].mean() - b[edge].mean()) < 5e-3
            assert np.isclose(a[edge].std(), b[edge].std(), rtol=0.1)


def test_growing_the_drawn_pixels_equals_dilating_the_whole_canvas():
    """``_grow`` dilates only the drawn pixels' box: the same film mask as dilating the whole
    canvas, for shapes inside the film, across its border and at the canvas's corner, and
    none for an empty canvas."""
    cv2 = pytest.importorskip("cv2", reason="the dilation reference is OpenCV's")
    from lts360.simulator.board_window import _grow

    width, height, r = 90, 70, 6
    off = r + 1
    rng = np.random.default_rng(8)
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    for pts in ([(30, 20), (60, 25), (45, 50)], [(-5, -5), (20, 3), (2, 30)],
                [(80, 60), (96, 75), (70, 83)], list(map(tuple, rng.integers(-8, 95, (5, 2))))):
        canvas = np.zeros((height + 2 * off, width + 2 * off), np.uint8)
        poly = (np.array(pts) + off).astype(np.int32)
        cv2.polylines(canvas, [poly], True, 1)
        full = cv2.dilate(canvas, disk)[off:off + height, off:off + width].astype(bool)
        got = _grow(canvas, r, off, width, height)
        assert got.any() and np.array_equal(got, full)
    empty = np.zeros((height + 2 * off, width + 2 * off), np.uint8)
    assert not _grow(empty, r, off, width, height).any()

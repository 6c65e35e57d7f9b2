"""The camera shots' flat interiors: board pixels whose rays all meet one square of the print,
rendered with the BSDF-sampled ambient estimator at one sample per pixel, the square edges at a
quarter of the sample count (:func:`lts360.simulator.calib_render._render`, ``flat_interior``).

The paper camera at half scale (640 x 512), so that a square holds pixels away from its edges.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lts360.scenes.calib_plan import plan_calibration
from lts360.scenes.rig_io import load_rig
from lts360.simulator.board_window import board_edge_pixels, board_lines_mm, board_pixels

SCALE = 0.5


@pytest.fixture(scope="module")
def rig():
    return replace(load_rig("paper"), mirrors=())


@pytest.fixture(scope="module")
def board():
    shots = plan_calibration(load_rig("paper"), None, n_camera=4, n_mirror=1, n_laser=2, seed=0)
    return next(s.board for s in shots if s.kind == "camera")


def _mask(px, shape):
    m = np.zeros(shape, bool)
    m[px[:, 1], px[:, 0]] = True
    return m


def test_board_lines_are_the_grid_and_the_outline(board):
    lines = board_lines_mm(board)
    s, nx, ny = board.square_mm, board.squares_x, board.squares_y
    assert lines.shape == (nx + 1 + ny + 1 + 4, 2, 3)
    assert np.allclose(lines[..., 2], 0.0)
    # The outline encloses the printed area (margin included), the grid the squares.
    assert np.isclose(lines[..., 0].min(), -board.margin_mm)
    assert np.isclose(lines[..., 1].max(), ny * s + board.margin_mm)
    assert np.allclose(lines[:nx + 1, 0, 0], np.arange(nx + 1) * s)


def test_board_edge_pixels_hold_every_pixel_whose_samples_differ(variant, rig, board):
    """With the flat estimator a pixel whose rays all meet one square has one value for any
    sample count: at 1 and 64 spp the board's pixels differ (by more than one sample's rare
    miss of value zero, see ``FLAT_EDGE_MARGIN_PX``) only on :func:`board_edge_pixels`, even
    with no safety margin; and the edge pixels are a part of the board only."""
    from lts360.simulator.calib_render import _flat_integrator
    from lts360.simulator.render import prepare_scene, render_pixels
    from lts360.simulator.scene import SceneSpec

    spec = SceneSpec(rig, (), ambient="bright", targets=(board,))
    px = board_pixels(rig, board, scale=SCALE)
    out = []
    for spp in (1, 64):
        scene = prepare_scene(spec, spp=spp, scale=SCALE, laser_on=False)[0]
        out.append(render_pixels(spec, px, spp=spp, seed=4, scale=SCALE, laser_on=False,
                                 prepared=(scene, _flat_integrator()))[0])
    differ = np.abs(out[0] - out[1]) > 1.5 / 64 * np.maximum(out[0], 1e-3)
    edges = _mask(board_edge_pixels(rig, board, scale=SCALE, margin_px=0.0), (512, 640))
    listed = edges[px[:, 1], px[:, 0]]
    assert differ.sum() > 500  # the squares' edges are in the picture
    assert not np.any(differ & ~listed)
    assert 0.2 < listed.mean() < 0.9


def test_a_flat_camera_shot_is_a_full_render_within_its_noise(variant, rig, board):
    """The split picture against two windowed renders with the laser integrator at the full
    sample count (different seeds).  Away from the edges it holds the closed form ``ρ L_env``
    (``L_env`` where the rays miss the board); everywhere its mean is the full render's within
    the noise, and its own noise (what the difference to a full render holds beyond the full
    render's) is no larger than a full render's."""
    from lts360.simulator.calib_render import FLAT_EDGE_MARGIN_PX, _render
    from lts360.simulator.scene import AMBIENT_RADIANCE_W_M2_SR

    kw = dict(laser_on=False, spp=64, thin_lens=True, scale=SCALE, mirrors=False)
    full = [_render(rig, board, seed=k, context={}, **kw).radiance_W_m2_sr for k in (1, 2)]
    split = _render(rig, board, seed=3, context={}, flat_interior=True, **kw)
    s = split.radiance_W_m2_sr
    assert s.shape == (512, 640) and not split.laser_W_m2_sr.any()
    inb = _mask(board_pixels(rig, board, scale=SCALE), s.shape)
    edge = _mask(board_edge_pixels(rig, board, scale=SCALE, margin_px=FLAT_EDGE_MARGIN_PX),
                 s.shape) & inb
    flat = inb & ~edge
    assert flat.sum() > 1000
    L = AMBIENT_RADIANCE_W_M2_SR["bright"]
    exact = np.array([board.dark_reflectance * L, board.light_reflectance * L, L], np.float32)
    assert np.all(np.min(np.abs(s[flat][:, None] - exact[None]), axis=1) <= 1e-6 * L)
    own_full = np.var(full[0] - full[1]) / 2
    for m in (flat, edge):
        d = full[0][m] - s[m]
        assert abs(d.mean()) < 4 * d.std() / np.sqrt(m.sum())
        own_full_m = np.var(full[0][m] - full[1][m]) / 2
        assert np.var(d) - own_full_m <= own_full_m
    assert np.var(full[0][~inb] - s[~inb]) <= own_full  # outside: the same board-less picture
    with pytest.raises(ValueError):
        _render(rig, board, seed=3, context={}, flat_interior=True, **{**kw, "laser_on": True})

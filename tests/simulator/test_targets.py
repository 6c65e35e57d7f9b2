"""A rendered chessboard: OpenCV finds its corners where the truth projects them."""

from __future__ import annotations

import numpy as np
import pytest

from lts360.geometry import project_points
from lts360.scenes.rig import RigError
from lts360.scenes.rig_io import load_rig
from lts360.scenes.targets import Chessboard

mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3")
cv2 = pytest.importorskip("cv2", reason="corner detection needs OpenCV")


def _board_facing_camera(rig) -> Chessboard:
    n = rig.camera.center_mm / np.linalg.norm(rig.camera.center_mm)
    x = np.cross([0, 0, 1.0], n)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = x, np.cross(n, x), n
    T[:3, 3] = -7.0 * x - 6.0 * np.cross(n, x)
    return Chessboard(T_world_board=T)


def test_board_truth_and_texture():
    b = Chessboard()
    assert b.pattern_size == (6, 5) and b.size_mm == (16.0, 14.0)
    c = b.corners_board_mm()
    assert c.shape == (30, 3) and np.allclose(c[0], [2, 2, 0]) and np.allclose(c[-1], [12, 10, 0])
    tex = b.texture(8)
    # Image convention: the last row is the board's y_min edge; square (0, 0) is dark.
    assert tex[-9, 9] == b.dark_reflectance and tex[-9, 9 + 8] == b.light_reflectance  # 8 px/square, 4 px margin
    with pytest.raises(RigError, match="chessboard.squares_x"):
        Chessboard(squares_x=2)


def test_rendered_board_corners_match_the_truth():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec

    rig = load_rig("paper")
    board = _board_facing_camera(rig)
    res = render_radiance(SceneSpec(rig, (), ambient="bright", targets=(board,)), spp=16,
                          thin_lens=False, laser_on=False)
    img = res.radiance_W_m2_sr
    im8 = np.clip(img / img.max() * 255, 0, 255).astype(np.uint8)
    ok, corners = cv2.findChessboardCornersSB(im8, board.pattern_size, flags=cv2.CALIB_CB_ACCURACY)
    assert ok
    cam = rig.camera
    truth = project_points(board.corners_world_mm(), cam.K, cam.distortion, cam.R, cam.t_mm)
    corners = corners.reshape(-1, 2)
    d = np.linalg.norm(corners[:, None, :] - truth[None, :, :], axis=2)
    err = d.min(axis=1)
    assert len(set(d.argmin(axis=1))) == 30  # one detection per true corner
    # Measured: rms 0.07 px, max 0.18 px (squares of ~10 px, the SB detector's accuracy).
    assert np.sqrt(np.mean(err**2)) < 0.1 and err.max() < 0.3
    # Square (0, 0) of the board renders dark: the texture is not mirrored.
    centre = board.T_world_board[:3, :3] @ [1.0, 1.0, 0.0] + board.T_world_board[:3, 3]
    u, v = project_points(centre[None], cam.K, None, cam.R, cam.t_mm)[0]
    assert img[int(round(v)), int(round(u))] < 0.2 * np.percentile(img, 99)

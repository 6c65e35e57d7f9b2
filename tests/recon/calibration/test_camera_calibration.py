"""Zhang calibration (OpenCV) from rendered chessboard images against the true camera.

Measured (12 poses, 9×7 squares of 5 mm, 1280×1024, pinhole, no noise): reprojection RMS
0.11 px, fx −0.035 %, fy −0.059 %, cx +0.08 px, cy +1.8 px. Issue 5 asks for 0.05 %, 0.2 px
and 0.05 px: not reached yet (corner localisation ~0.1 px is the limit); these tolerances
guard the current figures.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lts360.recon.calibration.board import BoardGeometry
from lts360.recon.calibration.camera import calibrate_camera

mi = pytest.importorskip("mitsuba", reason="rendering the calibration images needs Mitsuba 3")
pytest.importorskip("cv2", reason="calibration needs OpenCV")


def _poses(rig, board):
    from scipy.spatial.transform import Rotation

    R_cw = rig.camera.R.T
    C = rig.camera.center_mm
    flip = np.diag([1.0, -1.0, -1.0])  # board z towards the camera
    out, k = [], 0
    for dx in (-40, -15, 15, 40):
        for dy in (-30, 0, 30):
            k += 1
            tilt = Rotation.from_euler("xy", [(-1) ** k * 25, (1 if dx <= 0 else -1) * 25],
                                       degrees=True).as_matrix()
            R_wb = R_cw @ flip @ tilt
            w, h = board.size_mm
            T = np.eye(4)
            T[:3, :3] = R_wb
            T[:3, 3] = R_cw @ np.array([dx, dy, 170.0]) + C - R_wb @ np.array(
                [w / 2 - board.margin_mm, h / 2 - board.margin_mm, 0.0])
            out.append(dataclasses.replace(board, T_world_board=T))
    return out


@pytest.mark.slow
def test_zhang_calibration_recovers_the_rendered_camera():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.scenes.rig_io import load_rig
    from lts360.scenes.targets import Chessboard
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec

    rig = dataclasses.replace(load_rig("paper"), mirrors=())  # the board seen directly only
    board = Chessboard(squares_x=9, squares_y=7, square_mm=5.0, margin_mm=5.0)
    images = [render_radiance(SceneSpec(rig, (), ambient="bright", targets=(b,)), spp=8,
                              thin_lens=False, laser_on=False).radiance_W_m2_sr
              for b in _poses(rig, board)]
    res = calibrate_camera(images, BoardGeometry((8, 6), 5.0))
    K = rig.camera.K
    assert res.used.sum() >= 10
    assert res.rms_px < 0.2
    assert abs(res.K[0, 0] / K[0, 0] - 1) < 2e-3 and abs(res.K[1, 1] / K[1, 1] - 1) < 2e-3
    assert np.all(np.abs(res.K[:2, 2] - K[:2, 2]) < 4.0)
    assert np.all(np.abs(res.dist[:2]) < 0.02)  # the true lens has no distortion


def test_too_few_images_is_a_clear_error():
    with pytest.raises(ValueError, match="usable images"):
        calibrate_camera([np.zeros((64, 64), np.uint8)] * 3, BoardGeometry((8, 6), 5.0))


def test_corners_far_off_the_fit_are_left_out(monkeypatch):
    """A few corners 0.6–1.2 px off (the SB detector does this next to a narrow margin or at
    a blurred edge; measured on renders) are found and left out, the rest of their images
    kept.  Synthetic corners: the planned poses projected exactly, 0.03 px noise, and one
    corner moved in each of eight images; the detector is replaced by a lookup."""
    import lts360.recon.calibration.camera as cc
    from lts360.geometry.camera import project_points
    from lts360.scenes.calib_plan import plan_calibration
    from lts360.scenes.rig_io import load_rig

    rig = load_rig("paper")
    cam = rig.camera
    shots = [s for s in plan_calibration(rig, n_camera=16, n_mirror=1, n_laser=2, seed=2)
             if s.kind == "camera"]
    rng = np.random.default_rng(5)
    corners, moved = [], []
    for k, s in enumerate(shots):
        uv = project_points(s.board.corners_world_mm(), cam.K, None, cam.R, cam.t_mm)
        uv = uv + rng.normal(0.0, 0.03, uv.shape)
        j = -1
        if k < 8:
            j = int(rng.integers(len(uv)))
            uv[j] += rng.uniform(0.6, 1.2) * np.array([np.cos(k), np.sin(k)])
        corners.append(uv)
        moved.append(j)
    images = [np.full((cam.height_px, cam.width_px), k, np.uint8) for k in range(len(shots))]
    monkeypatch.setattr(cc, "detect_corners", lambda im, board: corners[int(im[0, 0])].copy())
    geo = BoardGeometry(shots[0].board.pattern_size, shots[0].board.square_mm)

    def errors(c):
        return (abs(c.K[0, 0] / cam.K[0, 0] - 1) * 100, abs(c.K[0, 2] - cam.K[0, 2]),
                abs(c.K[1, 2] - cam.K[1, 2]))

    cal = calibrate_camera(images, geo, zero_tangent=True)
    assert cal.used.all()
    for keep, j in zip(cal.corner_kept, moved):
        expected = np.ones(len(keep), bool)
        if j >= 0:
            expected[j] = False
        np.testing.assert_array_equal(keep, expected)
    naive = calibrate_camera(images, geo, zero_tangent=True, corner_outlier_px=np.inf)
    assert all(k.all() for k in naive.corner_kept)
    assert cal.rms_px < 0.05 < naive.rms_px  # 0.03·√2 ≈ 0.042 px without the moved ones
    assert sum(errors(cal)) < sum(errors(naive))


@pytest.mark.slow
def test_symmetrized_corners_and_the_board_handedness():
    """SB is not mirror-symmetric, nor symmetric under a half turn: its corners sit off the
    true projections by an offset common to the board.  ``flips=4`` (the image, its two
    flips and its half turn averaged) makes a board and its mirror image give the same
    corners by construction (to 1e-3 px).  The default ``flips=2`` (the image and its half
    turn: half the detector's time) cancels the part of the offset that turns with the
    image — on the demo's 30 camera boards all of the mean offset (−0.0003, −0.0003 px
    against −0.0004, −0.0004 with four flips and −0.0078, −0.0020 without; RMS error 0.043
    against 0.042 and 0.057 px) — so the mirror image agrees on average within 0.01 px.  On
    this 64-spp render the board's mean offset is (0.007, 0.016) px plain, (0.001, 0.005)
    with four flips and (−0.000, 0.005) with two; every set within 0.12 px RMS of the true
    projections, as are the saddle-point corners (the noisier at this sample count)."""
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from scipy.spatial import cKDTree

    from lts360.geometry.camera import project_points
    from lts360.recon.calibration.camera import detect_corners
    from lts360.scenes.rig_io import load_rig
    from lts360.scenes.targets import Chessboard
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec

    rig = dataclasses.replace(load_rig("paper"), mirrors=())
    board = Chessboard(squares_x=9, squares_y=7, square_mm=5.0, margin_mm=5.0)
    img = render_radiance(SceneSpec(rig, (), ambient="bright", targets=(_poses(rig, board)[4],)),
                          spp=64, thin_lens=False, laser_on=False).radiance_W_m2_sr
    geo = BoardGeometry((8, 6), 5.0)
    w = img.shape[1]
    cam = rig.camera
    true = project_points(_poses(rig, board)[4].corners_world_mm(), cam.K, None, cam.R, cam.t_mm)

    def offset(corners):
        _, j = cKDTree(true).query(corners)
        d = corners - true[j]
        return d.mean(axis=0), np.sqrt(np.mean(np.sum(d ** 2, axis=1)))

    plain, _ = offset(detect_corners(img, geo, symmetrize=False))
    for flips, mean_px, max_px in ((4, 1e-3, 1e-3), (2, 0.01, 0.15)):
        a = detect_corners(img, geo, flips=flips)
        b = detect_corners(np.ascontiguousarray(img[:, ::-1]), geo, flips=flips)
        b[:, 0] = w - 1 - b[:, 0]
        dist, idx = cKDTree(b).query(a)
        assert len(set(idx.tolist())) == len(a)
        assert np.all(np.abs((b[idx] - a).mean(axis=0)) < mean_px) and dist.max() < max_px
        mean, rms = offset(a)
        assert rms < 0.12
        assert np.linalg.norm(mean) < 0.5 * np.linalg.norm(plain)
    assert offset(detect_corners(img, geo, refine=True))[1] < 0.12
    with pytest.raises(ValueError, match="flips"):
        detect_corners(img, geo, flips=3)


def _board_image(R, t, K, geo, *, size=(360, 300), blur_px=1.5, ss=4):
    """A board (4 % / 80 % albedo, 2 mm light margin, grey beyond) at pose (R, t), hard
    edges sampled ``ss × ss`` per pixel, Gaussian blur, 200 units at full light."""
    from scipy import ndimage

    w, h = size
    o = (np.arange(ss) + 0.5) / ss - 0.5
    u, v = np.meshgrid(np.repeat(np.arange(w), ss) + np.tile(o, w),
                       np.repeat(np.arange(h), ss) + np.tile(o, h))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    n = R[:, 2]
    xb = (rays * ((n @ t) / (rays @ n))[..., None] - t) @ R
    s = geo.square_mm
    nx, ny = geo.pattern_size
    inside = ((xb[..., 0] > -s) & (xb[..., 0] < nx * s) & (xb[..., 1] > -s)
              & (xb[..., 1] < ny * s))
    plate = ((xb[..., 0] > -s - 2) & (xb[..., 0] < nx * s + 2) & (xb[..., 1] > -s - 2)
             & (xb[..., 1] < ny * s + 2))
    dark = (np.floor(xb[..., 0] / s) + np.floor(xb[..., 1] / s)) % 2 == 0
    albedo = np.where(inside & dark, 0.04, np.where(plate, 0.80, 0.3))
    pix = albedo.reshape(h, ss, w, ss).mean(axis=(1, 3))
    return 200.0 * ndimage.gaussian_filter(pix, blur_px)


@pytest.mark.slow
def test_the_board_model_rounds_calibrate_the_camera_from_every_pixel():
    """Eight synthetic board images (hard edges, 1.5 px blur, no noise, squares ~17 px) of a
    62° camera.  SB's corners are 0.1–0.3 px off here and Zhang's method on them is poor
    (fx −5.7 %, k1/k2 +0.09/−0.49).  One round on the corners of the image model of the
    squares around each: fx within 0.05 %, the principal point within 0.1 px, k1, k2 within
    0.02 of the true zero and 0.01 px RMS (measured: +0.017 %, +0.04/−0.01 px,
    +0.005/−0.012, 0.004 px; one image dropped as an outlier)."""
    from scipy.spatial.transform import Rotation

    K = np.array([[300.0, 0.0, 181.3], [0.0, 300.0, 148.6], [0.0, 0.0, 1.0]])
    geo = BoardGeometry((7, 5), 4.0)
    centre = np.array([14.0, 10.0, 0.0])
    images = []
    for k, (ax, ay, dx, dy) in enumerate([(25, 0, -3, -2), (-25, 0, 3, 2), (0, 25, 2, -3),
                                          (0, -25, -2, 3), (20, 20, 0, 0), (-20, 20, 4, 0),
                                          (20, -20, 0, 4), (-20, -20, -4, -4)]):
        R = Rotation.from_euler("xyz", [180.0 + ax, ay, 10.0 * k], degrees=True).as_matrix()
        t = np.array([dx, dy, 70.0]) - R @ centre
        images.append(_board_image(R, t, K, geo))
    sb = calibrate_camera(images, geo, zero_tangent=True)
    cal = calibrate_camera(images, geo, zero_tangent=True, board_model_rounds=1)
    assert cal.used.sum() >= 7
    assert abs(cal.K[0, 0] / K[0, 0] - 1) < 5e-4 and abs(cal.K[1, 1] / K[1, 1] - 1) < 5e-4
    assert np.all(np.abs(cal.K[:2, 2] - K[:2, 2]) < 0.1)
    assert np.all(np.abs(cal.dist[:2]) < 0.02)
    assert cal.rms_px < 0.01 < sb.rms_px
    assert abs(sb.K[0, 0] / K[0, 0] - 1) > 10 * abs(cal.K[0, 0] / K[0, 0] - 1)


def test_corners_found_beforehand_give_the_same_calibration(monkeypatch):
    """``corners=`` (found while the images were rendered) is the detector's output handed
    over: the same calibration as detecting them here; a count that does not match the
    images is refused.  Synthetic corners as above, the detector a lookup."""
    import lts360.recon.calibration.camera as cc
    from lts360.geometry.camera import project_points
    from lts360.scenes.calib_plan import plan_calibration
    from lts360.scenes.rig_io import load_rig

    rig = load_rig("paper")
    cam = rig.camera
    shots = [s for s in plan_calibration(rig, n_camera=8, n_mirror=1, n_laser=2, seed=3)
             if s.kind == "camera"]
    rng = np.random.default_rng(6)
    corners = [project_points(s.board.corners_world_mm(), cam.K, None, cam.R, cam.t_mm)
               + rng.normal(0.0, 0.03, (len(s.board.corners_world_mm()), 2)) for s in shots]
    corners[2] = None  # a board not found
    images = [np.full((cam.height_px, cam.width_px), k, np.uint8) for k in range(len(shots))]
    calls = []

    def lookup(im, board):
        calls.append(int(im[0, 0]))
        c = corners[int(im[0, 0])]
        return None if c is None else c.copy()

    monkeypatch.setattr(cc, "detect_corners", lookup)
    geo = BoardGeometry(shots[0].board.pattern_size, shots[0].board.square_mm)
    here = calibrate_camera(images, geo, zero_tangent=True)
    assert len(calls) == len(images)
    given = calibrate_camera(images, geo, zero_tangent=True, corners=corners)
    assert len(calls) == len(images)  # not detected again
    np.testing.assert_array_equal(given.K, here.K)
    np.testing.assert_array_equal(given.used, here.used)
    assert not given.used[2]
    with pytest.raises(ValueError, match="corner sets"):
        calibrate_camera(images, geo, corners=corners[:-1])

"""Calibration pose planning: every planned board is seen as its kind requires."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lts360.scenes.calib_plan import laser_crossing_ok, plan_calibration, shot_visibility
from lts360.scenes.rig_io import load_rig
from lts360.scenes.targets import Chessboard


@pytest.fixture(scope="module")
def rig():
    return load_rig("paper")


@pytest.fixture(scope="module")
def shots(rig):
    return plan_calibration(rig, n_camera=6, n_mirror=2, n_laser=3, seed=4)


def test_counts_names_and_kinds(shots):
    kinds = [s.kind for s in shots]
    assert kinds.count("camera") == 6 and kinds.count("mirror") == 4 and kinds.count("laser") == 3
    assert len({s.name for s in shots}) == len(shots)
    assert {s.mirror for s in shots if s.kind == "mirror"} == {"left", "right"}


def test_every_shot_is_seen_as_planned(rig, shots):
    for s in shots:
        assert s.mirrors_covered == (s.kind == "camera"), s.name
        vis = shot_visibility(dataclasses.replace(rig, mirrors=()) if s.mirrors_covered else rig,
                              s.board)
        assert vis["direct"] == 1.0, s.name
        if s.kind in ("mirror", "laser"):
            assert s.mirror in ("left", "right") and vis[s.mirror] == 1.0, (s.name, vis)
        others = [v for k, v in vis.items() if k not in ("direct", s.mirror)]
        assert max(others, default=0.0) < 0.5, (s.name, vis)
    assert [s.mirror for s in shots if s.kind == "laser"] == ["left", "right", "left"]


def _check_laser_shot(rig, s, *, min_cos, min_angle_deg):
    L = np.asarray(rig.laser.origin_mm)
    X = s.board.corners_world_mm()
    assert X[:, 2].min() < 0 < X[:, 2].max(), s.name  # the sheet z = 0 crosses the squares
    T = s.board.T_world_board
    n = T[:3, 2]
    centre = X.mean(axis=0)
    to_board = (centre - L) * [1, 1, 0]
    assert -n @ to_board / np.linalg.norm(to_board) >= min_cos, s.name  # lit from the front
    line = np.cross(n, [0.0, 0.0, 1.0])
    line /= np.linalg.norm(line)
    off_axes = np.degrees(np.arccos(np.abs([line @ T[:3, 0], line @ T[:3, 1]])))
    assert off_axes.min() >= min_angle_deg, s.name


def test_laser_shots_straddle_the_sheet_lit_from_the_front_and_oblique(rig, shots):
    for s in (s for s in shots if s.kind == "laser"):
        _check_laser_shot(rig, s, min_cos=0.2, min_angle_deg=15.0)


def test_laser_shots_seen_directly_only_face_laser_and_camera(rig):
    plan = plan_calibration(rig, n_camera=4, n_mirror=1, n_laser=3, seed=4,
                            laser_in_mirror=False)
    C = rig.camera.center_mm
    for s in (s for s in plan if s.kind == "laser"):
        assert s.mirror is None
        vis = shot_visibility(rig, s.board)
        assert vis["direct"] == 1.0 and max(v for k, v in vis.items() if k != "direct") < 0.5
        _check_laser_shot(rig, s, min_cos=0.0, min_angle_deg=0.0)
        n = s.board.T_world_board[:3, 2]
        assert n @ (C - s.board.corners_world_mm().mean(axis=0)) > 0


def test_laser_crossing_rejects_a_board_the_sheet_misses_or_lights_from_behind(rig, shots):
    s = next(s for s in shots if s.kind == "laser")
    assert laser_crossing_ok(rig, s.board)
    lifted = s.board.T_world_board.copy()
    lifted[2, 3] += 20.0  # the sheet passes below the squares
    assert not laser_crossing_ok(rig, dataclasses.replace(s.board, T_world_board=lifted))
    flipped = s.board.T_world_board.copy()
    flipped[:3, 1:3] *= -1  # turned over about its x axis: printed side away from the laser
    assert not laser_crossing_ok(rig, dataclasses.replace(s.board, T_world_board=flipped))


def test_same_seed_same_plan_other_seed_other_plan(rig, shots):
    again = plan_calibration(rig, n_camera=6, n_mirror=2, n_laser=3, seed=4)
    other = plan_calibration(rig, n_camera=6, n_mirror=2, n_laser=3, seed=5)
    for a, b in zip(shots, again):
        np.testing.assert_array_equal(a.board.T_world_board, b.board.T_world_board)
    assert not np.allclose(shots[0].board.T_world_board, other[0].board.T_world_board)


def test_a_board_too_large_for_the_mirrors_is_a_clear_error(rig):
    huge = Chessboard(squares_x=20, squares_y=20, square_mm=8.0)
    with pytest.raises(ValueError, match="valid mirror poses"):
        plan_calibration(rig, huge, camera_board=Chessboard(), n_camera=4, n_mirror=1, n_laser=2,
                         max_tries=200)


def test_too_few_shots_requested(rig):
    with pytest.raises(ValueError, match="n_laser >= 2"):
        plan_calibration(rig, n_laser=1)


def _tilt_about_image_x_deg(rig, board):
    n = rig.camera.R @ board.T_world_board[:3, 2]  # board normal in the camera frame
    return np.degrees(np.arctan2(n[1], -n[2]))


@pytest.mark.slow
def test_camera_shots_without_mirrors_tilt_both_ways(rig):
    """With the mirrors in place the accepted camera poses all lean one way about the image
    x axis (a second full board in a mirror refuses the others), which leaves cy and fx
    poorly determined; planned without the mirrors they lean both ways."""
    free = plan_calibration(rig, n_camera=16, n_mirror=1, n_laser=2, seed=7)
    held = plan_calibration(rig, n_camera=16, n_mirror=1, n_laser=2, seed=7,
                            cover_mirrors_for_camera=False)
    t_free = [_tilt_about_image_x_deg(rig, s.board) for s in free if s.kind == "camera"]
    t_held = [_tilt_about_image_x_deg(rig, s.board) for s in held if s.kind == "camera"]
    assert not any(s.mirrors_covered for s in held)
    assert sum(t < -10 for t in t_free) >= 3 and sum(t > 10 for t in t_free) >= 3
    assert sum(t < -10 for t in t_held) <= 2  # measured: 1 of 40 at seed 7

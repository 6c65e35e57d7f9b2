import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from lts360.geometry import (
    backproject_pixels,
    camera_center,
    distort_normalized,
    look_at,
    project_camera_points,
    project_points,
    undistort_normalized,
    world_to_camera,
)

K = np.array([[1509.4, 0.0, 639.5], [0.0, 1509.4, 511.5], [0.0, 0.0, 1.0]])
# Distortions of real 8 mm lenses lie well inside these bounds (|k1| ~ 0.1-0.3).
dist_st = st.tuples(st.floats(-0.3, 0.3), st.floats(-0.2, 0.2), st.floats(-0.005, 0.005),
                    st.floats(-0.005, 0.005), st.floats(-0.1, 0.1)).map(np.array)
xy_st = arrays(float, (32, 2), elements=st.floats(-0.45, 0.45))  # ±23° half field of view


@given(xy=xy_st, dist=dist_st)
def test_undistort_inverts_distort_to_1e6_px(xy, dist):
    xyd = distort_normalized(xy, dist)
    back = undistort_normalized(xyd, dist)
    # 1e-6 px in normalised units is 1e-6 / f_px.
    assert np.max(np.abs(back - xy)) * K[0, 0] < 1e-6


@given(xy=xy_st, dist=dist_st)
def test_project_backproject_round_trip(xy, dist):
    depth = 180.0
    pts = np.column_stack([xy * depth, np.full(len(xy), depth)])
    px = project_camera_points(pts, K, dist)
    rays = backproject_pixels(px, K, dist)
    # The ray through the projected pixel passes through the point (to 1e-9 of its depth).
    rebuilt = rays * (depth / rays[:, 2:3])
    assert np.allclose(rebuilt, pts, atol=1e-9 * depth)
    assert np.allclose(np.linalg.norm(rays, axis=1), 1.0)


def test_distortion_matches_opencv():
    cv2 = pytest.importorskip("cv2", reason="OpenCV is a declared dependency; skip only if absent")
    rng = np.random.default_rng(3)
    pts = rng.uniform([-60, -50, 150], [60, 50, 220], size=(200, 3))
    dist = np.array([-0.21, 0.11, 0.0012, -0.0008, -0.03])
    ours = project_camera_points(pts, K, dist)
    theirs, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, dist)
    # Both are double precision evaluations of the same polynomial.
    assert np.max(np.abs(ours - theirs[:, 0, :])) < 1e-9


def test_look_at_is_opencv_convention():
    R, t = look_at([0.0, -100.0, 0.0], [0.0, 0.0, 0.0], up=(0, 0, 1))
    assert np.allclose(R, [[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # x right, y down, z forward
    assert np.allclose(camera_center(R, t), [0, -100, 0])
    assert np.isclose(np.linalg.det(R), 1.0)


def test_projected_circle_is_an_ellipse():
    """A circle in a plane seen by a pinhole projects onto a conic: fit it and check residuals."""
    R, t = look_at([0.0, -137.9, 115.7], [0.0, 20.0, 0.0])
    theta = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    circle = np.column_stack([10 * np.cos(theta), 10 * np.sin(theta), np.zeros_like(theta)])
    uv = project_points(circle, K, None, R, t)
    u, v = uv[:, 0] / 1000, uv[:, 1] / 1000
    A = np.column_stack([u * u, u * v, v * v, u, v, np.ones_like(u)])
    _, s, vt = np.linalg.svd(A)
    conic = vt[-1]
    assert s[-1] / s[0] < 1e-12  # exactly a conic
    a, b, c = conic[0], conic[1] / 2, conic[2]
    assert a * c - b * b > 0  # an ellipse, not a hyperbola or parabola


def test_bad_shapes_raise_naming_argument():
    with pytest.raises(ValueError, match="points_cam_mm"):
        project_camera_points(np.zeros((3, 2)), K)
    with pytest.raises(ValueError, match="dist"):
        distort_normalized(np.zeros((1, 2)), [1, 2, 3])
    with pytest.raises(ValueError, match="R"):
        world_to_camera(np.zeros((1, 3)), np.eye(2), np.zeros(3))

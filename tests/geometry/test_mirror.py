import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from lts360.geometry import (
    camera_center,
    look_at,
    mirror_matrix,
    project_points,
    reflect_directions,
    reflect_points,
    reflect_pose,
    reflect_rays,
    transform_plane,
)

normal_st = arrays(float, 3, elements=st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 0.1)
offset_st = st.floats(-200, 200)
pts_st = arrays(float, (16, 3), elements=st.floats(-300, 300))


@given(n=normal_st, d=offset_st)
def test_mirror_matrix_is_an_involution_with_det_minus_one(n, d):
    T = mirror_matrix(n, d)
    assert np.allclose(T @ T, np.eye(4), atol=1e-9)
    assert np.isclose(np.linalg.det(T), -1.0)
    assert np.allclose(T[3], [0, 0, 0, 1])


@given(n=normal_st, d=offset_st, pts=pts_st)
def test_reflection_is_symmetric_about_the_plane(n, d, pts):
    nu = n / np.linalg.norm(n)
    img = reflect_points(pts, n, d)
    mid = (pts + img) / 2
    assert np.allclose(mid @ nu, d, atol=1e-9)  # midpoints lie on the plane
    seg = img - pts
    assert np.allclose(np.cross(seg, nu), 0, atol=1e-9)  # symmetry lines are along n
    T = mirror_matrix(n, d)
    assert np.allclose(img, pts @ T[:3, :3].T + T[:3, 3], atol=1e-9)


@given(n=normal_st, d=offset_st, pts=pts_st)
def test_reflected_rays_pass_through_reflected_points(n, d, pts):
    origins, targets = pts[:8], pts[8:]
    dirs = targets - origins
    o2, d2 = reflect_rays(origins, dirs, n, d)
    assert np.allclose(o2 + d2, reflect_points(targets, n, d), atol=1e-8)
    assert np.allclose(np.linalg.norm(reflect_directions(dirs, n), axis=1),
                       np.linalg.norm(dirs, axis=1))


def test_virtual_camera_pose_projects_like_mirrored_points():
    R, t = look_at([0.0, -137.9, 115.7], [0.0, 20.0, 0.0])
    K = np.array([[1500.0, 0, 640], [0, 1500.0, 512], [0, 0, 1]])
    n, d = np.array([np.cos(np.pi / 4), -np.sin(np.pi / 4), 0.0]), -42.4
    pts = np.random.default_rng(0).uniform(-15, 15, (50, 3))
    Rv, tv = reflect_pose(R, t, n, d)
    assert np.isclose(np.linalg.det(Rv), -1.0)
    a = project_points(pts, K, None, Rv, tv)
    b = project_points(pts, K, None, R, t, T_mirror=mirror_matrix(n, d))
    assert np.allclose(a, b)
    # The virtual centre is the mirror image of the real centre.
    assert np.allclose(camera_center(Rv, tv), reflect_points(camera_center(R, t), n, d)[0])


def test_two_mirrors_at_90_degrees_make_a_half_turn():
    s = np.sqrt(0.5)
    T_l = mirror_matrix([s, -s, 0], -s * 60)
    T_r = mirror_matrix([-s, -s, 0], -s * 60)
    # Product of reflections in planes at 90° = rotation by 180° about their common line.
    assert np.allclose(T_l @ T_r, T_r @ T_l)
    assert np.allclose((T_l @ T_r) @ [0, 0, 0, 1], [0, 120, 0, 1])
    assert np.isclose(np.linalg.det(T_l @ T_r), 1.0)


@given(n=normal_st, d=offset_st)
def test_transform_plane_keeps_points_on_it(n, d):
    nu = n / np.linalg.norm(n)
    p = nu * d + np.cross(nu, [0.3, 0.2, 0.9]) * 5.0
    R, t = look_at([10.0, -50.0, 30.0], [0.0, 0.0, 0.0])
    n2, d2 = transform_plane(n, d, R, t)
    assert np.isclose(n2 @ (R @ p + t), d2, atol=1e-9)


def test_degenerate_plane_rejected():
    with pytest.raises(ValueError, match="normal"):
        mirror_matrix([0, 0, 0], 1.0)

"""The one mirror-path test (lts360.geometry.mirror_path): closed forms and properties."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lts360.geometry.mirror import mirror_matrix
from lts360.geometry.mirror_path import PathMirror, path_valid, quad_extent, rectangle_extent


def _mirror_y(y0_mm=20.0, half_w=10.0, half_h=10.0):
    """A mirror in the plane y = y0 facing −y (towards the origin), a square about (0, y0, 0)."""
    n, d = np.array([0.0, -1.0, 0.0]), -y0_mm
    return PathMirror(n=n, d=d, T=mirror_matrix(n, d),
                      contains=rectangle_extent([0.0, y0_mm, 0.0], [1.0, 0.0, 0.0],
                                                [0.0, 0.0, 1.0], 2 * half_w, 2 * half_h))


def test_direct_path_blocked_only_by_the_object_behind():
    pts = np.array([[5.0, 0.0, 0.0], [-5.0, 0.0, 0.0]])
    ok, leave, arrive = path_valid(pts, np.array([100.0, 0.0, 0.0]), (), [], 5.0)
    # the point facing the target sees it; the one behind the cylinder does not
    assert ok.tolist() == [True, False]
    np.testing.assert_allclose(leave, [[1, 0, 0], [1, 0, 0]])
    np.testing.assert_allclose(arrive, leave)


def test_single_mirror_hit_point_and_reflected_direction():
    """Target at (0, 0, 10), point at (0, 0, −10), mirror y = 20: the path hits the mirror at
    its centre line (z = 0, y = 20) and arrives along the reflected direction."""
    m = _mirror_y()
    ok, leave, arrive = path_valid(np.array([[0.0, 0.0, -10.0]]), np.array([0.0, 0.0, 10.0]),
                                   (0,), [m], 0.0)
    assert ok[0]
    s = np.hypot(20.0, 10.0)
    np.testing.assert_allclose(leave[0], [0.0, 20.0 / s, 10.0 / s], atol=1e-12)
    np.testing.assert_allclose(arrive[0], [0.0, -20.0 / s, 10.0 / s], atol=1e-12)


def test_outside_the_mirror_or_on_its_back_is_not_a_path():
    m = _mirror_y(half_w=1.0)
    pts = np.array([[0.0, 0.0, 0.0], [6.0, 0.0, 0.0]])
    ok, _, _ = path_valid(pts, np.array([0.0, 0.0, 0.0]) + [0, 0, 1.0], (0,), [m], 0.0)
    assert ok.tolist() == [True, False]  # the second meets the plane at x = 6 > 1
    back = PathMirror(n=-m.n, d=-m.d, T=m.T, contains=m.contains)
    ok, _, _ = path_valid(pts[:1], np.array([0.0, 0.0, 1.0]), (0,), [back], 0.0)
    assert not ok[0]


def test_an_unknown_extent_reflects_everywhere_and_blocks_nothing():
    m = _mirror_y(half_w=1.0)
    free = PathMirror(n=m.n, d=m.d, T=m.T, contains=None)
    ok, _, _ = path_valid(np.array([[6.0, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), (0,),
                          [free], 0.0)
    assert ok[0]


def test_rectangle_and_quad_extents_agree():
    rect = rectangle_extent([0, 20, 0], [1, 0, 0], [0, 0, 1], 4.0, 2.0)
    corners = np.array([[-2, 20, -1], [2, 20, -1], [2, 20, 1], [-2, 20, 1]], float)
    quad = quad_extent(corners, np.array([0.0, -1.0, 0.0]))
    rng = np.random.default_rng(0)
    p = np.column_stack([rng.uniform(-3, 3, 500), np.full(500, 20.0), rng.uniform(-2, 2, 500)])
    # away from the edges the two tests must agree exactly (they differ only by 1e-9 slack)
    away = (np.abs(np.abs(p[:, 0]) - 2) > 1e-6) & (np.abs(np.abs(p[:, 2]) - 1) > 1e-6)
    assert np.array_equal(rect(p)[away], quad(p)[away])


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-8, 8), z=st.floats(-8, 8), tz=st.floats(5, 40))
def test_path_through_a_mirror_equals_the_straight_path_to_the_virtual_target(x, z, tz):
    """Length and direction: the folded path is as long as the straight line to the mirror
    image of the target, and its first leg points at that image."""
    m = _mirror_y(half_w=50.0, half_h=50.0)
    target = np.array([0.0, 0.0, tz])
    X = np.array([[x, 0.0, z]])
    ok, leave, arrive = path_valid(X, target, (0,), [m], 0.0)
    virtual = (m.T @ np.append(target, 1.0))[:3]
    np.testing.assert_allclose(leave[0], (virtual - X[0]) / np.linalg.norm(virtual - X[0]),
                               atol=1e-12)
    # the reflected leg keeps the angle with the normal: mirror law
    np.testing.assert_allclose(arrive[0] @ m.n, -(leave[0] @ m.n), atol=1e-12)
    assert ok[0]

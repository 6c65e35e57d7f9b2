import dataclasses

import numpy as np
import pytest

from lts360.recon.model import calibration_from_dict
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.views import get_views, make_views, view_windows
from lts360.scenes.coverage import coverage
from lts360.scenes.rig_io import load_rig
from lts360.simulator.io import rig_truth

R_GAUGE_MM = 9.99935  # the plug gauge of paper §4.5


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


@pytest.fixture(scope="module")
def cal(paper):
    return calibration_from_dict(rig_truth(paper, paper.camera.K, paper.camera.image_size))


def test_standard_grid_size_and_points():
    g = CylGrid.from_ranges((8.0, 12.0))
    assert g.shape == (3600, 801)  # 0.1° over a full turn (half-open), 5 µm with both ends
    assert g.is_full_turn and g.r_step_mm == pytest.approx(0.005)
    assert g.theta_rad[0] == pytest.approx(-np.pi) and g.theta_rad[-1] < np.pi
    pts = g.points_meas([0, 900])
    assert pts.shape == (2, 801, 3) and np.all(pts[..., 2] == 0)
    assert np.allclose(np.hypot(pts[..., 0], pts[..., 1]), g.r_mm)
    part = CylGrid.from_ranges((9.0, 11.0), theta_range_deg=(-30.0, 30.0), theta_step_deg=0.5,
                               r_step_mm=0.01)
    assert part.shape == (121, 201) and not part.is_full_turn  # partial θ range: both ends


@pytest.mark.parametrize("kwargs, field", [
    (dict(r_range_mm=(12.0, 8.0)), "r_range_mm"),
    (dict(r_range_mm=(8.0, 12.0), theta_step_deg=0.0), "theta_step_deg"),
    (dict(r_range_mm=(8.0, 12.0), r_step_mm=-1.0), "r_step_mm"),
    (dict(r_range_mm=(8.0, 12.0), theta_range_deg=(0.0, 400.0)), "theta_range_deg"),
])
def test_grid_validation(kwargs, field):
    with pytest.raises(ValueError, match=field):
        CylGrid.from_ranges(**kwargs)


def test_windows_agree_with_the_scene_coverage(paper, cal):
    """Windows derived from the calibration equal the rig-based visibility of scenes.coverage."""
    cov = coverage(paper, R_GAUGE_MM, theta_step_deg=0.1, max_bounces=2)
    names = ("direct", "left", "right", "left-right", "right-left")
    win = view_windows(cal, (R_GAUGE_MM, R_GAUGE_MM), cov.theta_rad, 80.0, views=names)
    for name in names:
        assert np.array_equal(win[name], cov.seen[name]), name
    assert not win["left-right"].any()  # the corner image lies behind a long object


def test_windows_over_a_radius_range_are_the_intersection(cal):
    theta = np.radians(np.arange(-180.0, 180.0, 0.5))
    wide = view_windows(cal, (8.0, 12.0), theta)
    for r in (8.0, 10.0, 12.0):
        single = view_windows(cal, (r, r), theta)
        for name in wide:
            assert np.all(single[name][wide[name]]), (name, r)
    # Together the three views still see the whole section, with overlaps at the sides.
    union = np.logical_or.reduce(list(wide.values()))
    assert union.all()
    assert (wide["direct"] & wide["left"]).any() and (wide["direct"] & wide["right"]).any()


def test_unbounded_mirrors_widen_the_windows(cal):
    bare = dataclasses.replace(cal, mirrors=tuple(dataclasses.replace(m, corners_mm=None)
                                                  for m in cal.mirrors))
    theta = np.radians(np.arange(-180.0, 180.0, 0.5))
    a = view_windows(cal, (8.0, 12.0), theta)
    b = view_windows(bare, (8.0, 12.0), theta)
    for name in a:
        assert np.all(b[name][a[name]])


def test_view_matrices(cal):
    views = make_views(cal, double_reflections=True)
    assert list(views) == ["direct", "left", "right", "left-right", "right-left"]
    assert np.array_equal(views["direct"].T_cam, np.eye(4))
    T_l, T_r = views["left"].T_cam, views["right"].T_cam
    assert np.allclose(views["left-right"].T_cam, T_r @ T_l)  # object -> left -> right -> camera
    assert np.allclose(views["left-right"].T_cam, views["right-left"].T_cam)  # β = 90°
    assert np.allclose(views["left"].virtual_camera_cam_mm, T_l[:3, 3])
    with pytest.raises(ValueError, match="views"):
        get_views(cal, ("left-left",))
    with pytest.raises(ValueError, match="views"):
        get_views(cal, ("top",))

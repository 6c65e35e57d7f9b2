import numpy as np
import pytest

from lts360.scenes.coverage import circular_windows, coverage, mirror_sequences, path_valid
from lts360.scenes.rig_io import load_rig


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


@pytest.fixture(scope="module")
def cov20(paper):
    return coverage(paper, 10.0)


def test_paper_rig_sees_360_degrees_of_a_20mm_section(cov20):
    assert cov20.coverage_deg == pytest.approx(360.0, abs=1e-6)
    # Neighbouring views overlap: direct/left, direct/right at the sides, left/right at the back.
    assert cov20.overlap_deg("direct", "left") > 20.0
    assert cov20.overlap_deg("direct", "right") > 20.0
    assert cov20.overlap_deg("left", "right") > 5.0


def test_views_are_where_geometry_puts_them(cov20):
    # Direct view: the front (θ = -90°); left mirror: the -X side; right mirror: the +X side.
    th = np.degrees(cov20.theta_rad)
    for view, centre in (("direct", -90.0), ("left", 180.0), ("right", 0.0)):
        assert cov20.measured[view][np.argmin(np.abs(((th - centre) + 180) % 360 - 180))]
    # Symmetry of the rig about the YZ plane: left(θ) == right(180° - θ).
    n = len(th)
    mirror_idx = (np.round((np.radians(180.0) - cov20.theta_rad + np.pi) /
                           (2 * np.pi / n)).astype(int)) % n
    assert np.array_equal(cov20.measured["left"], cov20.measured["right"][mirror_idx])


def test_all_three_views_of_a_28mm_object_fit_the_frame_with_margin(paper):
    cov = coverage(paper, 14.0)
    assert cov.coverage_deg == pytest.approx(360.0, abs=1e-6)
    assert cov.image_margin_px(paper.camera.image_size) > 50.0


def test_a_face_no_laser_reaches_is_not_measured(paper):
    # With the mirrors removed only the front is lit and seen.
    import dataclasses
    bare = dataclasses.replace(paper, mirrors=())
    cov = coverage(bare, 10.0)
    assert set(cov.views()) == {"direct"}
    assert 120.0 < cov.coverage_deg < 180.0
    assert not cov.measured["direct"][np.argmin(np.abs(cov.theta_rad - np.pi / 2))]


def test_double_reflections_are_hidden_by_a_long_object(paper, cov20):
    # At 90° the corner image lies behind the object itself (seen from the camera).
    assert cov20.measured_deg("left-right") == 0.0 and cov20.measured_deg("right-left") == 0.0


def test_path_through_mirror_obeys_the_law_of_reflection(paper):
    left = paper.mirror("left")
    pts = np.array([[-10.0, 0.0, 0.0]])
    ok, leave, arrive = path_valid(pts, paper.camera.center_mm, (0,), paper.mirrors, 10.0)
    assert ok[0]
    # Incoming and outgoing directions are mirror images of each other.
    r = leave[0] - 2 * (leave[0] @ left.normal) * left.normal
    assert np.allclose(r, arrive[0])


def test_sequences_and_windows():
    assert mirror_sequences((0, 1), 2) == [(), (0,), (1,), (0, 1), (1, 0)]
    th = np.radians(np.arange(-180, 180, 1.0))
    mask = (np.degrees(th) > 170) | (np.degrees(th) < -170)
    assert circular_windows(th, mask) == [(171.0, -171.0)]

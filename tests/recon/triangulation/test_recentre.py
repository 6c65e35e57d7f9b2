"""A section far off the axis is measured about its own centre: the calibration's origin moved
there (the projections unchanged), the centre found from the first-pass profile, and a
rendered Ø6 mm gauge whose section does not hold the axis measured whole."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lts360.recon.model import calibration_from_frame_truth, shift_origin
from lts360.recon.triangulation.band import Profile
from lts360.recon.triangulation.measure import RECENTRE_MAX_INCIDENCE_DEG, recentre_point
from lts360.recon.triangulation.views import get_views, project_meas_points


@pytest.fixture(scope="module")
def cal():
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth

    rig = load_rig("paper")
    return calibration_from_frame_truth(rig_truth(rig, rig.camera.K, rig.camera.image_size))


@settings(max_examples=20, deadline=None)
@given(cx=st.floats(-8, 8), cy=st.floats(-8, 8))
def test_a_shifted_origin_projects_every_point_where_it_was(cal, cx, cy):
    """X in the old frame is X − c in the new one; each view projects both to the same pixel."""
    moved = shift_origin(cal, (cx, cy))
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-12, 12, (50, 2)), np.zeros(50)])
    for view in get_views(cal, ("direct",) + cal.mirror_names + ("left-right",)):
        (v2,) = get_views(moved, [view.name])
        a = project_meas_points(X, cal, view)
        b = project_meas_points(X - [cx, cy, 0.0], moved, v2)
        ok = np.all(np.isfinite(a), axis=1)
        assert np.allclose(a[ok], b[ok], atol=1e-8)
    assert moved.view_offsets_mm.keys() == cal.view_offsets_mm.keys()


def _circle_profile(c, r, step_deg=1.0):
    """The first-pass profile (about the axis) of a circle that holds the axis."""
    th = np.radians(np.arange(-180, 180, step_deg))
    u = np.column_stack([np.cos(th), np.sin(th)])
    cu = u @ np.asarray(c, float)
    rr = cu + np.sqrt(cu ** 2 - np.dot(c, c) + r ** 2)
    return Profile(th, rr, np.ones(th.size, bool), True)


def test_recentre_point_keeps_the_axis_for_a_section_near_it():
    e_max = 10.0 * math.sin(math.radians(RECENTRE_MAX_INCIDENCE_DEG))  # 3.42 mm for R = 10
    assert recentre_point(_circle_profile((0.0, 0.0), 10.0)) == (0.0, 0.0)
    assert recentre_point(_circle_profile((0.95 * e_max, 0.0), 10.0)) == (0.0, 0.0)
    cx, cy = recentre_point(_circle_profile((1.05 * e_max * 0.6, -1.05 * e_max * 0.8), 10.0))
    assert (cx, cy) == (round(1.05 * e_max * 0.6, 2), round(-1.05 * e_max * 0.8, 2))


def test_recentre_point_ignores_a_profile_with_too_few_measured_angles():
    p = _circle_profile((5.0, 0.0), 6.0)
    m = np.zeros(p.theta_rad.size, bool)
    m[:5] = True
    assert recentre_point(Profile(p.theta_rad, p.r_mm, m, True)) == (0.0, 0.0)


def test_a_gauge_whose_section_misses_the_axis_is_measured_whole():
    """Ø6 mm, 3.5 mm off the axis (the axis outside the section): about the axis most rays
    miss it or graze it; about its own centre every view measures it."""
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3")
    from pathlib import Path

    from lts360.experiments.score import score_cloud
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    if mi.variant() is None:
        mi.set_variant("llvm_ad_mono")
    obj = build_object("plug-gauge:d=6,x=2.5,y=-2.5")
    frame = simulate_frame(load_rig("paper"), obj, spp=4, seed=2, thin_lens=False, scale=0.5)
    cal = calibration_from_frame_truth(frame.truth)
    cloud, grid, log = measure_sections_following([Section(Path("-"), 0.0, image=frame.image)],
                                                  cal, theta_step_deg=0.5, reject=True)
    # the coarse pass's circle (1° × 50 µm about the axis) is near the centre; any point well
    # inside the section serves
    assert np.hypot(*np.subtract(log.centre_mm[0], (2.5, -2.5))) < 0.3, log.centre_mm
    assert "about the section's own centre" in log.describe()
    ok = cloud.valid
    # θ and r of the rows are about the axis again, as the cloud's points
    assert np.allclose(cloud.radius_mm[ok], np.hypot(*cloud.points_mm[ok, :2].T))
    assert np.allclose(np.cos(cloud.theta_rad[ok]) * cloud.radius_mm[ok], cloud.points_mm[ok, 0])
    m = score_cloud(cloud, obj, use_mesh=False)
    assert m["coverage_deg"] >= 0.97 * 360.0, m["coverage_deg"]
    assert all(v["n"] > 150 for v in m["views"].values()) and len(m["views"]) == 3
    # The line-centre bias of Ø6 mm at this sampling (measured 2026-12-04: −17.3 µm; at full
    # size and 64 spp −12 µm, STUDIES.md); ±7 µm is room for the seeded 4-spp half-size
    # render, not for a failed re-centring (STUDIES.md: points over −28…+20 µm about the axis).
    assert -0.025 < m["radius_bias_mm"] < -0.010, m["radius_bias_mm"]

"""The radial band found from the image: the first-pass profile, the grid that follows it, and
sections of other sizes and off the axis measured with no radius given (analytic images made
by ``test_inverse.synthesize_section``; rendered gauges in the slow tier)."""

from __future__ import annotations

import numpy as np
import pytest
from test_inverse import synthesize_section

from lts360.recon.calibration.model import calibration_from_dict
from lts360.recon.triangulation.band import (BandSearch, follow_profile, measurable_radii,
                                             profile_windows)
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse
from lts360.recon.triangulation.measure import make_runner
from lts360.recon.triangulation.peaks import Quality
from lts360.scenes.rig_io import load_rig
from lts360.simulator.io import rig_truth


def _circle_r(theta, centre, radius):
    """Radius along the ray θ of a circle of ``radius`` about ``centre`` (the far crossing)."""
    u = np.stack([np.cos(theta), np.sin(theta)], -1)
    cu = u @ np.asarray(centre, float)
    cx = u[:, 0] * centre[1] - u[:, 1] * centre[0]
    return cu + np.sqrt(radius**2 - cx**2)


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


@pytest.fixture(scope="module")
def cal(paper):
    return calibration_from_dict(rig_truth(paper, paper.camera.K, paper.camera.image_size))


@pytest.fixture(scope="module")
def search(cal):
    return BandSearch(cal, make_runner(cal))


def test_follow_profile_recovers_an_off_axis_circle_despite_wrong_picks():
    rng = np.random.default_rng(3)
    th = np.radians(np.arange(-180.0, 180.0, 1.0))
    truth = _circle_r(th, (2.5, -1.0), 8.0)
    cand = np.stack([truth + rng.normal(0, 0.01, th.size) for _ in range(3)])
    cand[:, rng.random(th.size) < 0.4] = np.nan            # each view sees part of the turn
    wrong = rng.random(cand.shape) < 0.1                   # 10 % picks on another stripe
    cand[wrong] = rng.uniform(1.0, 40.0, wrong.sum())
    cand[:, 100:104] = np.nan                              # a gap: interpolated
    p = follow_profile(th, cand, periodic=True)
    # The band's centre need only be good to a fraction of what the ±1 mm band leaves beside
    # the line (±0.4 mm): the ±3° running median of sparse, noisy picks is within 0.15 mm.
    assert p is not None and np.max(np.abs(p.r_mm - truth)) < 0.15
    assert np.median(np.abs(p.r_mm - truth)) < 0.02
    fine = np.radians(np.arange(-180.0, 180.0, 0.1))
    assert np.max(np.abs(p.at(fine) - _circle_r(fine, (2.5, -1.0), 8.0))) < 0.15
    # Normals of the circle: from its centre through the surface point.
    pts = p.r_mm[:, None] * np.stack([np.cos(th), np.sin(th)], -1) - (2.5, -1.0)
    psi = np.arctan2(pts[:, 1], pts[:, 0])
    err = np.angle(np.exp(1j * (p.normal_angle_at(th) - psi)))
    assert np.median(np.abs(err)) < np.radians(2.0)
    assert follow_profile(th, np.full((3, th.size), np.nan), periodic=True) is None


def test_grid_following_a_profile():
    th = np.radians(np.arange(-180.0, 180.0, 2.0))
    rc = _circle_r(th, (3.0, 0.0), 10.0)
    g = CylGrid.following(th, rc, 1.0, r_step_mm=0.01)
    assert g.n_r == 201 and g.follows_profile
    r = g.radii_mm()
    assert np.allclose(r[:, 100], rc) and np.allclose(r[:, -1] - r[:, 0], 2.0)
    assert g.r_range_mm == pytest.approx((rc.min() - 1.0, rc.max() + 1.0))
    pts = g.points_meas()
    assert np.allclose(np.hypot(pts[..., 0], pts[..., 1]), r)
    assert not CylGrid.from_ranges((8.0, 12.0)).follows_profile
    with pytest.raises(ValueError, match="r_shift_mm"):
        CylGrid(theta_rad=th, r_mm=np.linspace(1, 2, 5), r_shift_mm=np.zeros(3))
    with pytest.raises(ValueError, match="stay > 0"):
        CylGrid.following(th, np.full(th.size, 0.5), 1.0)


def test_measurable_radii_stop_short_of_the_mirrors(cal):
    r0, r1 = measurable_radii(cal)
    # The paper rig's mirrors: 60 mm corner distance at 90°, planes 42.4 mm from the axis.
    assert r0 == pytest.approx(0.1) and r1 == pytest.approx(0.95 * 60.0 / np.sqrt(2), rel=1e-6)


@pytest.mark.parametrize("centre,radius", [((0.0, 0.0), 9.99935), ((2.5, 1.0), 10.0),
                                           ((0.0, 0.0), 4.0), ((-1.0, 0.0), 16.0)])
def test_sections_of_other_sizes_and_off_the_axis_without_a_radius(paper, cal, search, centre,
                                                                    radius):
    img, _ = synthesize_section(paper, radius, centre_xy_mm=centre, step_deg=0.02)
    profile = search.profile(img)
    assert profile is not None
    truth_c = _circle_r(profile.theta_rad, centre, radius)
    assert np.max(np.abs(profile.r_mm - truth_c)) < 0.1
    grid = search.fine_grid(profile, theta_step_deg=0.5, r_step_mm=0.005)
    plan = plan_inverse(cal, grid, precompute=False, windows=profile_windows(cal, grid, profile))
    res = inverse_triangulate(img, cal, grid, plan=plan)
    truth = _circle_r(grid.theta_rad, centre, radius)
    covered = res.n_views > 0
    assert covered.mean() > 0.97, covered.mean()
    for name, v in res.views.items():
        err = v.r_mm[v.valid] - truth[v.valid]
        # The synthetic line is symmetric about the projected curve: the centroid is exact to
        # its sub-pixel error (the paper rig: ~1 µm per 5 µm sample, a few µm at grazing views).
        assert np.median(np.abs(err)) < 0.003 and np.max(np.abs(err)) < 0.03, name
        assert not np.any(v.quality == Quality.TRUNCATED), name


def test_a_fixed_band_that_cuts_the_line_flags_it_truncated(paper, cal):
    """The gauge's line (r ≈ 10 mm) against the outer end of a band 8–10.02 mm: every view's
    profile is TRUNCATED, none is a valid point (the centroid of half a line would read ~0.1 mm
    small)."""
    img, _ = synthesize_section(paper, 10.0, step_deg=0.05)
    grid = CylGrid.from_ranges((8.0, 10.02), theta_step_deg=1.0)
    res = inverse_triangulate(img, cal, grid)
    for name, v in res.views.items():
        inside = v.window & (v.quality != Quality.NO_PEAK)
        assert inside.sum() > 50, name
        assert np.mean(v.quality[inside] == Quality.TRUNCATED) > 0.95, name
        assert not np.any(v.valid & (v.quality == Quality.TRUNCATED))


def test_continuity_flags_a_point_off_its_view_profile():
    from lts360.recon.triangulation.reject import continuity_outliers

    rng = np.random.default_rng(1)
    th = np.radians(np.arange(-180.0, 180.0, 0.1))
    r = _circle_r(th, (1.0, 0.5), 10.0) + rng.normal(0, 0.003, th.size)
    r[1000:1900] = np.nan                                   # the view sees part of the turn
    r[[200, 201, 2500]] += (0.2, -0.15, 0.3)                # a flank's stripe: 150–300 µm off
    out = continuity_outliers(r, half_window=20)
    assert np.flatnonzero(out).tolist() == [200, 201, 2500]
    assert not continuity_outliers(np.full(th.size, np.nan), half_window=20).any()

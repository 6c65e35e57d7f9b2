"""The radial band found from the image: the first-pass profile, the grid that follows it, and
sections of other sizes and off the axis measured with no radius given (analytic images made
by ``test_inverse.synthesize_section``; rendered gauges in the slow tier)."""

from __future__ import annotations

import numpy as np
import pytest
from test_inverse import synthesize_section

from lts360.recon.model import calibration_from_dict
from lts360.recon.triangulation.band import (
    BandSearch,
    follow_profile,
    measurable_radii,
    profile_windows,
)
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


def test_a_pit_of_picks_its_view_cannot_see_is_dropped(search):
    # The aluminium pipe's short scan with interreflections: four adjacent picks of the left
    # view 5.7 mm from the axis (light scattered inside the Ø22 mm pipe's stripe), with the
    # pipe's own candidates sparse around them, pulled the profile into a 4.5 mm pit; the
    # left camera cannot see the bottom of a pit that narrow, so the picks are dropped.
    th = search.grid.theta_rad
    deg = np.round(np.degrees(th)).astype(int)
    cand = np.full((len(search.views), th.size), np.nan)
    cand[0] = 11.0
    dim = (deg >= 80) & (deg <= 110)
    cand[:, dim] = np.nan
    left = search.views.index("left")
    for d, r in ((85, 11.0), (89, 11.05), (99, 10.99), (104, 11.07), (88, 3.8), (90, 5.65),
                 (91, 5.67), (92, 5.69), (93, 5.71), (94, 2.9), (95, 2.91), (96, 2.93)):
        cand[left, deg == d] = r
    pit = follow_profile(th, cand, periodic=True)
    assert pit.r_mm[deg == 92][0] < 7.0  # the picks outvote the pipe's few candidates
    drop = search._hidden_pits(pit, cand)
    assert drop[left, (deg >= 90) & (deg <= 93)].all()
    assert not drop[:, ~dim].any()  # nothing of the round pipe itself
    p = follow_profile(th, np.where(drop, np.nan, cand), periodic=True)
    assert np.max(np.abs(p.r_mm - 11.0)) < 0.1


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


def test_self_occlusion_of_a_circle_is_the_far_half_closed_form():
    """A ray along +x from a point of a circle re-enters it exactly when the point lies on the
    circle's −x half; an outward ray never does."""
    from lts360.recon.triangulation.band import Profile, self_occluded

    th = np.radians(np.arange(-180.0, 180.0, 0.5))
    centre = (1.5, -2.0)
    p = Profile(th, _circle_r(th, centre, 8.0), np.ones(th.size, bool), True)
    r = p.at(th)
    local = np.arctan2(r * np.sin(th) - centre[1], r * np.cos(th) - centre[0])
    along_x = np.tile([1.0, 0.0], (th.size, 1))
    hidden = self_occluded(p, th, along_x)
    # off the tangent points, where the ray dips less than 0.04 mm into the circle (the
    # march's tolerance is 0.02 mm) or rises less than 0.066 mm above it 0.5 mm on (it may
    # graze within 0.05 mm there)
    clear = np.abs(np.cos(local)) > 0.1
    assert np.array_equal(hidden[clear], (np.cos(local) < 0)[clear])
    outward = np.column_stack([np.cos(local), np.sin(local)])
    assert not self_occluded(p, th, outward).any()


def test_a_valley_s_far_flank_stays_in_the_window_and_a_strand_behind_another_is_hidden(
        cal, search):
    """Cable-like profile: six Ø7 mm strands about a 7 mm circle.  The window of the profile's
    circle keeps the flanks that turn away (their fading is what FADING reads); the θ whose
    path to a camera crosses the next strand are hidden.  A round section's windows are those
    of its own normal and nothing of it is hidden."""
    from lts360.recon.triangulation.band import Profile, hidden_rows
    from lts360.recon.triangulation.views import view_windows

    th = np.radians(np.arange(-180.0, 180.0, 1.0))

    def strands(t):
        c = [(7.0 * np.cos(a), 7.0 * np.sin(a)) for a in np.radians(np.arange(0, 360, 60))]
        with np.errstate(invalid="ignore"):
            return np.nanmax([_circle_r(t, ci, 3.5) for ci in c], axis=0)

    for r_of in (lambda t: np.full(t.size, 10.0), strands):
        prof = Profile(th, r_of(th), np.ones(th.size, bool), True)
        grid = search.fine_grid(prof, theta_step_deg=0.5, r_step_mm=0.01)
        rng = (grid.radii_mm()[:, 0], grid.radii_mm()[:, -1])
        names = ("direct", "left", "right")
        own = view_windows(cal, rng, grid.theta_rad, views=names,
                           normal_angle_rad=prof.normal_angle_at(grid.theta_rad))
        got = profile_windows(cal, grid, prof)
        hidden = hidden_rows(cal, grid, prof, got)
        assert all(np.all(got[n] >= own[n]) and not np.any(hidden[n] & ~got[n]) for n in names)
        added = sum(int(np.sum(got[n] & ~own[n])) for n in names)
        n_hidden = sum(int(hidden[n].sum()) for n in names)
        if np.ptp(prof.r_mm) == 0:
            assert added == 0 and n_hidden == 0
        else:
            assert added > 20 and n_hidden > 20, (added, n_hidden)


def test_hidden_rows_are_flagged_and_count_as_faded():
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import InverseResult, ViewResult
    from lts360.recon.triangulation.reject import fading_points, mark_hidden, rejection_counts

    grid = CylGrid.from_ranges((9.0, 11.0), theta_step_deg=0.5, r_step_mm=0.01)
    n = grid.n_theta
    win = np.zeros(n, bool)
    win[100:400] = True
    r = np.where(win, 10.0, np.nan)
    v = ViewResult("direct", grid.theta_rad, r, r.copy(),
                   np.where(win, Quality.FOUND, Quality.OUTSIDE_WINDOW).astype(np.uint8),
                   np.where(win, 100.0, np.nan), win, np.zeros(2))
    v.r_mm[260] = np.nan  # a row without a peak keeps its reason
    v.quality[260] = Quality.NO_PEAK
    res = InverseResult(grid, {"direct": v}, "centroid", 10.0, None, False)
    hid = np.zeros(n, bool)
    hid[250:280] = True  # 15° hidden: 2.6 mm of arc
    out = mark_hidden(res, {"direct": hid})
    w = out.views["direct"]
    assert np.all(np.isnan(w.r_mm[250:280])) and w.quality[260] == Quality.NO_PEAK
    assert np.sum(w.quality[250:280] == Quality.HIDDEN) == 29
    assert rejection_counts(w.quality)["hidden"] == 29
    assert np.isfinite(w.r_mm[249]) and np.isfinite(w.r_mm[280])
    fade = fading_points(w.r_mm, w.window, grid.theta_step_rad)
    # 0.5 mm of arc either side of the hidden stretch: 6 samples of 0.087 mm (r = 10 mm, 0.5°)
    assert fade[244:250].all() and fade[280:286].all() and not fade[200:240].any()

"""Truth-free rejection (lts360.recon.triangulation.reject) on synthetic profiles made for each
criterion: a line that fades inside its window, a notch, a round section off the axis."""

import numpy as np
import pytest

from lts360.recon.triangulation.reject import (
    fading_points,
    notch_depth,
    rejection_counts,
    section_profile,
)

TH = np.radians(np.arange(-180.0, 180.0, 0.1))
STEP = np.radians(0.1)


def _circle(r, x0=0.0, y0=0.0):
    """Radius along each θ ray of a circle of radius r centred at (x0, y0)."""
    c, s = np.cos(TH), np.sin(TH)
    b = x0 * c + y0 * s
    return b + np.sqrt(b * b - (x0 * x0 + y0 * y0 - r * r))


def test_fading_points_flank_a_faded_stretch_inside_the_window():
    r = np.full(TH.size, 10.0)
    window = np.zeros(TH.size, bool)
    window[1000:2000] = True
    r[~window] = np.nan
    r[1500:1530] = np.nan  # 3° faded (0.52 mm at r = 10 mm)
    out = fading_points(r, window, STEP, margin_mm=0.5, gap_mm=0.3)
    k = int(round(0.5 / (10.0 * STEP)))
    assert out[1500 - k:1500].all() and out[1530:1530 + k].all()
    assert not out[:1500 - k - 1].any() and not out[1530 + k + 1:].any()
    # The window's own ends are no fading: a round section's lines end there.
    assert not out[1000:1010].any() and not out[1990:2000].any()


def test_a_short_dropout_is_not_a_faded_stretch():
    r = np.full(TH.size, 10.0)
    window = np.ones(TH.size, bool)
    r[700:705] = np.nan  # 0.09 mm: a speckle dropout
    assert not fading_points(r, window, STEP, gap_mm=0.3).any()


def test_notch_depth_finds_a_valley_and_no_round_section():
    # A round section off the axis lies above every chord (a circle by L²/2R).
    for x0, y0, r0 in ((0.0, 0.0, 10.0), (3.0, 0.0, 10.0), (2.0, -2.0, 5.0)):
        prof = section_profile(TH, [_circle(r0, x0, y0)])
        assert np.nanmax(notch_depth(TH, prof)) < 0
    # A V-shaped valley 0.3 mm deep and 10° wide at θ = 30° on a 3 mm strand.
    r = np.full(TH.size, 3.0) - 0.3 * np.clip(1 - np.abs(np.degrees(TH) - 30) / 5.0, 0, None)
    d = notch_depth(TH, section_profile(TH, [r]))
    at = np.abs(np.degrees(TH) - 30) < 2
    assert np.all(d[at] > 0.08)
    assert np.all(d[np.abs(np.degrees(TH) - 30) > 40] < 0.01)


def test_section_profile_is_the_median_of_the_views():
    a = np.full(TH.size, 10.0)
    b = np.full(TH.size, 10.0)
    b[100:110] = 10.5  # one view's wrong pick where two views see
    c = np.full(TH.size, 10.0)
    prof = section_profile(TH, [a, b, c])
    assert np.allclose(prof, 10.0)
    assert np.isnan(section_profile(TH, [np.full(TH.size, np.nan)])).all()


def test_rejection_counts_name_every_code():
    from lts360.recon.triangulation.peaks import Quality

    q = np.array([Quality.NOTCH, Quality.NOTCH, Quality.FADING, Quality.FOUND,
                  Quality.DISCONTINUOUS, Quality.TRUNCATED, Quality.HIDDEN], np.uint8)
    assert rejection_counts(q) == {"continuity": 1, "fading": 1, "notch": 2, "hidden": 1,
                                   "flank": 0, "neighbours": 0, "truncated": 1,
                                   "saturated_plateau": 0}
    assert rejection_counts(np.array([Quality.FLANK] * 3, np.uint8))["flank"] == 3
    # the codes are stored in files: appended, never renumbered
    assert (Quality.HIDDEN, Quality.FLANK, Quality.NEIGHBOURS) == (10, 11, 12)


def test_bad_arguments():
    with pytest.raises(ValueError):
        fading_points(np.ones(3), np.ones(4, bool), STEP)
    with pytest.raises(ValueError):
        fading_points(np.ones(3), np.ones(3, bool), 0.0)


def test_the_cloud_header_carries_the_rejections(tmp_path):
    from lts360.recon.triangulation.cloud import (
        Cloud,
        read_cloud,
        read_cloud_rejections,
        write_cloud,
    )
    from lts360.recon.triangulation.peaks import Quality

    n = 4
    pts = np.array([[1.0, 0, 0], [np.nan] * 3, [np.nan] * 3, [0, 1.0, 0]])
    q = np.array([Quality.FOUND, Quality.NOTCH, Quality.FADING, Quality.FOUND], np.uint8)
    cloud = Cloud(pts, np.zeros(n), np.ones(n), np.zeros(n, np.uint8), q,
                  np.zeros(n, np.int32), np.ones(n, np.float32))
    write_cloud(tmp_path / "c.ply", cloud, comments=["measured by a test"])
    assert read_cloud_rejections(tmp_path / "c.ply")["notch"] == 1
    assert read_cloud_rejections(tmp_path / "c.ply")["fading"] == 1
    assert len(read_cloud(tmp_path / "c.ply")) == n
    with pytest.raises(ValueError):
        write_cloud(tmp_path / "d.ply", cloud, comments=["two\nlines"])


def test_reject_spurious_flags_a_faded_flank_and_keeps_a_round_section():
    import dataclasses

    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import InverseResult, ViewResult
    from lts360.recon.triangulation.peaks import Quality
    from lts360.recon.triangulation.reject import reject_spurious

    grid = CylGrid.from_ranges((9.0, 11.0), theta_step_deg=0.1, r_step_mm=0.005)
    th = grid.theta_rad
    r = _circle(10.0, 1.0, 0.5)
    window = (th > -1.0) & (th < 1.5)
    q = np.where(window, Quality.FOUND, Quality.OUTSIDE_WINDOW).astype(np.uint8)
    v = ViewResult("direct", th, np.where(window, r, np.nan), r, q, np.ones(th.size), window,
                   np.zeros(2))
    res = InverseResult(grid, {"direct": v}, "centroid", 25.5, 255.0, False)
    out = reject_spurious(res)
    assert out.views["direct"].valid.sum() == window.sum()  # round: nothing rejected
    faded = window & (np.abs(th - 0.2) < np.radians(2))
    rr = np.where(faded, np.nan, v.r_mm)
    qq = np.where(faded, Quality.NO_PEAK, q).astype(np.uint8)
    out = reject_spurious(dataclasses.replace(res, views={
        "direct": dataclasses.replace(v, r_mm=rr, quality=qq)}))
    assert int(np.sum(out.views["direct"].quality == Quality.FADING)) > 0
    assert not np.any(out.views["direct"].valid & (out.views["direct"].quality != Quality.FOUND))


def _faded(r, at_deg, width_deg):
    """``r`` with a stretch of ``width_deg`` about ``at_deg`` faded (NaN) and its gap mask."""
    gap = np.abs(np.degrees(TH) - at_deg) < width_deg / 2
    return np.where(gap, np.nan, r), gap


def test_a_round_surface_that_only_turns_dim_keeps_its_flanks():
    """A faded stretch on a circle (a specular pipe away from its glint) has its flanks above
    the chord by the circle's own sagitta: with an axially straight surface it is kept; with
    the surface turning away along the axis (a shoulder, slope 1), or the slope unknown (one
    frame), the flanks are FADING as before."""
    from lts360.recon.triangulation.reject import convex_gaps

    r0 = _circle(11.0, 0.5, -0.3)
    r, gap = _faded(r0, 40.0, 3.0)
    window = np.ones(TH.size, bool)
    prof = section_profile(TH, [r])
    flat = np.full(TH.size, 0.05)
    kept = fading_points(r, window, STEP, profile_mm=prof, theta_rad=TH, axial_slope=flat)
    assert not kept.any()
    shoulder = fading_points(r, window, STEP, profile_mm=prof, theta_rad=TH,
                             axial_slope=np.full(TH.size, 1.0))
    one_frame = fading_points(r, window, STEP, profile_mm=prof, theta_rad=TH)
    plain = fading_points(r, window, STEP)
    assert plain.sum() == 2 * 26 and np.array_equal(shoulder, plain)  # 0.5 mm each side
    assert np.array_equal(one_frame, plain)
    m = int(round(0.5 / (11.0 * STEP)))
    assert convex_gaps(gap, prof, TH, margin=m, reach=2 * m, axial_slope=flat)[gap].all()


def test_a_valley_between_strands_is_never_convex():
    """Two 1.5 mm strands' crowns with the valley between faded: the flanks dip below the
    chord joining the crowns, so the stretch stays FADING whatever the axial slope."""
    from lts360.recon.triangulation.reject import convex_gaps

    # a scalloped section: 6 strands of radius 1.5 mm on a 4.5 mm pitch circle (Ø 9 mm)
    centres = np.radians(np.arange(0, 360, 60))
    x, y = np.cos(TH), np.sin(TH)
    r = np.full(TH.size, np.nan)
    for c in centres:
        b = 3.0 * (x * np.cos(c) + y * np.sin(c))
        disc = b * b - (9.0 - 1.5 ** 2)
        r = np.fmax(r, np.where(disc >= 0, b + np.sqrt(np.maximum(disc, 0)), np.nan))
    rv, gap = _faded(r, 30.0, 6.0)  # the valley at 30° between strands at 0° and 60°
    prof = section_profile(TH, [rv])
    m = int(round(0.5 / (np.nanmedian(rv) * STEP)))
    reach = int(round(1.0 / (np.nanmedian(rv) * STEP)))
    assert not convex_gaps(gap, prof, TH, margin=m, reach=reach,
                           axial_slope=np.zeros(TH.size)).any()
    assert fading_points(rv, np.ones(TH.size, bool), STEP, profile_mm=prof, theta_rad=TH,
                         axial_slope=np.zeros(TH.size)).sum() > 20


def test_axial_slopes_compare_neighbouring_sections_in_one_frame():
    """|dr/dz| per θ is the larger of the two sides' differences over the pitch; sections
    measured about other centres (frames) are not compared."""
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import InverseResult, ViewResult
    from lts360.recon.triangulation.peaks import Quality
    from lts360.recon.triangulation.reject import axial_slopes

    grid = CylGrid.from_ranges((9.0, 13.0), theta_step_deg=0.1, r_step_mm=0.005)
    th = grid.theta_rad

    def section(radius):
        r = np.full(th.size, radius)
        v = ViewResult("direct", th, r, r, np.full(th.size, Quality.FOUND, np.uint8),
                       np.ones(th.size), np.ones(th.size, bool), np.zeros(2))
        return InverseResult(grid, {"direct": v}, "centroid", 25.5, 255.0, False)

    res = [section(10.0), section(10.1), section(10.5)]  # z = 0, 0.5, 1.0
    s = axial_slopes(res, [0.0, 0.5, 1.0])
    assert np.allclose(s[0], 0.2) and np.allclose(s[1], 0.8) and np.allclose(s[2], 0.8)
    s = axial_slopes(res, [0.0, 0.5, 1.0], frames=[(0, 0), (0, 0), (1.0, 0)])
    assert np.allclose(s[1], 0.2) and np.isnan(s[2]).all()


def test_reject_scan_keeps_a_dim_stretch_of_a_straight_pipe_and_not_of_a_shoulder():
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import InverseResult, ViewResult
    from lts360.recon.triangulation.peaks import Quality
    from lts360.recon.triangulation.reject import reject_scan

    grid = CylGrid.from_ranges((9.0, 13.0), theta_step_deg=0.1, r_step_mm=0.005)
    th = grid.theta_rad

    def section(radius):
        r = np.full(th.size, radius)
        gap = np.abs(np.degrees(th) - 40.0) < 1.5
        q = np.where(gap, Quality.NO_PEAK, Quality.FOUND).astype(np.uint8)
        v = ViewResult("direct", th, np.where(gap, np.nan, r), r, q, np.ones(th.size),
                       np.ones(th.size, bool), np.zeros(2))
        return InverseResult(grid, {"direct": v}, "centroid", 25.5, 255.0, False)

    def fading(results):
        return [int(np.sum(r.views["direct"].quality == Quality.FADING)) for r in results]

    straight = [section(11.0), section(11.02), section(11.0)]  # slope 0.04
    assert fading(reject_scan(straight, [0.0, 0.5, 1.0])) == [0, 0, 0]
    shoulder = [section(11.0), section(11.5), section(12.0)]  # slope 1
    assert all(n > 0 for n in fading(reject_scan(shoulder, [0.0, 0.5, 1.0])))
    # one section alone: no slope, the flanks are FADING as in a single frame
    assert fading(reject_scan(straight[:1], [0.0]))[0] > 0


def test_in_a_scan_a_round_sections_shallow_notch_is_kept_and_a_valley_is_not():
    """An 80 µm ripple on a round section (a glint's structured error: a dip between two
    bumps 0.5 mm away) is a NOTCH in one frame but not in a scan, where the profile is within
    0.1 mm of the section's circle; a 0.3 mm valley is a NOTCH in both."""
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import InverseResult, ViewResult
    from lts360.recon.triangulation.peaks import Quality
    from lts360.recon.triangulation.reject import reject_scan

    grid = CylGrid.from_ranges((9.0, 13.0), theta_step_deg=0.1, r_step_mm=0.005)
    th = grid.theta_rad

    def section(depth, ripple=False):
        deg = np.degrees(th) - 40.0
        if ripple:  # arc s about 40°: −depth at s = 0, +depth at s = ±0.5 mm
            s_mm = np.radians(deg) * 11.0
            dip = np.where(np.abs(s_mm) <= 0.75, depth * np.cos(2 * np.pi * s_mm / 1.0), 0.0)
        else:
            dip = depth * np.clip(1 - np.abs(deg) / 3.0, 0, None)
        r = 11.0 - dip
        v = ViewResult("direct", th, r, r, np.full(th.size, Quality.FOUND, np.uint8),
                       np.ones(th.size), np.ones(th.size, bool), np.zeros(2))
        return InverseResult(grid, {"direct": v}, "centroid", 25.5, 255.0, False)

    def notches(results):
        return [int(np.sum(r.views["direct"].quality == Quality.NOTCH)) for r in results]

    zs = [0.0, 0.5, 1.0]
    shallow = [section(0.08, ripple=True)] * 3
    assert notches(reject_scan(shallow[:1], zs[:1]))[0] > 0
    assert notches(reject_scan(shallow, zs)) == [0, 0, 0]
    deep = [section(0.3)] * 3
    assert all(n > 0 for n in notches(reject_scan(deep, zs)))


def _scan_section(th, r):
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import InverseResult, ViewResult
    from lts360.recon.triangulation.peaks import Quality

    grid = CylGrid.from_ranges((8.0, 14.0), theta_step_deg=np.degrees(th[1] - th[0]),
                               r_step_mm=0.005)
    r = np.broadcast_to(np.asarray(r, float), grid.theta_rad.shape).copy()
    v = ViewResult("direct", grid.theta_rad, r, r, np.full(r.size, Quality.FOUND, np.uint8),
                   np.ones(r.size), np.ones(r.size, bool), np.zeros(2))
    return InverseResult(grid, {"direct": v}, "centroid", 25.5, 255.0, False)


def _flank(results):
    from lts360.recon.triangulation.peaks import Quality

    return [int(np.sum(r.views["direct"].quality == Quality.FLANK)) for r in results]


def test_a_section_on_a_shoulder_is_a_flank_and_its_neighbours_are_not():
    """A 45° shoulder between Ø22 and Ø24 mm, sections 0.5 mm apart: the section on it differs
    from both neighbours by slope 1 and is FLANK whole; the sections beside it differ from one
    neighbour only; the scan's end sections, with one neighbour, lie before the turn here (slope
    0 to it) and are kept."""
    from lts360.recon.triangulation.reject import flank_slopes, reject_scan

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    res = [_scan_section(th, r) for r in (11.0, 11.0, 11.5, 12.0, 12.0)]
    zs = [0.0, 0.5, 1.0, 1.5, 2.0]
    fl = flank_slopes(res, zs)
    assert np.allclose(fl[0], 0.0) and np.allclose(fl[-1], 0.0)
    assert np.allclose(fl[2], 1.0) and np.allclose(fl[1], 0.0) and np.allclose(fl[3], 0.0)
    assert _flank(reject_scan(res, zs)) == [0, 0, th.size, 0, 0]
    # without the end-section rule the ends are never judged
    fl = flank_slopes(res, zs, end_sections=False)
    assert np.isnan(fl[0]).all() and np.isnan(fl[-1]).all()
    # a gentle taper (slope 0.1, a 6° cone) is measured, not flagged
    taper = [_scan_section(th, 11.0 + 0.05 * k) for k in range(5)]
    assert _flank(reject_scan(taper, zs)) == [0] * 5
    # the criterion off
    assert _flank(reject_scan(res, zs, max_flank_slope=None)) == [0] * 5


def test_a_scan_that_ends_on_a_flank_flags_its_end_sections():
    """A short scan of a groove whose end sections lie on its 45° flanks (the undercut
    shaft's 5-section scan): each end differs from its only neighbour by slope 1 where that
    neighbour's slope beyond is 0, so the surface turned within the last two pitches; with
    no section beyond, the end is on the flank or past it and its points are flagged.  The
    rule off, they are kept."""
    from lts360.recon.triangulation.reject import reject_scan

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    zs = [0.5 * k for k in range(5)]
    res = [_scan_section(th, r) for r in (11.5, 11.0, 11.0, 11.0, 11.5)]
    assert _flank(reject_scan(res, zs)) == [th.size, 0, 0, 0, th.size]
    from lts360.recon.triangulation.reject_tolerances import TOLERANCES

    assert TOLERANCES.flank_end_sections
    from lts360.recon.triangulation.reject import flank_slopes

    fl = flank_slopes(res, zs, end_sections=False)
    assert np.isnan(fl[0]).all() and np.isnan(fl[-1]).all()


def test_a_cone_keeps_its_slope_and_is_not_a_flank():
    """A 27° cone (slope 0.5) scanned over seven sections: every section differs from both
    neighbours by slope 0.5, but the slope does not change from section to section, so the
    sheet lies on a straight slope and measures it.  A groove's flank two sections long
    between flat stretches is FLANK."""
    from lts360.recon.triangulation.reject import reject_scan

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    zs = [0.5 * k for k in range(7)]
    cone = [_scan_section(th, 10.0 + 0.5 * z) for z in zs]
    assert _flank(reject_scan(cone, zs)) == [0] * 7
    groove = [_scan_section(th, r) for r in (11.0, 11.0, 11.0, 11.3, 11.6, 11.6, 11.6)]
    assert _flank(reject_scan(groove, zs)) == [0, 0, 0, th.size, 0, 0, 0]


def test_a_bump_narrower_than_the_stated_arc_is_not_a_flank():
    """A 1° bump 0.3 mm high in the middle section only (a noisy valley of a cable): its slope
    to both neighbours is 0.6, but over less than 2 mm of arc."""
    from lts360.recon.triangulation.reject import reject_scan

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    bump = 11.0 + 0.3 * (np.abs(np.degrees(th) - 30.0) < 0.5)
    res = [_scan_section(th, 11.0), _scan_section(th, bump), _scan_section(th, 11.0)]
    assert _flank(reject_scan(res, [0.0, 0.5, 1.0])) == [0, 0, 0]
    wide = 11.0 + 0.3 * (np.abs(np.degrees(th) - 30.0) < 10.0)  # 3.8 mm of arc
    res[1] = _scan_section(th, wide)
    assert _flank(reject_scan(res, [0.0, 0.5, 1.0]))[1] > 0


def test_a_helix_turns_between_sections_and_is_not_a_flank():
    """Six strands laid at 4°/mm, sections 0.34 mm apart: :func:`screw_rate` finds the lay
    within one θ step per pair, and along the helix the profile does not change, so no
    section is FLANK; compared straight along the axis the strands' flanks would be."""
    from lts360.recon.triangulation.reject import _side_slopes, reject_scan, screw_rate

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    rate = np.radians(4.0)  # rad/mm
    zs = [0.34 * k for k in range(6)]
    res = [_scan_section(th, 10.0 + 0.5 * np.cos(6 * (th - rate * z))) for z in zs]
    assert abs(screw_rate(res, zs) - rate) <= np.radians(0.2) / 0.34
    assert _flank(reject_scan(res, zs)) == [0] * 6
    straight = _side_slopes(res, zs)[2].min(axis=0)
    assert straight.max() > 0.15  # the test would fail without the screw


def test_a_round_scan_has_no_screw():
    """A surface of revolution aligns equally at every shift: the smallest turn, 0; sections
    in different frames are not paired."""
    from lts360.recon.triangulation.reject import reject_scan, screw_rate

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    res = [_scan_section(th, 11.0 + 1e-4 * k) for k in range(4)]
    zs = [0.0, 0.5, 1.0, 1.5]
    assert screw_rate(res, zs) == 0.0
    assert _flank(reject_scan(res, zs)) == [0] * 4
    assert screw_rate(res, zs, frames=[(0, 0), (1, 0), (2, 0), (3, 0)]) == 0.0


def _strands_with_valley(th, z, rate, rejected_valley: bool):
    """Six strands turned by ``rate``·z; the valley at 30° (turned with them) either rejected
    (``NOTCH``, no radius) or measured 0.25 mm above its bottom (a bridge on the sheet's tail)."""
    import dataclasses

    from lts360.recon.triangulation.peaks import Quality

    res = _scan_section(th, 10.0 + 0.5 * np.cos(6 * (th - rate * z)))
    v = res.views["direct"]
    d = np.degrees(np.angle(np.exp(1j * (th - rate * z - np.radians(30.0)))))
    valley = np.abs(d) < 3.0
    if rejected_valley:
        q = np.where(valley, Quality.NOTCH, v.quality).astype(np.uint8)
        r = np.where(valley, np.nan, v.r_mm)
    else:
        q, r = v.quality, np.where(valley, v.r_mm + 0.25, v.r_mm)
    return dataclasses.replace(res, views={"direct": dataclasses.replace(v, r_mm=r, quality=q)})


def test_a_valley_both_neighbours_rejected_along_the_helix_is_rejected_between_them():
    from lts360.recon.triangulation.peaks import Quality
    from lts360.recon.triangulation.reject import reject_like_neighbours

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    rate = np.radians(4.0)
    zs = [0.0, 0.34, 0.68]
    res = [_strands_with_valley(th, z, rate, rejected) for z, rejected
           in zip(zs, (True, False, True))]
    out = reject_like_neighbours(res, zs, screw_rad_per_mm=rate)
    q = out[1].views["direct"].quality
    d = np.degrees(np.angle(np.exp(1j * (th - rate * zs[1] - np.radians(30.0)))))
    assert np.all(q[np.abs(d) < 2.6] == Quality.NEIGHBOURS)  # the bridge, the whole valley
    assert not np.any(q[np.abs(d) > 3.5] == Quality.NEIGHBOURS)
    assert not np.any(out[1].views["direct"].valid & (q == Quality.NEIGHBOURS))
    # the ends have one neighbour each and are left alone
    assert out[0] is res[0] and out[2] is res[2]
    # not turned back by the screw, the neighbours' valleys miss this one's by ±1.4°: less
    assert np.sum(reject_like_neighbours(res, zs)[1].views["direct"].quality
                  == Quality.NEIGHBOURS) < np.sum(q == Quality.NEIGHBOURS)
    # one neighbour's rejection is not enough
    res2 = [res[0], res[1], _strands_with_valley(th, zs[2], rate, False)]
    assert not np.any(reject_like_neighbours(res2, zs, screw_rad_per_mm=rate)[1]
                      .views["direct"].quality == Quality.NEIGHBOURS)


def test_a_round_section_is_not_rejected_like_its_neighbours():
    """A pipe's dim stretch recurs along the axis; where the section is round it stays."""
    import dataclasses

    from lts360.recon.triangulation.peaks import Quality
    from lts360.recon.triangulation.reject import reject_like_neighbours

    th = np.radians(np.arange(-180.0, 180.0, 0.2))
    dim = np.abs(np.degrees(th) - 40.0) < 2.0

    def section(faded):
        res = _scan_section(th, 11.0)
        v = res.views["direct"]
        if faded:
            q = np.where(dim, Quality.FADING, v.quality).astype(np.uint8)
            v = dataclasses.replace(v, r_mm=np.where(dim, np.nan, v.r_mm), quality=q)
        return dataclasses.replace(res, views={"direct": v})

    res = [section(True), section(False), section(True)]
    out = reject_like_neighbours(res, [0.0, 0.5, 1.0])
    assert not np.any(out[1].views["direct"].quality == Quality.NEIGHBOURS)

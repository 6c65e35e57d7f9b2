"""Each view's twin where that view measured the section: the views' offsets from their
overlaps, the compensation undone, and each view's pixels (closed forms, no render)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lts360.twin.profile import SectionProfile, ray_radii, view_offsets

TH = np.radians(np.arange(-180.0, 180.0, 0.1))
#: Three views' arcs (degrees) overlapping pairwise, as the rig's direct, left and right views.
ARCS = {"direct": (-155.0, -14.0), "left": (60.0, 250.0), "right": (-47.0, 76.0)}


def _in_arc(deg, lo, hi):
    d = np.mod(deg - lo, 360.0)
    return d <= hi - lo


def _views(radius_of, offsets):
    """Each view's radii along ``TH`` on its arc: ``radius_of(theta, t)`` for the view's
    translation ``t``, NaN off its arc."""
    deg = np.degrees(TH)
    return {n: np.where(_in_arc(deg, *ARCS[n]), radius_of(TH, np.asarray(offsets[n])), np.nan)
            for n in ARCS}


def test_offsets_of_the_first_order_model_come_back_without_their_mean():
    """Radii ``r = R + u·t`` per view (a circle about the origin moved by ``t``, to first
    order) give back the translations less their mean (the overlaps say nothing of a common
    one), within ``|t|²/R`` (the ray Jacobian reads the data's own slope, ``O(t/R)``)."""
    t = {"direct": (0.02, -0.01), "left": (-0.05, 0.04), "right": (0.06, 0.03)}
    R = 6.0

    def lin(th, tk):
        return R + np.cos(th) * tk[0] + np.sin(th) * tk[1]

    got = view_offsets(TH, _views(lin, t), ridge=0.0)
    mean = np.mean([np.asarray(v) for v in t.values()], axis=0)
    tol = max(np.hypot(*v) for v in t.values()) ** 2 / R
    for n in t:
        assert np.allclose(got[n], np.asarray(t[n]) - mean, atol=tol), n
    assert np.allclose(sum(got.values()), 0.0, atol=1e-12)  # the minimum-norm solution


def _ellipse_radii(a, b, theta, t):
    """Distance along the rays from the origin to the ellipse (x/a)² + (y/b)² = 1 centred at
    ``t``: the root of a quadratic in the ray's length."""
    c, s = np.cos(theta), np.sin(theta)
    A = (c / a) ** 2 + (s / b) ** 2
    B = -2 * (c * t[0] / a ** 2 + s * t[1] / b ** 2)
    C = (t[0] / a) ** 2 + (t[1] / b) ** 2 - 1
    return (-B + np.sqrt(B * B - 4 * A * C)) / (2 * A)


@pytest.mark.parametrize("a, b", [(6.0, 6.0), (10.0, 8.0)])
def test_translated_circles_and_ellipses_are_recovered_to_second_order(a, b):
    """Each view's points lie on the same closed curve moved by its own translation (≤ 71 µm):
    the offsets come back within 2 µm (the model is first order: ``(t·w)²/2R`` is left, and
    the ellipse needs the slope term ``r′/r`` of the ray Jacobian)."""
    t = {"direct": (0.0, 0.0), "left": (-0.05, 0.05), "right": (0.05, -0.03)}
    got = view_offsets(TH, _views(lambda th, tk: _ellipse_radii(a, b, th, tk), t))
    mean = np.mean([np.asarray(v) for v in t.values()], axis=0)
    for n in t:
        assert np.allclose(got[n], np.asarray(t[n]) - mean, atol=2e-3), (n, got[n])


def test_offsets_ignore_spikes_and_views_without_overlap():
    """5 % of the rays with a 0.3 mm spike move the offsets by < 1 µm (Tukey's biweight); a
    view that shares no ray keeps 0, and none shared gives zeros."""
    t = {"direct": (0.03, 0.0), "left": (-0.03, 0.02), "right": (0.0, -0.02)}

    def lin(th, tk):
        return 8.0 + np.cos(th) * tk[0] + np.sin(th) * tk[1]

    clean = view_offsets(TH, _views(lin, t))
    rng = np.random.default_rng(3)
    dirty = _views(lin, t)
    for r in dirty.values():
        r[rng.uniform(size=r.size) < 0.05] += 0.3
    got = view_offsets(TH, dirty)
    for n in t:
        assert np.allclose(got[n], clean[n], atol=1e-3), n
    lone = {"a": np.where(TH < 0, 8.0, np.nan), "b": np.where(TH > 0.5, 8.1, np.nan)}
    assert all(np.all(v == 0) for v in view_offsets(TH, lone).values())
    three = dict(_views(lin, t), far=np.full(TH.size, np.nan))
    assert np.all(view_offsets(TH, three)["far"] == 0)


def test_the_views_moved_by_their_offsets_read_the_same_curve():
    """The point of the offsets: after them the views' radii agree on the shared rays of an
    ellipse whose views were moved by up to 71 µm (the seams they left are gone)."""
    t = {"direct": (0.0, 0.0), "left": (-0.05, 0.05), "right": (0.05, -0.03)}
    got = view_offsets(TH, _views(lambda th, tk: _ellipse_radii(10.0, 8.0, th, tk), t))
    phi = (np.arange(1440) + 0.5) * 2 * np.pi / 1440
    ell = SectionProfile(np.zeros(2), phi, _ellipse_radii(10.0, 8.0, phi, (0.0, 0.0)), 1.0, 0.0)
    for n in t:  # each view's curve moved back by its offset from the mean is the ellipse
        moved = ray_radii(ell.vertices_mm + np.asarray(t[n]) - got[n], TH)
        assert np.max(np.abs(moved - ray_radii(ell.vertices_mm + np.mean(
            [np.asarray(v) for v in t.values()], axis=0), TH))) < 3e-3


def _cal(offsets, radial, scales):
    return SimpleNamespace(view_offsets_mm=offsets, view_radial_offsets_mm=radial,
                           view_scales=scales)


@pytest.mark.parametrize("name", ["direct", "left"])
def test_uncompensated_is_the_inverse_of_the_compensation(name):
    """A compensated view reads ``ρ → scale·ρ + offset`` along its rays, then its §4.4
    translation (mirror views): undoing it gives the profile back to round-off, both ways."""
    from lts360.twin.debias import _compensated, _uncompensated

    cal = _cal({"left": np.array([0.04, -0.07])}, {"direct": 0.012, "left": -0.008},
               {"direct": 1.0004, "left": 0.9997})
    phi = np.linspace(0, 2 * np.pi, 500, endpoint=False)
    v = np.column_stack([0.3 + 9 * np.cos(phi), -0.2 + 7 * np.sin(phi)])
    assert np.allclose(_uncompensated(_compensated(v, cal, name, True), cal, name, True), v,
                       atol=1e-12)
    assert np.allclose(_compensated(_uncompensated(v, cal, name, True), cal, name, True), v,
                       atol=1e-12)
    assert _uncompensated(v, cal, name, False) is v  # nothing to undo
    rho = np.hypot(*v.T)
    back = np.hypot(*_uncompensated(v, cal, name, True).T) if name == "direct" else None
    if back is not None:  # the direct view: radii only, (ρ − offset) / scale
        assert np.allclose(back, (rho - 0.012) / 1.0004, atol=1e-12)


def test_placed_undoes_the_compensation_and_keeps_the_faces():
    """A compensated view's twin is its profile moved out of the compensation (x, y only, the
    same faces: a loaded scene is reused); an uncompensated view's is the mesh itself."""
    from lts360.twin.debias import _placed, _uncompensated
    from lts360.twin.profile import prism_mesh

    phi = (np.arange(360) + 0.5) * 2 * np.pi / 360
    mesh = prism_mesh(SectionProfile(np.array([0.1, 0.0]), phi, np.full(360, 5.0), 1.0, 0.0),
                      half_length_mm=4.0)
    assert _placed(mesh, None, "left", False) is mesh
    cal = _cal({"left": np.array([0.03, -0.02])}, {"left": 0.01}, {"left": 1.001})
    moved = _placed(mesh, cal, "left", True)
    assert np.array_equal(moved.faces, mesh.faces)
    assert np.array_equal(moved.vertices[:, 2], mesh.vertices[:, 2])
    assert np.allclose(moved.vertices[:, :2],
                       _uncompensated(np.asarray(mesh.vertices)[:, :2], cal, "left", True))


def _circle_profile(c, r, n=1440):
    phi = (np.arange(n) + 0.5) * 2 * np.pi / n
    return SectionProfile(np.asarray(c, float), phi, np.full(n, float(r)), 1.0, 0.0)


def test_a_placed_profile_is_the_common_one_moved_and_bent_as_the_view_measured_it():
    """A view's points on a Ø12 circle 60 µm off (a calibration's error) and 5 µm larger over
    its arc, with a quadratic departure of ±3 µm along it (a smooth distortion) and a glint's
    ripple of 4 µm at 2.5° (its own bias): the placed profile is the common circle moved by
    the offset and bent by the smooth part within 0.3 µm on the arc, held at the arc's ends
    beyond it; the ripple is not carried (within 0.3 µm of the smooth curve)."""
    from lts360.twin.profile import placed_profile

    common = _circle_profile((0.0, 0.0), 6.0)
    t = np.array([0.06, -0.02])
    a = np.radians(np.linspace(-60.0, 80.0, 4000))
    mid = np.radians(10.0)
    x = (a - mid) / np.pi
    smooth = 0.005 + 0.003 * (2 * (x / x.max()) ** 2 - 1)
    ripple = 0.004 * np.sin(a * 360.0 / 2.5)
    pts = t + (6.0 + smooth + ripple)[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    got = placed_profile(common, pts, t)
    assert np.allclose(got.center_mm, t)
    deg = np.degrees(got.phi_rad)
    deg = np.where(deg > 180, deg - 360, deg)
    on = (deg > -58) & (deg < 78)
    want = np.interp(deg[on], np.degrees(a), 6.0 + smooth)
    assert np.max(np.abs(got.rho_mm[on] - want)) < 3e-4
    off = (deg > 100) & (deg < 170)  # beyond the arc's end at 80°: held at its value there
    assert np.max(np.abs(got.rho_mm[off] - (6.0 + smooth[-1]))) < 3e-4
    # a view with too few points is only moved
    few = placed_profile(common, pts[:20], t)
    assert np.allclose(few.rho_mm, 6.0) and np.allclose(few.center_mm, t)


def test_a_placed_profile_ignores_a_views_stray_points():
    """2 % of the view's points 0.2 mm off (spikes) do not bend the placed profile (robust
    fit): within 0.2 µm of the clean circle's."""
    from lts360.twin.profile import placed_profile

    rng = np.random.default_rng(3)
    common = _circle_profile((0.1, 0.0), 10.0)
    a = np.radians(np.linspace(100.0, 260.0, 3000))
    r = 10.0 + np.where(rng.uniform(size=a.size) < 0.02, 0.2, 0.0)
    pts = np.array([0.1, 0.0]) + r[:, None] * np.column_stack([np.cos(a), np.sin(a)])
    got = placed_profile(common, pts, np.zeros(2))
    assert np.max(np.abs(got.rho_mm - 10.0)) < 2e-4


def test_each_views_pixels_are_the_plans_split_by_view():
    """Every pixel the plan reads belongs to exactly one view's part (each view's twin is
    rendered on its own pixels, and together they cover the plan's)."""
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import plan_inverse, plan_pixels
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth
    from lts360.twin.debias import view_pixels

    rig = load_rig("paper")
    cal = calibration_from_frame_truth(rig_truth(rig, rig.camera.K, rig.camera.image_size))
    grid = CylGrid(np.radians(np.arange(-180.0, 180.0, 1.0)), np.arange(8.0, 12.0, 0.05))
    plan = plan_inverse(cal, grid, precompute=False)
    parts = view_pixels(plan)
    assert set(parts) == set(plan.views)
    allpx = np.concatenate(list(parts.values()))
    assert len({tuple(p) for p in allpx}) == len(allpx)  # no pixel twice
    assert {tuple(p) for p in allpx} == {tuple(p) for p in plan_pixels(plan)}
    assert view_pixels(plan) is parts  # kept per plan

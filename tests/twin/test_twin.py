"""The digital-twin bias correction: its geometry against closed forms, its rig against the
calibration it comes from, and a rendered gauge whose bias it removes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lts360.twin.profile import prism_mesh, ray_radii, section_profile


@pytest.fixture(scope="module")
def paper_rig():
    from lts360.scenes.rig_io import load_rig

    return load_rig("paper")


def _circle(c, r, n=4000, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 2 * np.pi, n)
    rr = r + noise * rng.standard_normal(n)
    return np.column_stack([c[0] + rr * np.cos(t), c[1] + rr * np.sin(t)])


@settings(max_examples=30, deadline=None)
@given(cx=st.floats(-4, 4), cy=st.floats(-4, 4), r=st.floats(6, 20),  # the origin inside
       th=st.floats(0, 2 * np.pi))
def test_ray_radius_of_a_circle_is_the_closed_form(cx, cy, r, th):
    """A ray from the origin at θ meets the circle |X − c| = r at t = c·u + √((c·u)² − |c|² + r²);
    the polygon of 1440 vertices is within its sagitta r(1 − cos(π/1440)) of it along the
    normal, ≤ 1/cos(incidence) times that along the ray (incidence ≤ asin(|c|/r))."""
    from lts360.twin.profile import SectionProfile

    phi = (np.arange(1440) + 0.5) * 2 * np.pi / 1440
    prof = SectionProfile(np.array([cx, cy]), phi, np.full(1440, r), 1.0, 0.0)
    u = np.array([np.cos(th), np.sin(th)])
    cu = np.array([cx, cy]) @ u
    exact = cu + np.sqrt(cu ** 2 - cx ** 2 - cy ** 2 + r ** 2)
    got = ray_radii(prof.vertices_mm, [th])[0]
    cos_inc = np.sqrt(1 - min((cx * cx + cy * cy) / (r * r), 1.0))
    assert got == pytest.approx(exact, rel=0, abs=r * (1 - np.cos(np.pi / 1440)) / cos_inc + 1e-9)
    assert got <= exact + 1e-9  # the chords lie inside the circle


def test_ray_radii_pick_the_crossing_nearest_the_hint():
    """A ray that crosses a non-convex profile twice returns the crossing nearest the hint
    (the detector's radius), the farthest without one, and NaN when it misses."""
    outer = np.array([[-2.0, -2.0], [2.0, -2.0], [2.0, 2.0], [-2.0, 2.0]])
    # a square with a slot x ∈ [1, 1.5] cut down from its top: the ray along +x crosses its
    # boundary at x = 1, 1.5 and 2
    c = np.array([[-2, -2], [2, -2], [2, 2], [1.5, 2], [1.5, -0.5], [1, -0.5], [1, 2], [-2, 2]],
                 float)
    assert ray_radii(c, [0.0], near_mm=[1.9])[0] == pytest.approx(2.0)
    assert ray_radii(c, [0.0], near_mm=[1.1])[0] == pytest.approx(1.0)
    assert ray_radii(c, [0.0], near_mm=[1.4])[0] == pytest.approx(1.5)
    assert ray_radii(c, [0.0])[0] == pytest.approx(2.0)
    assert ray_radii(outer + 10.0, [np.pi])[0] != ray_radii(outer + 10.0, [np.pi])[0]  # NaN: missed


def _ray_radii_every_pair(v, th, near=None):
    """Reference: every ray against every edge (what ray_radii did before it paired them)."""
    e = np.roll(v, -1, axis=0) - v
    u = np.column_stack([np.cos(th), np.sin(th)])
    uxe = u[:, :1] * e[None, :, 1] - u[:, 1:] * e[None, :, 0]
    pxu = v[None, :, 0] * u[:, 1:] - v[None, :, 1] * u[:, :1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (v[:, 0] * e[:, 1] - v[:, 1] * e[:, 0])[None, :] / uxe
        s = pxu / uxe
    hit = (uxe != 0) & (s >= 0) & (s < 1) & (t > 0)
    if near is None:
        out = np.max(np.where(hit, t, -np.inf), axis=1)
    else:
        k = np.argmin(np.where(hit, np.abs(t - near[:, None]), np.inf), axis=1)
        out = np.where(hit[np.arange(len(th)), k], t[np.arange(len(th)), k], np.nan)
    return np.where(np.isfinite(out), out, np.nan)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 120), star=st.booleans(),
       shift=st.floats(0.0, 4.0), n_rays=st.integers(1, 300))
def test_ray_radii_tests_every_edge_a_ray_can_cross(seed, n, star, shift, n_rays):
    """Pairing each edge with the rays inside the angle it subtends finds exactly what testing
    every ray against every edge finds, bit for bit: star-shaped profiles around or beside
    the origin, self-intersecting polygons, rays through the vertices, at ±π and beyond, NaN."""
    rng = np.random.default_rng(seed)
    if star:
        phi = np.sort(rng.uniform(-np.pi, np.pi, n))
        v = rng.uniform(0.5, 3.0, n)[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    else:
        v = rng.normal(0.0, 2.0, (n, 2))
    v = v + shift * rng.normal(size=2)
    th = np.concatenate([rng.uniform(-7.0, 7.0, n_rays), np.arctan2(v[:, 1], v[:, 0]),
                         [np.pi, -np.pi, np.nan]])
    near = rng.uniform(0.0, 6.0, th.size)
    for hint in (None, near):
        np.testing.assert_array_equal(ray_radii(v, th, hint), _ray_radii_every_pair(v, th, hint))


def test_profile_of_a_noisy_circle_is_the_circle():
    pts = _circle((1.5, -0.7), 10.0, n=20000, noise=0.02, seed=1)
    prof = section_profile(pts, smooth_deg=2.0)
    assert np.allclose(prof.center_mm, (1.5, -0.7), atol=2e-3)
    assert np.abs(prof.rho_mm - 10.0).max() < 6e-3
    assert prof.coverage == 1.0 and prof.largest_gap_deg == 0.0


def test_profile_bridges_a_gap_and_reports_it():
    pts = _circle((0, 0), 8.0, n=8000)
    ang = np.degrees(np.arctan2(pts[:, 1], pts[:, 0])) % 360
    prof = section_profile(pts[(ang < 100) | (ang > 130)])
    assert 29 <= prof.largest_gap_deg <= 31
    assert np.abs(prof.rho_mm - 8.0).max() < 1e-3  # a circle's gap is closed on the circle


def test_profile_refuses_too_few_points():
    with pytest.raises(ValueError, match="need 50"):
        section_profile(_circle((0, 0), 5.0, n=20))


def test_prism_is_watertight_with_the_profile_as_its_section():
    pts = _circle((0.5, 0.2), 6.0, n=6000)
    mesh = prism_mesh(section_profile(pts), half_length_mm=10.0)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0  # outward normals
    area = np.pi * 6.0 ** 2
    assert mesh.volume == pytest.approx(area * 20.0, rel=1e-4)


def test_twin_rig_reproduces_the_calibration(paper_rig):
    """The twin of a perfect calibration is the true rig: the same camera projection, mirror
    planes and laser plane (the calibration made from the twin equals the first)."""
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.simulator.io import rig_truth
    from lts360.twin.rig import twin_rig

    cal = calibration_from_frame_truth(rig_truth(paper_rig, paper_rig.camera.K,
                                                 paper_rig.camera.image_size))
    twin = twin_rig(cal, paper_rig)
    cal2 = calibration_from_frame_truth(rig_truth(twin, twin.camera.K, twin.camera.image_size))
    assert np.allclose(cal2.K, cal.K) and np.allclose(cal2.T_cam_meas, cal.T_cam_meas)
    for m in cal.mirrors:
        m2 = cal2.mirror(m.name)
        assert np.allclose(m2.n, m.n, atol=1e-12) and m2.d_mm == pytest.approx(m.d_mm)
        assert np.allclose(m2.corners_mm, m.corners_mm, atol=1e-9)
    assert np.allclose(cal2.laser_plane[0], cal.laser_plane[0])
    assert cal2.laser_plane[1] == pytest.approx(cal.laser_plane[1])
    assert twin.camera.f_number == paper_rig.camera.f_number


def _tilted_calibration(cal, deg: float, index: int = 0):
    """``cal`` with mirror ``index`` turned by ``deg`` about an axis in the sheet's plane."""
    import dataclasses

    m = cal.mirrors[index]
    a = np.radians(deg)
    axis = cal.R_cam_meas @ np.array([1.0, 1.0, 0.0]) / np.sqrt(2)  # in the sheet's plane
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Rot = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    tilted = dataclasses.replace(m, n=Rot @ m.n, corners_mm=None)
    mirrors = list(cal.mirrors)
    mirrors[index] = tilted
    return dataclasses.replace(cal, mirrors=tuple(mirrors))


def test_twin_rig_lights_through_mirrors_made_perpendicular(paper_rig):
    """A calibration whose mirror is 0.05° out of perpendicular to its laser plane (what an
    estimated calibration carries) is accepted: the camera side keeps the calibrated mirror,
    the laser side turns it about its line in the sheet until perpendicular (the same line,
    so the reflected sheet stays in the plane); the true calibration's laser side is its own."""
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.simulator.io import rig_truth
    from lts360.twin.rig import laser_side_mirrors, twin_rig

    cal = calibration_from_frame_truth(rig_truth(paper_rig, paper_rig.camera.K,
                                                 paper_rig.camera.image_size))
    assert laser_side_mirrors(twin_rig(cal, paper_rig)) is None
    twin = twin_rig(_tilted_calibration(cal, 0.05), paper_rig)
    lasers = laser_side_mirrors(twin)
    assert lasers is not None
    for cam_m, las_m in zip(twin.mirrors, lasers):
        assert abs(las_m.normal[2]) < 1e-12  # perpendicular to the sheet z = 0
        # the same line in the sheet: two points of the camera-side line lie on both planes
        n, d = cam_m.normal, cam_m.d_mm
        e = np.cross(n, [0.0, 0.0, 1.0])
        p0 = np.linalg.lstsq(np.array([n, [0, 0, 1.0]]), np.array([d, 0.0]), rcond=None)[0]
        for s in (-30.0, 30.0):
            q = p0 + s * e / np.linalg.norm(e)
            assert abs(q @ las_m.normal - las_m.d_mm) < 1e-9  # mm, round-off
        # the reflected apex stays in the sheet
        O = twin.laser.origin_mm
        assert abs((O - 2 * (O @ las_m.normal - las_m.d_mm) * las_m.normal)[2]) < 1e-9
    # the calibrated (tilted) mirror is what the camera sees (the axis lies in its plane)
    assert abs(twin.mirrors[0].normal[2]) == pytest.approx(np.sin(np.radians(0.05)), rel=1e-6)


def test_twin_rig_refuses_mirrors_far_from_perpendicular(paper_rig):
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.simulator.io import rig_truth
    from lts360.twin.rig import twin_rig

    cal = calibration_from_frame_truth(rig_truth(paper_rig, paper_rig.camera.K,
                                                 paper_rig.camera.image_size))
    with pytest.raises(ValueError, match="out of perpendicular"):
        twin_rig(_tilted_calibration(cal, 1.0), paper_rig)


def test_perturbed_design_moves_one_input(paper_rig):
    from lts360.twin.debias import perturbed_design

    d = perturbed_design(paper_rig, "focus_distance_mm", 2.0)
    assert d.camera.focus_distance_mm == paper_rig.camera.focus_distance_mm + 2.0
    assert d.camera.f_number == paper_rig.camera.f_number
    w = perturbed_design(paper_rig, "waist_rel", 0.1).laser
    assert w.waist_um == pytest.approx(1.1 * paper_rig.laser.waist_um)
    assert w.m_squared == pytest.approx(paper_rig.laser.m_squared)  # the same beam quality
    with pytest.raises(ValueError, match="unknown twin input"):
        perturbed_design(paper_rig, "colour", 1.0)


def test_twin_rig_refuses_a_foreign_frame(paper_rig):
    import dataclasses

    from lts360.recon.model import calibration_from_frame_truth
    from lts360.simulator.io import rig_truth
    from lts360.twin.rig import twin_rig

    cal = calibration_from_frame_truth(rig_truth(paper_rig, paper_rig.camera.K,
                                                 paper_rig.camera.image_size))
    T = np.array(cal.T_cam_meas)
    shifted = np.eye(4)
    shifted[:3, 3] = (100.0, 0.0, 0.0)  # the measurement origin 100 mm off the rig's axis
    bad = dataclasses.replace(cal, T_cam_meas=T @ shifted, laser_plane=cal.laser_plane)
    with pytest.raises(ValueError, match="not rig"):
        twin_rig(bad, paper_rig)


@pytest.fixture(scope="module")
def small_gauge_frame(tmp_path_factory):
    """A noise-free Ø12 mm gauge 2 mm off the axis at half scale (its views disagree by
    ~11 µm and its radius reads ~10 µm small as measured)."""
    import mitsuba as mi

    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame, write_frame

    if mi.variant() is None:
        mi.set_variant("llvm_ad_mono")
    # The full frame, the realisation these figures were measured on (a support-only frame
    # is another realisation of the same render noise).
    frame = simulate_frame(load_rig("paper"), build_object("plug-gauge:d=12,x=2"), spp=16,
                           seed=0, noise="none", scale=0.5, support="full")
    return write_frame(tmp_path_factory.mktemp("twin") / "g12", frame)


def _gauge_errors(cloud, c=(2.0, 0.0), r_true=6.0):
    from lts360.geometry.fit import fit_circle

    p = cloud.points_mm[cloud.valid, :2]
    r = np.hypot(*(p - np.asarray(c)).T)
    views = cloud.view[cloud.valid]
    means = [np.mean(r[views == k] - r_true) for k in np.unique(views)]
    return 1e3 * (fit_circle(p).radius_mm - r_true), 1e3 * np.ptp(means)


def test_the_twin_removes_the_line_centre_bias_of_a_rendered_gauge(small_gauge_frame):
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.scenes.rig_io import load_rig
    from lts360.twin import TwinCorrector

    cal = load_calibration(small_gauge_frame / "frame.json")
    sec = [Section(small_gauge_frame / "image.png", 0.0)]
    plain, _, _ = measure_sections_following(sec, cal, reject=True)
    twin = TwinCorrector(cal, load_rig("paper"), spp=64)
    corrected, _, _ = measure_sections_following(sec, cal, reject=True, correct=twin)
    b0, s0 = _gauge_errors(plain)
    b1, s1 = _gauge_errors(corrected)
    assert b0 < -5.0 and s0 > 6.0  # what there is to correct (measured: -10.1 and 11.8 µm)
    assert abs(b1) < 3.0 and abs(b1) < 0.3 * abs(b0)  # measured: +1.6 µm
    assert s1 < 0.5 * s0  # measured: 4.6 µm (1.6 µm before each view had its own twin;
    #                       over eight twin seeds 3.4 ± 1.3 µm against 3.6 ± 1.5 µm before)
    log = twin.log.summary()
    assert set(log) == {"direct", "left", "right"}
    assert all(v["n_uncorrected"] == 0 and v["mean_bias_um"] < -3 for v in log.values())
    # the rig file's inputs moved by their u: each moves each view's correction by a little
    from lts360.twin.debias import INPUT_U

    for name, rec in twin.log.inputs.items():
        assert set(rec["by_input_um"]) == set(INPUT_U)
        assert 0 < rec["u_um"] < 5.0, (name, rec)
    # the correction moves the points along their rays and nothing else
    assert np.array_equal(plain.valid, corrected.valid)
    assert np.allclose(plain.theta_rad, corrected.theta_rad)


def test_measure_with_the_twin_records_it_in_the_cloud(small_gauge_frame, tmp_path, capsys):
    from lts360.cli import main

    out = tmp_path / "c.ply"
    assert main(["measure", str(small_gauge_frame), "--calibration",
                 str(small_gauge_frame / "frame.json"), "--out", str(out),
                 "--bias-model", "twin", "--twin-spp", "16"]) == 0
    printed = capsys.readouterr().out
    assert "twin bias correction: direct" in printed
    assert "one section, so its twin is a straight prism" in printed  # says what it cannot do
    header = out.read_bytes().split(b"end_header")[0].decode()
    assert header.count("comment lts360 twin ") == 3
    from lts360.recon.triangulation.cloud import read_cloud_twin

    rec = read_cloud_twin(out)
    assert set(rec) == {"direct", "left", "right"}
    assert all(v["u_inputs_um"] > 0 and v["corrected"] > 100 for v in rec.values())
    # inspect counts the correction's input u in the sizes' U
    import json

    assert main(["inspect", str(out), "--out", str(tmp_path / "ins")]) == 0
    data = json.loads((tmp_path / "ins" / "inspection.json").read_text())
    u_twin = data["settings"]["twin_u_inputs_mm"]
    assert 0 < u_twin < 0.005
    assert data["sections"][0]["d_ls_mm"]["u"] >= 2 * u_twin


@pytest.mark.parametrize("extra, message", [
    (["--method", "classic"], "needs the inverse method"),
    (["--twin-material", "cheese"], "unknown material"),
    (["--twin-spp", "0"], "--twin-spp"),
    (["--twin-rig", "no-such-rig"], "--bias-model twin"),
])
def test_twin_usage_errors_are_one_line_exit_2(small_gauge_frame, tmp_path, capsys, extra,
                                                message):
    from lts360.cli import main

    rc = main(["measure", str(small_gauge_frame), "--calibration",
               str(small_gauge_frame / "frame.json"), "--out", str(tmp_path / "c.ply"),
               "--bias-model", "twin", *extra])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and message in err and "\n" not in err


def _wavy_profile(z, *, r0=11.0, wave=0.1, lam=5.0, bend=0.02, lobes=0.03):
    """The exact section at ``z`` of a pipe with an axial waviness, three lobes and an axis
    bent in x (centre ``bend·z²``), as a SectionProfile about that centre."""
    from lts360.twin.profile import SectionProfile

    phi = (np.arange(1440) + 0.5) * 2 * np.pi / 1440
    rho = r0 + wave * np.cos(2 * np.pi * z / lam) + lobes * np.cos(3 * phi)
    return SectionProfile(np.array([bend * z * z, 0.0]), phi, rho, 1.0, 0.0)


def test_axial_form_is_the_three_point_stencil_of_a_wavy_bent_pipe():
    """With one section each side the form is the finite differences of ρ along the rays from
    the section's centre: for a waviness ρ = A cos(kz) the slope −A sin(kh)/h … and for the
    bent axis (centre b·z²) the order-1 terms 2b·z·cos φ and 2b·cos φ; within 5e-4 (the lobes
    seen from an offset centre, δ·3A_l/R, are the largest term left out)."""
    from lts360.twin.profile import axial_form

    A, lam, b, h = 0.1, 5.0, 0.02, 0.5
    k = 2 * np.pi / lam
    for z0 in (0.0, 0.7, 1.25):
        mid = _wavy_profile(z0, bend=0.0)  # the section's own frame: its centre at 0
        nb = [(dz, _wavy_profile(z0 + dz)) for dz in (-h, h)]
        # rays from this section's centre: move the neighbours into its frame
        import dataclasses
        c0 = np.array([b * z0 * z0, 0.0])
        nb = [(dz, dataclasses.replace(p, center_mm=p.center_mm - c0)) for dz, p in nb]
        form = axial_form(mid, nb, order=2)
        rp, rm = A * np.cos(k * (z0 + h)), A * np.cos(k * (z0 - h))
        r0 = A * np.cos(k * z0)
        slope0 = (rp - rm) / (2 * h)
        curv0 = (rp - 2 * r0 + rm) / h ** 2
        # the bend: a circle's radius along the ray from an offset δ·x̂ is ≈ δ cos φ (to δ²/2R)
        dp, dm = b * (z0 + h) ** 2 - b * z0 ** 2, b * (z0 - h) ** 2 - b * z0 ** 2
        slope1 = (dp - dm) / (2 * h)
        curv1 = (dp + dm) / h ** 2
        c = np.cos(mid.phi_rad)
        assert np.allclose(form.slope, slope0 + slope1 * c, atol=5e-4), z0
        assert np.allclose(form.curvature_per_mm, curv0 + curv1 * c, atol=2e-3), z0
        assert form.dz_mm == (-h, h) and form.reach_mm == h


def test_axial_form_ignores_a_glint_in_one_neighbour():
    """A neighbour whose profile is 20 µm off over 20° of arc (a glint's bias there, not the
    surface) leaves the robust form within 2 % of the clean one, where a per-φ form is off
    by 0.16 /mm of curvature on that arc."""
    import dataclasses

    from lts360.twin.profile import axial_form

    mid = _wavy_profile(0.0, bend=0.0)
    up = _wavy_profile(0.5, bend=0.0)
    down = _wavy_profile(-0.5, bend=0.0)
    arc = (np.degrees(up.phi_rad) > 100) & (np.degrees(up.phi_rad) < 120)
    glint = dataclasses.replace(up, rho_mm=up.rho_mm - 0.02 * arc)
    clean = axial_form(mid, [(-0.5, down), (0.5, up)])
    dirty = axial_form(mid, [(-0.5, down), (0.5, glint)])
    assert np.allclose(dirty.curvature_per_mm, clean.curvature_per_mm,
                       atol=0.02 * np.abs(clean.curvature_per_mm).max())
    assert np.allclose(dirty.slope, clean.slope, atol=5e-4)


def test_axial_form_with_one_neighbour_is_a_slope_and_refuses_bad_input():
    from lts360.twin.profile import axial_form

    mid = _wavy_profile(1.25, bend=0.0)
    form = axial_form(mid, [(0.5, _wavy_profile(1.75, bend=0.0))])
    assert np.all(form.curvature_per_mm == 0)
    assert np.allclose(form.slope, (0.1 * np.cos(2 * np.pi * 1.75 / 5) - 0.1 * np.cos(
        2 * np.pi * 1.25 / 5)) / 0.5, atol=1e-5)
    assert axial_form(mid, []) is None and axial_form(mid, [(0.0, mid)]) is None
    with pytest.raises(ValueError, match="order"):
        axial_form(mid, [(0.5, mid), (-0.5, mid)], order=9)


def test_loft_is_watertight_and_carries_the_profile_along_its_form():
    """Each ring of the loft within the form's reach is ρ + slope·dz + curvature·dz²/2 (the
    form's own closed form), the rings beyond it repeat the last; form None is the prism."""
    from lts360.twin.profile import AxialForm, loft_mesh

    prof = _wavy_profile(0.0, bend=0.0)
    n = prof.rho_mm.size
    form = AxialForm(np.full(n, 0.05), np.full(n, -0.16), 1.0, (-0.5, 0.5))
    mesh = loft_mesh(prof, form, half_length_mm=10.0)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    v = mesh.vertices[:-2].reshape(-1, n, 3)
    z = v[:, 0, 2]
    assert z[0] == -10.0 and z[-1] == 10.0 and np.min(np.diff(z)) > 0
    assert np.max(np.diff(z[np.abs(z) <= 1.0])) <= 0.02 + 1e-12  # fine across the sheet
    rho = np.hypot(v[..., 0] - prof.center_mm[0], v[..., 1] - prof.center_mm[1])
    dz = np.clip(z, -1.0, 1.0)[:, None]
    assert np.allclose(rho, prof.rho_mm + 0.05 * dz - 0.08 * dz * dz, atol=1e-9)
    assert np.allclose(rho[np.argmin(np.abs(z))], prof.rho_mm)  # the section itself at dz = 0
    prism = loft_mesh(prof, None, half_length_mm=10.0)
    assert len(prism.vertices) == 2 * n + 2


def test_stencil_takes_the_nearest_section_each_side():
    from lts360.twin.debias import _stencil

    nb = [(-1.0, "a"), (-0.5, "b"), (0.5, "c"), (1.0, "d")]
    assert _stencil(nb) == [(-0.5, "b"), (0.5, "c")]
    assert _stencil(nb[2:]) == [(0.5, "c"), (1.0, "d")]  # a scan's end: one side
    assert _stencil(nb[:1]) == [(-1.0, "a")]


def test_a_calibration_without_optics_loads_and_the_twin_asks_for_the_rig(
        small_gauge_frame, tmp_path, capsys):
    """An older calibration.json (no optics record) loads; the twin then needs --twin-rig and
    says so in one line (exit 2)."""
    import json

    from lts360.cli import main
    from lts360.recon.model import calibration_to_dict, load_calibration

    cal = load_calibration(small_gauge_frame / "frame.json")
    assert cal.optics["rig"] == "paper" and "[design]" in cal.optics["rig_toml"]
    old = calibration_to_dict(cal)
    del old["optics"]
    path = tmp_path / "old.json"
    path.write_text(json.dumps(old))
    assert load_calibration(path).optics == {}
    rc = main(["measure", str(small_gauge_frame), "--calibration", str(path),
               "--out", str(tmp_path / "c.ply"), "--bias-model", "twin"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "records no optics" in err and "--twin-rig" in err and "\n" not in err
    assert not (tmp_path / "c.ply").exists()


def test_a_twin_rig_of_another_design_is_refused(small_gauge_frame, tmp_path, capsys):
    from lts360.cli import main

    other = tmp_path / "other.toml"
    other.write_text('base = "paper"\n[design]\nalpha_deg = 30.0\n')
    rc = main(["measure", str(small_gauge_frame), "--calibration",
               str(small_gauge_frame / "frame.json"), "--out", str(tmp_path / "c.ply"),
               "--bias-model", "twin", "--twin-rig", str(other)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "not the rig the calibration was made with" in err
    assert "design.alpha_deg" in err and "\n" not in err


def test_twin_design_takes_the_recorded_rig_and_an_override_of_the_same_design(paper_rig):
    import dataclasses

    from lts360.recon.model import calibration_from_frame_truth
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth
    from lts360.twin.rig import twin_design

    cal = calibration_from_frame_truth(rig_truth(paper_rig, paper_rig.camera.K,
                                                 paper_rig.camera.image_size))
    assert twin_design(cal).camera.f_number == paper_rig.camera.f_number
    assert twin_design(cal, "paper-f8").camera.f_number == load_rig("paper-f8").camera.f_number
    with pytest.raises(ValueError, match="records no optics"):
        twin_design(dataclasses.replace(cal, optics={}))
    assert twin_design(dataclasses.replace(cal, optics={}), "paper").name == "paper"


def _perturbed_calibration(cal, tilt_deg: float = 0.05, offset_mm: float = 0.05):
    """``cal`` with each mirror turned by ±``tilt_deg`` about an axis in the sheet's plane
    (out of perpendicular to the sheet) and moved by ±``offset_mm`` along its normal: the
    size of an estimated calibration's plane errors."""
    import dataclasses

    mirrors = []
    for k, m in enumerate(cal.mirrors):
        s = 1.0 if k % 2 == 0 else -1.0
        axis = cal.R_cam_meas @ np.array([1.0, s, 0.0]) / np.sqrt(2)
        a = np.radians(s * tilt_deg)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        Rot = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
        # turned about the mirror's line in the sheet (through its centre's foot there)
        c = cal.T_meas_cam[:3, :3] @ m.corners_mm.mean(axis=0) + cal.T_meas_cam[:3, 3]
        pivot = cal.R_cam_meas @ np.array([c[0], c[1], 0.0]) + cal.t_cam_meas_mm
        pivot = pivot - (pivot @ m.n - m.d_mm) * m.n
        n = Rot @ m.n
        mirrors.append(dataclasses.replace(m, n=n, d_mm=float(n @ pivot) + s * offset_mm,
                                           corners_mm=None))
    return dataclasses.replace(cal, mirrors=tuple(mirrors))


def _view_corrections(cal, frame_dir, spp: int = 64):
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.scenes.rig_io import load_rig
    from lts360.twin import TwinCorrector

    twin = TwinCorrector(cal, load_rig("paper"), spp=spp, input_u=None)
    measure_sections_following([Section(frame_dir / "image.png", 0.0)], cal, reject=True,
                               correct=twin)
    return twin.log.summary()


#: The twins compared below render at this many samples per pixel (see the test's docstring).
COMPARE_SPP = 1024


@pytest.mark.slow
def test_the_twin_of_a_perturbed_calibration_corrects_as_the_true_one(small_gauge_frame,
                                                                      monkeypatch):
    """The same image measured with the true calibration and with one whose mirrors are 0.05°
    out of perpendicular to the sheet (turned about an axis in it) and ±50 µm off: each view's
    mean twin correction agrees with the true calibration's within the issue's 1 µm.

    Measured 2026-12-05 (half scale, Ø12 gauge 2 mm off the axis, twins at 1024 spp, keyed
    sampler), over the default seed and six others: perturbed − true direct −0.21…+0.19,
    left −0.26…+0.24, right +0.19…+0.79 µm; the tilt alone direct +0.04…+0.32, left
    −0.24…+0.19, right +0.48…+0.73 µm (default seed: +0.01/+0.17/+0.55 and +0.17/+0.06/+0.73).
    The right view's +0.5…+0.6 µm is what the twin leaves of a tilted mirror (not identified).
    What made them differ before: (1) the twin was one profile of all views' points, and the
    mirror views 0.1 mm off made it a patchwork whose seams lie at each view's ends, where
    the correction is largest (now each view's twin is the seam-free profile placed where the
    view measured it: ``placed_profile``); (2) the two twins drew independent render noise
    (Mitsuba's sampler is seeded per wavefront lane and the two plans' pixel lists differ):
    at 64 spp single pairs differed by up to 7 µm (now the keyed sampler: a pixel's samples
    are its own).  At 64 spp, keyed, seven seeds: up to 1.3 µm (right) and 2.0 µm (direct,
    the tilt alone, one seed) — the twin's own render noise where the two surfaces differ —
    hence 1024 spp here.  Lit through the calibrated mirrors as they are instead, the tilt
    moves the mirror views' corrections by tens of µm (second part)."""
    from lts360.recon.model import load_calibration

    cal = load_calibration(small_gauge_frame / "frame.json")
    true = _view_corrections(cal, small_gauge_frame, COMPARE_SPP)
    est = _view_corrections(_perturbed_calibration(cal), small_gauge_frame, COMPARE_SPP)
    tilted = _view_corrections(_perturbed_calibration(cal, offset_mm=0.0), small_gauge_frame,
                               COMPARE_SPP)
    assert set(true) == set(est) == set(tilted) == {"direct", "left", "right"}
    for name in true:
        assert all(v[name]["n_uncorrected"] == 0 for v in (true, est, tilted)), name
        assert abs(est[name]["mean_bias_um"] - true[name]["mean_bias_um"]) < 1.0, name
        assert abs(tilted[name]["mean_bias_um"] - true[name]["mean_bias_um"]) < 1.0, name
    # the same mirrors on the laser side light the back off the plane: tens of µm
    import lts360.twin.debias as debias

    monkeypatch.setattr(debias, "laser_side_mirrors", lambda rig: None)
    base = _view_corrections(cal, small_gauge_frame)
    old = _view_corrections(_perturbed_calibration(cal, offset_mm=0.0), small_gauge_frame)
    assert max(abs(old[n]["mean_bias_um"] - base[n]["mean_bias_um"])
               for n in ("left", "right")) > 30.0  # measured: 66 and 57 µm


def test_a_noisy_profile_is_smoothed_to_its_noise_and_loses_its_outliers():
    """Speckle-like noise (σ 30 µm, correlated over ~1°, 2 % spikes of 0.3 mm) on a circle: the
    profile widens its smoothing until the noise is averaged down and drops the spikes; the
    same points without noise keep the 1° profile, a groove's flank included."""
    rng = np.random.default_rng(4)
    n = 4400
    phi = np.sort(rng.uniform(0, 2 * np.pi, n))
    corr = np.convolve(rng.normal(0, 1, n + 11), np.ones(12) / np.sqrt(12), "valid")[:n]
    spikes = np.where(rng.uniform(size=n) < 0.02, 0.3, 0.0)
    groove = np.where(np.abs(phi - 1.0) < 0.05, -0.2, 0.0)  # a 0.2 mm deep, 5.7° wide groove
    rho = 10.0 + groove

    def pts(r):
        return np.column_stack([r * np.cos(phi), r * np.sin(phi)])

    clean = section_profile(pts(rho))
    # only points at the ideal step, in the one bin that straddles it, are off the profile
    assert clean.smooth_deg == 1.0 and clean.n_outliers <= 0.005 * n
    k = np.argmin(np.abs(clean.phi_rad - 1.0))
    assert clean.rho_mm[k] == pytest.approx(9.8, abs=0.01)  # the groove is kept
    noisy = section_profile(pts(10.0 + 0.03 * corr + spikes))
    assert noisy.smooth_deg > 10.0 and noisy.n_outliers >= 0.8 * int((spikes > 0).sum())
    assert 5.0 < noisy.noise_um < 45.0  # about the 1° profile, which follows correlated noise
    assert np.std(noisy.rho_mm) < 8e-3  # 30 µm of noise: a few µm left
    old = section_profile(pts(10.0 + 0.03 * corr + spikes), noise_target_um=None)
    assert np.std(old.rho_mm) > 3 * np.std(noisy.rho_mm) and old.smooth_deg == 1.0

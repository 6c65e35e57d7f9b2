"""cut-tube: watertight boolean mesh, exact truth with partial sections, mesh within
tolerance, validation, placement, spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from meshcheck import face_points, outermost_hit_radius, radial_error  # noqa: E402

import lts360.scenes.objects.cut_tube as ct
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, parse_spec

P = ct.CutTubeParams
#: Vertices of the tube are computed from the radius directly, those of the cut by Manifold in
#: double precision: only float64 rounding separates them from their surfaces.
VERTEX_TOL_MM = 1e-9
#: Barycentric weights of a triangle's centroid and edge midpoints (where the error peaks).
_PROBES = np.array([[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.5, 0.0, 0.5], [0.0, 0.5, 0.5]])


# --- helpers (same in every object test module) -------------------------------------------


# --- fixtures --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def params():
    return P()


@pytest.fixture(scope="module")
def obj(params):
    return params.build()


def _plane_gap_mm(p, points_mm):
    """Height of each point above the cut plane (mm; ≤ 0 inside the solid)."""
    theta = np.arctan2(points_mm[:, 1], points_mm[:, 0])
    return points_mm[:, 2] - p.cut_height_at(theta, np.hypot(points_mm[:, 0], points_mm[:, 1]))


def _outer_faces(obj, p):
    """Faces of the outer cylinder (not the cut face, the caps or the bore)."""
    m = obj.mesh_object
    tri = m.vertices[m.faces]
    split = (p.outer_diameter_mm + p.inner_diameter_mm) / 4
    sel = (np.hypot(tri[..., 0], tri[..., 1]).min(1) > split) & (np.abs(m.face_normals[:, 2]) < 0.5)
    return tri[sel]


def _check_outer_faces(obj, p, weights):
    """Points of ``weights`` on the outer faces, those in the measured zone, against the truth
    (the straight wall has long triangles: select points, not whole faces)."""
    pts = face_points(_outer_faces(obj, p), weights)
    lo, hi = obj.measured_zone_z_mm
    pts = pts[(pts[:, 2] >= lo) & (pts[:, 2] <= hi)]
    err = radial_error(pts, obj.radius_fn)
    ok = np.isfinite(err)
    assert ok.sum() >= 100
    assert np.max(np.abs(err[ok])) <= p.mesh_tolerance_mm
    # Where the truth says "cut away", the point is on a chord just under the cut edge: at most
    # (R − r) tan α above the plane's height at the outer radius.
    R = p.outer_diameter_mm / 2
    theta = np.arctan2(pts[~ok, 1], pts[~ok, 0])
    above = pts[~ok, 2] - p.cut_height_at(theta, R)
    slope = math.tan(math.radians(p.cut_angle_deg))
    assert np.all(above > 0) and np.all(above <= slope * p.mesh_tolerance_mm + VERTEX_TOL_MM)


# --- tests -----------------------------------------------------------------------------------

def test_paper_defaults_and_partial_sections(obj, params):
    assert (params.outer_diameter_mm, obj.sections, obj.pitch_mm) == (25.0, 25, 0.68)
    half = (25 - 1) * 0.68 / 2 + 0.5
    assert obj.measured_zone_z_mm == pytest.approx((-half, half))
    assert obj.material.name == "brass" and obj.name == "cut-tube"
    assert obj.params == dataclasses.asdict(params)
    # Sections of the paper's scan: the upper quarter to half see only part of the circle,
    # none is cut away completely.
    z = (np.arange(25) - 12) * 0.68
    theta = np.linspace(-np.pi, np.pi, 3600, endpoint=False)
    present = np.isfinite(obj.radius_fn(theta[None, :], z[:, None])).mean(axis=1)
    partial = (present > 0) & (present < 1)
    assert np.all(present > 0)
    assert 25 / 4 <= partial.sum() <= 25 / 2
    assert np.all(partial[np.argmax(partial):])  # the partial ones are the upper ones


def test_mesh_is_a_closed_solid_of_the_right_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    p = params
    R, r_in, L = p.outer_diameter_mm / 2, p.inner_diameter_mm / 2, p.length_mm
    n = obj.notes["n_theta"]
    c_n = math.sin(2 * math.pi / n) * n / (2 * math.pi)  # area of the inscribed n-gon / circle
    # A plane through the axis at z_c cuts a centred prism at its mean height z_c (the first
    # moments of the cross-section vanish): exact for the n-gon tube and for the true one.
    volume = math.pi * (R ** 2 - r_in ** 2) * (p.cut_height_mm + L / 2)
    assert m.volume == pytest.approx(c_n * volume, rel=1e-12)
    # The cut face is the annulus seen through the inclined plane.
    slope, az = math.tan(math.radians(p.cut_angle_deg)), math.radians(p.cut_azimuth_deg)
    up = np.array([-slope * math.cos(az), -slope * math.sin(az), 1.0])
    up /= np.linalg.norm(up)
    cut = m.face_normals @ up > 1 - 1e-9
    assert np.max(np.abs(_plane_gap_mm(p, m.vertices[m.faces[cut]].reshape(-1, 3)))) < VERTEX_TOL_MM
    assert m.area_faces[cut].sum() == pytest.approx(
        c_n * math.pi * (R ** 2 - r_in ** 2) / math.cos(math.radians(p.cut_angle_deg)), rel=1e-12)


def test_outer_vertices_lie_on_the_true_surface(obj, params):
    p = params
    v = obj.mesh_object.vertices
    assert np.all(_plane_gap_mm(p, v) <= VERTEX_TOL_MM)  # nothing above the cut
    lo, hi = obj.measured_zone_z_mm
    R = p.outer_diameter_mm / 2
    r = np.hypot(v[:, 0], v[:, 1])
    outer = r > (p.outer_diameter_mm + p.inner_diameter_mm) / 4
    zone = (v[:, 2] >= lo) & (v[:, 2] <= hi)
    on_cut = np.abs(_plane_gap_mm(p, v)) < VERTEX_TOL_MM
    # Tube vertices: exactly on the cylinder.
    assert (outer & zone & ~on_cut).sum() > 1000
    assert np.max(np.abs(radial_error(v[outer & zone & ~on_cut], obj.radius_fn))) < VERTEX_TOL_MM
    # Vertices made by the cut (at least one per side of the n-gon, part of them in the zone):
    # on the plane and on the n-gon, within a chord sagitta of the cylinder.
    assert (outer & on_cut).sum() >= obj.notes["n_theta"] and (outer & on_cut & zone).any()
    assert np.max(np.abs(r[outer & on_cut] - R)) <= p.mesh_tolerance_mm


def test_outer_faces_are_within_tolerance(obj, params):
    rng = np.random.default_rng(41)
    _check_outer_faces(obj, params, np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=200)]))


def test_rays_from_the_axis_meet_the_true_radius(obj, params):
    p = params
    rng = np.random.default_rng(42)
    lo, hi = obj.measured_zone_z_mm
    R = p.outer_diameter_mm / 2
    theta = rng.uniform(-np.pi, np.pi, 200)
    z = rng.uniform(lo, hi, 200)
    # Half of them just above or below the cut edge.
    edge = p.cut_height_at(theta[:100], R) + rng.uniform(-0.05, 0.05, 100)
    z[:100] = np.clip(edge, lo, hi)
    m = obj.mesh_object
    hit = outermost_hit_radius(m.vertices[m.faces], theta, z)
    truth = obj.radius_fn(theta, z)
    there = np.isfinite(truth)
    assert 50 < there.sum() < 190
    assert np.max(np.abs(hit[there] - truth[there])) <= p.mesh_tolerance_mm
    # Where the outer wall is cut away the ray meets at most the cut face (or nothing).
    met = ~there & np.isfinite(hit)
    hit_pts = np.stack([hit * np.cos(theta), hit * np.sin(theta), z], -1)[met]
    assert np.max(np.abs(_plane_gap_mm(p, hit_pts)), initial=0.0) < VERTEX_TOL_MM
    assert np.all(hit[met] <= R)


def test_radius_function_shape(params):
    p = params
    R = p.outer_diameter_mm / 2
    theta = np.linspace(-np.pi, np.pi, 721)
    edge = p.cut_height_at(theta, R)
    assert np.all(p.radius(theta, edge) == R)
    assert np.all(np.isnan(p.radius(theta, edge + 1e-9)))
    assert np.all(p.radius(theta, edge - 1.0) == R)
    rise = R * math.tan(math.radians(p.cut_angle_deg))
    assert edge.max() == pytest.approx(p.cut_height_mm + rise)
    assert theta[np.argmax(edge)] == pytest.approx(math.radians(p.cut_azimuth_deg), abs=0.01)
    assert np.isnan(p.radius(0.0, -p.length_mm / 2 - 1e-6))
    assert p.radius(0.0, -p.length_mm / 2) == R


@settings(max_examples=6)
@given(angle=st.floats(0.0, 45.0), height=st.floats(-6.0, 6.0), azimuth=st.floats(-180, 180),
       inner=st.floats(5.0, 24.0))
# Nearly and exactly horizontal cuts: the plane (almost) contains a ring of the tube grid.
@example(angle=1e-6, height=0.0, azimuth=0.0, inner=5.0)
@example(angle=0.0, height=-2.0, azimuth=0.0, inner=20.0)
def test_any_cut_gives_a_watertight_solid_within_tolerance(angle, height, azimuth, inner):
    p = P(cut_angle_deg=angle, cut_height_mm=height, cut_azimuth_deg=azimuth,
          inner_diameter_mm=inner, mesh_tolerance_mm=0.01)
    obj = p.build()
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent
    n = obj.notes["n_theta"]
    c_n = math.sin(2 * math.pi / n) * n / (2 * math.pi)
    volume = math.pi * (p.outer_diameter_mm ** 2 - inner ** 2) / 4 * (height + p.length_mm / 2)
    assert m.volume == pytest.approx(c_n * volume, rel=1e-9)
    _check_outer_faces(obj, p, _PROBES)


@pytest.mark.parametrize("field, value", [
    ("outer_diameter_mm", 70.0), ("outer_diameter_mm", float("nan")), ("inner_diameter_mm", 0.5),
    ("cut_angle_deg", -1.0), ("cut_angle_deg", 61.0), ("cut_azimuth_deg", 181.0),
    ("cut_height_mm", 25.0), ("length_mm", 10.0), ("mesh_tolerance_mm", 1e-5),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        P(**{field: value})


@settings(max_examples=20)
@given(value=st.one_of(st.floats(max_value=-0.01), st.floats(min_value=60.01)))
def test_any_out_of_range_angle_is_refused(value):
    with pytest.raises(ValueError, match=r"cut_angle_deg must be in \[0, 60\]"):
        P(cut_angle_deg=value)


def test_inconsistent_parameters_fail_with_one_line():
    with pytest.raises(ValueError, match=r"inner_diameter_mm \(25\) must be smaller than "
                                         r"outer_diameter_mm \(25\)") as e:
        P(inner_diameter_mm=25.0)
    assert "\n" not in str(e.value)
    # The cut plane would run out through an end of the tube.
    with pytest.raises(ValueError, match="cut_height_mm.*cut_angle_deg.*length_mm"):
        P(cut_angle_deg=60.0)
    with pytest.raises(ValueError, match="cut_height_mm.*cut_angle_deg.*length_mm"):
        P(cut_height_mm=-15.0)
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params):
    placement = Placement(x_mm=-4.0, y_mm=-3.0, tilt_deg=15.0, tilt_azimuth_deg=200.0)
    obj = params.build(placement)
    v_obj = obj.mesh_object.vertices
    lo, hi = obj.measured_zone_z_mm
    on_cut = np.abs(_plane_gap_mm(params, v_obj)) < VERTEX_TOL_MM
    sel = (np.hypot(v_obj[:, 0], v_obj[:, 1]) > 12.0) & (v_obj[:, 2] >= lo) \
        & (v_obj[:, 2] <= hi) & ~on_cut
    v_world = obj.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(obj.radial_error(v_world))) < VERTEX_TOL_MM


def test_spec_round_trip():
    entry, values, placement = parse_spec("cut-tube:angle=20,cut_z=5,id=18,cut_azimuth=90,x=2")
    assert entry.name == "cut-tube" and entry.params_cls is P
    assert values == {"cut_angle_deg": 20.0, "cut_height_mm": 5.0, "inner_diameter_mm": 18.0,
                      "cut_azimuth_deg": 90.0}
    assert placement == Placement(x_mm=2.0)
    obj = build_object("cut-tube:angle=25,tilt=4,azimuth_deg=30")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    assert np.array_equal(again.mesh_object.faces, obj.mesh_object.faces)

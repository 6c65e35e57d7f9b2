"""cube: exact polygon-section mesh, analytic truth (ray–face intersection), validation,
placement, spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshcheck import face_points, outermost_hit_radius, radial_error  # noqa: E402

import lts360.scenes.objects.cube as cu
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, parse_spec

P = cu.CubeParams
#: The mesh is exact (planar faces through exact vertices): only float64 rounding remains.
EXACT_TOL_MM = 1e-9
#: Barycentric weights of a triangle's centroid and edge midpoints.
_PROBES = np.array([[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.5, 0.0, 0.5], [0.0, 0.5, 0.5]])


# --- helpers (same in every object test module) -------------------------------------------


def barycentric_grid(n):
    """All barycentric weights ``(i, j, n − i − j) / n``."""
    g = [(i, j, n - i - j) for i in range(n + 1) for j in range(n + 1 - i)]
    return np.array(g, dtype=float) / n


def side_faces(obj, zone_only=True):
    """(m, 3, 3) triangles of the outer surface (not the end caps), in the measured zone."""
    m = obj.mesh_object
    tri = m.vertices[m.faces]
    keep = np.ptp(tri[..., 2], axis=1) > 0
    if zone_only:
        lo, hi = obj.measured_zone_z_mm
        keep &= (tri[..., 2].min(1) >= lo) & (tri[..., 2].max(1) <= hi)
    return tri[keep]


def band_faces(obj, j):
    """Side triangles between grid rows ``j`` and ``j + 1`` (star_mesh vertex layout)."""
    n_t = obj.notes["n_theta"]
    f = obj.mesh_object.faces
    rows = f // n_t
    keep = (f < obj.notes["n_z"] * n_t).all(1) & (rows.min(1) == j) & (rows.max(1) == j + 1)
    return obj.mesh_object.vertices[f[keep]]


def distance_to_outline(points_xy, vertices):
    """(n,) distance of 2-D points to the closed polygon outline ``vertices`` (k, 2)."""
    a = vertices
    b = np.roll(vertices, -1, axis=0)
    d = b - a
    t = np.einsum("nkd,kd->nk", points_xy[:, None, :] - a[None], d) / np.einsum("kd,kd->k", d, d)
    foot = a[None] + np.clip(t, 0, 1)[..., None] * d[None]
    return np.linalg.norm(points_xy[:, None, :] - foot, axis=2).min(axis=1)


# --- fixtures --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def params():
    return P()


@pytest.fixture(scope="module")
def obj(params):
    return params.build()


# --- tests -----------------------------------------------------------------------------------

def test_paper_defaults_and_scan(obj, params):
    assert (params.edge_mm, params.groove_depth_mm, params.groove_angle_deg) == (28.0, 1.5, 90.0)
    assert (obj.sections, obj.pitch_mm) == (25, 0.68)
    half = (25 - 1) * 0.68 / 2 + 0.5
    assert obj.measured_zone_z_mm == pytest.approx((-half, half))
    assert obj.material.name == "rust" and obj.name == "cube"
    assert obj.params == dataclasses.asdict(params)
    assert obj.mesh_tolerance_mm == 0.001
    assert obj.notes["groove_width_mm"] == pytest.approx(3.0, rel=1e-15)


def test_mesh_is_a_closed_grooved_cube_of_exact_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent
    a, t, w = params.edge_mm, params.groove_depth_mm, params.groove_width_mm
    assert m.volume == pytest.approx((a * a - t * w / 2) * a, rel=1e-13)
    assert m.bounds == pytest.approx(np.array([[-a / 2] * 3, [a / 2] * 3]), abs=1e-12)
    # Seven grid angles: four corners, two groove edges, the groove bottom.
    assert obj.notes["n_theta"] == 7 and len(m.faces) < 100


def test_mesh_vertices_are_the_section_polygon(obj, params):
    v = obj.mesh_object.vertices
    side = v[np.hypot(v[:, 0], v[:, 1]) > 0]
    assert np.max(np.abs(radial_error(side, obj.radius_fn))) < EXACT_TOL_MM
    poly = params.section_vertices()
    for z in np.unique(side[:, 2]):
        ring = side[side[:, 2] == z][:, :2]
        d = np.linalg.norm(ring[:, None, :] - poly[None], axis=2)
        assert d.shape == (7, 7) and np.max(d.min(axis=1)) < 1e-12 and np.max(d.min(axis=0)) < 1e-12


def test_outer_faces_are_exact(obj):
    tri = side_faces(obj, zone_only=False)
    rng = np.random.default_rng(41)
    weights = np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=200)])
    pts = face_points(tri, weights)
    err = radial_error(pts, obj.radius_fn)
    assert np.all(np.isfinite(err))
    assert np.max(np.abs(err)) < EXACT_TOL_MM <= obj.mesh_tolerance_mm


def test_rays_from_the_axis_meet_the_true_radius(obj, params):
    rng = np.random.default_rng(42)
    lo, hi = obj.measured_zone_z_mm
    theta = rng.uniform(-np.pi, np.pi, 300)
    z = rng.uniform(lo, hi, 300)
    theta[:60] = rng.uniform(-0.2, 0.2, 60)  # the groove
    hit = outermost_hit_radius(side_faces(obj, zone_only=False), theta, z)
    assert np.max(np.abs(hit - obj.radius_fn(theta, z))) < EXACT_TOL_MM


def test_closed_forms(params):
    p = params
    h, t, w = p.edge_mm / 2, p.groove_depth_mm, p.groove_width_mm
    # Plain faces: r = (a/2) / |cos θ| or (a/2) / |sin θ|.
    edge_angle = math.atan2(w / 2, h)
    th = np.linspace(edge_angle, math.pi / 4, 1001)
    for sign in (1, -1):
        assert np.allclose(p.radius(sign * th, 0.0), h / np.cos(th), rtol=1e-14, atol=0)
    th = np.linspace(math.pi / 4, 3 * math.pi / 4, 1001)
    assert np.allclose(p.radius(th, 2.0), h / np.sin(th), rtol=1e-14, atol=0)
    assert np.allclose(p.radius(th + math.pi, 2.0), h / np.sin(th), rtol=1e-14, atol=0)
    assert np.allclose(p.radius(th + math.pi / 2, -3.0), h / np.sin(th), rtol=1e-14, atol=0)
    # Corners, groove bottom and groove edges.
    assert p.radius(math.pi / 4, 0.0) == pytest.approx(h * math.sqrt(2), rel=1e-15)
    assert p.radius(0.0, 0.0) == pytest.approx(h - t, abs=1e-13)
    assert p.radius(edge_angle, 0.0) == pytest.approx(math.hypot(h, w / 2), rel=1e-14)
    # The flanks are at 45° for a 90° groove: r sin θ = r cos θ − (h − t) on the upper flank.
    th = np.linspace(0, edge_angle, 1001)
    r = p.radius(th, 0.0)
    assert np.max(np.abs(r * np.sin(th) - (r * np.cos(th) - (h - t)))) < 1e-13
    # Prism: the same at every height, none beyond the ends.
    assert p.radius(0.3, -h) == p.radius(0.3, h) == p.radius(0.3, 0.0)
    assert np.isnan(p.radius(0.3, h + 1e-9))


@settings(max_examples=60)
@given(theta=st.floats(-10.0, 10.0), z=st.floats(-14.0, 14.0),
       face=st.sampled_from([0, 90, 180, 270]), depth=st.floats(0.1, 5.0),
       angle=st.floats(30.0, 150.0))
def test_radius_lands_on_the_section_outline(theta, z, face, depth, angle):
    if 2 * depth * math.tan(math.radians(angle) / 2) >= 14.0:
        depth = 0.1
    p = P(groove_face_deg=float(face), groove_depth_mm=depth, groove_angle_deg=angle)
    r = float(p.radius(theta, z))
    point = np.array([[r * math.cos(theta), r * math.sin(theta)]])
    assert distance_to_outline(point, p.section_vertices())[0] < 1e-12
    # Rotating the grooved face rotates the radius function.
    p0 = dataclasses.replace(p, groove_face_deg=0.0)
    assert r == pytest.approx(float(p0.radius(theta - math.radians(face), z)), rel=1e-13)


@pytest.mark.parametrize("face", [90.0, 180.0, 270.0])
def test_other_faces_are_exact_too(face, params):
    o = dataclasses.replace(params, groove_face_deg=face).build()
    m = o.mesh_object
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume == pytest.approx(params.build().mesh_object.volume, rel=1e-13)
    tri = side_faces(o, zone_only=False)
    err = radial_error(face_points(tri, _PROBES), o.radius_fn)
    assert np.max(np.abs(err)) < EXACT_TOL_MM


@pytest.mark.parametrize("field, value", [
    ("edge_mm", 19.0), ("edge_mm", 41.0), ("edge_mm", float("nan")), ("groove_depth_mm", 0.05),
    ("groove_depth_mm", 6.0), ("groove_angle_deg", 20.0), ("groove_angle_deg", 170.0),
    ("groove_face_deg", 45.0), ("groove_face_deg", -90.0), ("mesh_tolerance_mm", 1e-6),
    ("mesh_tolerance_mm", 0.05),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field) as e:
        P(**{field: value})
    assert "\n" not in str(e.value)


def test_inconsistent_parameters_fail_with_one_line():
    with pytest.raises(ValueError, match=r"groove_face_deg must be one of 0, 90, 180, 270"):
        P(groove_face_deg=45.0)
    with pytest.raises(ValueError, match=r"groove width .* must be smaller than edge_mm/2") as e:
        P(groove_depth_mm=5.0, groove_angle_deg=150.0)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params):
    placement = Placement(x_mm=1.2, y_mm=4.0, tilt_deg=12.0, tilt_azimuth_deg=200.0)
    placed = params.build(placement)
    v_obj = placed.mesh_object.vertices
    lo, hi = placed.measured_zone_z_mm
    sel = (np.hypot(v_obj[:, 0], v_obj[:, 1]) > 0) & (v_obj[:, 2] >= lo) & (v_obj[:, 2] <= hi)
    assert sel.sum() == 14  # the two rings at the zone limits
    v_world = placed.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(placed.radial_error(v_world))) < EXACT_TOL_MM


def test_spec_round_trip():
    entry, values, placement = parse_spec("cube:face=90,depth=1,angle=60,y=-2")
    assert entry.name == "cube" and entry.params_cls is P
    assert values == {"groove_face_deg": 90.0, "groove_depth_mm": 1.0, "groove_angle_deg": 60.0}
    assert placement == Placement(y_mm=-2.0)
    obj = build_object("cube:face=180,tilt=3,x=0.5")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    with pytest.raises(ValueError, match="unknown parameter"):
        parse_spec("cube:bogus=1")

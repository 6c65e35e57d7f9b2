"""grooved-shaft: watertight twisted mesh, exact helical truth, mesh within tolerance,
validation, placement, spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshcheck import _wrap, face_points, outermost_hit_radius, radial_error  # noqa: E402
from scipy.integrate import quad

import lts360.scenes.objects.grooved_shaft as gs
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, parse_spec

P = gs.GroovedShaftParams
#: Vertices are computed from r(θ, z) directly: only float64 rounding separates them.
VERTEX_TOL_MM = 1e-8
#: Barycentric weights of a triangle's centroid and edge midpoints (where the error peaks).
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


# --- fixtures --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def params():
    return P()


@pytest.fixture(scope="module")
def obj(params):
    return params.build()


# --- tests -----------------------------------------------------------------------------------

def test_paper_defaults_and_scan(obj, params):
    assert params.diameter_mm == 13.0 and params.handedness == "right"
    assert (obj.sections, obj.pitch_mm) == (20, 0.68)
    half = (20 - 1) * 0.68 / 2 + 0.5
    assert obj.measured_zone_z_mm == pytest.approx((-half, half))
    assert obj.material.name == "black-oxide-steel" and obj.name == "grooved-shaft"
    assert obj.params == dataclasses.asdict(params)
    assert obj.mesh_tolerance_mm == params.mesh_tolerance_mm == 0.001
    assert obj.spec.startswith("grooved-shaft:diameter_mm=13.0,")


def test_mesh_is_closed_and_of_the_right_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert len(m.faces) < 2_000_000
    p = params
    R, L = p.diameter_mm / 2, p.length_mm
    # Every section z = const is the same up to a rotation: area = ½ ∫ f² dφ.  The groove
    # removes ½ ∫ (R² − f²) dφ with dφ = 2π du / lead.
    removed, _ = quad(lambda u: (R * R - p.profile(2 * math.pi * u / p.groove_lead_mm) ** 2) / 2,
                      -p.groove_width_mm / 2, p.groove_width_mm / 2, epsabs=1e-13)
    volume = L * (math.pi * R * R - 2 * math.pi / p.groove_lead_mm * removed)
    # Vertices lie on the surface; chords are off it by at most the tolerance.
    assert abs(m.volume - volume) <= 2 * math.pi * R * L * obj.mesh_tolerance_mm
    assert abs(m.volume - volume) > 0  # not trivially equal: the mesh is an approximation


def test_outer_vertices_lie_on_the_true_surface(obj):
    v = obj.mesh_object.vertices
    lo, hi = obj.measured_zone_z_mm
    sel = (np.hypot(v[:, 0], v[:, 1]) > 0) & (v[:, 2] >= lo) & (v[:, 2] <= hi)
    assert sel.sum() > 10_000
    assert np.max(np.abs(radial_error(v[sel], obj.radius_fn))) < VERTEX_TOL_MM


def test_groove_edges_are_grid_helices(obj, params):
    # The kinks of the profile are grid lines: some vertex sits at φ = ±π w / L of every row.
    v = obj.mesh_object.vertices
    v = v[np.hypot(v[:, 0], v[:, 1]) > 0]
    phi = _wrap(np.arctan2(v[:, 1], v[:, 0]) - params.twist_rad_per_mm * v[:, 2])
    a = params.groove_half_angle_rad
    for edge in (-a, a):
        on = np.abs(_wrap(phi - edge)) < 1e-12
        assert on.sum() == obj.notes["n_z"]


def test_outer_faces_are_within_tolerance(obj):
    tri = side_faces(obj)
    rng = np.random.default_rng(21)
    weights = np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=4)])
    err = radial_error(face_points(tri, weights), obj.radius_fn)
    assert np.all(np.isfinite(err))
    assert np.max(np.abs(err)) <= obj.mesh_tolerance_mm


def test_rows_are_congruent_so_one_dense_band_bounds_the_whole_mesh(obj, params):
    n_t, n_z = obj.notes["n_theta"], obj.notes["n_z"]
    rows = obj.mesh_object.vertices[: n_t * n_z].reshape(n_z, n_t, 3)
    z = rows[:, 0, 2]
    turn = params.twist_rad_per_mm * (z - z[0])
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    x0, y0 = rows[0, :, 0][None, :], rows[0, :, 1][None, :]
    assert np.max(np.abs(rows[..., 0] - (c * x0 - s * y0))) < 1e-9
    assert np.max(np.abs(rows[..., 1] - (s * x0 + c * y0))) < 1e-9
    # So a dense sampling of one band measures the error of every band.
    tri = band_faces(obj, n_z // 2)
    assert len(tri) == 2 * n_t
    err = radial_error(face_points(tri, barycentric_grid(24)), obj.radius_fn)
    assert np.max(np.abs(err)) <= obj.mesh_tolerance_mm


def test_rays_from_the_axis_meet_the_true_radius(obj, params):
    rng = np.random.default_rng(22)
    lo, hi = obj.measured_zone_z_mm
    z = rng.uniform(lo, hi, 160)
    theta = rng.uniform(-np.pi, np.pi, 160)
    # The groove and its edges, where the profile is steepest.
    a = params.groove_half_angle_rad
    theta[:60] = params.twist_rad_per_mm * z[:60] + rng.choice([-a, a], 60) \
        + rng.normal(0.0, 0.05, 60)
    hit = outermost_hit_radius(side_faces(obj, zone_only=False), theta, z)
    assert np.max(np.abs(hit - obj.radius_fn(theta, z))) <= obj.mesh_tolerance_mm


def test_groove_profile_is_the_circular_arc(params):
    p = params
    R, t, w, L = p.diameter_mm / 2, p.groove_depth_mm, p.groove_width_mm, p.groove_lead_mm
    rho = p.arc_radius_mm
    assert rho == pytest.approx((w * w / 4 + t * t) / (2 * t), rel=1e-15)
    # Right hand: the groove centre crosses θ = 0 at z = 0 and advances by one lead per turn.
    assert p.radius(0.0, 0.0) == pytest.approx(R - t, abs=1e-12)
    assert p.radius(math.pi / 2, L / 4) == pytest.approx(R - t, abs=1e-12)
    assert p.radius(math.pi / 2, -L / 4) == pytest.approx(R, abs=1e-12)
    # Along the axis at θ = 0 the section is the arc (u, r): u² + (r − (R − t + ρ))² = ρ².
    u = np.linspace(-w / 2, w / 2, 1001)
    r = p.radius(np.zeros_like(u), u)
    assert np.max(np.abs(u ** 2 + (r - (R - t + rho)) ** 2 - rho ** 2)) < 1e-12
    assert np.all(r <= R + 1e-15) and r[0] == pytest.approx(R, abs=1e-12)
    # Beyond the groove the shaft is the plain cylinder, and beyond its ends there is none.
    u_out = np.linspace(w / 2, L - w / 2, 1001)
    assert np.all(p.radius(0.0, u_out) == R)
    assert np.isnan(p.radius(0.0, p.length_mm / 2 + 1e-6))


def test_left_hand_groove_is_the_mirror_image(params, obj):
    left = dataclasses.replace(params, handedness="left")
    theta = np.linspace(-3, 3, 101)
    z = np.linspace(-5, 5, 101)
    assert np.allclose(left.radius(theta, z), params.radius(-theta, z), rtol=0, atol=1e-12)
    m = left.build().mesh_object
    assert m.is_watertight and m.is_winding_consistent
    # Same profile, same grid rules: the same volume up to the float rounding of the nodes.
    assert m.volume == pytest.approx(obj.mesh_object.volume, rel=1e-12)


@settings(max_examples=40)
@given(theta=st.floats(-np.pi, np.pi), z=st.floats(-10.0, 10.0), dz=st.floats(-8.0, 8.0),
       hand=st.sampled_from(["right", "left"]), lead=st.floats(4.0, 100.0))
def test_helical_invariance(theta, z, dz, hand, lead):
    p = P(handedness=hand, groove_lead_mm=lead)
    moved = p.radius(theta + 2 * math.pi * dz / lead * (1 if hand == "right" else -1), z + dz)
    assert moved == pytest.approx(p.radius(theta, z), abs=1e-11)


@settings(max_examples=10)
@given(diameter=st.floats(5.0, 40.0), lead=st.floats(6.0, 100.0), width=st.floats(0.2, 5.0),
       depth_share=st.floats(0.05, 1.0), hand=st.sampled_from(["right", "left"]),
       phase=st.floats(-180.0, 180.0))
def test_resolution_rule_holds_for_any_parameters(diameter, lead, width, depth_share, hand, phase):
    # A coarse tolerance keeps the meshes small; the rule is the same at every tolerance.
    width = min(width, 0.9 * lead)
    depth = max(0.02, depth_share * 0.4 * width)
    p = P(diameter_mm=diameter, groove_lead_mm=lead, groove_width_mm=width, groove_depth_mm=depth,
          handedness=hand, groove_phase_deg=phase, length_mm=16.0, mesh_tolerance_mm=0.01)
    obj = p.build()
    assert obj.mesh_object.is_watertight
    tri = band_faces(obj, obj.notes["n_z"] // 2)
    err = radial_error(face_points(tri, barycentric_grid(12)), obj.radius_fn)
    assert np.max(np.abs(err)) <= p.mesh_tolerance_mm


@pytest.mark.parametrize("field, value", [
    ("diameter_mm", 4.0), ("diameter_mm", float("nan")), ("groove_lead_mm", 3.0),
    ("groove_lead_mm", 120.0), ("groove_width_mm", 0.1), ("groove_width_mm", 6.0),
    ("groove_depth_mm", 0.01), ("groove_depth_mm", 0.7), ("handedness", "up"),
    ("groove_phase_deg", 181.0), ("length_mm", 15.0), ("length_mm", 250.0),
    ("mesh_tolerance_mm", 1e-6), ("mesh_tolerance_mm", 0.1),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field) as e:
        P(**{field: value})
    assert "\n" not in str(e.value)


def test_inconsistent_parameters_fail_with_one_line():
    with pytest.raises(ValueError, match="groove_width_mm .* must be smaller than groove_lead_mm"):
        P(groove_lead_mm=4.0, groove_width_mm=4.5, groove_depth_mm=0.5)
    with pytest.raises(ValueError, match=r"groove_depth_mm must be in \[0.02, 0.6\]"):
        P(groove_depth_mm=0.61)
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params, obj):
    placement = Placement(x_mm=2.5, y_mm=-3.1, tilt_deg=6.0, tilt_azimuth_deg=-35.0)
    placed = params.build(placement)
    v_obj = placed.mesh_object.vertices
    lo, hi = placed.measured_zone_z_mm
    sel = (np.hypot(v_obj[:, 0], v_obj[:, 1]) > 0) & (v_obj[:, 2] >= lo) & (v_obj[:, 2] <= hi)
    v_world = placed.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(placed.radial_error(v_world))) < VERTEX_TOL_MM
    assert np.array_equal(v_obj, obj.mesh_object.vertices)


def test_spec_round_trip():
    entry, values, placement = parse_spec("grooved-shaft:d=13,lead=8,hand=left,depth=0.3,x=1.5")
    assert entry.name == "grooved-shaft" and entry.params_cls is P
    assert values == {"diameter_mm": 13.0, "groove_lead_mm": 8.0, "handedness": "left",
                      "groove_depth_mm": 0.3}
    assert placement == Placement(x_mm=1.5)
    obj = build_object("grooved-shaft:lead=20,tol=0.005,phase=30,tilt=2")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    with pytest.raises(ValueError, match="unknown parameter"):
        parse_spec("grooved-shaft:bogus=1")

"""undercut-shaft: watertight mesh, exact truth, mesh within tolerance, validation, placement,
spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from meshcheck import face_points, outermost_hit_radius, radial_error  # noqa: E402
from scipy.integrate import quad

import lts360.scenes.objects.undercut_shaft as us
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, parse_spec

P = us.UndercutShaftParams
#: Vertices are computed from r(θ, z) directly: only float64 rounding separates them.
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


def _outer_zone_faces(obj):
    """Faces of the shaft's side (not the end fans around the axis) in the measured zone."""
    m = obj.mesh_object
    tri = m.vertices[m.faces]
    lo, hi = obj.measured_zone_z_mm
    side = np.hypot(tri[..., 0], tri[..., 1]).min(1) > 1.0
    inside = (tri[..., 2].min(1) >= lo) & (tri[..., 2].max(1) <= hi)
    return tri[side & inside]


# --- tests -----------------------------------------------------------------------------------

def test_paper_defaults_and_scan(obj, params):
    assert params.diameter_mm == 25.0
    assert (obj.sections, obj.pitch_mm) == (25, 0.68)
    half = (25 - 1) * 0.68 / 2 + 0.5
    assert obj.measured_zone_z_mm == pytest.approx((-half, half))
    assert obj.material.name == "ground-steel" and obj.name == "undercut-shaft"
    assert obj.params == dataclasses.asdict(params)
    lo, hi = obj.measured_zone_z_mm
    assert lo < params.groove_z_mm - params.groove_width_mm / 2
    assert params.groove_z_mm + params.groove_width_mm / 2 < hi


def test_mesh_is_a_closed_solid_of_the_right_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert len(m.faces) < 1_500_000
    n = obj.notes["n_theta"]
    c_n = math.sin(2 * math.pi / n) * n / (2 * math.pi)  # area of the inscribed n-gon / circle
    # Between two rings the mesh is a frustum of a regular n-gon: exact volume.
    z = np.unique(m.vertices[:, 2])
    r = params.radius(0.0, z)
    frusta = math.pi * np.sum(np.diff(z) / 3 * (r[:-1] ** 2 + r[:-1] * r[1:] + r[1:] ** 2))
    assert m.volume == pytest.approx(c_n * frusta, rel=1e-12)
    # And the true solid of revolution, integrated piece by piece.
    h = params.length_mm / 2
    knots = [-h, *obj.notes["profile_breaks_z_mm"], h]
    volume = sum(quad(lambda zz: math.pi * params.radius(0.0, zz) ** 2, a, b, epsabs=1e-10)[0]
                 for a, b in zip(knots[:-1], knots[1:]))
    area = math.pi * params.diameter_mm * params.length_mm
    assert abs(m.volume - c_n * volume) <= area * obj.mesh_tolerance_mm
    assert abs(frusta - volume) <= area * obj.mesh_tolerance_mm


def test_rings_sit_on_every_kink(obj):
    z = np.unique(obj.mesh_object.vertices[:, 2])
    for k in obj.notes["profile_breaks_z_mm"]:
        assert np.min(np.abs(z - k)) == 0.0


def test_vertices_lie_on_the_true_surface(obj):
    v = obj.mesh_object.vertices
    lo, hi = obj.measured_zone_z_mm
    sel = (np.hypot(v[:, 0], v[:, 1]) > 1.0) & (v[:, 2] >= lo) & (v[:, 2] <= hi)
    assert sel.sum() > 5_000
    assert np.max(np.abs(radial_error(v[sel], obj.radius_fn))) < VERTEX_TOL_MM


def test_outer_faces_are_within_tolerance(obj):
    tri = _outer_zone_faces(obj)
    rng = np.random.default_rng(31)
    weights = np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=40)])
    err = radial_error(face_points(tri, weights), obj.radius_fn)
    assert np.all(np.isfinite(err))
    assert np.max(np.abs(err)) <= obj.mesh_tolerance_mm


def test_rays_from_the_axis_meet_the_true_radius(obj, params):
    rng = np.random.default_rng(32)
    lo, hi = obj.measured_zone_z_mm
    theta = rng.uniform(-np.pi, np.pi, 200)
    z = rng.uniform(lo, hi, 200)
    z[:100] = params.groove_z_mm + rng.uniform(-2.0, 2.0, 100)  # half of them in the groove
    m = obj.mesh_object
    hit = outermost_hit_radius(m.vertices[m.faces], theta, z)
    assert np.max(np.abs(hit - obj.radius_fn(theta, z))) <= obj.mesh_tolerance_mm


def test_profile_is_a_din509_like_groove(params):
    p = params
    R, t, rho = p.diameter_mm / 2, p.groove_depth_mm, p.fillet_radius_mm
    u_c, u_e, a = p.profile_breaks_mm()
    assert 0 <= u_c < u_e <= a == p.groove_width_mm / 2
    z = p.groove_z_mm + np.linspace(-4.0, 4.0, 160001)
    r = p.radius(0.0, z)
    u = np.abs(z - p.groove_z_mm)
    assert np.all(r[u >= a] == R) and np.all(r[u <= u_c] == R - t)
    assert r.min() == R - t and np.allclose(r, r[::-1], atol=1e-12)  # symmetric
    # The fillets are arcs of radius ρ tangent to the bottom.
    f = (u > u_c) & (u < u_e)
    assert np.allclose(np.hypot(u[f] - u_c, r[f] - (R - t + rho)), rho, atol=1e-12)
    # The flanks are straight at the flank angle.
    fl = (u > u_e) & (u < a)
    slope = np.diff(r)[fl[1:] & fl[:-1]] / np.diff(z)[0]
    assert np.allclose(np.abs(slope), math.tan(math.radians(p.flank_angle_deg)), rtol=1e-6)
    # Continuous, and C¹ at the fillet ends (the kink is at the groove edge only).
    dz = z[1] - z[0]
    assert np.max(np.abs(np.diff(r))) <= math.tan(math.radians(p.flank_angle_deg)) * dz * (1 + 1e-6)
    d = np.diff(r) / dz
    jump = np.abs(np.diff(d))
    edge = np.abs(np.abs(z[1:-1] - p.groove_z_mm) - a) < 2 * dz
    assert jump[edge].max() > 0.5 and jump[~edge].max() < 0.02
    assert np.isnan(p.radius(0.0, p.length_mm / 2 + 1e-6))
    assert p.radius(np.zeros((2, 3)), 0.0).shape == (2, 3)


@settings(max_examples=10)
@given(depth=st.floats(0.05, 2.0), fillet=st.floats(0.1, 5.0), flank=st.floats(10.0, 80.0),
       extra=st.floats(0.0, 3.0), groove_z=st.floats(-3.0, 3.0))
@example(depth=2.0, fillet=0.1, flank=80.0, extra=0.0, groove_z=0.0)  # steepest fillet end
def test_resolution_rule_holds_for_any_parameters(depth, fillet, flank, extra, groove_z):
    width = us.min_groove_width_mm(depth, fillet, flank) + extra
    assume(width <= 10.0)
    # A coarse tolerance keeps the meshes small; the rule is the same at every tolerance.
    p = P(groove_depth_mm=depth, fillet_radius_mm=fillet, flank_angle_deg=flank,
          groove_width_mm=width, groove_z_mm=groove_z, mesh_tolerance_mm=0.01)
    obj = p.build()
    err = radial_error(face_points(_outer_zone_faces(obj), _PROBES), obj.radius_fn)
    assert np.max(np.abs(err)) <= p.mesh_tolerance_mm


@pytest.mark.parametrize("field, value", [
    ("diameter_mm", 4.0), ("diameter_mm", float("nan")), ("groove_depth_mm", 0.0),
    ("groove_depth_mm", 2.5), ("fillet_radius_mm", 0.05), ("fillet_radius_mm", 6.0),
    ("flank_angle_deg", 90.0), ("flank_angle_deg", 5.0), ("groove_width_mm", 11.0),
    ("groove_z_mm", 19.0), ("length_mm", 10.0), ("mesh_tolerance_mm", 0.02),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        P(**{field: value})


@settings(max_examples=20)
@given(value=st.one_of(st.floats(max_value=9.9), st.floats(min_value=80.1)))
def test_any_out_of_range_flank_angle_is_refused(value):
    with pytest.raises(ValueError, match=r"flank_angle_deg must be in \[10, 80\]"):
        P(flank_angle_deg=value)


def test_inconsistent_parameters_fail_with_one_line():
    # Too narrow for its depth, fillets and flanks: the message gives the smallest width.
    with pytest.raises(ValueError, match=r"groove_width_mm must be in \[1\.29706") as e:
        P(groove_width_mm=1.0)
    assert "\n" not in str(e.value)
    P(groove_width_mm=us.min_groove_width_mm(0.4, 0.6, 45.0))  # zero-width flat bottom is allowed
    with pytest.raises(ValueError, match="need a groove_width_mm of at least 11.5"):
        P(groove_depth_mm=1.0, fillet_radius_mm=1.0, flank_angle_deg=10.0)
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params):
    placement = Placement(x_mm=1.1, y_mm=2.2, tilt_deg=20.0, tilt_azimuth_deg=123.0)
    obj = params.build(placement)
    v_obj = obj.mesh_object.vertices
    lo, hi = obj.measured_zone_z_mm
    sel = (np.hypot(v_obj[:, 0], v_obj[:, 1]) > 1.0) & (v_obj[:, 2] >= lo) & (v_obj[:, 2] <= hi)
    v_world = obj.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(obj.radial_error(v_world))) < VERTEX_TOL_MM


def test_spec_round_trip():
    entry, values, placement = parse_spec("undercut-shaft:width=4,depth=0.3,fillet=1,tilt=1")
    assert entry.name == "undercut-shaft" and entry.params_cls is P
    assert values == {"groove_width_mm": 4.0, "groove_depth_mm": 0.3, "fillet_radius_mm": 1.0}
    assert placement == Placement(tilt_deg=1.0)
    obj = build_object("undercut-shaft:flank=30,x=0.5")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)

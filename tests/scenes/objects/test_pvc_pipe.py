"""pvc-pipe: watertight mesh, exact truth, mesh within tolerance, validation, placement, spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from meshcheck import face_points, outermost_hit_radius, radial_error  # noqa: E402
from scipy.special import erf, ive

import lts360.scenes.objects.pvc_pipe as pvc
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, parse_spec

P = pvc.PvcPipeParams
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


def _outer_face_mask(mesh):
    """Faces of the outer surface: their normals point away from the axis (the bore's point
    towards it, the end caps' along it)."""
    centroid = mesh.triangles_center
    radial = centroid[:, :2] / np.hypot(centroid[:, 0], centroid[:, 1])[:, None]
    return np.einsum("ij,ij->i", mesh.face_normals[:, :2], radial) > 0.5


def _outer_zone_vertex_mask(obj):
    m = obj.mesh_object
    lo, hi = obj.measured_zone_z_mm
    outer = np.zeros(len(m.vertices), dtype=bool)
    outer[m.faces[_outer_face_mask(m)].ravel()] = True
    return outer & (m.vertices[:, 2] >= lo) & (m.vertices[:, 2] <= hi)


def _outer_zone_faces(obj):
    m = obj.mesh_object
    tri = m.vertices[m.faces]
    lo, hi = obj.measured_zone_z_mm
    inside = (tri[..., 2].min(1) >= lo) & (tri[..., 2].max(1) <= hi)
    return tri[_outer_face_mask(m) & inside]


# --- tests -----------------------------------------------------------------------------------

def test_paper_defaults_and_scan(obj, params):
    assert (params.outer_diameter_mm, params.wall_mm) == (32.0, 2.1)
    assert (obj.sections, obj.pitch_mm) == (26, 0.68)
    half = (26 - 1) * 0.68 / 2 + 0.5
    assert obj.measured_zone_z_mm == pytest.approx((-half, half))
    assert obj.material.name == "white-pvc" and obj.name == "pvc-pipe"
    assert obj.params == dataclasses.asdict(params)
    assert obj.mesh_tolerance_mm == params.mesh_tolerance_mm == 0.001


def test_mesh_is_a_closed_tube_of_the_right_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert len(m.faces) < 1_500_000
    p = params
    R, w, L = p.outer_diameter_mm / 2, p.wall_mm, p.length_mm
    k = (R / p.dent_sigma_arc_mm) ** 2
    s = p.dent_sigma_z_mm * math.sqrt(2)
    i_theta = 2 * math.pi * ive(0, k)  # ∫ exp(-k (1 - cos θ)) dθ
    i_z = p.dent_sigma_z_mm * math.sqrt(math.pi / 2) * (erf((L / 2 - p.dent_z_mm) / s)
                                                        + erf((L / 2 + p.dent_z_mm) / s))
    # ∬ (r² - (r - w)²) / 2 dθ dz; the ovality integrates to zero.
    volume = w * (2 * math.pi * R * L - p.dent_depth_mm * i_theta * i_z) - math.pi * w * w * L
    # Vertices lie on the surfaces, so the mesh misses the chord segments of its regular
    # n-gons: area factor c_n.  What remains is the interpolation error of the deformations,
    # at most the tolerance over both surfaces.
    n = obj.notes["n_theta"]
    c_n = math.sin(2 * math.pi / n) * n / (2 * math.pi)
    area = 2 * math.pi * (2 * R - w) * L
    assert abs(m.volume - c_n * volume) <= area * obj.mesh_tolerance_mm


def test_outer_vertices_lie_on_the_true_surface(obj, params):
    v = obj.mesh_object.vertices
    lo, hi = obj.measured_zone_z_mm
    sel = _outer_zone_vertex_mask(obj)
    assert sel.sum() > 10_000
    assert np.max(np.abs(radial_error(v[sel], obj.radius_fn))) < VERTEX_TOL_MM
    # The inner surface is the outer one moved in by the wall.
    inner = v[~sel & (v[:, 2] >= lo) & (v[:, 2] <= hi)]
    theta = np.arctan2(inner[:, 1], inner[:, 0])
    r_in = np.hypot(inner[:, 0], inner[:, 1])
    assert np.max(np.abs(r_in - params.inner_radius(theta, inner[:, 2]))) < VERTEX_TOL_MM


def test_outer_faces_are_within_tolerance(obj, params):
    tri = _outer_zone_faces(obj)
    rng = np.random.default_rng(11)
    weights = np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=12)])
    err = radial_error(face_points(tri, weights), obj.radius_fn)
    assert np.all(np.isfinite(err))
    assert np.max(np.abs(err)) <= obj.mesh_tolerance_mm


def test_rays_from_the_axis_meet_the_true_radius(obj):
    rng = np.random.default_rng(12)
    lo, hi = obj.measured_zone_z_mm
    theta = rng.uniform(-np.pi, np.pi, 150)
    z = rng.uniform(lo, hi, 150)
    # The dent itself, where the curvature is largest.
    theta[:20] = math.radians(obj.params["dent_theta_deg"]) + rng.normal(0, 0.1, 20)
    z[:20] = np.clip(obj.params["dent_z_mm"] + rng.normal(0, 1.0, 20), lo, hi)
    m = obj.mesh_object
    hit = outermost_hit_radius(m.vertices[m.faces], theta, z)
    assert np.max(np.abs(hit - obj.radius_fn(theta, z))) <= obj.mesh_tolerance_mm


def test_radius_function_shape(params):
    p = params
    theta = np.linspace(-np.pi, np.pi, 20001)
    R = p.outer_diameter_mm / 2
    # Dent: deepest at its centre, depth as given (the ovality there is known).
    t_d = math.radians(p.dent_theta_deg)
    oval_at_dent = p.ovality_mm / 4 * math.cos(2 * (t_d - math.radians(p.ovality_angle_deg)))
    deepest = R + oval_at_dent - p.dent_depth_mm
    assert p.radius(t_d, p.dent_z_mm) == pytest.approx(deepest, abs=1e-12)
    # Far from the dent: pure ovality, D_max - D_min = ovality_mm, major axis as given.
    z_far = p.dent_z_mm + 10 * p.dent_sigma_z_mm
    p_far = dataclasses.replace(p, length_mm=200.0)
    diam = p_far.radius(theta, z_far) + p_far.radius(theta + np.pi, z_far)
    assert diam.max() - diam.min() == pytest.approx(p.ovality_mm, abs=1e-9)
    major = theta[np.argmax(diam)]
    assert abs(math.remainder(major - math.radians(p.ovality_angle_deg), np.pi)) < 1e-3
    # Periodic, and NaN beyond the ends.
    assert np.allclose(p.radius(theta, 0.3), p.radius(theta + 2 * np.pi, 0.3), atol=1e-12)
    assert np.isnan(p.radius(0.0, p.length_mm / 2 + 1e-6))
    assert np.isfinite(p.radius(0.0, p.length_mm / 2))


@settings(max_examples=8)
@given(depth=st.floats(0.0, 1.5), sigma_arc=st.floats(2.0, 20.0), sigma_z=st.floats(2.0, 20.0),
       ovality=st.floats(0.0, 3.2), oval_deg=st.floats(-180, 180), dent_deg=st.floats(-180, 180),
       dent_z=st.floats(-9.0, 9.0))
# Sharpest dent and strongest ovality: the inner and outer radius ranges overlap.
@example(depth=1.5, sigma_arc=2.0, sigma_z=2.0, ovality=3.2, oval_deg=0.0, dent_deg=0.0, dent_z=0.0)
def test_resolution_rule_holds_for_any_parameters(depth, sigma_arc, sigma_z, ovality, oval_deg,
                                                  dent_deg, dent_z):
    # A coarse tolerance keeps the meshes small; the rule is the same at every tolerance.
    p = P(dent_depth_mm=depth, dent_sigma_arc_mm=sigma_arc, dent_sigma_z_mm=sigma_z,
          ovality_mm=ovality, ovality_angle_deg=oval_deg, dent_theta_deg=dent_deg,
          dent_z_mm=dent_z, mesh_tolerance_mm=0.01)
    obj = p.build()
    tri = _outer_zone_faces(obj)
    err = radial_error(face_points(tri, _PROBES), obj.radius_fn)
    assert np.max(np.abs(err)) <= p.mesh_tolerance_mm


@pytest.mark.parametrize("field, value", [
    ("outer_diameter_mm", 5.0), ("outer_diameter_mm", float("nan")), ("wall_mm", 0.1),
    ("ovality_mm", -0.1), ("ovality_mm", 4.0), ("ovality_angle_deg", 200.0),
    ("dent_depth_mm", -0.1), ("dent_depth_mm", 2.5), ("dent_sigma_arc_mm", 1.0),
    ("dent_sigma_z_mm", 25.0), ("dent_theta_deg", -181.0), ("dent_z_mm", 9.5),
    ("length_mm", 15.0), ("mesh_tolerance_mm", 1e-6), ("mesh_tolerance_mm", 0.1),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        P(**{field: value})


@settings(max_examples=20)
@given(value=st.one_of(st.floats(max_value=9.99), st.floats(min_value=60.01)))
def test_any_out_of_range_diameter_is_refused(value):
    with pytest.raises(ValueError, match=r"outer_diameter_mm must be in \[10, 60\]"):
        P(outer_diameter_mm=value)


def test_inconsistent_parameters_fail_with_one_line():
    with pytest.raises(ValueError, match="dent_depth_mm .* must be smaller than wall_mm") as e:
        P(dent_depth_mm=2.2)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="outer_diameter_mm/2"):
        P(outer_diameter_mm=10.0, wall_mm=4.0, dent_depth_mm=1.0, ovality_mm=1.0)
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params):
    placement = Placement(x_mm=3.2, y_mm=-1.7, tilt_deg=7.5, tilt_azimuth_deg=40.0)
    obj = params.build(placement)
    v_obj = obj.mesh_object.vertices
    sel = _outer_zone_vertex_mask(obj)
    v_world = obj.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(obj.radial_error(v_world))) < VERTEX_TOL_MM


def test_spec_round_trip():
    entry, values, placement = parse_spec("pvc-pipe:od=32,dent=0.5,ovality_angle_deg=30,x=1.5")
    assert entry.name == "pvc-pipe" and entry.params_cls is P
    assert values == {"outer_diameter_mm": 32.0, "dent_depth_mm": 0.5, "ovality_angle_deg": 30.0}
    assert placement == Placement(x_mm=1.5)
    obj = build_object("pvc-pipe:dent=0.5,tol=0.005,tilt=2")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    with pytest.raises(ValueError, match="unknown parameter"):
        parse_spec("pvc-pipe:bogus=1")

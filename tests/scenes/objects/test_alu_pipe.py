"""alu-pipe: watertight mesh, exact truth, mesh within tolerance, validation, placement, spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from meshcheck import face_points, outermost_hit_radius, radial_error  # noqa: E402

import lts360.scenes.objects.alu_pipe as alu
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, parse_spec

P = alu.AluPipeParams
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
    assert params.outer_diameter_mm == 22.0
    assert (obj.sections, obj.pitch_mm) == (26, 0.68)
    half = (26 - 1) * 0.68 / 2 + 0.5
    assert obj.measured_zone_z_mm == pytest.approx((-half, half))
    assert obj.material.name == "machined-aluminium" and obj.name == "alu-pipe"
    assert obj.params == dataclasses.asdict(params)
    assert obj.mesh_tolerance_mm == params.mesh_tolerance_mm == 0.001


def test_mesh_is_a_closed_tube_of_the_right_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert len(m.faces) < 1_500_000
    p = params
    R, w, L = p.outer_diameter_mm / 2, p.wall_mm, p.length_mm
    lam, phase = p.waviness_wavelength_mm, math.radians(p.waviness_phase_deg)
    wave = p.waviness_amplitude_mm * lam / (2 * math.pi) * (
        math.sin(math.pi * L / lam + phase) - math.sin(-math.pi * L / lam + phase))
    # ∬ (r² - (r - w)²) / 2 dθ dz; the lobes integrate to zero.
    volume = w * (2 * math.pi * R * L + 2 * math.pi * wave) - math.pi * w * w * L
    # Vertices lie on the surfaces, so the mesh misses the chord segments of its regular
    # n-gons: area factor c_n.  What remains is the interpolation error of the undulations,
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
    inner = v[~sel & (v[:, 2] >= lo) & (v[:, 2] <= hi)]
    theta = np.arctan2(inner[:, 1], inner[:, 0])
    r_in = np.hypot(inner[:, 0], inner[:, 1])
    assert np.max(np.abs(r_in - params.inner_radius(theta, inner[:, 2]))) < VERTEX_TOL_MM


def test_outer_faces_are_within_tolerance(obj, params):
    tri = _outer_zone_faces(obj)
    rng = np.random.default_rng(21)
    weights = np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=12)])
    err = radial_error(face_points(tri, weights), obj.radius_fn)
    assert np.all(np.isfinite(err))
    assert np.max(np.abs(err)) <= obj.mesh_tolerance_mm


def test_rays_from_the_axis_meet_the_true_radius(obj):
    rng = np.random.default_rng(22)
    lo, hi = obj.measured_zone_z_mm
    theta = rng.uniform(-np.pi, np.pi, 150)
    z = rng.uniform(lo, hi, 150)
    m = obj.mesh_object
    hit = outermost_hit_radius(m.vertices[m.faces], theta, z)
    assert np.max(np.abs(hit - obj.radius_fn(theta, z))) <= obj.mesh_tolerance_mm


def test_radius_function_shape(params):
    p = params
    R = p.outer_diameter_mm / 2
    theta = np.linspace(-np.pi, np.pi, 36000, endpoint=False)
    z = np.linspace(-5.0, 5.0, 2001)
    # The lobes average out around the circumference (exactly, over 360 equal steps):
    # what is left is the axial waviness.
    mean = p.radius(theta[None, ::100], z[:, None]).mean(axis=1)
    wave = p.waviness_amplitude_mm * np.cos(2 * np.pi * z / p.waviness_wavelength_mm
                                            + math.radians(p.waviness_phase_deg))
    assert np.allclose(mean, R + wave, atol=1e-12)
    assert mean.max() - mean.min() == pytest.approx(2 * p.waviness_amplitude_mm, abs=1e-6)
    # The number of lobes is the number of maxima around the circumference.
    r = p.radius(theta, 0.0)
    peaks = (r > np.roll(r, 1)) & (r > np.roll(r, -1))
    assert peaks.sum() == p.lobes
    assert abs(math.remainder(theta[np.argmax(r)] - math.radians(p.lobe_angle_deg),
                              2 * np.pi / p.lobes)) < 1e-3
    assert np.isnan(p.radius(0.0, p.length_mm / 2 + 1e-6))


@settings(max_examples=8)
@given(wave=st.floats(0.0, 0.3), wavelength=st.floats(3.0, 40.0), phase=st.floats(-180, 180),
       lobes=st.integers(2, 12), lobe=st.floats(0.0, 0.2), lobe_deg=st.floats(-180, 180))
@example(wave=0.3, wavelength=3.0, phase=0.0, lobes=12, lobe=0.2, lobe_deg=0.0)  # sharpest
def test_resolution_rule_holds_for_any_parameters(wave, wavelength, phase, lobes, lobe, lobe_deg):
    # A coarse tolerance keeps the meshes small; the rule is the same at every tolerance.
    p = P(waviness_amplitude_mm=wave, waviness_wavelength_mm=wavelength, waviness_phase_deg=phase,
          lobes=lobes, lobe_amplitude_mm=lobe, lobe_angle_deg=lobe_deg, mesh_tolerance_mm=0.01)
    obj = p.build()
    tri = _outer_zone_faces(obj)
    err = radial_error(face_points(tri, _PROBES), obj.radius_fn)
    assert np.max(np.abs(err)) <= p.mesh_tolerance_mm


@pytest.mark.parametrize("field, value", [
    ("outer_diameter_mm", 5.0), ("outer_diameter_mm", float("inf")), ("wall_mm", 0.1),
    ("waviness_amplitude_mm", -0.01), ("waviness_amplitude_mm", 0.4),
    ("waviness_wavelength_mm", 1.0), ("waviness_phase_deg", 190.0), ("lobes", 1),
    ("lobes", 13), ("lobes", 2.5), ("lobes", True), ("lobe_amplitude_mm", 0.3),
    ("lobe_angle_deg", -200.0), ("length_mm", 300.0), ("mesh_tolerance_mm", 0.0),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        P(**{field: value})


@settings(max_examples=20)
@given(value=st.one_of(st.floats(max_value=2.99), st.floats(min_value=40.01)))
def test_any_out_of_range_wavelength_is_refused(value):
    with pytest.raises(ValueError, match=r"waviness_wavelength_mm must be in \[3, 40\]"):
        P(waviness_wavelength_mm=value)


def test_inconsistent_parameters_fail_with_one_line():
    with pytest.raises(ValueError, match="must be smaller than outer_diameter_mm/2") as e:
        P(outer_diameter_mm=6.0, wall_mm=3.0)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params):
    placement = Placement(x_mm=-2.5, y_mm=4.0, tilt_deg=12.0, tilt_azimuth_deg=-75.0)
    obj = params.build(placement)
    v_obj = obj.mesh_object.vertices
    sel = _outer_zone_vertex_mask(obj)
    v_world = obj.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(obj.radial_error(v_world))) < VERTEX_TOL_MM


def test_spec_round_trip():
    entry, values, placement = parse_spec("alu-pipe:lobes=4,wave=0.05,wavelength=6,y=-2")
    assert entry.name == "alu-pipe" and entry.params_cls is P
    assert values == {"lobes": 4, "waviness_amplitude_mm": 0.05, "waviness_wavelength_mm": 6.0}
    assert isinstance(values["lobes"], int)
    assert placement == Placement(y_mm=-2.0)
    obj = build_object("alu-pipe:lobes=5,tol=0.005,tilt=3,azimuth_deg=10")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    with pytest.raises(ValueError, match="lobes: expected a int"):
        parse_spec("alu-pipe:lobes=2.5")

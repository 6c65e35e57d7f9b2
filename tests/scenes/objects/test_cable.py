"""cable, cable-6, cable-8: stranded-conductor envelope, exact truth vs brute-force distance to
the helices, mesh within tolerance, validation, placement, spec."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshcheck import _wrap, face_points, outermost_hit_radius, radial_error  # noqa: E402
from scipy.integrate import quad

import lts360.scenes.objects.cable as cb
from lts360.scenes.objects.base import Placement
from lts360.scenes.objects.catalog import build_object, get_object_type, parse_spec

P = cb.CableParams
#: Vertices are computed from r(θ, z) directly: only float64 rounding separates them.
VERTEX_TOL_MM = 1e-8
#: Brute force vs Newton: the brute force's parabolic refinement of a sampled distance is
#: good to ~1e-11 mm; the two share nothing but the definition of the envelope.
BRUTE_TOL_MM = 1e-9
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


def brute_envelope(p, theta, z, n_t=801, n_r=241):
    """Largest r at which (r cos θ, r sin θ, z) is within ρ of an outer wire's helix, from the
    definition alone: distance to each helix by dense sampling of its parameter (parabolic
    refinement), then a scan and a bisection along the ray."""
    theta = np.asarray(theta, dtype=float)
    z = np.asarray(z, dtype=float)
    R, rho, N = p.helix_radius_mm, p.wire_radius_mm, p.outer_wires
    c = (1.0 if p.lay_direction == "right" else -1.0) * p.lay_length_mm / (2 * math.pi)
    beta = math.radians(p.strand_phase_deg) + 2 * math.pi * np.arange(N) / N
    # Only helix points with |c t − z| ≤ ρ can be within ρ.
    t = (z[:, None, None] + rho * np.linspace(-1.0, 1.0, n_t)[None, None, :]) / c
    ang = np.cos(t + beta[None, :, None] - theta[:, None, None])
    dz2 = (c * t - z[:, None, None]) ** 2

    def min_d2(r):
        d2 = r[:, None, None] ** 2 + R * R - 2 * r[:, None, None] * R * ang + dz2
        i = np.clip(np.argmin(d2, axis=2), 1, n_t - 2)
        lo, mid, hi = (np.take_along_axis(d2, (i + k)[..., None], 2)[..., 0] for k in (-1, 0, 1))
        curv = hi - 2 * mid + lo
        best = np.where(curv > 0, mid - (hi - lo) ** 2 / (8 * np.where(curv > 0, curv, 1)), mid)
        return best.min(axis=1)

    grid = np.linspace(R - rho, R + rho, n_r)
    inside = np.stack([min_d2(np.full(theta.shape, g)) <= rho * rho for g in grid], 1)
    top = n_r - 1 - np.argmax(inside[:, ::-1], axis=1)
    assert inside.any(axis=1).all() and (top < n_r - 1).all()
    lo, hi = grid[top], grid[top + 1]
    for _ in range(60):
        mid = (lo + hi) / 2
        ok = min_d2(mid) <= rho * rho
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return (lo + hi) / 2


# --- fixtures --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def params():
    return get_object_type("cable-8").make_params({})


@pytest.fixture(scope="module")
def obj(params):
    return params.build()


# --- tests -----------------------------------------------------------------------------------

@pytest.mark.parametrize("name, diameter, sections", [("cable-6", 6.0, 40), ("cable-8", 8.0, 39),
                                                      ("cable", 8.0, 39)])
def test_paper_presets_and_scans(name, diameter, sections):
    o = build_object(name)
    assert o.name == name and o.spec.startswith(name + ":")
    assert o.params["diameter_mm"] == diameter and o.params["strands"] == 7
    assert (o.sections, o.pitch_mm) == (sections, 0.34)
    half = (sections - 1) * 0.34 / 2 + 0.5
    assert o.measured_zone_z_mm == pytest.approx((-half, half))
    assert o.material.name == "weathered-aluminium"
    assert o.mesh_tolerance_mm == 0.001
    assert o.params == dataclasses.asdict(P(**o.params))
    n = o.notes
    # 7 equal wires: three wire diameters across, 6 outer wires, lay 13 d.
    assert n["strand_diameter_mm"] == pytest.approx(diameter / 3, rel=1e-14)
    assert n["nominal_strand_diameter_mm"] == pytest.approx(diameter / 3, rel=1e-14)
    assert n["inner_strand_diameter_mm"] == pytest.approx(diameter / 3, rel=1e-14)
    assert (n["layers"], n["outer_wires"]) == (2, 6)
    assert n["lay_length_mm"] == pytest.approx(13 * diameter)
    assert n["lay_angle_deg"] == pytest.approx(
        math.degrees(math.atan(2 * math.pi * diameter / 3 / (13 * diameter))), rel=1e-12)


def test_mesh_is_closed_and_of_the_right_volume(obj, params):
    m = obj.mesh_object
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert len(m.faces) < 2_000_000
    sec = params.section()
    # Every section is the same up to a rotation: area = N ∫ f² / 2 dφ, dφ = Θ'(ω) dω.
    half, _ = quad(lambda w: float(sec.radius(w)) ** 2 / 2 * float(sec.theta_derivative(w)),
                   0.0, sec.omega_cusp_rad, epsabs=1e-13, limit=200)
    volume = params.length_mm * 2 * sec.n_wires * half
    perimeter = 2 * math.pi * params.diameter_mm / 2 * 1.5  # generous bound of the outline
    assert abs(m.volume - volume) <= perimeter * params.length_mm * obj.mesh_tolerance_mm


def test_outer_vertices_lie_on_the_true_surface(obj):
    v = obj.mesh_object.vertices
    lo, hi = obj.measured_zone_z_mm
    sel = (np.hypot(v[:, 0], v[:, 1]) > 0) & (v[:, 2] >= lo) & (v[:, 2] <= hi)
    assert sel.sum() > 10_000
    assert np.max(np.abs(radial_error(v[sel], obj.radius_fn))) < VERTEX_TOL_MM


def test_cusps_are_grid_helices(obj, params):
    v = obj.mesh_object.vertices
    v = v[np.hypot(v[:, 0], v[:, 1]) > 0]
    phi = np.arctan2(v[:, 1], v[:, 0]) - params.twist_rad_per_mm * v[:, 2] \
        - math.radians(params.strand_phase_deg)
    period = 2 * math.pi / params.outer_wires
    on_cusp = np.abs(_wrap((phi - period / 2) * params.outer_wires) / params.outer_wires) < 1e-12
    assert on_cusp.sum() == params.outer_wires * obj.notes["n_z"]


def test_outer_faces_are_within_tolerance(obj):
    tri = side_faces(obj)
    rng = np.random.default_rng(31)
    weights = np.vstack([_PROBES, rng.dirichlet(np.ones(3), size=12)])
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
    tri = band_faces(obj, n_z // 2)
    assert len(tri) == 2 * n_t
    err = radial_error(face_points(tri, barycentric_grid(30)), obj.radius_fn)
    assert np.max(np.abs(err)) <= obj.mesh_tolerance_mm


def test_rays_from_the_axis_meet_the_true_radius(obj, params):
    rng = np.random.default_rng(32)
    lo, hi = obj.measured_zone_z_mm
    z = rng.uniform(lo, hi, 200)
    theta = rng.uniform(-np.pi, np.pi, 200)
    # Next to the cusps, where the envelope is steepest.
    period = 2 * math.pi / params.outer_wires
    cusp = params.twist_rad_per_mm * z[:80] + period / 2 + period * rng.integers(0, 6, 80)
    theta[:80] = cusp + rng.normal(0.0, 0.01, 80)
    hit = outermost_hit_radius(side_faces(obj, zone_only=False), theta, z)
    assert np.max(np.abs(hit - obj.radius_fn(theta, z))) <= obj.mesh_tolerance_mm


@pytest.mark.parametrize("kw", [
    {}, {"strands": 19, "lay_direction": "left", "strand_phase_deg": 40.0},
    {"strands": 37, "lay_ratio": 10.0, "diameter_mm": 6.0}])
def test_envelope_matches_brute_force_distance_to_the_helices(kw):
    p = P(**kw)
    rng = np.random.default_rng(33)
    theta = rng.uniform(-np.pi, np.pi, 24)
    z = rng.uniform(-6.0, 6.0, 24)
    assert np.max(np.abs(p.radius(theta, z) - brute_envelope(p, theta, z))) < BRUTE_TOL_MM


def test_crests_and_cusps(params):
    p = params
    sec = p.section()
    N, tau = p.outer_wires, p.twist_rad_per_mm
    period = 2 * math.pi / N
    z = 1.7
    crest = math.radians(p.strand_phase_deg) + tau * z + period * np.arange(N)
    # The envelope reaches d/2 exactly at the crests, nowhere more.
    assert np.max(np.abs(p.radius(crest, z) - p.diameter_mm / 2)) < 1e-13
    phi = np.linspace(0, 2 * math.pi, 60001)
    r = p.radius(phi + tau * z, z)
    assert r.max() <= p.diameter_mm / 2 + 1e-13
    # The minimum is at the cusps, half-way between crests, where a brute force agrees.
    cusp = crest + period / 2
    r_cusp = p.radius(cusp, np.full(N, z))
    assert r.min() >= r_cusp.min() - 1e-13
    assert np.ptp(r_cusp) < 1e-12
    assert np.max(np.abs(r_cusp - brute_envelope(p, cusp, np.full(N, z)))) < BRUTE_TOL_MM
    assert r_cusp[0] == pytest.approx(float(sec.radius(sec.omega_cusp_rad)), abs=1e-13)
    # Continuous across the cusp (neighbours overlap), with a kink there.
    eps = 1e-7
    left, right = p.radius(cusp[0] - eps, z), p.radius(cusp[0] + eps, z)
    assert left == pytest.approx(right, abs=1e-12) and abs(left - r_cusp[0]) < 1e-4
    slope = (p.radius(cusp[0] - eps, z) - r_cusp[0]) / eps
    assert slope > 1.0


def test_wire_size_closes_the_outer_layer():
    for strands, extra in ((7, 0.0), (19, 0.028), (37, 0.036)):
        p = P(strands=strands)
        rho, R, N = p.wire_radius_mm, p.helix_radius_mm, p.outer_wires
        assert R + rho == pytest.approx(p.diameter_mm / 2, rel=1e-15)
        assert rho == pytest.approx(R * math.sin(math.pi / N), rel=1e-14)  # touch when straight
        nominal = p.diameter_mm / (2 * p.layers - 1)
        assert 2 * rho / nominal - 1 == pytest.approx(extra, abs=0.0005)
        sec = p.section()
        # The oblique cut is wider than π/N: neighbours overlap in every z section.
        assert float(sec.theta(sec.omega_tangent_rad)) > math.pi / N


def test_newton_solves_to_machine_precision(params):
    sec = params.section()
    phi = np.linspace(0, math.pi / sec.n_wires, 10001)
    w = sec.omega_of(phi)
    assert np.max(np.abs(sec.theta(w) - phi)) < 4e-16
    assert np.all(np.diff(w) > 0) and w[0] == 0 and w[-1] == pytest.approx(sec.omega_cusp_rad)


@settings(max_examples=40)
@given(theta=st.floats(-np.pi, np.pi), z=st.floats(-7.0, 7.0), dz=st.floats(-7.0, 7.0),
       direction=st.sampled_from(["right", "left"]), lay=st.floats(10.0, 16.0),
       strands=st.sampled_from([7, 19, 37]))
def test_helical_invariance(theta, z, dz, direction, lay, strands):
    p = P(lay_direction=direction, lay_ratio=lay, strands=strands)
    sign = 1 if direction == "right" else -1
    moved = p.radius(theta + sign * 2 * math.pi * dz / p.lay_length_mm, z + dz)
    assert moved == pytest.approx(p.radius(theta, z), abs=1e-12)
    # Even about each crest.
    assert p.radius(-theta + 2 * p.twist_rad_per_mm * z, z) == pytest.approx(p.radius(theta, z),
                                                                              abs=1e-12)


@settings(max_examples=8)
@given(diameter=st.floats(3.0, 30.0), strands=st.sampled_from([7, 19, 37]),
       lay=st.floats(10.0, 16.0), direction=st.sampled_from(["right", "left"]),
       phase=st.floats(-180.0, 180.0), tol=st.sampled_from([0.001, 0.01]))
def test_resolution_rule_holds_for_any_parameters(diameter, strands, lay, direction, phase, tol):
    p = P(diameter_mm=diameter, strands=strands, lay_ratio=lay, lay_direction=direction,
          strand_phase_deg=phase, mesh_tolerance_mm=tol)
    o = p.build()
    assert o.mesh_object.is_watertight
    tri = band_faces(o, o.notes["n_z"] // 2)
    err = radial_error(face_points(tri, barycentric_grid(12)), o.radius_fn)
    assert np.max(np.abs(err)) <= p.mesh_tolerance_mm


@pytest.mark.parametrize("field, value", [
    ("diameter_mm", 2.0), ("diameter_mm", float("inf")), ("lay_ratio", 9.0), ("lay_ratio", 17.0),
    ("lay_direction", "Z"), ("strand_phase_deg", -200.0), ("length_mm", 10.0),
    ("length_mm", 300.0), ("mesh_tolerance_mm", 1e-5), ("mesh_tolerance_mm", 0.02),
    ("strands", 12), ("strands", 7.5), ("strands", True), ("preset", "cable-10"),
])
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=field) as e:
        P(**{field: value})
    assert "\n" not in str(e.value)


def test_strand_count_error_lists_the_allowed_values():
    with pytest.raises(ValueError, match=r"cable-6: strands must be one of 7, 19, 37 "
                                         r"\(1\+6, 1\+6\+12, 1\+6\+12\+18\), got 12"):
        build_object("cable-6:strands=12")
    with pytest.raises(ValueError, match="unknown material"):
        P(material="cheese")


def test_placement_keeps_the_truth(params, obj):
    placement = Placement(x_mm=-4.0, y_mm=2.2, tilt_deg=9.0, tilt_azimuth_deg=120.0)
    placed = params.build(placement)
    v_obj = placed.mesh_object.vertices
    lo, hi = placed.measured_zone_z_mm
    sel = (np.hypot(v_obj[:, 0], v_obj[:, 1]) > 0) & (v_obj[:, 2] >= lo) & (v_obj[:, 2] <= hi)
    v_world = placed.mesh_world().vertices[sel]
    assert np.max(np.abs(v_world - v_obj[sel])) > 1.0  # the placement really moved it
    assert np.max(np.abs(placed.radial_error(v_world))) < VERTEX_TOL_MM
    assert np.array_equal(v_obj, obj.mesh_object.vertices)


def test_spec_round_trip():
    entry, values, placement = parse_spec("cable:d=8,strands=7")
    assert entry.name == "cable" and entry.params_cls is P
    assert values == {"diameter_mm": 8.0, "strands": 7} and placement == Placement()
    entry, values, _ = parse_spec("cable-6:lay=12,direction=left")
    assert entry.make_params(values) == P(diameter_mm=6.0, preset="cable-6", lay_ratio=12.0,
                                          lay_direction="left")
    obj = build_object("cable-6:strands=19,lay=11,phase=10,x=1.5,tilt=2")
    assert obj.name == "cable-6" and obj.spec.startswith("cable-6:")
    again = build_object(obj.spec)
    assert again.params == obj.params and again.placement == obj.placement
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    with pytest.raises(ValueError, match="unknown parameter"):
        parse_spec("cable-8:bogus=1")

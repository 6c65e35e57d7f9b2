"""A user's part: a mesh file (STL, PLY, OBJ) or an extruded DXF/CSV section, with its truth."""

import json

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from lts360.scenes.objects import build_object, object_types
from lts360.scenes.objects.catalog import object_from_truth
from lts360.scenes.objects.part import check_in_field, part_truth
from lts360.scenes.objects.profile_part import extrude_ring, polygon_radius

#: 16 mm across flats; corners at 0°, 60°, …
HEX_R_MM = 8.0 / np.cos(np.pi / 6.0)
#: An L section with the axis in its foot: from there the tip of its upright hides behind the
#: inner corner, so a ray from the axis meets the boundary three times (not star-shaped).
L_RING = np.array([[-2.0, -2.0], [8.0, -2.0], [8.0, 1.0], [1.0, 1.0], [1.0, 8.0],
                   [-2.0, 8.0]]) - np.array([6.0, -0.5])


def hex_ring(across_flats_mm=16.0):
    a = np.radians(np.arange(6) * 60.0)
    r = across_flats_mm / 2.0 / np.cos(np.pi / 6.0)
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


def hex_radius(theta):
    """Closed form: a flat at distance 8 mm, its normal at 30° + k·60°."""
    return 8.0 / np.cos(np.mod(theta, np.pi / 3.0) - np.pi / 6.0)


def write_csv(path, ring, header="x_mm,y_mm"):
    xy = np.vstack([ring, ring[:1]])
    path.write_text(header + "\n" + "\n".join(f"{float(x)!r},{float(y)!r}" for x, y in xy) + "\n")
    return path


def write_dxf(path, ring, close=True, units=4):
    import ezdxf

    doc = ezdxf.new()
    doc.header["$INSUNITS"] = units
    doc.modelspace().add_lwpolyline([tuple(p) for p in ring], close=close)
    doc.saveas(path)
    return path


@pytest.fixture
def hex_stl(tmp_path):
    path = tmp_path / "hex.stl"
    extrude_ring(hex_ring(), -20.0, 20.0).export(path)
    return path


def test_both_parts_are_listed_and_need_their_file():
    types = object_types()
    assert types["mesh"].from_file and types["profile"].from_file
    assert not types["plug-gauge"].from_file
    for name in ("mesh", "profile"):
        with pytest.raises(ValueError, match=f"{name}: path is required"):
            build_object(name)


def test_polygon_radius_of_a_hexagon_is_the_closed_form():
    th = np.linspace(-np.pi, np.pi, 7201)
    # float64 ray–edge intersection: a few ulp of 9 mm
    assert polygon_radius(hex_ring(), th) == pytest.approx(hex_radius(th), abs=1e-12)


@given(st.lists(st.floats(2.0, 15.0), min_size=3, max_size=24), st.floats(0.0, 2 * np.pi))
def test_polygon_radius_lands_on_the_boundary_of_any_star_polygon(radii, phase):
    import shapely

    n = len(radii)
    ang = phase + np.arange(n) * 2 * np.pi / n
    ring = np.column_stack([np.array(radii) * np.cos(ang), np.array(radii) * np.sin(ang)])
    # at each vertex's angle the radius is the vertex's
    assert polygon_radius(ring, ang) == pytest.approx(radii, rel=1e-9)
    th = np.linspace(0, 2 * np.pi, 257)
    r = polygon_radius(ring, th)
    pts = shapely.points(r * np.cos(th), r * np.sin(th))
    # on the boundary to float64 rounding of intersections at ≤ 15 mm
    assert np.max(shapely.distance(shapely.LinearRing(ring), pts)) < 1e-9


def test_profile_from_csv_and_dxf_is_the_exact_extruded_hexagon(tmp_path):
    th = np.linspace(-np.pi, np.pi, 3601)
    for path in (write_csv(tmp_path / "hex.csv", hex_ring()),
                 write_dxf(tmp_path / "hex.dxf", hex_ring())):
        obj = build_object(f"profile:path={path},length=30,x=1.5,tilt_deg=2")
        mesh = obj.mesh_object
        assert mesh.is_watertight and mesh.is_winding_consistent
        # volume: 6 equilateral triangles of side R, times the length (float64 rounding)
        assert mesh.volume == pytest.approx(1.5 * np.sqrt(3) * HEX_R_MM ** 2 * 30.0, rel=1e-12)
        assert obj.radius_fn(th, np.zeros_like(th)) == pytest.approx(hex_radius(th), abs=1e-9)
        assert np.isnan(obj.radius_fn(np.array([0.0]), np.array([15.5])))[0]  # beyond the end
        again = build_object(obj.spec)
        assert again.spec == obj.spec and np.array_equal(again.mesh_object.vertices,
                                                         mesh.vertices)


def test_profile_units_and_centre(tmp_path):
    ring_in = hex_ring() / 25.4 + np.array([1.0, 0.5])  # inches, origin off the centre
    obj = build_object(f"profile:path={write_csv(tmp_path / 'h.csv', ring_in, 'x_in,y_in')},"
                       f"centre=1")
    th = np.linspace(-np.pi, np.pi, 721)
    # the centroid moved onto the axis: the hexagon's own r(θ), to float64 rounding of 25.4·x
    assert obj.radius_fn(th, np.zeros_like(th)) == pytest.approx(hex_radius(th), abs=1e-9)


def test_a_non_star_section_has_no_radius_and_says_so(tmp_path):
    obj = build_object(f"profile:path={write_csv(tmp_path / 'l.csv', L_RING)}")
    assert obj.radius_fn is None and "star-shaped" in obj.notes["truth"]
    assert obj.mesh_object.is_watertight


def test_mesh_part_radius_matches_the_closed_form(hex_stl):
    obj = build_object(f"mesh:path={hex_stl}")
    assert obj.radius_fn is not None and obj.mesh_tolerance_mm == 0.0
    assert obj.measured_zone_z_mm == (-19.0, 19.0)
    th = np.linspace(-np.pi, np.pi, 3601)
    z = np.linspace(-18, 18, th.size)
    # STL stores float32 vertices and Open3D casts in float32: ~1e-6 mm at 9 mm
    assert obj.radius_fn(th, z) == pytest.approx(hex_radius(th), abs=2e-6)
    assert np.all(np.isnan(obj.radius_fn(np.zeros(2), np.array([-20.5, 20.5]))))


def test_mesh_part_in_metres_and_inches_is_the_same_part(tmp_path, hex_stl):
    ref = build_object(f"mesh:path={hex_stl}").mesh_object
    for units, scale in (("m", 1e-3), ("in", 1 / 25.4)):
        path = tmp_path / f"hex-{units}.ply"
        m = ref.copy()
        m.apply_scale(scale)
        m.export(path)
        obj = build_object(f"mesh:path={path},units={units}")
        # PLY keeps float64 (STL float32 for ref): the scale round trip, relative 1e-7
        assert np.abs(obj.mesh_object.bounds - ref.bounds).max() < 1e-5


def test_a_re_entrant_mesh_is_scored_by_mesh_distance_only(tmp_path):
    path = tmp_path / "l.obj"
    extrude_ring(L_RING, -10, 10).export(path)
    obj = build_object(f"mesh:path={path}")
    assert obj.radius_fn is None and "star-shaped" in obj.notes["truth"]


@pytest.mark.parametrize("make,match", [
    (lambda p: trimesh.Trimesh(*_open_box(), process=False).export(p), "not watertight"),
    (lambda p: p.write_text("solid nothing\nendsolid nothing\n"), "no triangles|not a readable"),
])
def test_bad_meshes_are_refused_in_one_line(tmp_path, make, match):
    path = tmp_path / "bad.stl"
    make(path)
    with pytest.raises(ValueError, match=match) as exc:
        build_object(f"mesh:path={path}")
    assert "\n" not in str(exc.value)


def _open_box():
    box = trimesh.creation.box((10, 10, 10))
    return box.vertices, box.faces[:-1]  # one triangle missing: a hole


@pytest.mark.parametrize("spec,match", [
    ("mesh:path=nope.stl", "no such file"),
    ("mesh:path=part.step", "must end in"),
    ("profile:path=x.dxf,length=1", "length_mm"),
])
def test_bad_part_specs_name_the_field(tmp_path, monkeypatch, spec, match):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.dxf").write_text("")
    with pytest.raises(ValueError, match=match):
        build_object(spec)


def test_open_dxf_contour_is_refused(tmp_path):
    path = write_dxf(tmp_path / "open.dxf", hex_ring(), close=False)
    with pytest.raises(ValueError, match="not closed"):
        build_object(f"profile:path={path}")


def test_field_check_says_by_how_much(tmp_path, hex_stl):
    from lts360.scenes.rig_io import load_rig

    rig = load_rig("paper")
    check_in_field(build_object(f"mesh:path={hex_stl},x=10"), rig)  # 19.24 mm ≤ 20 mm
    with pytest.raises(ValueError, match=r"reaches 21\.238 mm .* 1\.238 mm beyond"):
        check_in_field(build_object(f"mesh:path={hex_stl},x=12"), rig)


def test_truth_rebuilds_from_the_frame_folder_copy(tmp_path, hex_stl):
    from lts360.scenes.objects.part import copy_part

    obj = build_object(f"mesh:path={hex_stl},x=0.5,tilt_deg=1")
    entry = {"spec": obj.spec, **part_truth(obj)}
    frame = tmp_path / "frame"
    frame.mkdir()
    copy_part(entry, frame)
    (frame / "frame.json").write_text(json.dumps({"object": entry}))
    hex_stl.unlink()  # the original is gone: the folder is self-contained
    again = object_from_truth(entry, frame)
    assert np.array_equal(again.mesh_object.vertices, obj.mesh_object.vertices)
    assert np.allclose(again.T_world_object, obj.T_world_object)
    (frame / "part.stl").write_bytes((frame / "part.stl").read_bytes()[:-4] + b"\0\0\0\0")
    with pytest.raises(ValueError, match="SHA-256"):
        object_from_truth(entry, frame)

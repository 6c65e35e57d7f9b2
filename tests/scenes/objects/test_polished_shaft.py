"""polished-shaft: the undercut shaft's exact geometry with steep shoulders, in polished
aluminium, under its own name and spec."""

import numpy as np
import trimesh

from lts360.scenes.materials import get_material
from lts360.scenes.objects import build_object
from lts360.scenes.objects.undercut_shaft import UndercutShaftParams


def test_defaults_name_material_and_spec():
    obj = build_object("polished-shaft")
    assert obj.name == "polished-shaft" and obj.material == get_material("polished-aluminium")
    assert obj.spec.startswith("polished-shaft:") and build_object(obj.spec).spec == obj.spec
    assert obj.params["flank_angle_deg"] == 70.0 and obj.params["groove_depth_mm"] == 1.0


def test_same_mesh_and_truth_as_the_undercut_shaft_with_the_same_parameters():
    obj = build_object("polished-shaft:x=0.3,tilt_deg=0.5")
    twin = UndercutShaftParams(diameter_mm=20.0, groove_width_mm=3.0, groove_depth_mm=1.0,
                               fillet_radius_mm=0.3, flank_angle_deg=70.0,
                               material="polished-aluminium").build(obj.placement)
    assert np.array_equal(obj.mesh_object.vertices, twin.mesh_object.vertices)
    theta, z = np.meshgrid(np.linspace(-np.pi, np.pi, 7), np.linspace(-2, 2, 41))
    assert np.array_equal(obj.radius_fn(theta, z), twin.radius_fn(theta, z))
    assert obj.radius_fn(np.zeros(1), np.zeros(1))[0] == 10.0 - 1.0  # the groove's bottom


def test_watertight_and_within_its_mesh_tolerance():
    obj = build_object("polished-shaft")
    mesh = obj.mesh_object
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    pts, _ = trimesh.sample.sample_surface(mesh, 20000, seed=1)
    z0, z1 = obj.measured_zone_z_mm
    pts = pts[(pts[:, 2] > z0) & (pts[:, 2] < z1)]
    err = np.hypot(pts[:, 0], pts[:, 1]) - obj.radius_fn(np.arctan2(pts[:, 1], pts[:, 0]), pts[:, 2])
    outer = np.abs(err) < 0.05  # the end fans lie inside
    assert outer.mean() > 0.3 and np.max(np.abs(err[outer])) <= obj.mesh_tolerance_mm + 1e-9

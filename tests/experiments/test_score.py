"""Scoring against the truth: known errors in, the same numbers out."""

import numpy as np
import pytest
import trimesh

from lts360.experiments.score import score_cloud, signed_mesh_distance
from lts360.recon.triangulation.cloud import VIEW_CODES, Cloud, read_cloud, write_cloud
from lts360.scenes.objects import build_object


def _ring_cloud(obj, r_offset_mm, z_values, n_theta=720, rng=None):
    clouds = []
    th = np.linspace(-np.pi, np.pi, n_theta, endpoint=False)
    for k, z in enumerate(z_values):
        r = obj.radius_fn(th, np.full_like(th, z)) + r_offset_mm
        pts = np.column_stack([r * np.cos(th), r * np.sin(th), np.full_like(th, z)])
        pts = pts @ obj.T_world_object[:3, :3].T + obj.T_world_object[:3, 3]
        view = np.where(np.sin(th) < -0.3, VIEW_CODES["direct"],
                        np.where(np.cos(th) < 0, VIEW_CODES["left"], VIEW_CODES["right"]))
        clouds.append(Cloud(pts, th, r, view.astype(np.uint8), np.zeros(n_theta, np.uint8),
                            np.full(n_theta, k, np.int32), np.ones(n_theta, np.float32)))
    return Cloud.concatenate(clouds)


def test_known_radial_offset_is_scored_exactly():
    obj = build_object("plug-gauge:x=0.2,y=-0.1")
    cloud = _ring_cloud(obj, 0.010, [0.0, 0.68])
    m = score_cloud(cloud, obj)
    assert m["n_points"] == 1440 and m["coverage_deg"] == pytest.approx(360.0)
    assert m["mean_mm"] == pytest.approx(0.010, abs=1e-9) and m["rms_mm"] == pytest.approx(0.010, abs=1e-9)
    assert m["radius_bias_mm"] == pytest.approx(0.010, abs=1e-9)
    assert m["fitted_diameter_mm"] == pytest.approx(19.9987 + 0.020, abs=1e-8)
    # The mesh distance agrees to the mesh tolerance (1 µm chords) plus float32 (~2 µm).
    assert m["mesh_distance"]["mean_mm"] == pytest.approx(0.010, abs=3e-3)
    assert set(m["views"]) == {"direct", "left", "right"}


def test_invalid_points_are_not_scored():
    obj = build_object("plug-gauge")
    cloud = _ring_cloud(obj, 0.0, [0.0])
    q = cloud.quality.copy()
    q[:360] = 1
    pts = cloud.points_mm.copy()
    pts[:360] = np.nan
    bad = Cloud(pts, cloud.theta_rad, cloud.radius_mm, cloud.view, q, cloud.section, cloud.intensity)
    m = score_cloud(bad, obj)
    assert m["n_points"] == 360 and m["coverage_deg"] == pytest.approx(180.0, abs=0.5)


def test_mesh_distance_sign_and_size():
    mesh = trimesh.creation.box(extents=(10, 10, 10))
    d = signed_mesh_distance(mesh, np.array([[0, 0, 6.0], [0, 0, 4.0]]))
    assert d == pytest.approx([1.0, -1.0], abs=1e-5)


def test_cloud_ply_round_trip_and_trimesh_reads_it(tmp_path):
    obj = build_object("plug-gauge")
    cloud = _ring_cloud(obj, 0.0, [0.0, 0.34])
    path = write_cloud(tmp_path / "c.ply", cloud)
    back = read_cloud(path)
    for name in ("points_mm", "theta_rad", "radius_mm", "view", "quality", "section", "intensity"):
        assert np.array_equal(getattr(back, name), getattr(cloud, name))
    pc = trimesh.load(path)
    assert np.allclose(pc.vertices, cloud.points_mm)
    with pytest.raises(ValueError, match="not a PLY"):
        (tmp_path / "x.ply").write_text("hello")
        read_cloud(tmp_path / "x.ply")


def test_measurable_knows_which_side_of_the_gauge_each_view_sees():
    """The direct view sees the front (−Y, towards the camera) of a cylinder, not its back; the
    mirrors (behind it, at +Y) see the back.  Lit: the laser is at −Y, the mirrors relight the
    back."""
    import json

    from lts360.experiments.score import measurable
    from lts360.recon.triangulation.cloud import VIEW_CODES
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth

    rig = load_rig("paper")
    truth = json.loads(json.dumps(rig_truth(rig, rig.camera.K, (1280, 1024)),
                                  default=lambda v: v.tolist()))
    obj = build_object("plug-gauge")
    r = obj.params["diameter_mm"] / 2
    th = np.radians([-90.0, 90.0])  # front (facing the camera) and back
    pts = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(2)])
    direct = measurable(pts, np.full(2, VIEW_CODES["direct"]), obj, truth)
    assert direct.tolist() == [True, False]
    back_left = measurable(pts[1:], np.array([VIEW_CODES["left"]]), obj, truth)
    front_left = measurable(pts[:1], np.array([VIEW_CODES["left"]]), obj, truth)
    assert back_left.tolist() == [True] and front_left.tolist() == [False]

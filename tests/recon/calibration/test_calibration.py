import dataclasses
import json

import numpy as np
import pytest

from lts360.geometry import project_points
from lts360.recon.model import (
    Calibration,
    MirrorPlane,
    calibration_to_dict,
    load_calibration,
    make_T_cam_meas,
    save_calibration,
)
from lts360.recon.triangulation.views import get_views, project_meas_points
from lts360.scenes.rig_io import load_rig
from lts360.simulator.io import rig_truth, write_json


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


@pytest.fixture()
def frame_json(paper, tmp_path):
    path = tmp_path / "frame.json"
    write_json(path, rig_truth(paper, paper.camera.K, paper.camera.image_size))
    return path


@pytest.fixture()
def cal(frame_json):
    return load_calibration(frame_json)


def test_frame_json_gives_the_world_as_measurement_frame(paper, cal):
    cam = paper.camera
    assert cal.image_size == cam.image_size
    assert np.array_equal(cal.K, cam.K) and np.array_equal(cal.dist, cam.distortion)
    assert np.allclose(cal.T_cam_meas[:3, :3], cam.R, atol=1e-15)
    assert np.allclose(cal.T_cam_meas[:3, 3], cam.t_mm, atol=1e-12)
    # The laser plane (world z = 0) in the camera frame contains the images of world points z = 0.
    n, d = cal.laser_plane
    pts = np.random.default_rng(0).uniform(-15, 15, (50, 3)) * [1, 1, 0]
    assert np.allclose((pts @ cam.R.T + cam.t_mm) @ n, d, atol=1e-9)
    # Mirror planes: the camera is on the reflecting side, corners on the planes.
    for m in cal.mirrors:
        assert m.d_mm < 0
        assert np.allclose(m.corners_mm @ m.n, m.d_mm, atol=1e-9)


def test_frame_json_views_project_like_the_world_rig(paper, cal):
    """Eq. 4 through the calibration (camera frame) equals Eq. 4 with the world mirror matrices."""
    cam = paper.camera
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-12, 12, (200, 2)), np.zeros(200)])
    for view in get_views(cal, ("direct", "left", "right", "left-right")):
        T = None
        for name in view.mirrors:
            T = paper.mirror(name).T if T is None else paper.mirror(name).T @ T
        want = project_points(pts, cam.K, cam.distortion, cam.R, cam.t_mm, T_mirror=T)
        got = project_meas_points(pts, cal, view)
        assert np.allclose(got, want, atol=1e-9), view.name  # float rounding only


def test_round_trip_preserves_every_field(cal, tmp_path):
    cal2 = dataclasses.replace(
        cal, dist=np.array([-0.12, 0.05, 1e-4, -2e-4, 0.01]),
        mirrors=(cal.mirrors[0], dataclasses.replace(cal.mirrors[1], corners_mm=None)),
        view_offsets_mm={"left": [0.012, -0.007]}, uncertainty={"sigma_K": np.eye(2)})
    out = tmp_path / "out"
    out.mkdir()
    path = out / "cal.json"
    save_calibration(path, cal2)
    back = load_calibration(path)
    assert calibration_to_dict(back) == json.loads(json.dumps(calibration_to_dict(cal2),
                                                              default=lambda a: a.tolist()))
    assert back.mirrors[1].corners_mm is None
    assert np.array_equal(back.view_offsets_mm["left"], [0.012, -0.007])
    assert np.array_equal(back.view_offsets_mm["right"], [0.0, 0.0])  # filled with zeros
    data = json.loads(path.read_text())  # OpenCV's names
    assert {"camera_matrix", "distortion_coefficients", "image_width", "image_height"} <= set(data)
    assert [p.name for p in out.iterdir()] == ["cal.json"]  # no temporary left behind


def test_failed_save_leaves_the_old_file(cal, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    path = out / "cal.json"
    save_calibration(path, cal)
    before = path.read_text()
    bad = dataclasses.replace(cal, uncertainty={"x": object()})
    with pytest.raises(TypeError, match="uncertainty"):
        save_calibration(path, bad)
    assert path.read_text() == before
    assert [p.name for p in out.iterdir()] == ["cal.json"]


def test_opencv_filestorage_matrices_and_four_distortion_coefficients(cal, tmp_path):
    data = calibration_to_dict(cal)
    data["camera_matrix"] = {"type_id": "opencv-matrix", "rows": 3, "cols": 3, "dt": "d",
                             "data": np.ravel(data["camera_matrix"]).tolist()}
    data["distortion_coefficients"] = [0.1, -0.01, 0.0, 0.0]
    path = tmp_path / "cv.json"
    path.write_text(json.dumps(data))
    back = load_calibration(path)
    assert np.array_equal(back.K, cal.K)
    assert np.array_equal(back.dist, [0.1, -0.01, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d.pop("camera_matrix"), "camera_matrix: missing"),
    (lambda d: d.update(camera_matrix=[[1, 0], [0, 1]]), "camera_matrix"),
    (lambda d: d.update(distortion_coefficients=[0.1, 0.2, 0.3]), "distortion_coefficients"),
    (lambda d: d.update(image_width=12.5), "image_width"),
    (lambda d: d["mirrors"][0].pop("normal"), r"mirrors\[0\].normal: missing"),
    (lambda d: d["mirrors"][0].update(d_mm=float("nan")), "d_mm"),
    (lambda d: d["mirrors"][1].update(name="left"), "unique"),
    (lambda d: d["laser_plane"].update(normal=[0, 0, 0]), "laser_plane.n"),
    (lambda d: d.update(T_cam_meas=np.eye(4).tolist()), "T_cam_meas"),
    (lambda d: d.update(view_offsets_mm={"direct": [0, 0]}), "view_offsets_mm"),
    (lambda d: d.update(view_offsets_mm={"left": [0, 0, 0]}), r"view_offsets_mm\[left\]"),
])
def test_bad_fields_fail_with_one_line_naming_them(cal, tmp_path, mutate, field):
    data = calibration_to_dict(cal)
    mutate(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=field) as info:
        load_calibration(path)
    assert "\n" not in str(info.value)


def test_bad_files(tmp_path, frame_json):
    with pytest.raises(ValueError, match="cannot read"):
        load_calibration(tmp_path / "absent.json")
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_calibration(tmp_path / "broken.json")
    data = json.loads(frame_json.read_text())
    del data["camera"]["R"]
    (tmp_path / "f.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"camera\.R: missing"):
        load_calibration(tmp_path / "f.json")


def test_corners_off_the_plane_and_mirror_orientation():
    n = np.array([0.0, 0.6, 0.8])
    m = MirrorPlane("left", n, 50.0)  # given facing away from the camera: flipped
    assert m.d_mm == -50.0 and np.allclose(m.n, -n)
    corners = np.array([[0, 0, 62.5], [10, 0, 62.5], [10, 10, 55], [0, 10, 55.0]])
    MirrorPlane("left", n, 50.0, corners)  # on the plane
    with pytest.raises(ValueError, match="corners_mm"):
        MirrorPlane("left", n, 50.0, corners + [0, 0, 0.1])
    with pytest.raises(ValueError, match="mirror name"):
        MirrorPlane("a-b", n, 50.0)


def test_make_T_cam_meas_puts_the_frame_in_the_laser_plane():
    n = np.array([0.1, -0.7, 0.6])
    n /= np.linalg.norm(n)
    T = make_T_cam_meas((n, -30.0), (5.0, 2.0, 150.0), (1.0, 0.0, 0.0))
    R, t = T[:3, :3], T[:3, 3]
    assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) > 0
    assert np.allclose(R[:, 2], n) and t @ n == pytest.approx(-30.0)
    cal = Calibration(image_size=(64, 48), K=np.diag([100.0, 100.0, 1.0]), dist=None, mirrors=(),
                      laser_plane=(n, -30.0), T_cam_meas=T)
    assert cal.view_offsets_mm == {}


def test_tilted_laser_in_a_frame_json_is_re_based(paper, tmp_path):
    truth = rig_truth(paper, paper.camera.K, paper.camera.image_size)
    tilt = np.array([0.0, np.sin(0.01), np.cos(0.01)])
    truth["laser"]["plane"] = {"n": tilt, "d": 0.5}
    write_json(tmp_path / "frame.json", truth)
    cal = load_calibration(tmp_path / "frame.json")
    T_world_meas = np.linalg.inv(np.vstack([np.column_stack([paper.camera.R, paper.camera.t_mm]),
                                            [0, 0, 0, 1]])) @ cal.T_cam_meas
    assert np.allclose(T_world_meas[:3, 2], tilt)                      # z along the sheet normal
    assert T_world_meas[:3, 3] @ tilt == pytest.approx(0.5)            # origin in the sheet
    assert np.allclose(T_world_meas[:2, 3], 0.0, atol=1e-12)           # on the world Z axis

import math

import numpy as np
import pytest

from lts360.geometry import mirror_matrix, project_points
from lts360.scenes.rig import RigDesign, RigError, build_rig
from lts360.scenes.rig_io import load_rig, rig_from_dict, rig_to_toml


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


def test_paper_rig_matches_the_paper(paper):
    cam, laser = paper.camera, paper.laser
    assert (cam.width_px, cam.height_px, cam.pixel_pitch_um) == (1280, 1024, 5.3)
    assert cam.focal_length_mm == 8.0 and cam.f_number == 2.8  # working aperture (see preset)
    assert laser.wavelength_nm == 660.0 and laser.power_mW == 1.0 and laser.fan_angle_deg == 50.0
    # Triangulation angle: between the optical axis and the laser plane z = 0.
    alpha = math.degrees(math.asin(abs(cam.optical_axis @ laser.normal)))
    assert alpha == pytest.approx(40.0, abs=1e-9)
    # Mirrors: vertical, 90° between them.
    left, right = paper.mirror("left"), paper.mirror("right")
    assert abs(left.normal[2]) < 1e-12 and abs(right.normal[2]) < 1e-12
    assert math.degrees(math.acos(-left.normal @ right.normal)) == pytest.approx(90.0)


def test_principal_point_uses_pixel_centres_at_integers(paper):
    K = paper.camera.K
    assert K[0, 2] == pytest.approx(1280 / 2 - 0.5) and K[1, 2] == pytest.approx(1024 / 2 - 0.5)
    # The aim point projects to the principal point.
    aim = np.array([[0.0, paper.design.camera_target_y_mm, 0.0]])
    uv = project_points(aim, K, None, paper.camera.R, paper.camera.t_mm)
    assert np.allclose(uv, K[:2, 2])


def test_mirror_geometry(paper):
    for m in paper.mirrors:
        # The corner edge (0, D, z) lies on both planes; the rectangle starts at the corner.
        corner = np.array([0.0, paper.design.mirror_corner_distance_mm, 3.0])
        assert m.normal @ corner == pytest.approx(m.d_mm)
        assert np.allclose(m.T, mirror_matrix(m.normal, m.d_mm))
        # The object axis is on the reflecting side at the designed clearance.
        assert -m.d_mm == pytest.approx(60.0 * math.sin(math.radians(45.0)))


def test_toml_round_trip(paper, tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text(rig_to_toml(paper))
    again = load_rig(path)
    assert again.name == "paper"
    assert np.allclose(again.camera.K, paper.camera.K)
    assert np.allclose(again.camera.R, paper.camera.R) and np.allclose(again.camera.t_mm, paper.camera.t_mm)
    for a, b in zip(again.mirrors, paper.mirrors):
        assert np.allclose(a.corners_mm, b.corners_mm)


def test_rigid_design_changes_move_components():
    a = build_rig(RigDesign(alpha_deg=30.0), camera=dict(width_px=64, height_px=48,
                  pixel_pitch_um=5.3, focal_length_mm=8.0, f_number=2.0, distortion=[0] * 5),
                  laser=dict(fan_angle_deg=50, waist_um=100, rayleigh_range_mm=40,
                             wavelength_nm=660, power_mW=1))
    assert math.degrees(math.asin(abs(a.camera.optical_axis[2]))) == pytest.approx(30.0)


@pytest.mark.parametrize("table,key,value,match", [
    ("design", "alpha_deg", 95.0, r"design.alpha_deg: must be in \[10, 80\]"),
    ("design", "beta_deg", 10.0, r"design.beta_deg: must be in \[60, 150\]"),
    ("design", "mirror_corner_distance_mm", 20.0, r"design.mirror_corner_distance_mm: mirrors pass"),
    ("camera", "f_number", 0.1, r"camera.f_number: must be in"),
    ("camera", "width_px", 12.5, r"camera.width_px: must be an integer"),
    ("laser", "rayleigh_range_mm", 2000.0, r"laser.rayleigh_range_mm: .*M² < 1"),
    ("laser", "fan_profile", "square", r"laser.fan_profile"),
    ("laser", "colour", 1, r"laser.colour: unknown key"),
    ("stage", "pitch_mm", -1.0, r"stage.pitch_mm"),
])
def test_bad_rig_fields_fail_with_the_field_name(table, key, value, match):
    import tomllib
    from importlib import resources
    data = tomllib.loads(resources.files("lts360.scenes").joinpath("presets", "paper.toml").read_text())
    data[table][key] = value
    with pytest.raises(RigError, match=match):
        rig_from_dict(data)


def test_unknown_rig_source():
    with pytest.raises(RigError, match="neither a preset"):
        load_rig("/nonexistent/rig.toml")


def test_paper_f8_is_the_paper_rig_stopped_down(paper):
    f8 = load_rig("paper-f8")
    assert f8.name == "paper-f8" and f8.camera.f_number == 8.0
    assert f8.camera.aperture_diameter_mm == pytest.approx(paper.camera.aperture_diameter_mm * 2.8 / 8)
    assert np.array_equal(f8.camera.K, paper.camera.K) and np.array_equal(f8.camera.R, paper.camera.R)
    assert f8.camera.focus_distance_mm == paper.camera.focus_distance_mm
    assert f8.laser.waist_um == paper.laser.waist_um and f8.sensor == paper.sensor
    for a, b in zip(f8.mirrors, paper.mirrors):
        assert np.array_equal(a.corners_mm, b.corners_mm)


def test_a_rig_file_with_a_base(tmp_path):
    (tmp_path / "wide.toml").write_text('base = "paper"\n[design]\nalpha_deg = 35.0\n'
                                        '[laser]\nwaist_um = 200.0\nrayleigh_range_mm = 150.0\n')
    (tmp_path / "wide-f4.toml").write_text('name = "mine"\nbase = "wide.toml"\n'
                                           '[camera]\nf_number = 4.0\n')
    rig = load_rig(tmp_path / "wide-f4.toml")  # a base relative to the file, two levels
    paper = load_rig("paper")
    assert rig.name == "mine"
    assert rig.design.alpha_deg == 35.0 and rig.design.beta_deg == paper.design.beta_deg
    assert rig.laser.waist_um == 200.0 and rig.laser.power_mW == paper.laser.power_mW
    assert rig.camera.f_number == 4.0 and rig.camera.pixel_pitch_um == paper.camera.pixel_pitch_um
    assert load_rig(tmp_path / "wide.toml").name == "wide"  # the file's own name, not the base's
    (tmp_path / "loop.toml").write_text('base = "loop.toml"\n')
    with pytest.raises(RigError, match="bases deep"):
        load_rig(tmp_path / "loop.toml")
    (tmp_path / "typo.toml").write_text('base = "paper"\n[camera]\nf_numbr = 4.0\n')
    with pytest.raises(RigError, match="f_numbr"):
        load_rig(tmp_path / "typo.toml")
    (tmp_path / "nobase.toml").write_text('base = "nothere.toml"\n')
    with pytest.raises(RigError, match="neither a preset"):
        load_rig(tmp_path / "nobase.toml")

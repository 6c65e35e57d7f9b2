"""`lts360 compensate` (paper §4.4) on a rendered gauge: a mirror plane shifted by δ moves
that view's points by 2δ along the mirror's normal, and the command's offsets follow it
exactly; `lts360 measure --compensate` applies them and refuses a calibration without any."""

import dataclasses
import json

import numpy as np
import pytest

from lts360.cli import main

pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")


def _offsets(path):
    return {k: np.asarray(v) for k, v in json.loads(path.read_text())["view_offsets_mm"].items()}


def test_offsets_follow_a_shifted_mirror(tmp_path, capsys):
    from lts360.recon.model import load_calibration, save_calibration

    ref = tmp_path / "ref"
    assert main(["render", "--object", "plug-gauge", "--out", str(ref), "--spp", "16",
                 "--seed", "1", "--noise", "none"]) == 0
    true = load_calibration(ref / "frame.json")
    delta = 0.030  # mm, the left mirror moved along its normal
    mirrors = tuple(dataclasses.replace(m, d_mm=m.d_mm + delta, corners_mm=m.corners_mm + delta * m.n)
                    if m.name == "left" else m for m in true.mirrors)
    save_calibration(tmp_path / "shifted.json", dataclasses.replace(true, mirrors=mirrors))

    for name in ("frame.json", "shifted.json"):
        src = ref / name if name == "frame.json" else tmp_path / name
        assert main(["compensate", str(ref), "--calibration", str(src),
                     "--out", str(tmp_path / f"comp-{name}")]) == 0
    a, b = _offsets(tmp_path / "comp-frame.json"), _offsets(tmp_path / "comp-shifted.json")
    # The shifted mirror's view moves by 2δ·n (its in-plane part): the offset moves back.
    n_meas = true.R_cam_meas.T @ true.mirror("left").n
    expected = -2.0 * delta * n_meas[:2]
    np.testing.assert_allclose(b["left"] - a["left"], expected, atol=1e-3)
    np.testing.assert_allclose(b["right"], a["right"], atol=1e-3)
    assert "left" in capsys.readouterr().out

    # Compensated, the shifted calibration measures what the true one does.
    clouds = {}
    for name in ("frame.json", "shifted.json"):
        out = tmp_path / f"{name}.ply"
        assert main(["measure", str(ref), "--calibration", str(tmp_path / f"comp-{name}"),
                     "--compensate", "--out", str(out), "--backend", "numpy"]) == 0
        clouds[name] = out
    import trimesh

    pa = np.asarray(trimesh.load(clouds["frame.json"]).vertices)
    pb = np.asarray(trimesh.load(clouds["shifted.json"]).vertices)
    ra, rb = np.hypot(pa[:, 0], pa[:, 1]), np.hypot(pb[:, 0], pb[:, 1])
    assert abs(np.nanmedian(ra) - np.nanmedian(rb)) < 1e-3, (np.nanmedian(ra), np.nanmedian(rb))


def test_measure_refuses_to_compensate_without_offsets(tmp_path, capsys):
    ref = tmp_path / "ref"
    assert main(["render", "--object", "plug-gauge", "--out", str(ref), "--spp", "1",
                 "--scale", "0.25", "--noise", "none"]) == 0
    assert main(["measure", str(ref), "--calibration", str(ref / "frame.json"), "--compensate",
                 "--out", str(tmp_path / "c.ply")]) == 2
    assert "lts360 compensate" in capsys.readouterr().err
    assert not (tmp_path / "c.ply").exists()


@pytest.fixture(scope="module")
def gauge_ref(tmp_path_factory):
    ref = tmp_path_factory.mktemp("master") / "ref"
    assert main(["render", "--object", "plug-gauge:x=0.5", "--out", str(ref), "--spp", "16",
                 "--scale", "0.5", "--noise", "none"]) == 0
    return ref


def test_mastering_sets_the_size_and_its_u_reaches_inspect(gauge_ref, tmp_path, capsys):
    """One shot of a master of known diameter: measured with the mastered calibration, the
    same image reads the master's radius (the fit forces it; measured: see below), and the
    master's diameter u is counted in inspect's U."""
    from lts360.geometry.fit import fit_circle
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.cloud import read_cloud

    d = 19.9987
    cal = tmp_path / "mastered.json"
    assert main(["compensate", str(gauge_ref), "--calibration", str(gauge_ref / "frame.json"),
                 "--out", str(cal), "--master-diameter-mm", str(d),
                 "--master-u-mm", "0.002"]) == 0
    printed = capsys.readouterr().out
    assert "mastered with 1 shot(s) of Ø19.9987 mm" in printed and "radial" in printed
    c = load_calibration(cal)
    assert set(c.view_radial_offsets_mm) == {"direct", "left", "right"}
    assert c.master["diameters_mm"] == [d] and not c.master["fitted_scale"]
    assert all(u >= 0.001 for u in c.master["u_radius_mm"].values())  # u(D)/2 at least
    plain, mastered = tmp_path / "plain.ply", tmp_path / "mastered.ply"
    assert main(["measure", str(gauge_ref), "--calibration", str(gauge_ref / "frame.json"),
                 "--out", str(plain)]) == 0
    assert main(["measure", str(gauge_ref), "--calibration", str(cal), "--compensate",
                 "--out", str(mastered)]) == 0
    radius = {}
    for name, path in (("plain", plain), ("mastered", mastered)):
        cl = read_cloud(path)
        radius[name] = fit_circle(cl.points_mm[cl.valid, :2]).radius_mm - d / 2
    # the same image: the mastered radius is the master's within the fit's stated U (k = 2)
    # (the measurement's band and rejection are not the compensation's)
    u_fit = 1e-3 * c.master["rms_um"] / np.sqrt(c.master["n_points"] / 3)  # order of it
    assert abs(radius["mastered"]) <= 2 * max(c.master["u_radius_mm"].values()), radius
    assert u_fit > 0
    assert main(["inspect", str(mastered), "--out", str(tmp_path / "ins")]) == 0
    data = json.loads((tmp_path / "ins" / "inspection.json").read_text())
    assert data["settings"]["master_u_radius_mm"] >= 0.001


@pytest.mark.parametrize("value, message", [
    ("0", "must be in (0, 40]"),
    ("-5", "must be in (0, 40]"),
    ("55", "must be in (0, 40]"),
    ("20,20", "must differ by at least 1 mm"),
    ("20,x", "expected numbers"),
])
def test_master_bad_input_is_one_line_exit_2(gauge_ref, tmp_path, capsys, value, message):
    out = tmp_path / "m.json"
    rc = main(["compensate", str(gauge_ref), "--calibration", str(gauge_ref / "frame.json"),
               "--out", str(out), f"--master-diameter-mm={value}"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and message in err and "\n" not in err, err
    assert not out.exists()


def test_mastering_with_the_twin_fits_the_bias_corrected_references(gauge_ref, tmp_path,
                                                                     capsys):
    """With --bias-model twin the references' line-centre bias is removed before the fit, so
    the masters set what the twin leaves (measurements made with the twin are not corrected
    twice): the radial offsets differ from the plain mastering's by about the twin's bias."""
    plain, twin = tmp_path / "plain.json", tmp_path / "twin.json"
    base = ["compensate", str(gauge_ref), "--calibration", str(gauge_ref / "frame.json"),
            "--master-diameter-mm", "19.9987"]
    assert main(base + ["--out", str(plain)]) == 0
    assert main(base + ["--out", str(twin), "--bias-model", "twin"]) == 0
    out = capsys.readouterr().out
    assert "reference twin bias correction: direct" in out
    a = json.loads(plain.read_text())["view_radial_offsets_mm"]
    b = json.loads(twin.read_text())["view_radial_offsets_mm"]
    assert set(a) == set(b) == {"direct", "left", "right"}
    assert any(abs(a[k] - b[k]) > 1e-3 for k in a)  # the twin's bias: several µm
    rc = main(["compensate", str(gauge_ref), "--calibration", str(gauge_ref / "frame.json"),
               "--out", str(tmp_path / "x.json"), "--bias-model", "twin"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "only with masters" in err and "\n" not in err

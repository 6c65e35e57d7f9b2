"""`lts360 compensate` (paper §4.4) on a rendered gauge: a mirror plane shifted by δ moves
that view's points by 2δ along the mirror's normal, and the command's offsets follow it
exactly; `lts360 measure --compensate` applies them and refuses a calibration without any."""

import dataclasses
import json

import numpy as np
import pytest

from lts360.cli import main

pytest.importorskip("mitsuba")


def _offsets(path):
    return {k: np.asarray(v) for k, v in json.loads(path.read_text())["view_offsets_mm"].items()}


def test_offsets_follow_a_shifted_mirror(tmp_path, capsys):
    from lts360.recon.calibration.model import load_calibration, save_calibration

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

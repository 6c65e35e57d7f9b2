"""``lts360 inspect``: a report from a cloud file, and bad input as one line, exit 2, nothing
written."""

import json

import numpy as np
import pytest
from _profiles import scan_cloud

from lts360.cli import main
from lts360.recon.triangulation.cloud import Cloud, write_cloud


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("in")
    c = scan_cloud(n_sections=3)
    write_cloud(d / "scan.ply", c)
    bad = Cloud(np.full_like(c.points_mm, np.nan), c.theta_rad, c.radius_mm, c.view,
                np.ones_like(c.quality), c.section, c.intensity)
    write_cloud(d / "empty.ply", bad)
    (d / "open.csv").write_text("x_mm,y_mm\n10,0\n0,10\n-10,0\n0,-10\n")
    (d / "units.csv").write_text("x_furlong,y_furlong\n10,0\n0,10\n-10,0\n10,0\n")
    (d / "values.csv").write_text("x_mm,y_mm\n10,0\n0,ten\n-10,0\n10,0\n")
    return d


@pytest.mark.parametrize("args,field", [
    (("empty.ply",), "no valid point"),
    (("scan.ply", "--nominal", "open.csv"), "not closed"),
    (("scan.ply", "--nominal", "units.csv"), "unit does not parse"),
    (("scan.ply", "--nominal", "values.csv"), "not two finite numbers"),
    (("scan.ply", "--nominal", "teapot"), "teapot"),
    (("scan.ply", "--tolerance-mm", "0.1"), "--nominal"),
    (("scan.ply", "--nominal", "plug-gauge", "--tolerance-mm", "-1"), "--tolerance-mm"),
    (("scan.ply", "--nominal", "plug-gauge", "--upper-mm", "0.1"), "--upper-mm"),
    (("scan.ply", "--nominal", "plug-gauge", "--upper-mm", "-0.1", "--lower-mm", "0.1"),
     "upper"),
    (("scan.ply", "--lump-mm", "abc"), "--lump-mm"),
    (("scan.ply", "--u-radial-mm", "-0.001"), "--u-radial-mm"),
    (("nope.ply",), "nope.ply"),
    (("scan.ply", "--calibration", "nope.json"), "nope.json"),
    (("scan.ply", "--truth", "."), "--truth"),
])
def test_bad_input_is_one_line_exit_2_nothing_written(args, field, files, tmp_path,
                                                      monkeypatch, capsys):
    monkeypatch.chdir(files)
    out = tmp_path / "report"
    assert main(["inspect", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err and field in lines[0]
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_a_report_from_a_cloud_file(files, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["inspect", str(files / "scan.ply"), "--out", str(out), "--nominal",
                 "plug-gauge:d=20", "--upper-mm", "0.1", "--lower-mm", "-0.1"]) == 0
    data = json.loads((out / "inspection.json").read_text())
    assert data["n_sections"] == 3 and data["nominal"]["pass"] is True
    assert "PASS" in capsys.readouterr().out


def test_a_radial_offset_adds_to_sizes_only():
    from lts360.inspect.run import inspect_cloud

    cloud = scan_cloud(n_sections=1, noise_mm=0.002)
    a = inspect_cloud(cloud).data["sections"][0]
    b = inspect_cloud(cloud, u_radial_mm=0.003).data["sections"][0]
    assert b["d_ls_mm"]["u"] == pytest.approx(np.hypot(a["d_ls_mm"]["u"], 0.006))
    assert b["d_min_mm"]["u"] == pytest.approx(np.hypot(a["d_min_mm"]["u"], 0.006))
    for key in ("ovality_mm", "centre_x_mm"):
        assert b[key]["u"] == a[key]["u"]
    assert b["ront_mm"]["MZCI"]["u"] == a["ront_mm"]["MZCI"]["u"]


@pytest.mark.parametrize("args,field", [
    (("--diameter-mm", "32±-0.3"), "--diameter-mm"),
    (("--diameter-mm", "32"), "--diameter-mm"),
    (("--ovality-max-mm", "-1"), "--ovality-max-mm"),
    (("--filter-upr", "0"), "--filter-upr"),
    (("--filter-upr", "50", "--filter", "none"), "--filter-upr"),
    (("--nominal", "-3"), "--nominal"),
])
def test_bad_tolerances_and_filters_are_one_line_exit_2(args, field, files, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["inspect", str(files / "scan.ply"), *args, "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and field in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_tolerances_give_the_exit_status_a_line_acts_on(files, tmp_path, capsys):
    """The scan's sections are Ø 20 mm with 0.2 mm ovality: D min 19.9, D max 20.1."""
    ok = tmp_path / "ok"
    assert main(["inspect", str(files / "scan.ply"), "--out", str(ok), "--nominal", "20",
                 "--diameter-mm", "20±0.3", "--ovality-max-mm", "0.5"]) == 0
    data = json.loads((ok / "inspection.json").read_text())
    assert data["verdict"] == {"pass": True, "failed": []}
    assert data["nominal"]["source"] == "Ø 20 mm"
    assert data["command"].startswith("lts360 inspect") and data["tool"]["version"]
    assert data["settings"]["filter"].startswith("ISO 12181-2 Gaussian, 50 UPR")
    assert "PASS" in capsys.readouterr().out
    bad = tmp_path / "bad"
    assert main(["inspect", str(files / "scan.ply"), "--out", str(bad),
                 "--diameter-mm", "20+-0.05", "--ovality-max-mm", "0.1"]) == 1
    data = json.loads((bad / "inspection.json").read_text())
    assert data["verdict"]["pass"] is False and len(data["verdict"]["failed"]) == 6
    s = data["sections"][0]["checks"]
    assert s["diameter"]["conformance_iso14253"] == "does not conform"  # 0.1 mm out, U ~ µm
    assert "FAIL" in capsys.readouterr().out


def test_measure_names_the_frame_json_of_a_scan_folder(tmp_path, capsys):
    """A scan folder has no frame.json of its own: `measure` says which file to use."""
    scan = tmp_path / "scan"
    (scan / "section_0000").mkdir(parents=True)
    (scan / "scan.json").write_text('{"sections": [{"dir": "section_0000", "z_mm": 0.0}]}')
    (scan / "section_0000" / "frame.json").write_text("{}")
    assert main(["measure", str(scan), "--calibration", str(scan / "frame.json"), "--out",
                 str(tmp_path / "c.ply")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--calibration" in lines[0]
    assert str(scan / "section_0000" / "frame.json") in lines[0]
    assert not (tmp_path / "c.ply").exists()

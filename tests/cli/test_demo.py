"""The README's main job runs end to end and writes what it says."""

import json
import subprocess
import sys

import pytest


def test_demo_writes_rig_objects_frames_and_scores(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "lts360.cli", "demo", "--quick", "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "total: 360.0° of 360°" in proc.stdout
    for name in ("rig.png", "sections.png", "rig.toml", "summary.json"):
        assert (out / name).is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert len(list((out / "objects").glob("*.ply"))) == len(summary["objects"]) >= 9
    for frame in ("plug-gauge-none", "plug-gauge-realistic"):
        d = out / "frames" / frame
        for name in ("image.png", "radiance.exr", "truth.ply", "frame.json", "cloud.ply", "metrics.json"):
            assert (d / name).is_file()
        m = json.loads((d / "metrics.json").read_text())
        assert m["coverage_deg"] > 355.0 and abs(m["radius_bias_mm"]) < 0.01
    assert not list(tmp_path.glob(".*partial"))  # no half-written output left behind


@pytest.mark.slow
@pytest.mark.timeout(1800)  # the whole demo: minutes on 2 cores
def test_the_full_demo_calibrates_and_runs_the_plug_gauge_study(tmp_path):
    """The README's main job as a user runs it (minutes): calibration from rendered images,
    the gauge placed and measured, the paper's table beside ours."""
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "lts360.cli", "demo", "--gauge-trials", "3",
                           "--out", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "expanded uncertainty U (k = 2)" in proc.stdout
    for name in ("calibration/calibration.json", "calibration/report.json", "calibration/fig8.png",
                 "plug-gauge/table.json", "plug-gauge/plug-gauge.png",
                 "plug-gauge/trials/results.nc"):
        assert (out / name).is_file(), name
    assert len(list((out / "plug-gauge" / "clouds").glob("*.ply"))) == 3
    table = json.loads((out / "plug-gauge" / "table.json").read_text())
    assert table["n_measurements"] == 3 and table["mean_coverage_deg"] > 350.0
    # Measured as a user would (§4.4, master, twin): the size within a few µm (10 placements:
    # +1.8 µm, STUDIES.md). What §4.4 alone reads depends on the calibration's realisation
    # (−15.4 and −3.0 µm for two speckle generators' boards): the master removes it, so only
    # ours is bounded; every step is measured on the same images.
    assert table["ours"] == "c44_master_twin"
    assert abs(table["mean_radius_error_mm"]) < 0.006
    assert {"c44", "c44_master", "c44_twin", "c44_master_twin"} <= set(table["steps"])
    assert all(abs(s["mean_radius_error_mm"]) < 0.05 for s in table["steps"].values())
    assert "§4.4 + master + twin" in proc.stdout and "maximum error |mean| + U" in proc.stdout

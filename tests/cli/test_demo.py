"""The README's main job runs end to end and writes what it says."""

import json
import subprocess
import sys


def test_demo_writes_rig_objects_frames_and_scores(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "lts360.cli", "demo", "--out", str(out)],
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

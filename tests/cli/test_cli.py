"""The command line: one clear line and exit code 2 on bad input, no traceback."""

import subprocess
import sys

import pytest
import trimesh

from lts360.cli import main


def run(*args):
    return subprocess.run([sys.executable, "-m", "lts360.cli", *args], capture_output=True, text=True)


@pytest.mark.parametrize("args,field", [
    (("object", "plug-gauge:d=50", "--out", "x.ply"), "diameter_mm"),
    (("object", "plug-gauge:wobble=1", "--out", "x.ply"), "wobble"),
    (("object", "teapot", "--out", "x.ply"), "teapot"),
    (("rig", "no-such-rig.toml"), "no-such-rig.toml"),
    (("rig", "--coverage", "--radius-mm", "-3"), "--radius-mm"),
    (("rig", "--radius-mm", "abc"), "--radius-mm"),
    (("frobnicate",), "frobnicate"),
    (("calibrate", "--out", "c", "--images", "no-such-dir"), "--images"),
    (("calibrate", "--out", "c", "--board", "7x6"), "--board"),
    (("calibrate", "--out", "c", "--laser-poses", "1"), "--laser-poses"),
    (("calibrate", "--out", "c", "--camera-model", "-1"), "--camera-model"),
    (("study", "plug-gauge", "--out", "s", "--trials", "0"), "--trials"),
    (("study", "plug-gauge", "--out", "s", "--calibration", "nope.json"), "--calibration"),
    (("study", "design-space", "--out", "s", "--alpha-deg", "40:20:5"), "--alpha-deg"),
    (("study", "design-space", "--out", "s", "--draws", "1"), "--draws"),
    (("study", "monte-carlo", "--out", "s", "--trials", "1"), "--trials"),
    (("study", "monte-carlo", "--out", "s", "--compensation-shots", "0"), "--compensation-shots"),
    (("study", "plug-gauge", "--out", "s", "--compensation-shots", "101"), "--compensation-shots"),
    (("study", "plug-gauge", "--out", "s", "--rig", "no-such-rig.toml"), "no-such-rig.toml"),
    (("study", "plug-gauge", "--out", "s", "--placement-mm", "-1"), "--placement-mm"),
    (("study", "monte-carlo", "--out", "s", "--master", "--no-compensate"), "--master"),
    (("study", "monte-carlo", "--out", "s", "--placement-mm", "11"), "--placement-mm"),
    (("study", "monte-carlo", "--out", "s", "--spp", "0"), "--spp"),
    (("measure", "f", "--calibration", "c.json", "--out", "c.ply", "--reject", "maybe"),
     "--reject"),
    (("study", "examples", "--out", "s", "--objects", "teapot"), "teapot"),
    (("study", "algorithms", "--out", "s", "--workers", "2", "--dask", "tcp://x:1"), "--dask"),
    (("study", "nonsense", "--out", "s"), "nonsense"),
    (("render", "--object", "plug-gauge", "--out", "f", "--speed-mm-s", "100"), "--exposure-us"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "-5",
      "--speed-mm-s", "100"), "--exposure-us"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "100",
      "--shutter", "rolling"), "line_time_s"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "100",
      "--vibration-mm", "1,x"), "--vibration-mm"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "100", "--scale", "0.125",
      "--speed-mm-s", "1e6"), "measured zone"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "100", "--scale", "0.125",
      "--shutter", "rolling", "--line-time-us", "100", "--profile-rate-hz", "100"),
     "trigger period"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "100",
      "--speed-mm-s", "100", "--sections", "3"), "--profile-rate-hz"),
    (("study", "line-speed", "--out", "s", "--shutters", "diagonal"), "--shutters"),
    (("study", "line-speed", "--out", "s", "--exposures-us", "0"), "--exposures-us"),
    (("study", "line-speed", "--out", "s", "--speeds-mm-s", "fast"), "--speeds-mm-s"),
    (("study", "line-speed", "--out", "s", "--objects", "teapot"), "teapot"),
    (("study", "bias", "--out", "s", "--placements-mm", "3"), "--placements-mm"),
    (("study", "bias", "--out", "s", "--placements-mm", "30:0"), "--placements-mm"),
    (("study", "bias", "--out", "s", "--diameters-mm", "0.5"), "--diameters-mm"),
    (("study", "bias", "--out", "s", "--twin-spp", "0"), "--twin-spp"),
    (("render", "--object", "plug-gauge", "--out", "f", "--exposure-us", "100",
      "--vibration-mm", "0.1,0.1", "--vibration-hz", "50", "--vibration-kind", "random",
      "--vibration-seed", "-2"), "vibration_seed"),
    (("render", "--object", "plug-gauge", "--out", "f", "--max-scatter", "4"), "--max-scatter"),
    (("render", "--object", "plug-gauge", "--out", "f", "--roughness", "0"), "--roughness"),
    (("render", "--object", "plug-gauge", "--out", "f", "--roughness", "-0.2"), "--roughness"),
    (("compensate", "ref", "--calibration", "nope.json", "--out", "c.json"), "nope.json"),
    (("compensate", "ref", "--calibration", "c.json", "--out", "c2.json", "--band-mm", "20"),
     "--band-mm"),
])
def test_usage_errors_are_one_line_exit_2(args, field, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(list(args)) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert field in lines[0]
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_a_usage_error_is_exit_2_and_one_line_from_the_real_process(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "lts360.cli", "study", "plug-gauge", "--out",
                           "s", "--trials", "0"], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--trials" in lines[0] and "Traceback" not in proc.stderr
    assert not list(tmp_path.iterdir())


def test_help_for_every_command(capsys):
    for cmd in ("objects", "object", "rig", "render", "measure", "compensate", "score",
                "calibrate", "study", "demo"):
        assert main([cmd, "--help"]) == 0
        assert "usage: lts360" in capsys.readouterr().out
    for study in ("plug-gauge", "examples", "design-space", "monte-carlo", "algorithms"):
        assert main(["study", study, "--help"]) == 0
        out = capsys.readouterr().out
        assert "--seed" in out and "--dask" in out
    proc = run("measure", "--help")  # the installed entry point's module, as a process
    assert proc.returncode == 0 and "usage: lts360" in proc.stdout


def test_object_writes_a_watertight_mesh(tmp_path, capsys):
    out = tmp_path / "pg.ply"
    assert main(["object", "plug-gauge:d=19.9987,x=0.5,tilt_deg=1", "--out", str(out)]) == 0
    mesh = trimesh.load(out)
    assert mesh.is_watertight
    assert "watertight=True" in capsys.readouterr().out


def test_rig_coverage_table(capsys):
    assert main(["rig", "paper", "--coverage", "--radius-mm", "10"]) == 0
    out = capsys.readouterr().out
    assert "total: 360.0° of 360°" in out
    for view in ("direct", "left", "right"):
        assert f"  {view} " in out


def test_objects_lists_every_object(capsys):
    assert main(["objects"]) == 0
    out = capsys.readouterr().out
    assert "plug-gauge" in out and "diameter_mm (d)" in out


def test_version_prints_the_installed_version_and_exits_0(capsys):
    from importlib.metadata import version

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"lts360 {version('lts360')}"


def test_render_a_moving_scan_triggered_at_a_profile_rate(tmp_path, capsys):
    import json

    out = tmp_path / "scan"
    assert main(["render", "--object", "plug-gauge", "--out", str(out), "--scale", "0.0625",
                 "--spp", "1", "--exposure-us", "100", "--speed-mm-s", "100",
                 "--profile-rate-hz", "50", "--sections", "2"]) == 0
    scan = json.loads((out / "scan.json").read_text())
    assert [s["t_trigger_s"] for s in scan["sections"]] == [0.0, 0.02]
    assert scan["sections"][1]["z_mm"] == pytest.approx(-2.0)  # 100 mm/s for 20 ms
    frame = json.loads((out / "section_0001" / "frame.json").read_text())
    assert frame["motion"]["t_trigger_s"] == 0.02
    assert frame["motion"]["acquisition"]["trigger"]["profile_rate_hz"] == 50.0


def test_the_console_script_runs_exit_handlers_and_keeps_exit_codes(tmp_path):
    """``lts360`` skips the interpreter's teardown, not its exit handlers: a registered handler
    still runs (after the command's output), a usage error still exits 2, and a reader that
    closes the pipe early ends the command with 1 and no traceback."""
    code = ("import atexit, sys; from lts360.cli import run; "
            "atexit.register(lambda: print('handler ran')); sys.argv = ['lts360', *sys.argv[1:]]; "
            "run()")
    ok = subprocess.run([sys.executable, "-c", code, "objects"], capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stdout.rstrip().endswith("handler ran")
    assert "plug-gauge" in ok.stdout
    bad = subprocess.run([sys.executable, "-c", code, "frobnicate"], capture_output=True, text=True)
    assert bad.returncode == 2 and "handler ran" in bad.stdout and "Traceback" not in bad.stderr
    head = subprocess.Popen([sys.executable, "-m", "lts360.cli", "objects"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    head.stdout.close()  # the reader leaves before the first line
    assert head.wait(timeout=60) == 1
    assert "Traceback" not in head.stderr.read().decode()

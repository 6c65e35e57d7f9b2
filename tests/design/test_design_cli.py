"""``lts360 design``: bad input (one line, exit 2, nothing written), a map, a small optimisation."""

from __future__ import annotations

import json

import pytest

from lts360.cli import main
from lts360.scenes.rig_io import load_rig


@pytest.mark.parametrize("argv, message", [
    (["--free", "alpha,beta_deg"], "unknown design parameter 'alpha'"),
    (["--bound", "alpha_deg=5:50"], "bounds of alpha_deg: (5, 50) outside the valid range"),
    (["--bound", "alpha_deg=50"], "expected NAME=LO:HI"),
    (["--diameters-mm", "20,x"], "comma-separated numbers"),
    (["--diameters-mm", "-3"], "diameters_mm: must be positive"),
    (["--min-coverage-deg", "400"], "min_coverage_deg: must be in [0, 360]"),
    (["--calibration", "no-such.json"], "--calibration: no file 'no-such.json'"),
    (["--calibration", "pyproject.toml"], "not a calibration JSON"),
    (["--compensation-shots", "0"], "compensation_shots: must be an integer in [1, 100]"),
    (["--compensation-diameter-mm", "-1"], "compensation_diameter_mm: must be a positive"),
    (["--master", "--no-compensation"], "master: needs the compensation"),
])
def test_optimize_bad_input(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    assert main(["design", "optimize", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, message", [
    ([], "--pipeline needs --out"),
    (["--out", "OUT", "--seeds", "0,x"], "--seeds: comma-separated integers"),
    (["--out", "OUT", "--seeds", "1,1"], "seeds: must be distinct integers"),
    (["--out", "OUT", "--placements", "1"], "placements: must be an integer >= 2"),
    (["--out", "OUT", "--placement-mm", "-1"], "placement"),
    (["--out", "OUT", "--shares"], "--pipeline: not with --shares"),
    (["--out", "OUT", "--spp", "0"], "spp: must be an integer in [1, 4096]"),
])
def test_check_pipeline_bad_input(tmp_path, capsys, argv, message):
    """``design check --pipeline``: one line, exit 2, before anything is rendered."""
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert main(["design", "check", "paper", "--pipeline", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


def test_pipeline_options_need_pipeline(tmp_path, capsys):
    for argv in (["--out", str(tmp_path / "o")], ["--no-master-check"]):
        assert main(["design", "check", "paper", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert "need --pipeline" in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


def test_map_bad_input(tmp_path, capsys):
    assert main(["design", "map", "--x", "alpha_deg", "--y", "alpha_deg",
                 "--out", str(tmp_path / "m.png")]) == 2
    assert main(["design", "map", "--x", "alpha_deg", "--y", "beta_deg", "--n", "1",
                 "--out", str(tmp_path / "m.png")]) == 2
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # ~10 s: records the batched and the gradient models
def test_optimize_writes_a_loadable_rig_and_the_report(tmp_path, capsys):
    out = tmp_path / "opt"
    rc = main(["design", "optimize", "--out", str(out), "--free", "alpha_deg,f_number",
               "--starts", "2", "--grid-per-axis", "3", "--n-theta", "90",
               "--diameters-mm", "20"])
    assert rc == 0
    rig = load_rig(out / "rig.toml")
    rep = json.loads((out / "report.json").read_text())
    labels = [d["label"] for d in rep["designs"]]
    assert labels == ["base rig", "grid best", "gradient optimum"]
    opt = rep["designs"][2]
    assert opt["hard"]["ok"]
    assert opt["objective_um"] <= rep["designs"][1]["objective_um"] + 1e-9
    assert rig.design.alpha_deg == pytest.approx(opt["parameters"]["alpha_deg"])
    assert "gradient optimum" in (out / "report.txt").read_text()
    # the compensation's share is in U by default, and reported apart
    assert opt["sigma_R_compensation_um"] > 0
    assert opt["U_um"] == pytest.approx(2 * opt["sigma_R_um"], rel=1e-9)
    assert "share: §4.4 compensation" in (out / "report.txt").read_text()
    # the line-centre bias: the whole (negative) and what the twin leaves, a share of U
    assert opt["line_centre_bias_um"] < 0
    assert opt["sigma_R_bias_left_um"] == pytest.approx(0.1 * abs(opt["line_centre_bias_um"]),
                                                        rel=1e-6)
    assert "share: line-centre bias left" in (out / "report.txt").read_text()


@pytest.mark.slow  # ~15 s: records the models with a calibration covariance
def test_optimize_with_a_calibration_file(tmp_path):
    unc = {"camera": {"std": {"fx": 0.2, "fy": 0.2, "cx": 0.15, "cy": 0.15, "k1": 4e-4,
                              "k2": 1e-3}},
           "mirrors": {m: {"cov_abd": [[1.4e-4 ** 2, 0, 0], [0, 1e-4 ** 2, 0], [0, 0, 0.02 ** 2]]}
                       for m in ("left", "right")},
           "laser_plane": {"cov_abd": [[5e-4 ** 2, 0, 0], [0, 1.4e-4 ** 2, 0],
                                       [0, 0, 0.06 ** 2]]}}
    cal = tmp_path / "calibration.json"
    cal.write_text(json.dumps({"uncertainty": unc}))
    out = tmp_path / "opt"
    assert main(["design", "optimize", "--out", str(out), "--free", "alpha_deg",
                 "--starts", "1", "--grid-per-axis", "3", "--n-theta", "90",
                 "--diameters-mm", "20", "--calibration", str(cal)]) == 0
    rep = json.loads((out / "report.json").read_text())
    opt = rep["designs"][2]
    assert opt["sigma_R_calibration_um"] > 0.1
    assert rep["conditions"]["calibration"]["source"] == str(cal)
    out2 = tmp_path / "opt-plan"
    assert main(["design", "optimize", "--out", str(out2), "--free", "alpha_deg",
                 "--starts", "1", "--grid-per-axis", "3", "--n-theta", "90",
                 "--diameters-mm", "20", "--calibration", "plan"]) == 0
    rep2 = json.loads((out2 / "report.json").read_text())
    assert rep2["conditions"]["calibration"]["source"].startswith("plan of paper")
    assert rep2["designs"][2]["sigma_R_calibration_um"] > 0.1
    assert opt["sigma_R_um"] == pytest.approx(
        (opt["sigma_R_noise_um"] ** 2 + opt["sigma_R_compensation_um"] ** 2
         + opt["sigma_R_calibration_um"] ** 2 + opt["sigma_R_bias_left_um"] ** 2) ** 0.5,
        rel=1e-6)  # the four shares in quadrature (the bias the twin leaves among them)


@pytest.mark.slow  # ~5 s: records the batched model
def test_map_writes_a_png(tmp_path):
    out = tmp_path / "m.png"
    assert main(["design", "map", "--x", "alpha_deg", "--y", "beta_deg", "--n", "12",
                 "--n-theta", "90", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # ~10 s: records the batched and the gradient models
def test_optimize_infeasible_constraints_exit_2_and_write_nothing(tmp_path, capsys):
    out = tmp_path / "opt"
    rc = main(["design", "optimize", "--out", str(out), "--free", "alpha_deg,beta_deg",
               "--min-overlap-deg", "60", "--starts", "2", "--n-theta", "90",
               "--diameters-mm", "20"])
    assert rc == 2
    assert "no start reached a valid rig" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []

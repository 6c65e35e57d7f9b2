"""The GPU check (benchmarks/gpu_check.py, gpu_check.sh) runs end to end on the CPU.

CI has no GPU: the driver's quick sizes with the LLVM variant and backend go through the same
code (render rate and stripe check, recon kernel against LLVM and numpy, Monte Carlo trials in
a process pool); the table must have every row with finite, positive values, and LLVM must
agree with itself exactly.
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "gpu_check.sh"

#: Every row of the table, by key.
ROWS = (
    "render_first_16", "render_fps_16", "render_only_fps_16",
    "render_first_64", "render_fps_64", "render_only_fps_64",
    "stripe_rms_px_direct", "stripe_rms_px_left", "stripe_rms_px_right",
    "full_cached_fps_16", "support_fps_16", "support_fps_256",
    "recon_plan_s", "recon_setup_s", "recon_first_ms", "recon_ms", "recon_kernel_ms",
    "recon_vs_llvm_um", "recon_vs_llvm_n", "recon_vs_numpy_um", "recon_vs_numpy_n",
    "mc_setup_s", "mc_wall_s", "mc_1000_s",
)


def _load_driver():
    spec = importlib.util.spec_from_file_location("lts360_gpu_check_driver",
                                                  ROOT / "benchmarks" / "gpu_check.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def driver():
    return _load_driver()


@pytest.fixture(scope="module")
def quick_run(driver, tmp_path_factory):
    out = tmp_path_factory.mktemp("gpu-check") / "check.json"
    code = driver.main(["--variant", "llvm_ad_mono", "--backend", "llvm", "--quick",
                        "--json", str(out)])
    return code, json.loads(out.read_text())


@pytest.mark.slow  # the quick LLVM run of every part of the check
def test_quick_llvm_run_has_every_row_with_sane_values(quick_run):
    code, out = quick_run
    assert code == 0
    rows = {r["key"]: r for r in out["rows"]}
    assert set(ROWS) <= set(rows), f"missing rows: {sorted(set(ROWS) - set(rows))}"
    for key in ROWS:
        r = rows[key]
        assert "FAILED" not in r["note"], (key, r["note"])
        assert r["value"] is not None and math.isfinite(r["value"]), (key, r)
    for key in ROWS:
        if not key.startswith(("recon_vs_", "stripe_")):
            assert rows[key]["value"] > 0, key
    # The backend against itself: bit for bit.
    assert rows["recon_vs_llvm_um"]["value"] == 0.0
    assert rows["recon_vs_llvm_n"]["value"] == 0
    # Against the numpy reference (double precision): float32 rounding.
    assert rows["recon_vs_numpy_um"]["value"] < 0.05
    assert rows["recon_vs_numpy_n"]["value"] <= 2
    # Stripe centres within a fraction of a pixel of the projected section (quarter scale).
    for view in ("direct", "left", "right"):
        assert rows[f"stripe_rms_px_{view}"]["value"] < 0.3
    mc = out["raw"]["mc"]
    assert mc["done"] == mc["trials"] and mc["finite_y"] == mc["trials"]
    assert not mc["cut"]


@pytest.mark.slow  # the quick LLVM run of every part of the check
def test_table_prints_every_row_and_no_targets_in_quick_mode(driver, quick_run):
    _, out = quick_run
    text = driver.format_table(out["rows"], quick=True)
    lines = text.splitlines()
    assert len(lines) == 2 + len(out["rows"])
    for r in out["rows"]:
        assert any(line.startswith(r["what"]) for line in lines), r["what"]
    assert " yes " not in text and " NO " not in text


def test_verdicts_against_the_targets(driver):
    assert driver.verdict("render_fps_16", 120.0, quick=False) == "yes"
    assert driver.verdict("render_fps_16", 80.0, quick=False) == "NO"
    assert driver.verdict("recon_ms", 0.25, quick=False) == "yes"
    assert driver.verdict("recon_ms", 0.8, quick=False) == "NO"
    assert driver.verdict("support_fps_256", 520.0, quick=False) == "yes"
    assert driver.verdict("full_cached_fps_16", 120.0, quick=False) == "NO"
    assert driver.verdict("mc_1000_s", 75.0, quick=False) == "NO"
    assert driver.verdict("stripe_rms_px", 0.02, quick=True) == "n/a"
    assert driver.verdict("recon_plan_s", 1.0, quick=False) == ""


def test_shell_script_parses():
    subprocess.run(["bash", "-n", str(SCRIPT)], check=True)

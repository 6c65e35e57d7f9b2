"""The Monte Carlo trial's twin, rendered for each trial or frozen per placement, on the same
draws: what the frozen correction changes in each trial's result, and what each costs.

Each trial is run twice, ``twin_per="trial"`` then ``twin_per="placement"``, with the same
trial seed (the same image, calibration draw and reference shot); the paired differences of
``y_um`` (ours: §4.4 + master + twin), ``y_no_twin_um`` and ``twin_bias_um`` are summarised
against the spread of ``y_um`` itself (its standard deviation over the trials, an estimate of
u(y)).  CPU and wall time per trial of each mode (one process, trials one after another;
the frozen corrections' own cost — once per placement and process — is in its first trials).

Set-up as ``benchmarks/bench_mc_trial.py`` (``--setup DIR``: the placements' renders and the
calibration, made once).

Usage: python benchmarks/bench_mc_twin.py --setup DIR [--placements 2] [--trials 24]
       [--json OUT]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--setup", required=True)
    ap.add_argument("--placements", type=int, default=2)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--trials", type=int, default=24)
    ap.add_argument("--theta-step-deg", type=float, default=0.5)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    import mitsuba as mi

    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.monte_carlo import mc_trial
    from lts360.experiments.runner import plan_trials

    setup = Path(args.setup)
    base_file = setup / "base.json"
    if base_file.is_file():
        base = json.loads(base_file.read_text())
    else:
        root = Path(__file__).resolve().parent
        spec = importlib.util.spec_from_file_location("gpu_check", root / "gpu_check.py")
        gc = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(gc)
        setup.mkdir(parents=True, exist_ok=True)
        base = gc.mc_setup(setup, args.placements, args.spp)
        base_file.write_text(json.dumps(base, indent=2))
    params = {k: v for k, v in base.items() if k != "setup_s"}
    params.update(master=True, steps=True, bias_model="twin",
                  theta_step_deg=args.theta_step_deg)
    out = {}
    for mode in ("trial", "placement"):
        trials = plan_trials([dict(params, twin_per=mode)] * args.trials, seed=0)
        rows, wall, cpu = [], [], []
        for t in trials:
            t0, c0 = time.perf_counter(), time.process_time()
            rows.append(mc_trial(t).values)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out[mode] = {"values": rows, "wall_s": wall, "cpu_s": cpu}
    keys = ("y_um", "y_no_twin_um", "twin_bias_um", "y_c44_master_um", "y_c44_um")
    a, b = out["trial"]["values"], out["placement"]["values"]
    y = np.array([r["y_um"] for r in a])
    report = {"trials": args.trials, "u_y_trial_um": float(np.std(y, ddof=1)),
              "u_y_placement_um": float(np.std([r["y_um"] for r in b], ddof=1)),
              "paired": {}}
    for k in keys:
        d = np.array([rb[k] - ra[k] for ra, rb in zip(a, b)], float)
        report["paired"][k] = {"mean_um": float(np.nanmean(d)), "std_um": float(np.nanstd(d)),
                               "max_abs_um": float(np.nanmax(np.abs(d)))}
    for mode in out:
        w, c = out[mode]["wall_s"][1:], out[mode]["cpu_s"][1:]
        report[mode] = {"first_wall_s": out[mode]["wall_s"][0],
                        "median_wall_s": statistics.median(w),
                        "median_cpu_s": statistics.median(c), "mean_cpu_s": statistics.mean(c),
                        "estimate_1000_cpu_min": 1000 * statistics.mean(c) / 2 / 60}
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text)


if __name__ == "__main__":
    main()

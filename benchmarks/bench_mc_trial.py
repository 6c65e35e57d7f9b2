"""Monte Carlo trials on the CPU: the wall time of ``mc_trial`` (sensor noise, speckle,
calibration draw, inverse triangulation) per trial, for an estimate of a 1000-trial run.

The trials are the study's main run as ``lts360 study monte-carlo`` makes them by default:
every input varying, §4.4 + master + twin, and the other configurations of each draw
(``steps``); ``--no-master``, ``--bias-model none``, ``--no-steps`` and ``--twin-per`` as the
study's options
(the setup's own ``base.json`` is not changed by them).

Set-up (``--setup DIR``): the study's placement renders and the true calibration, as
``benchmarks/gpu_check.py``'s ``mc_setup``; it is written once and reused, so that two
checkouts ("before" and "after", ``PYTHONPATH`` at each ``src``) time their trials on the same
renders.  Trials run one after another in this process (one core): the estimate for 1000
trials on ``c`` cores is ``1000 × median / c`` (the study's pool runs one trial per core).

Usage: python benchmarks/bench_mc_trial.py --setup DIR [--placements 2] [--trials 8]
       [--theta-step-deg 0.5] [--no-master] [--bias-model twin|none] [--no-steps]
       [--twin-per trial|placement] [--as-worker W] [--json OUT]

``--as-worker 2`` times a trial as one of the study's two pool workers on two cores runs it:
BLAS, OpenMP, Dr.Jit and the sensor's block loops at one thread each.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import time
from pathlib import Path


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--setup", required=True)
    ap.add_argument("--placements", type=int, default=2)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--trials", type=int, default=8)
    ap.add_argument("--theta-step-deg", type=float, default=0.5)
    ap.add_argument("--no-master", dest="master", action="store_false")
    ap.add_argument("--bias-model", choices=("twin", "none"), default="twin")
    ap.add_argument("--no-steps", dest="steps", action="store_false")
    ap.add_argument("--twin-per", choices=("trial", "placement"), default="trial")
    ap.add_argument("--as-worker", type=int, default=None, metavar="W",
                    help="run as one of W pool workers: native threads capped as the "
                         "study's pool caps them (limit_native_threads(cpu // W)); a checkout "
                         "without the cap runs uncapped, as its studies did")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    capped = None
    if args.as_worker:
        try:
            from lts360.experiments.runner import limit_native_threads
        except ImportError:
            capped = False
        else:
            limit_native_threads(max(1, (os.cpu_count() or 1) // args.as_worker))
            capped = True
    import mitsuba as mi

    mi.set_variant("llvm_ad_mono")
    import lts360
    from lts360.experiments.monte_carlo import mc_trial
    from lts360.experiments.runner import plan_trials

    root = Path(__file__).resolve().parent
    spec = importlib.util.spec_from_file_location("gpu_check", root / "gpu_check.py")
    gc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gc)
    setup = Path(args.setup)
    base_file = setup / "base.json"
    if base_file.is_file():
        base = json.loads(base_file.read_text())
    else:
        setup.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        base = gc.mc_setup(setup, args.placements, args.spp)
        base["setup_s"] = time.perf_counter() - t0
        base_file.write_text(json.dumps(base, indent=2))
    params = {k: v for k, v in base.items() if k != "setup_s"}
    params.update(master=args.master, steps=args.steps, bias_model=args.bias_model,
                  twin_per=args.twin_per)
    if args.bias_model == "twin":
        from lts360.recon.model import load_calibration
        from lts360.twin.rig import twin_design

        twin_design(load_calibration(params["calibration"]))  # refused here without optics
    trials = plan_trials([dict(params, theta_step_deg=args.theta_step_deg)] * (args.trials + 1),
                         seed=0)
    times, cpu = [], []
    for t in trials:
        t0, c0 = time.perf_counter(), time.process_time()
        mc_trial(t)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    cores = os.cpu_count() or 1
    med = statistics.median(times[1:])
    out = {"code": str(Path(lts360.__file__).resolve().parents[2]), "first_s": times[0],
           "median_s": med, "warm_s": times[1:], "estimate_1000_s": 1000 * med / cores,
           "cpu_median_s": statistics.median(cpu[1:]),
           "estimate_1000_cpu_s": 1000 * statistics.median(cpu[1:]) / cores,
           "configuration": {"master": args.master, "bias_model": args.bias_model,
                             "steps": args.steps, "twin_per": args.twin_per},
           "cores": cores, "load_average": os.getloadavg(), "setup_s": base.get("setup_s"),
           "as_worker": args.as_worker, "threads_capped": capped}
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text)


if __name__ == "__main__":
    main()

"""Design-model benchmark: one design's values and reverse-mode gradient (lts360.design).

Times :func:`lts360.design.model.evaluate` with ``gradient=True`` on the ``paper`` rig, every
parameter free (12), the optimiser's default conditions (diameters 10, 20, 30 mm, 180 θ per
case, image margin 20 px, the §4.4 compensation modelled; ``--calibration FILE`` adds that
calibration's covariance, ``--calibration plan`` the plan's, predicted per design): each
call a new design (a small perturbation, so no value can be
reused), warm (the first call — recording the frozen kernels, seconds — discarded); also one
batch of :data:`lts360.design.model.BATCH` designs without gradient.  Target ≤ 10 ms a design
on 2 cores.

Usage: PYTHONPATH=src python3 benchmarks/bench_design.py [--repeats 200] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--json", default=None)
    ap.add_argument("--calibration", default=None,
                    help="a calibration JSON whose covariance the model propagates, or 'plan' "
                    "(the covariance predicted per design from the calibration plan)")
    args = ap.parse_args()

    from lts360.design import model as M
    from lts360.design.params import DesignSpace
    from lts360.design.shares import CalibrationCovariance

    space = DesignSpace.create("paper")
    from lts360.design.calib_covariance import CalibrationPlan

    if args.calibration == "plan":
        cal = CalibrationPlan.from_rig(space.base)
    else:
        cal = CalibrationCovariance.from_file(args.calibration) if args.calibration else None
    cond = M.Conditions(diameters_mm=(10.0, 20.0, 30.0), margin_px=20.0, calibration=cal)
    x0 = space.base_x()
    t = time.perf_counter()
    M.evaluate(space, x0, cond)
    first = time.perf_counter() - t
    times = []
    for i in range(args.repeats):
        x = x0 * (1.0 + 1e-6 * (i + 1))
        t = time.perf_counter()
        e = M.evaluate(space, x, cond)
        times.append(time.perf_counter() - t)
        assert e.gradient is not None and np.all(np.isfinite(e.gradient))
    rng = np.random.default_rng(0)
    X = space.from_scaled(rng.uniform(size=(M.BATCH, len(space.free))))
    M.evaluate_batch(space, X, cond)
    t = time.perf_counter()
    M.evaluate_batch(space, X, cond)
    batch = time.perf_counter() - t
    out = {"median_ms": 1e3 * statistics.median(times),
           "p10_ms": 1e3 * float(np.percentile(times, 10)),
           "p90_ms": 1e3 * float(np.percentile(times, 90)),
           "first_call_s": first, "batch_ms_per_design": 1e3 * batch / M.BATCH,
           "parameters": len(space.free), "repeats": args.repeats,
           "calibration": (args.calibration or "none"),
           "cpus": os.cpu_count(), "machine": platform.platform()}
    print(f"design + gradient ({len(space.free)} parameters): median {out['median_ms']:.2f} ms "
          f"(p10 {out['p10_ms']:.2f}, p90 {out['p90_ms']:.2f}; first call {first:.1f} s); "
          f"batch without gradient {out['batch_ms_per_design']:.2f} ms a design")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()

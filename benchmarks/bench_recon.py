"""Reconstruction benchmark: inverse triangulation of one section on the standard grid.

Standard grid of issue 4: full 360°, 0.1° × 5 µm over a ±2 mm band (r = 8..12 mm: 3600 × 801),
three views (direct, left, right) restricted to their geometric windows; a rendered 1280×1024
image of the plug gauge with realistic noise; the true calibration.  Times the plan (projection
+ precomputed cubic samplers, once per calibration and grid) apart from the per-image work
(sampling + peak finding + assembly), for each peak detector on the numpy path, and the
Dr.Jit (LLVM) kernel of the centroid path (first call compiles; ``drjit_llvm_peaks`` is the
kernel alone, without the numpy assembly; min/max give the spread on a shared machine).

Usage: python benchmarks/bench_recon.py [--repeats 7] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    import mitsuba as mi

    mi.set_variant("llvm_ad_mono")
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    frame = simulate_frame(load_rig("paper"), build_object("plug-gauge"), spp=16, seed=1,
                           noise="realistic")
    cal = calibration_from_frame_truth(json.loads(json.dumps(frame.truth, default=lambda v: v.tolist())))
    grid = CylGrid.from_ranges((8.0, 12.0), theta_step_deg=0.1, r_step_mm=0.005)
    out = {"machine": f"{platform.node()} {os.cpu_count()} cores", "grid": list(grid.shape)}
    t0 = time.perf_counter()
    plan = plan_inverse(cal, grid, precompute=True)
    out["plan_s"] = time.perf_counter() - t0
    out["points"] = int(sum(v.uv.shape[0] * v.uv.shape[1] for v in plan.views.values()))
    for peak in ("centroid", "gauss", "steger"):
        opts = {"line_width_mm": 0.6} if peak == "steger" else None
        times = []
        for _ in range(args.repeats + 1):
            t0 = time.perf_counter()
            inverse_triangulate(frame.image, cal, grid, peak=peak, plan=plan, peak_options=opts)
            times.append(time.perf_counter() - t0)
        out[peak] = {"first_s": times[0], "median_s": statistics.median(times[1:])}
    t0 = time.perf_counter()
    inverse_triangulate(frame.image, cal, grid, peak="centroid")
    out["centroid_without_plan_s"] = time.perf_counter() - t0
    from lts360.recon.triangulation.fast import FastInverse

    t0 = time.perf_counter()
    fast = FastInverse(plan, backend="llvm")
    out["drjit_llvm_setup_s"] = time.perf_counter() - t0
    for key, call in [("drjit_llvm_centroid", lambda: fast(frame.image)),
                      ("drjit_llvm_peaks", lambda: fast.peaks(frame.image, threshold=25.5,
                                                              saturation=255.0))]:
        times = []
        for _ in range(args.repeats + 1):
            t0 = time.perf_counter()
            call()
            times.append(time.perf_counter() - t0)
        warm = times[1:]
        out[key] = {"first_s": times[0], "median_s": statistics.median(warm),
                    "min_s": min(warm), "max_s": max(warm)}
    from lts360.recon.triangulation.classic import classic_triangulate, view_regions

    t0 = time.perf_counter()
    regions = view_regions(cal, grid)
    out["classic_regions_s"] = time.perf_counter() - t0
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        classic_triangulate(frame.image, cal, grid, regions=regions)
        times.append(time.perf_counter() - t0)
    out["classic"] = {"median_s": statistics.median(times)}
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()

"""Render cost of a moving frame against the still one (LLVM, this machine's cores).

The plug gauge in the paper rig, 16 spp, noise-free: a still frame
(:func:`lts360.simulator.frame.simulate_frame`), a frame fed along the axis at 1 m/s with a
global shutter (100 µs: the sub-frames the 0.1 px step asks for), and the same with a rolling
shutter (10 µs per row of the full image: a 10 ms readout, rendered row band by row band).
Each is run once to compile (reported apart), then ``--repeats`` times; medians.

Usage: python benchmarks/bench_motion.py [--scale 0.5] [--repeats 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    import mitsuba as mi

    mi.set_variant("llvm_ad_mono")
    from lts360.scenes.motion import Acquisition, Motion, Shutter
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.motion import simulate_moving_frame

    rig, obj = load_rig("paper"), build_object("plug-gauge")
    E = 1e-4
    line = 1e-5 / args.scale  # the full image's 10 µs per row, on the scaled rows
    cases = {
        "still": lambda s: simulate_frame(rig, obj, spp=args.spp, seed=s, scale=args.scale,
                                          exposure_time_s=E),
        "global 1 m/s": lambda s: simulate_moving_frame(
            rig, obj, Acquisition(E, motion=Motion(speed_mm_s=1000.0)), spp=args.spp, seed=s,
            scale=args.scale),
        "rolling 1 m/s": lambda s: simulate_moving_frame(
            rig, obj, Acquisition(E, shutter=Shutter("rolling", line),
                                  motion=Motion(speed_mm_s=1000.0)),
            spp=args.spp, seed=s, scale=args.scale),
    }
    out = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
           "scale": args.scale, "spp": args.spp, "cases": {}}
    for name, fn in cases.items():
        t = time.perf_counter()
        f = fn(0)
        first = time.perf_counter() - t
        runs = []
        for k in range(args.repeats):
            t = time.perf_counter()
            fn(k + 1)
            runs.append(time.perf_counter() - t)
        renders = f.truth.get("motion", {}).get("renders", 1)
        out["cases"][name] = {"first_s": first, "median_s": statistics.median(runs),
                              "runs_s": runs, "renders": renders}
        print(f"{name:14s} first {first:6.2f} s, median {statistics.median(runs):6.2f} s "
              f"({renders} render{'s' if renders != 1 else ''})")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()

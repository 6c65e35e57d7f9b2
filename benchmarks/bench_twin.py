"""Cost of the digital twin's bias correction and of the band search that re-centres a section
(LLVM, this machine's cores).

The noise-free plug gauge frame (16 spp, full resolution) measured with the true calibration
and no radius given: the plain measurement (``measure_sections_following``), the same with the
twin (``--bias-model twin``: a 64-spp render of the plan's pixels and its measurement), and a
Ø6 mm gauge 3 mm off the axis (measured about its own centre).  Each is run once to compile
(reported apart), then ``--repeats`` times; medians.

Usage: python benchmarks/bench_twin.py [--repeats 3] [--twin-spp 64] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--twin-spp", type=int, default=64)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    import mitsuba as mi

    mi.set_variant("llvm_ad_mono")
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame
    from lts360.twin import TwinCorrector

    rig = load_rig("paper")
    frames = {spec: simulate_frame(rig, build_object(spec), spp=16, seed=0, noise="none")
              for spec in ("plug-gauge", "plug-gauge:d=6,x=3")}

    def run(spec, twin):
        f = frames[spec]
        cal = calibration_from_frame_truth(f.truth)
        sec = [Section(Path("-"), 0.0, image=f.image)]
        corr = TwinCorrector(cal, rig, spp=args.twin_spp) if twin else None
        t = time.perf_counter()
        _, _, log = measure_sections_following(sec, cal, reject=True, correct=corr)
        return time.perf_counter() - t, log, corr

    cases = {"gauge, plain": ("plug-gauge", False), "gauge, twin": ("plug-gauge", True),
             "Ø6 mm at x = 3 mm, plain (re-centred)": ("plug-gauge:d=6,x=3", False),
             "Ø6 mm at x = 3 mm, twin": ("plug-gauge:d=6,x=3", True)}
    out = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
           "twin_spp": args.twin_spp, "cases": {}}
    for name, (spec, twin) in cases.items():
        first, _, _ = run(spec, twin)
        runs, renders = [], []
        for _ in range(args.repeats):
            dt, log, corr = run(spec, twin)
            runs.append(dt)
            if corr is not None:
                renders.append(corr.log.render_s)
        row = {"first_s": first, "median_s": statistics.median(runs),
               "twin_render_s": statistics.median(renders) if renders else None,
               "centre_mm": list(log.centre_mm[0])}
        out["cases"][name] = row
        print(f"{name:40s} first {first:6.2f} s, median {row['median_s']:6.2f} s"
              + (f" (twin render {row['twin_render_s']:.2f} s)" if renders else "")
              + f", polar centre {tuple(round(c, 2) for c in log.centre_mm[0])}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()

"""Render cost of interreflections: one 1280×1024 frame of the paper rig, ``max_scatter`` 0 vs 1.

For each object, renders alternate between the settings (0, 1, 0, 1, ...) so that a change in
the machine's load hits both alike; the first pair (kernel compilation) is listed apart.  The
ratio is the median over the warm pairs of ``t(max_scatter) / t(0)``.

``--frame`` times whole realistic frames instead (``simulate_frame``: auto-exposure, speckle,
sensor noise, as the studies render them), and beside the pair a frame with ``max_scatter`` 0
on the geometric pixel support (``support="geometric"``, what a frame without
interreflections may render; one with them renders the full film).

Usage: python benchmarks/bench_scatter.py [--objects plug-gauge,alu-pipe,polished-shaft]
       [--spp 16] [--repeats 3] [--max-scatter 1] [--frame] [--json OUT]
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
    ap.add_argument("--variant", default="llvm_ad_mono")
    ap.add_argument("--objects", default="plug-gauge,alu-pipe,polished-shaft")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--max-scatter", type=int, default=1)
    ap.add_argument("--json", default=None, help="write the results here")
    ap.add_argument("--frame", action="store_true",
                    help="realistic frames (simulate_frame, noise realistic), and a support frame")
    args = ap.parse_args()
    if args.frame:
        return _frames(args)

    import mitsuba as mi

    mi.set_variant(args.variant)
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec, object_meshes

    rig = load_rig("paper")
    results = {"machine": f"{platform.node()} {os.cpu_count()} cores {platform.processor()}",
               "variant": args.variant, "spp": args.spp, "max_scatter": args.max_scatter,
               "objects": {}}
    for name in args.objects.split(","):
        spec = SceneSpec(rig, object_meshes(build_object(name)))
        pairs = []
        for _ in range(args.repeats + 1):
            pair = []
            for ms in (0, args.max_scatter):
                t0 = time.perf_counter()
                res = render_radiance(spec, spp=args.spp, seed=1, max_scatter=ms)
                pair.append(time.perf_counter() - t0)
                if _ == 0:
                    pair.append(float(res.laser_W_m2_sr.sum()))
            pairs.append(pair)
        first, warm = pairs[0], pairs[1:]
        ratio = statistics.median(b / a for a, b in warm)
        r = {"first_s": [first[0], first[2]], "warm_s": warm,
             "median_s": [statistics.median(p[0] for p in warm), statistics.median(p[1] for p in warm)],
             "ratio": ratio, "laser_sum_gain": first[3] / first[1] - 1.0}
        results["objects"][name] = r
        print(f"{name:16s} max_scatter 0: {r['median_s'][0]:.2f} s, {args.max_scatter}: "
              f"{r['median_s'][1]:.2f} s, ratio {ratio:.2f} (first pair {first[0]:.2f} / "
              f"{first[2]:.2f} s); laser light +{100 * r['laser_sum_gain']:.1f} %", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


def _frames(args) -> None:
    import mitsuba as mi

    mi.set_variant(args.variant)
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.reuse import SceneCache

    rig = load_rig("paper")
    results = {"machine": f"{platform.node()} {os.cpu_count()} cores {platform.processor()}",
               "variant": args.variant, "spp": args.spp, "max_scatter": args.max_scatter,
               "frame": True, "objects": {}}
    settings = ((0, "full"), (args.max_scatter, "full"), (0, "geometric"))
    for name in args.objects.split(","):
        obj, scenes = build_object(name), SceneCache()
        rows = []
        for _ in range(args.repeats + 1):
            row = []
            for ms, support in settings:
                t0 = time.perf_counter()
                simulate_frame(rig, obj, spp=args.spp, seed=1, noise="realistic", scenes=scenes,
                               max_scatter=ms, support=support)
                row.append(time.perf_counter() - t0)
            rows.append(row)
        warm = rows[1:]
        med = [statistics.median(r[k] for r in warm) for k in range(3)]
        ratio = statistics.median(r[1] / r[0] for r in warm)
        ratio_support = statistics.median(r[1] / r[2] for r in warm)
        results["objects"][name] = {"first_s": rows[0], "warm_s": warm, "median_s": med,
                                    "ratio": ratio, "ratio_to_support": ratio_support}
        print(f"{name:16s} frame max_scatter 0: {med[0]:.2f} s, {args.max_scatter}: {med[1]:.2f} s "
              f"(ratio {ratio:.2f}), 0 on the support: {med[2]:.2f} s (ratio {ratio_support:.2f})",
              flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()

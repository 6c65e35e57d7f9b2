"""Render benchmark: one full-resolution frame of the paper rig with the plug gauge.

Times (wall clock, median of warm runs; the first run, which JIT-compiles the kernels, apart):
* the laser integrator, noise-free expected radiance (``--noise none``),
* the whole frame with realistic sensor noise and speckle (render + sensor),
* Mitsuba's ``path`` integrator on the same scene and spp as the yardstick (dim ambient light
  in both, since ``path`` has no laser; the laser integrator also evaluates the laser).

Usage: python benchmarks/bench_render.py [--variant llvm_ad_mono] [--spp N] [--repeats 5]
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
    ap.add_argument("--spp", type=int, default=None, help="default: the renderer's default")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default=None, help="write the results here")
    args = ap.parse_args()

    import mitsuba as mi

    mi.set_variant(args.variant)
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import DEFAULT_SPP, simulate_frame
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec, object_meshes

    spp = args.spp or DEFAULT_SPP
    rig = load_rig("paper")
    obj = build_object("plug-gauge")
    results = {"machine": f"{platform.node()} {os.cpu_count()} cores {platform.processor()}",
               "variant": args.variant, "spp": spp, "image": list(rig.camera.image_size)}

    def timed(fn):
        t0 = time.perf_counter()
        fn()
        first = time.perf_counter() - t0
        warm = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            fn()
            warm.append(time.perf_counter() - t0)
        return {"first_s": first, "median_s": statistics.median(warm), "warm_s": warm}

    dark = SceneSpec(rig, object_meshes(obj), ambient="off")
    dim = SceneSpec(rig, object_meshes(obj), ambient="dim")
    results["laser_noise_free"] = timed(lambda: render_radiance(dark, spp=spp, seed=1))
    results["frame_realistic"] = timed(lambda: simulate_frame(rig, obj, spp=spp, seed=1,
                                                              noise="realistic"))
    results["laser_dim_ambient"] = timed(lambda: render_radiance(dim, spp=spp, seed=1))
    results["path_dim_ambient"] = timed(lambda: render_radiance(dim, spp=spp, seed=1,
                                                                integrator="path"))
    results["laser_over_path"] = (results["laser_dim_ambient"]["median_s"]
                                  / results["path_dim_ambient"]["median_s"])
    text = json.dumps(results, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()

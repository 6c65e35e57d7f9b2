"""Render what is measured: the full frame and the pixel support side by side.

Paper rig, plug gauge, 1280×1024, ``llvm_ad_mono`` by default.  Rows (wall clock, median of
the warm calls; the first call, which compiles, apart; ``cpu_median_s`` beside it: the
process's CPU time of a call, all threads — the work done, which other jobs sharing the machine
disturb far less than the wall clock):

* ``frame_realistic_16``: :func:`simulate_frame` at 16 spp with realistic noise and speckle,
  the default (the pixel support, when the code has one);
* ``frame_realistic_16_moved``: the first row with the object at a new stage height in every
  call (+0.25 mm): nothing about the geometry is the previous call's (the support computed anew);
* ``frame_realistic_16_full``: the same with ``support="full"`` (every pixel);
* ``frame_realistic_16_support``: the same with ``support="geometric"`` (the pixel support);
* ``frame_noise_free_256``: :func:`simulate_frame` at 256 spp without noise, the default;
* ``frame_noise_free_256_support``: the same on the pixel support;
* ``frame_realistic_16_reused``: the first row on a scene built once (``SceneCache``: the
  scene and the support are looked up, as a study's repeated frames do);
* ``frame_scatter_16``: the first row with one bounce of interreflected light
  (``max_scatter=1``, as the shiny examples render), the default support (the hull support
  where the code has one, else the full frame);
* ``frame_scatter_16_full``: the same with ``support="full"``;
* ``render_full_16``: :func:`render_radiance`, the full frame alone;
* ``sensor_realistic_16``: the sensor alone (:func:`sensor_image`, realistic noise, no
  speckle) on the render of one 16-spp frame: photo-electrons, the Poisson and read-noise
  draws and the conversion to digital values;
* ``speckle_keyed``: the frame's speckle, :func:`speckle_on_tiles` on the laser pixels of a
  16-spp frame (the code's way since the speckle is keyed to the pixel);
* ``speckle_bbox``: one :func:`speckle_pattern` on the same pixels' bounding box plus 16 px,
  the full frame's way before.

Run it with ``PYTHONPATH`` at another checkout's ``src`` to measure that code ("before"):
rows its ``simulate_frame`` cannot make (no ``support`` argument) are left out.

Usage: python benchmarks/bench_support.py [--repeats 3] [--rows a,b] [--json OUT]
"""

from __future__ import annotations

import argparse
import inspect
import itertools
import json
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path

ROWS = ("frame_realistic_16", "frame_realistic_16_moved", "frame_realistic_16_full", "frame_realistic_16_support",
        "frame_noise_free_256", "frame_noise_free_256_support", "frame_realistic_16_reused",
        "frame_scatter_16", "frame_scatter_16_full", "render_full_16", "sensor_realistic_16",
        "speckle_keyed", "speckle_bbox")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--variant", default="llvm_ad_mono")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rows", default=",".join(ROWS))
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    import mitsuba as mi

    mi.set_variant(args.variant)
    import lts360
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.render import render_radiance
    from lts360.simulator.scene import SceneSpec, object_meshes

    src = Path(lts360.__file__).resolve().parents[2]
    try:
        commit = subprocess.run(["git", "-C", str(src), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = "?"
    has_support = "support" in inspect.signature(simulate_frame).parameters
    rig, obj = load_rig("paper"), build_object("plug-gauge")
    spec = SceneSpec(rig, object_meshes(obj), ambient="off")
    fns = {"render_full_16": lambda: render_radiance(spec, spp=16, seed=1)}
    fns["frame_realistic_16"] = lambda: simulate_frame(rig, obj, spp=16, seed=1, noise="realistic")
    heights = itertools.count(1)
    fns["frame_realistic_16_moved"] = lambda: simulate_frame(
        rig, obj, spp=16, seed=1, noise="realistic", z_mm=0.25 * next(heights))
    fns["frame_noise_free_256"] = lambda: simulate_frame(rig, obj, spp=256, seed=1, noise="none")
    if has_support:
        from lts360.simulator.reuse import SceneCache

        cache = SceneCache()
        fns["frame_realistic_16_full"] = lambda: simulate_frame(
            rig, obj, spp=16, seed=1, noise="realistic", support="full")
        fns["frame_realistic_16_support"] = lambda: simulate_frame(
            rig, obj, spp=16, seed=1, noise="realistic", support="geometric")
        fns["frame_noise_free_256_support"] = lambda: simulate_frame(
            rig, obj, spp=256, seed=1, noise="none", support="geometric")
        fns["frame_realistic_16_reused"] = lambda: simulate_frame(
            rig, obj, spp=16, seed=1, noise="realistic", scenes=cache)
    if "max_scatter" in inspect.signature(simulate_frame).parameters:
        fns["frame_scatter_16"] = lambda: simulate_frame(
            rig, obj, spp=16, seed=1, noise="realistic", max_scatter=1)
        if has_support:
            fns["frame_scatter_16_full"] = lambda: simulate_frame(
                rig, obj, spp=16, seed=1, noise="realistic", max_scatter=1, support="full")
    if "sensor_realistic_16" in args.rows.split(","):
        from lts360.simulator import frame as frame_mod

        if hasattr(frame_mod, "sensor_image"):
            res = simulate_frame(rig, obj, spp=16, seed=1, noise="none").render
            fns["sensor_realistic_16"] = lambda: frame_mod.sensor_image(
                rig, res, noise="realistic", seed=1, speckle=False)
    if {"speckle_keyed", "speckle_bbox"} & set(args.rows.split(",")):
        _speckle_rows(fns, rig, obj, simulate_frame)
    out = {"code": str(src), "commit": commit, "variant": args.variant,
           "machine": f"{platform.node()} {os.cpu_count()} cores",
           "load_average": os.getloadavg(), "rows": {}}
    for name in args.rows.split(","):
        if name not in fns:
            continue
        t0 = time.perf_counter()
        fns[name]()
        first = time.perf_counter() - t0
        warm, cpu = [], []
        for _ in range(max(1, args.repeats)):
            t0, c0 = time.perf_counter(), time.process_time()
            fns[name]()
            warm.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out["rows"][name] = {"first_s": round(first, 4), "median_s": round(statistics.median(warm), 4),
                             "warm_s": [round(w, 4) for w in warm],
                             "cpu_median_s": round(statistics.median(cpu), 4)}
        print(name, out["rows"][name], flush=True)
    out["load_average_after"] = os.getloadavg()
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text)


def _speckle_rows(fns: dict, rig, obj, simulate_frame) -> None:
    """The speckle stage alone, on the laser pixels of one noise-free 16-spp frame."""
    import numpy as np

    from lts360.simulator import speckle as sp

    lit = simulate_frame(rig, obj, spp=16, seed=1, noise="none").render.laser_W_m2_sr > 0
    cam = rig.camera
    kw = dict(pixel_pitch_um=cam.pixel_pitch_um, wavelength_nm=rig.laser.wavelength_nm,
              f_number=cam.f_number,
              magnification=cam.focal_length_mm / (cam.focus_distance_mm - cam.focal_length_mm))
    rows, cols = np.flatnonzero(lit.any(axis=1)), np.flatnonzero(lit.any(axis=0))
    shape = (rows[-1] - rows[0] + 33, cols[-1] - cols[0] + 33)
    if hasattr(sp, "keyed_contrast"):  # the keyed speckle exists in this code
        fns["speckle_keyed"] = lambda: sp.speckle_on_tiles(lit, rng=1, **kw)
    fns["speckle_bbox"] = lambda: sp.speckle_pattern(shape, rng=1, **kw)


if __name__ == "__main__":
    main()

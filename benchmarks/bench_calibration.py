"""The demo's calibration stage, timed part by part: ``run_calibrate`` as ``lts360 demo`` calls
it (paper rig, realistic noise, seed 0, 64 spp: 48 board poses, 60 pictures), then
``calibrate_rig`` again on the images it wrote, its steps timed apart.

Rows (wall clock and the process's CPU time, one run each):

* ``calibrate``: the whole :func:`run_calibrate` (planning, rendering, fitting, report, fig8);
* ``render``: its rendering alone (:func:`render_calibration_images`, timed inside the run);
* ``fit``: :func:`calibrate_rig` on the written images;
* ``fit_camera``, ``fit_mirror_corners``, ``fit_mirror_planes``, ``fit_laser_lines``: its
  steps (Zhang with the corners, the real and virtual boards, the mirror planes, the laser
  lines).

The calibration's values are written beside the timings (``--json``) so that two checkouts'
results can be compared: run it with ``PYTHONPATH`` at another checkout's ``src`` to measure
that code ("before").

Usage: python benchmarks/bench_calibration.py [--out DIR] [--json OUT] [--seed N]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np


def _timed(fn, times: dict, key: str):
    """``fn`` adding its wall time to ``times[key]`` and the process's CPU time (all threads)
    to ``times[key + "_cpu"]``: the CPU time moves less than the wall time when other work
    shares the machine."""
    def wrapper(*a, **kw):
        t, c = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **kw)
        finally:
            times[key] = times.get(key, 0.0) + time.perf_counter() - t
            times[key + "_cpu"] = times.get(key + "_cpu", 0.0) + time.process_time() - c
    return wrapper


def _values(cal) -> dict:
    return {"fx": float(cal.K[0, 0]), "fy": float(cal.K[1, 1]), "cx": float(cal.K[0, 2]),
            "cy": float(cal.K[1, 2]), "dist": np.asarray(cal.dist).tolist(),
            "mirrors": {m.name: {"n": np.asarray(m.n).tolist(), "d_mm": float(m.d_mm)}
                        for m in cal.mirrors},
            "laser": {"n": np.asarray(cal.laser_plane[0]).tolist(),
                      "d_mm": float(cal.laser_plane[1])}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="output folder (default: a temporary one)")
    ap.add_argument("--json", default=None, help="write the rows and the values here")
    ap.add_argument("--seed", type=int, default=0,
                    help="the calibration's seed (default 0, the demo's): another noise "
                         "realisation, to see how far the values move by chance")
    args = ap.parse_args(argv)

    import mitsuba as mi

    mi.set_variant("llvm_ad_mono")
    import lts360.experiments.calibration_run as run
    import lts360.recon.calibration.from_images as fi
    import lts360.simulator.calib_render as cr

    times: dict[str, float] = {}
    out = Path(args.out or tempfile.mkdtemp(prefix="bench-calibration-"))
    cr_render = cr.render_calibration_images
    cr.render_calibration_images = _timed(cr_render, times, "render")
    _timed(run.run_calibrate, times, "calibrate")(out, rig_name="paper", noise="realistic", seed=args.seed,
                                                  say=lambda *_: None)
    cr.render_calibration_images = cr_render

    for name, key in (("_calibrate_camera", "fit_camera"),
                      ("_mirror_observations", "fit_mirror_corners"),
                      ("_fit_mirrors", "fit_mirror_planes"), ("_laser_lines", "fit_laser_lines")):
        setattr(fi, name, _timed(getattr(fi, name), times, key))
    result = _timed(fi.calibrate_rig, times, "fit")(fi.read_calibration_images(out / "images"))
    load = os.getloadavg()
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, cwd=Path(fi.__file__).parent).stdout.strip()
    except OSError:
        commit = ""
    for k in ("calibrate", "render", "fit", "fit_camera", "fit_mirror_corners",
              "fit_mirror_planes", "fit_laser_lines"):
        print(f"{k:20s} {times.get(k, float('nan')):7.2f} s wall "
              f"{times.get(k + '_cpu', float('nan')):7.2f} s CPU")
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {fi.__file__}")
    if args.json:
        Path(args.json).write_text(json.dumps(
            {"rows": times, "values": _values(result.calibration), "load": load,
             "commit": commit, "seed": args.seed, "machine": platform.processor() or platform.machine(),
             "cpus": os.cpu_count(), "date": time.strftime("%Y-%m-%d", time.gmtime())},
            indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Inspection benchmark: the whole report of a 40-section scan (``lts360 inspect``'s work).

A synthetic cloud like ``lts360 measure`` writes it: 40 sections 0.68 mm apart, every 0.1° of
θ from three interleaved views (3600 samples a section), an oval Ø20 mm section (0.2 mm) with a
dent of 0.1 mm, 2 µm of scatter, an axis tilted by 0.01 and a 4° gap flagged NO_PEAK.  Times
:func:`lts360.inspect.run.inspect_cloud` (against the nominal ``plug-gauge:d=20`` with a
0.3 mm band) and :func:`lts360.inspect.report.write_report` (JSON, CSV, four figures, the HTML
page), warm (imports done, the first run discarded); target ≤ 5 s on 2 cores.

Usage: python benchmarks/bench_inspect.py [--repeats 5] [--sections 40] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def synthetic_scan(n_sections: int, *, pitch_mm: float = 0.68, seed: int = 0):
    from lts360.recon.triangulation.cloud import Cloud

    rng = np.random.default_rng(seed)
    th = np.radians(np.arange(-180.0, 180.0, 0.1))
    parts = []
    for k in range(n_sections):
        z = (k - (n_sections - 1) / 2) * pitch_mm
        r = (10.0 + 0.05 * np.cos(2 * th)
             - 0.1 * np.exp(-(1 - np.cos(th + np.pi / 2)) * 30) * np.exp(-z**2 / 4.5)
             + 0.002 * rng.normal(size=th.size))
        pts = np.column_stack([r * np.cos(th) + 0.01 * z, r * np.sin(th), np.full(th.size, z)])
        q = np.zeros(th.size, np.uint8)
        gap = (th > np.radians(100)) & (th < np.radians(104))
        pts[gap], q[gap] = np.nan, 1
        parts.append(Cloud(pts, th, r, (np.arange(th.size) % 3).astype(np.uint8), q,
                           np.full(th.size, k, np.int32), np.ones(th.size, np.float32)))
    return Cloud.concatenate(parts)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sections", type=int, default=40)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    from lts360.inspect.nominal import ToleranceBand, load_nominal
    from lts360.inspect.report import write_report
    from lts360.inspect.run import inspect_cloud

    cloud = synthetic_scan(args.sections)
    nominal = load_nominal("plug-gauge:d=20")
    band = ToleranceBand.symmetric(0.3)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats + 1):
            t0 = time.perf_counter()
            ins = inspect_cloud(cloud, nominal=nominal, band=band, source="synthetic")
            t1 = time.perf_counter()
            write_report(ins, Path(tmp) / "report")
            t2 = time.perf_counter()
            if i:  # the first run warms the imports and caches
                rows.append((t1 - t0, t2 - t1, t2 - t0))
    med = [statistics.median(c) for c in zip(*rows)]
    out = {"sections": args.sections, "repeats": args.repeats,
           "inspect_median_s": med[0], "report_median_s": med[1], "total_median_s": med[2],
           "total_min_s": min(r[2] for r in rows), "total_max_s": max(r[2] for r in rows),
           "cpus": os.cpu_count(), "machine": platform.platform(),
           "load_average": os.getloadavg()}
    print(f"{args.sections} sections: inspect {med[0]:.2f} s + report {med[1]:.2f} s = "
          f"{med[2]:.2f} s (median of {args.repeats}; min {out['total_min_s']:.2f}, max "
          f"{out['total_max_s']:.2f}; load average {out['load_average'][0]:.1f} on "
          f"{out['cpus']} cores); target ≤ 5 s")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()

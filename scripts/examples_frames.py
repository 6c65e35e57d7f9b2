"""Measure the frames ``lts360 study examples --frames DIR`` stored, as the study does, and
count what its table does not.

    lts360 study examples --out ex1 --frames fr1 --section-scale 0.2 --max-scatter 1 ...
    python scripts/examples_frames.py measure fr1 --out m1 [--objects ...] [--multipeak off]
    python scripts/examples_frames.py render fr1 --objects plug-gauge --max-scatter 1

``render`` stores the frames of objects outside the study's list (e.g. ``plug-gauge``): 5
sections at the paper's 0.68 mm pitch about the middle of the object's measured zone, seeded
as the study seeds its trials (their index in ``--objects``), the study's other defaults.

``measure`` measures every stored scan with the study's ``measure_scan`` (clouds, figures and
inspection under ``--out``) and prints the study's columns and, beside them, the counts the
Examples and Interreflections sections of STUDIES.md quote: valid points off by > 0.1 / 0.2 mm
(analytic radial error, spurious ones included; truth-aware), the rows flagged ``SEVERAL_PEAKS``, and on
the round convex objects the false rejections (every row rejected by F / N / H / S / B, over
the valid points).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from lts360.experiments.examples_study import examples_params, measure_scan, stored_scan
from lts360.experiments.runner import plan_trials

ROUND = {"pvc-pipe", "alu-pipe", "plug-gauge"}


def render(args) -> None:
    names = args.objects.split(",")
    params = []
    for n in names:
        p = examples_params(Path(args.root), objects=["pvc-pipe"], max_scatter=args.max_scatter)[0]
        p.update(object=n, figure=0, sections=5, pitch_mm=0.68)
        params.append(p)
    for t in plan_trials(params, args.seed):
        scan = stored_scan(t.params, t.seed, args.root)
        print(f"{t.params['object']}: {len(scan['z_mm'])} frames, {scan['render_s']:.1f} s",
              flush=True)


def _extra(root: Path, name: str, obj_spec: str) -> dict:
    from lts360.recon.triangulation.cloud import read_cloud
    from lts360.recon.triangulation.peaks import Quality
    from lts360.scenes.objects import build_object

    cloud = read_cloud(root / "clouds" / f"{name}.ply")
    obj = build_object(obj_spec)
    valid = cloud.valid
    err = np.abs(obj.radial_error(cloud.points_mm[valid]))
    rejected = np.isin(cloud.quality, [Quality.FADING, Quality.NOTCH, Quality.HIDDEN,
                                       Quality.FLANK, Quality.NEIGHBOURS]).sum()
    return {"off_0.1": int((err > 0.1).sum()), "off_0.2": int((err > 0.2).sum()),
            "several": int((cloud.quality == Quality.SEVERAL_PEAKS).sum()),
            "false_rejections": (f"{100.0 * rejected / max(int(valid.sum()), 1):.2f} %"
                                 if name in ROUND else "—")}


def measure(args) -> None:
    frames, root = Path(args.root), Path(args.out)
    root.mkdir(parents=True, exist_ok=True)
    names = args.objects.split(",") if args.objects else sorted(
        p.stem for p in frames.glob("*.npz") if not p.stem.startswith("."))
    for name in names:
        with np.load(frames / f"{name}.npz") as f:
            p = json.loads(str(f["params"]))
            scan = {"images": f["images"], "z_mm": f["z_mm"], "truth": json.loads(str(f["truth"])),
                    "render_s": float(f["render_s"])}
        p.update(out=str(root.resolve()), calibration="", multipeak=args.multipeak == "on")
        v = measure_scan(p, scan).values
        e = _extra(root, name, p["object"])
        print(f"{name:15s} ms {p.get('max_scatter', 0)} sections {len(scan['z_mm']):2d} "
              f"points {int(v['n_points']):6d} cov {v['coverage_deg']:6.1f} "
              f"rms {1e3 * v['rms_mm']:5.1f} p95 {1e3 * v['p95_mm']:6.1f} "
              f"max {1e3 * v['max_abs_mm']:5.0f} off>0.1/0.2 {e['off_0.1']}/{e['off_0.2']} "
              f"F/N/H/S/B {int(v['n_rejected_fading'])}/{int(v['n_rejected_notch'])}/"
              f"{int(v['n_rejected_hidden'])}/{int(v['n_rejected_flank'])}/"
              f"{int(v['n_rejected_neighbours'])} several {e['several']} "
              f"spurious {int(v['n_spurious'])} "
              f"({100.0 * v['n_spurious'] / max(v['n_points'] + v['n_spurious'], 1):.2f} %) "
              f"false {e['false_rejections']} render {v['render_s_per_section']:.1f} s/section "
              f"measure {v['measure_s_per_section']:.3f} s/section", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("root")
    r.add_argument("--objects", required=True)
    r.add_argument("--max-scatter", type=int, choices=(0, 1, 2, 3), default=0)
    r.add_argument("--seed", type=int, default=0)
    m = sub.add_parser("measure")
    m.add_argument("root")
    m.add_argument("--out", required=True)
    m.add_argument("--objects", default="")
    m.add_argument("--multipeak", choices=("on", "off"), default="on")
    args = ap.parse_args(argv)
    (render if args.cmd == "render" else measure)(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())

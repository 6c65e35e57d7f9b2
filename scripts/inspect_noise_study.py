"""Inspection under realistic noise, against the truth (STUDIES.md, "Inspection under noise").

Usage::

    python scripts/inspect_noise_study.py ROOT [--filter-upr N | --filter none]

``ROOT`` holds one folder per scan, each with ``scan/`` (``lts360 render --sections N --noise
realistic``) and ``cloud.ply`` (``lts360 measure scan --calibration
scan/section_0000/frame.json``).  Each cloud is inspected with ``--truth scan``; printed: per
scan and quantity (D min, D max, ovality, RONt against each circle) how many sections lie within
their U(k = 2) of the truth, the events (lumps / neck-downs of D max / D min, and the local
lumps and dents of the arc-matched detector) found, the axis' tilt against the
true one (0: the renders stand upright) and the dominant wavelength.  ``ROOT/summary.json``
holds every number.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from lts360.cli import main

KEYS = ("d_min_mm", "d_max_mm", "ovality_mm")
REFS = ("LSCI", "MZCI", "MCCI", "MICI")


def study(root: Path, extra: list[str]) -> dict:
    out = {}
    for d in sorted(p for p in root.iterdir() if (p / "cloud.ply").is_file()):
        rep = d / ("report" + "".join(extra).replace("-", "_"))
        rc = main(["inspect", str(d / "cloud.ply"), "--truth", str(d / "scan"), "--out",
                   str(rep), *extra])
        data = json.loads((rep / "inspection.json").read_text())
        rows = []
        for s in data["sections"]:
            t = s["truth"]
            r = {"z_mm": s["z_mm"]}
            for k in KEYS:
                r[k] = (s[k]["value"] - t[k], s[k]["U_k2"])
            for ref in REFS:  # None: not determined by the points (reported as such)
                v = s["ront_mm"][ref]["value"]
                r["ront_" + ref] = (None if v is None else v - t["ront_mm"][ref],
                                    s["ront_mm"][ref]["U_k2"])
            rows.append(r)
        scan = data["scan"]
        out[d.name] = {"exit": rc, "filter": data["settings"].get("filter", "none"), "sections": rows,
                       "events": scan["events"],
                       "events_not_significant": scan.get("events_not_significant", []),
                       "local_events": scan.get("local_events", []),
                       "local_events_set_apart": scan.get("local_events_set_apart", []),
                       "local_events_settings": scan.get("local_events_settings", {}),
                       "axis": scan.get("axis"), "cylinder": scan.get("cylindricity"),
                       "spectrum": {k: v for k, v in scan.get("diameter_spectrum", {}).items()
                                    if k not in ("wavelength_mm", "amplitude_mm")}}
    return out


def _local(e: dict) -> tuple:
    """(kind, z, θ, depth µm, U µm, z score, p_noise) of an arc-matched event."""
    return (e["kind"], e["z_extreme_mm"], round(e["theta_deg"], 1), round(1e3 * e["depth_mm"], 1),
            round(1e3 * e["U_k2_mm"], 1), round(e["z_score"], 1), float(f"{e['p_noise']:.2g}"))


def summarise(res: dict) -> None:
    total = inside = undetermined = 0
    for name, r in res.items():
        cols = [c for c in r["sections"][0] if c != "z_mm"]
        cells = []
        for c in cols:
            vals = [s[c] for s in r["sections"] if s[c][0] is not None]
            ok = sum(abs(e) <= U for e, U in vals)
            worst = max(vals, key=lambda v: abs(v[0]) - v[1])
            nd = len(r["sections"]) - len(vals)
            cells.append(f"{c} {ok}/{len(vals)} (worst {1e3 * worst[0]:+.0f}/"
                         f"{1e3 * worst[1]:.0f} µm{f'; {nd} not determined' if nd else ''})")
            total += len(vals)
            inside += ok
            undetermined += nd
        ax = r["axis"] or {}
        print(f"{name}: {r['filter']}")
        print("   " + "; ".join(cells))
        print(f"   events {[(e['kind'], round(e['z_extreme_mm'], 2), round(1e3 * e['deviation_mm'], 1), round(e['confidence'] or 0, 3)) for e in r['events']]}"
              f" not significant {len(r['events_not_significant'])}; tilt "
              f"{ax.get('tilt_deg')} (U {ax.get('U_tilt_deg')}) {ax.get('note', '')}; "
              f"dominant wavelength {r['spectrum'].get('dominant_wavelength_mm')} "
              f"{r['spectrum'].get('note', '')}")
        st = r["local_events_settings"]
        print(f"   local events (critical z {st.get('critical_z', float('nan')):.2f}, noise scale "
              f"{st.get('noise_scale', float('nan')):.2f}): "
              f"{[_local(e) for e in r['local_events']]}; set apart "
              f"{[_local(e) for e in r['local_events_set_apart']]}")
    print(f"all: {inside}/{total} values within U(k = 2) ({100 * inside / max(total, 1):.1f} %); "
          f"{undetermined} not determined by the points (not reported)")


if __name__ == "__main__":
    root = Path(sys.argv[1])
    res = study(root, sys.argv[2:])
    (root / "summary.json").write_text(json.dumps(res, indent=1, default=float))
    summarise(res)

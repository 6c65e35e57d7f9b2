"""Scored clouds of a part with corners, by angle from the nearest corner (STUDIES.md, "Your
own parts: a hexagonal bar").

    python scripts/corner_table.py LABEL=FRAME:CLOUD [LABEL=FRAME:CLOUD ...] [--corners-deg 0,60,...]

For each cloud: its valid points' signed distance to the part's mesh (the frame's truth, as
``lts360 score``), rms over all, the count farther than 150 µm, the largest, and rms / mean /
count in bands of the angle about the axis from the nearest corner (default: a hexagon's,
0°, 60°, …).  Truth is read here only to score.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

BANDS = ((0.0, 1.0), (1.0, 2.0), (2.0, 4.0), (4.0, 180.0))


def rows(frame: str, cloud: str, corners_deg: np.ndarray) -> list[str]:
    from lts360.experiments.score import load_truth, signed_mesh_distance
    from lts360.recon.triangulation.cloud import read_cloud

    obj, _ = load_truth(frame)
    c = read_cloud(cloud)
    c = c.select(c.valid)
    e = 1e3 * signed_mesh_distance(obj.mesh_world(), c.points_mm)
    th = np.degrees(np.arctan2(c.points_mm[:, 1], c.points_mm[:, 0]))
    d = np.abs((th[:, None] - corners_deg[None, :] + 180.0) % 360.0 - 180.0).min(axis=1)
    out = [str(len(e)), f"{np.sqrt(np.mean(e ** 2)):.2f}", str(int((np.abs(e) > 150).sum())),
           f"{np.abs(e).max():.1f}"]
    for lo, hi in BANDS:
        m = (d >= lo) & (d < hi)
        out.append(f"{np.sqrt(np.mean(e[m] ** 2)):.1f}, {e[m].mean():+.1f} ({int(m.sum())})"
                   if m.any() else "–")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="LABEL=FRAME:CLOUD")
    ap.add_argument("--corners-deg", default="0,60,120,180,240,300")
    a = ap.parse_args(argv)
    corners = np.array([float(x) for x in a.corners_deg.split(",")])
    head = ["run", "points", "rms to the mesh (µm)", "> 150 µm", "largest |e| (µm)"] + [
        f"{lo:g}–{hi:g}° (rms, mean, n)" if hi < 180 else f"> {lo:g}°" for lo, hi in BANDS]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for run in a.runs:
        label, rest = run.split("=", 1)
        frame, cloud = rest.rsplit(":", 1)
        print("| " + " | ".join([label] + rows(frame, cloud, corners)) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

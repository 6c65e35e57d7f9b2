"""A closed section contour from a drawing: a CSV file of points or a DXF drawing.

Both readers return the contour as a counter-clockwise ring ``(m, 2)`` in millimetres (first
point not repeated).  They are shared by ``inspect --nominal`` (the nominal contour) and the
``profile`` object (an extruded part), so that a drawing reads the same way in both.

* **CSV**: ``x, y`` rows; an optional header names the unit in the column names (``x_mm,y_mm``,
  ``x_um``, ``x_in``, ``x_cm``, ``x_m``; no header: mm); the last row must repeat the first
  (the contour is closed); ``#`` starts a comment row.
* **DXF** (ezdxf): the largest closed curve of the model space (LWPOLYLINE, POLYLINE, CIRCLE,
  ELLIPSE, SPLINE; arcs, bulges and splines flattened to 0.1 µm), scaled by the drawing's
  ``$INSUNITS`` (unitless read as mm).

Every error is one line that starts with ``where`` (the option or object that read the file).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

__all__ = ["UNIT_MM", "CLOSURE_MM", "FLATTEN_MM", "closed_ring", "read_csv_ring",
           "read_dxf_ring"]

#: Units a contour file may use, in mm.
UNIT_MM = {"mm": 1.0, "um": 1e-3, "µm": 1e-3, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: Largest gap between a contour's first and last point for it to count as closed (mm).
CLOSURE_MM = 1e-6
#: Largest distance between a DXF curve and the polyline it is flattened to (mm).
FLATTEN_MM = 1e-4
_DXF_UNITS_MM = {0: 1.0, 1: 25.4, 2: 304.8, 4: 1.0, 5: 10.0, 6: 1000.0, 13: 1e-3}


def closed_ring(xy: np.ndarray, where: str) -> np.ndarray:
    """The counter-clockwise ring ``(m, 2)`` of a closed point list (last point = first)."""
    import shapely

    if len(xy) < 4:
        raise ValueError(f"{where}: a closed contour needs at least 3 distinct points and the "
                         f"first repeated at the end, got {len(xy)} rows")
    gap = float(np.hypot(*(xy[-1] - xy[0])))
    if gap > CLOSURE_MM:
        raise ValueError(f"{where}: the contour is not closed (last point {gap:.6g} mm from the "
                         f"first; repeat the first point at the end)")
    ring = xy[:-1]
    poly = shapely.Polygon(ring)
    if not poly.is_valid or poly.area <= 0:
        raise ValueError(f"{where}: the contour crosses itself or encloses no area")
    if not shapely.LinearRing(ring).is_ccw:
        ring = ring[::-1]
    return np.ascontiguousarray(ring, dtype=float)


def read_csv_ring(path, where: str) -> np.ndarray:
    """(m, 2) the closed contour of a CSV file of ``x, y`` rows (see the module docstring)."""
    p = Path(path)
    rows = [r for r in csv.reader(p.read_text().splitlines())
            if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise ValueError(f"{where}: no rows")
    scale = 1.0
    head = [c.strip() for c in rows[0]]
    try:
        float(head[0])
    except ValueError:
        units = set()
        for c in head[:2]:
            m = re.fullmatch(r"[A-Za-z]+[ _\[(]*([A-Za-zµ]+)[\])]*", c)
            u = m.group(1) if m else None
            if u not in UNIT_MM:
                raise ValueError(f"{where}: column {c!r}: the unit does not parse; name "
                                 f"columns like x_mm,y_mm (units: {', '.join(UNIT_MM)})")
            units.add(u)
        if len(units) != 1:
            raise ValueError(f"{where}: x and y must share one unit, got {sorted(units)}")
        scale = UNIT_MM[units.pop()]
        rows = rows[1:]
    xy = []
    for r in rows:
        try:
            if len(r) < 2:
                raise ValueError
            x, y = float(r[0]), float(r[1])
            if not (np.isfinite(x) and np.isfinite(y)):
                raise ValueError
        except ValueError:
            raise ValueError(f"{where}: row {r!r} is not two finite numbers") from None
        xy.append((x, y))
    return closed_ring(np.asarray(xy) * scale, where)


def read_dxf_ring(path, where: str) -> np.ndarray:
    """(m, 2) the largest closed curve of a DXF drawing's model space (see the module
    docstring)."""
    import ezdxf
    from ezdxf import path as dxfpath

    p = Path(path)
    try:
        doc = ezdxf.readfile(str(p))
    except (OSError, ezdxf.DXFError) as exc:
        raise ValueError(f"{where}: not a readable DXF ({exc})") from None
    code = int(doc.header.get("$INSUNITS", 0))
    if code not in _DXF_UNITS_MM:
        raise ValueError(f"{where}: drawing units $INSUNITS={code} do not parse as a "
                         f"length (use mm, cm, m, in, ft, µm or unitless)")
    scale = _DXF_UNITS_MM[code]
    best, open_ones = None, 0
    for e in doc.modelspace():
        if e.dxftype() not in ("LWPOLYLINE", "POLYLINE", "CIRCLE", "ELLIPSE", "SPLINE"):
            continue
        if e.dxftype() in ("CIRCLE", "ELLIPSE"):  # vertices on the exact curve
            verts = list(e.flattening(FLATTEN_MM / scale))
            if (verts[-1] - verts[0]).magnitude > 0:
                verts.append(verts[0])
        else:
            verts = dxfpath.make_path(e).flattening(FLATTEN_MM / scale)
        pts = np.array([(v.x, v.y) for v in verts])
        if len(pts) < 4 or np.hypot(*(pts[-1] - pts[0])) * scale > CLOSURE_MM:
            open_ones += 1
            continue
        area = abs(np.dot(pts[:-1, 0], pts[1:, 1]) - np.dot(pts[1:, 0], pts[:-1, 1])) / 2
        if best is None or area > best[0]:
            best = (area, pts)
    if best is None:
        raise ValueError(f"{where}: no closed contour in the model space"
                         + (f" ({open_ones} open curve(s): the contour is not closed)"
                            if open_ones else ""))
    return closed_ring(best[1] * scale, where)

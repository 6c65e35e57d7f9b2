"""Residual compensation of paper §4.4 with one joint circle.

The paper fits a circle to each view's points and translates each mirror view's centre onto
the direct view's centre.  Here one circle (centre, radius) and one translation per mirror
view are fitted to all the points together (the reference view's translation is zero).

The two trade off (tests/recon/calibration/test_compensation.py): a free-radius circle on a ~150° arc
has a poorly conditioned centre (with 5 µm point noise the joint fit's offsets scatter
0.74× as much as the paper's), but it ignores a view's own radius error, which the joint fit turns
into a translation (a view reading 5 µm large gets a ~3.8 µm offset).  On rendered gauges the
two gave offsets within 10 µm of each other and radius biases within 0.3 µm (STUDIES.md);
both are available.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from lts360.geometry.fit import fit_circle
from lts360.recon.triangulation.inverse import raw_view_points

__all__ = ["joint_view_offsets"]


def joint_view_offsets(result, *, reference: str = "direct", min_points: int = 10
                       ) -> dict[str, np.ndarray]:
    """Absolute (x, y) offsets (mm, measurement frame) of each non-reference view.

    Parameters
    ----------
    result : lts360.recon.triangulation.inverse.InverseResult, or a sequence of them
        Measurements of a round section; their raw (uncompensated) points are used.  Several
        measurements (the reference cylinder turned or moved between shots: new speckle, new
        sensor noise) are fitted together, each with its own circle and every one with the
        same view offsets: the offsets' random error falls as ``1/√k`` for ``k`` shots.

    Returns
    -------
    dict
        View name → (2,) offset, for ``Calibration.view_offsets_mm``.

    Raises
    ------
    ValueError
        No measurement, no reference view, a view with fewer than ``min_points`` valid
        points, or measurements that do not share their views.
    """
    results = list(result) if isinstance(result, (list, tuple)) else [result]
    if not results:
        raise ValueError("joint_view_offsets: no measurement")
    shots = [raw_view_points(r, reference=reference, min_points=min_points) for r in results]
    names = list(shots[0])
    if any(set(s) != set(names) for s in shots[1:]):
        raise ValueError(f"joint_view_offsets: the measurements have different views: "
                         f"{[sorted(s) for s in shots]}")
    others = [n for n in names if n != reference]
    col = {n: i for i, n in enumerate(others)}
    pts, shot, idx = [], [], []
    for k, s in enumerate(shots):
        for n in names:
            pts.append(s[n])
            shot.append(np.full(len(s[n]), k))
            idx.append(np.full(len(s[n]), col.get(n, -1)))
    allp, shot, idx = np.concatenate(pts), np.concatenate(shot), np.concatenate(idx)
    m = len(shots)

    def residual(x):
        c, r = x[:2 * m].reshape(m, 2), x[2 * m:3 * m]
        t = x[3 * m:].reshape(-1, 2)
        shift = np.where(idx[:, None] >= 0, t[np.maximum(idx, 0)], 0.0)
        return np.hypot(*(allp + shift - c[shot]).T) - r[shot]

    starts = [fit_circle(np.concatenate(list(s.values()))) for s in shots]
    x0 = np.concatenate([np.concatenate([f.center_mm for f in starts]),
                         [f.radius_mm for f in starts], np.zeros(2 * len(others))])
    sol = least_squares(residual, x0, method="lm", xtol=1e-14, ftol=1e-14)
    t = sol.x[3 * m:].reshape(-1, 2)
    return {n: t[col[n]].copy() for n in others}

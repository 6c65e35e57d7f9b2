"""Residual compensation of paper §4.4 with one joint circle.

The paper fits a circle to each view's points and translates each mirror view's centre onto
the direct view's centre.  Here one circle (centre, radius) and one translation per mirror
view are fitted to all the points together (the reference view's translation is zero).

The two trade off (tests/recon/test_compensation.py): a free-radius circle on a ~150° arc
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
from lts360.recon.inverse import raw_view_points

__all__ = ["joint_view_offsets"]


def joint_view_offsets(result, *, reference: str = "direct", min_points: int = 10
                       ) -> dict[str, np.ndarray]:
    """Absolute (x, y) offsets (mm, measurement frame) of each non-reference view.

    Parameters
    ----------
    result : lts360.recon.inverse.InverseResult
        A measurement of a round section; its raw (uncompensated) points are used.

    Returns
    -------
    dict
        View name → (2,) offset, for ``Calibration.view_offsets_mm``.

    Raises
    ------
    ValueError
        No reference view, or a view with fewer than ``min_points`` valid points.
    """
    by_view = raw_view_points(result, reference=reference, min_points=min_points)
    names, pts = list(by_view), list(by_view.values())
    others = [n for n in names if n != reference]
    label = np.concatenate([np.full(len(p), k) for k, p in enumerate(pts)])
    allp = np.concatenate(pts)
    start = fit_circle(allp)
    col = {n: i for i, n in enumerate(others)}
    idx = np.array([col.get(names[k], -1) for k in label])

    def residual(x):
        c, r, t = x[:2], x[2], x[3:].reshape(-1, 2)
        shift = np.where(idx[:, None] >= 0, t[np.maximum(idx, 0)], 0.0)
        return np.hypot(*(allp + shift - c).T) - r

    x0 = np.concatenate([start.center_mm, [start.radius_mm], np.zeros(2 * len(others))])
    sol = least_squares(residual, x0, method="lm", xtol=1e-14, ftol=1e-14)
    t = sol.x[3:].reshape(-1, 2)
    return {n: t[col[n]].copy() for n in others}

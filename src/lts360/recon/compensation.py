"""Residual compensation of paper §4.4 with one joint circle.

The paper fits a circle to each view's points and translates each mirror view's centre onto
the direct view's centre.  A view covers only ~150° of the section, and the centre of a
partial arc fitted with a free radius moves along the arc's axis with any error of that
view's radius: measured on a noise-free render with the *true* calibration, the paper's
per-view fits returned offsets of ~10 µm and moved the fitted radius from −2.2 to −7.1 µm.

Here one circle (centre, radius) and one translation per mirror view are fitted to all the
points together (the reference view's translation is zero): the union covers 360°, so the
circle is well determined and each view's translation is what best puts its arc on it.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from lts360.geometry.fit import fit_circle

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
    if reference not in result.views:
        raise ValueError(f"reference: no view {reference!r} in the result ({list(result.views)})")
    accept = [int(q) for q in result.accept]
    names, pts = [], []
    for name, v in result.views.items():
        ok = np.isfinite(v.r_raw_mm) & np.isin(v.quality, accept)
        if ok.sum() < min_points:
            raise ValueError(f"view {name!r}: {int(ok.sum())} valid points, need {min_points}")
        names.append(name)
        pts.append(v.raw_points_meas_mm[ok, :2])
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

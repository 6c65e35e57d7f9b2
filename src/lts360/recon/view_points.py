"""Each view's raw points of a measured round section: what the §4.4 compensation and the
mastering fit (:mod:`lts360.recon.calibration.compensation`) and the triangulation's own view
offsets (:func:`lts360.recon.triangulation.inverse.estimate_view_offsets`) start from.

Reads an :class:`~lts360.recon.triangulation.inverse.InverseResult` by its attributes only
(``views``, ``accept``; per view ``r_raw_mm``, ``quality``, ``raw_points_meas_mm``), so the
calibration part needs no import of the triangulation part.
"""

from __future__ import annotations

import numpy as np

__all__ = ["raw_view_points", "DIRECT"]

#: The name of the direct view.
DIRECT = "direct"


def raw_view_points(result, *, reference: str = DIRECT,
                    min_points: int = 10) -> dict[str, np.ndarray]:
    """Each view's uncompensated (x, y) points (measurement frame, accepted qualities) of a
    round section, for the residual compensation of paper §4.4.

    Raises
    ------
    ValueError
        No ``reference`` view, or a view with fewer than ``min_points`` valid points.
    """
    if reference not in result.views:
        raise ValueError(f"reference: no view {reference!r} in the result ({list(result.views)})")
    accept = [int(q) for q in result.accept]
    out = {}
    for name, v in result.views.items():
        ok = np.isfinite(v.r_raw_mm) & np.isin(v.quality, accept)
        if ok.sum() < min_points:
            raise ValueError(f"view {name!r}: {int(ok.sum())} valid points, a circle fit needs "
                             f"at least {min_points}")
        out[name] = v.raw_points_meas_mm[ok, :2]
    return out

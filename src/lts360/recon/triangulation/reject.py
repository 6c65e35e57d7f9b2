"""Truth-free rejection of spurious points: continuity along θ.

A point whose radius lies off a robust local fit of its own view's profile ``r(θ)`` by more
than ``k·σ`` is flagged ``DISCONTINUOUS`` and dropped from the valid points.  The local fit is
the running median of the view's valid radii over ``±half_window_deg``; ``σ`` is the robust
scatter (1.4826 × the median absolute deviation) of all the view's residuals, floored at
``floor_mm`` so that a noise-free section does not reject its pixel-locking ripple.  It uses
only the measurement: it runs on real images.

Where it stops: a spurious run longer than half the window (a whole hidden valley seen on a
neighbouring flank over several degrees) moves the median itself and is not caught; agreement
between views, visibility and illumination from a first-pass profile are not implemented.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from lts360.recon.triangulation.inverse import InverseResult
from lts360.recon.triangulation.peaks import Quality

__all__ = ["continuity_outliers", "reject_discontinuous", "DEFAULT_CONTINUITY_K",
           "DEFAULT_CONTINUITY_WINDOW_DEG", "DEFAULT_CONTINUITY_FLOOR_MM"]

DEFAULT_CONTINUITY_K = 6.0
DEFAULT_CONTINUITY_WINDOW_DEG = 2.0
#: Below this a residual is never an outlier: a few times the pixel-locking scatter (~3 µm rms).
DEFAULT_CONTINUITY_FLOOR_MM = 0.015


def continuity_outliers(r_mm, *, half_window: int, k: float = DEFAULT_CONTINUITY_K,
                        floor_mm: float = DEFAULT_CONTINUITY_FLOOR_MM,
                        periodic: bool = True) -> np.ndarray:
    """(n,) bool: valid radii off the running median of ``r_mm`` (NaN = no point) by more than
    ``max(k·σ, floor_mm)``.

    Parameters
    ----------
    r_mm : (n,) float
        One view's radii on uniform θ; NaN where it has no point.
    half_window : int, >= 1
        Samples each side of the running median.
    k : float, >0
    floor_mm : float, >= 0
    periodic : bool
        θ covers a full turn.
    """
    r = np.asarray(r_mm, dtype=float).ravel()
    if half_window < 1 or not k > 0 or floor_mm < 0:
        raise ValueError(f"need half_window >= 1, k > 0, floor_mm >= 0, got {half_window}, {k}, "
                         f"{floor_mm}")
    n = r.size
    valid = np.isfinite(r)
    if valid.sum() < 3:
        return np.zeros(n, dtype=bool)
    idx = np.arange(n)[:, None] + np.arange(-half_window, half_window + 1)[None, :]
    if periodic:
        stack = r[idx % n]
    else:
        stack = np.where((idx >= 0) & (idx < n), r[np.clip(idx, 0, n - 1)], np.nan)
    stack[:, half_window] = np.nan  # the point itself does not vote
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        local = np.nanmedian(stack, axis=1)
    res = r - local
    ok = valid & np.isfinite(res)
    if ok.sum() < 3:
        return np.zeros(n, dtype=bool)
    sigma = 1.4826 * np.median(np.abs(res[ok] - np.median(res[ok])))
    return ok & (np.abs(res) > max(k * sigma, floor_mm))


def reject_discontinuous(result: InverseResult, *, k: float = DEFAULT_CONTINUITY_K,
                         half_window_deg: float = DEFAULT_CONTINUITY_WINDOW_DEG,
                         floor_mm: float = DEFAULT_CONTINUITY_FLOOR_MM) -> InverseResult:
    """The result with each view's discontinuous points flagged ``DISCONTINUOUS`` and invalid."""
    grid = result.grid
    step = np.degrees(grid.theta_step_rad) if grid.n_theta > 1 else float("nan")
    if not np.isfinite(step):
        return result
    half = max(1, int(round(half_window_deg / step)))
    views = {}
    for name, v in result.views.items():
        out = continuity_outliers(v.r_mm, half_window=half, k=k, floor_mm=floor_mm,
                                  periodic=grid.is_full_turn)
        q = v.quality.copy()
        q[out] = Quality.DISCONTINUOUS
        views[name] = dataclasses.replace(v, r_mm=np.where(out, np.nan, v.r_mm), quality=q)
    return dataclasses.replace(result, views=views)

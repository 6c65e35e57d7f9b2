"""Two-point diameters, calliper widths and ovality of a section.

* **Two-point diameter** ``D(φ) = r(φ) + r(φ + π)``: the distance between the two profile
  points opposite each other through the centre (the LS centre), in ``n_directions``
  directions φ ∈ [0, π) — ISO 14405-1's two-point size taken through the centre.  ``r`` is
  interpolated linearly between the binned profile's directions; a direction whose either side
  falls in a θ gap gets no diameter (NaN), nothing is filled in.
* **Calliper (Feret) width** ``W(φ) = max pᵢ·n(φ) − min pᵢ·n(φ)``: the distance between two
  parallel jaws, what a shadow or two-axis gauge reads.  A curve of constant width (a
  Reuleaux-like three-lobed profile) has the same W in every direction; its lobes show only
  against a reference circle (:mod:`lts360.inspect.circles`).
* **Ovality** ``Dmax − Dmin`` of the two-point diameters, and as a percentage under the two
  definitions in use, each named:

  - ``ovality_over_sum_pct = 100 (Dmax − Dmin) / (Dmax + Dmin)``;
  - ``ovality_over_mean_pct = 100 (Dmax − Dmin) / D_mean``, ``D_mean`` the mean two-point
    diameter.

  With ``D_mean ≈ (Dmax + Dmin)/2`` the second is about twice the first: always say which.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.inspect.profile import DEFAULT_GAP_DEG, BinnedProfile, interp_profile

__all__ = ["Diameters", "two_point_diameters", "calliper_widths", "diameters",
           "DEFAULT_DIRECTIONS"]

#: Directions over [0, 180°): every 0.5°.
DEFAULT_DIRECTIONS = 360


def two_point_diameters(profile: BinnedProfile, *, n_directions: int = DEFAULT_DIRECTIONS,
                        gap_deg: float = DEFAULT_GAP_DEG) -> tuple[np.ndarray, np.ndarray]:
    """``(phi_rad, D_mm)``: two-point diameters through the profile's centre.

    Parameters
    ----------
    profile : BinnedProfile
    n_directions : int, >= 180
    gap_deg : float
        Neighbouring directions of the profile farther apart than this (plus one bin) are a
        gap: no diameter across them.
    """
    if n_directions < 180:
        raise ValueError(f"n_directions must be >= 180, got {n_directions}")
    phi = np.arange(n_directions) * (np.pi / n_directions)
    if len(profile.r_mm) < 2:
        return phi, np.full(n_directions, np.nan)
    r1 = interp_profile(profile, phi, gap_deg=gap_deg)
    r2 = interp_profile(profile, phi + np.pi, gap_deg=gap_deg)
    return phi, r1 + r2


def calliper_widths(xy_mm, *, n_directions: int = DEFAULT_DIRECTIONS) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
    """``(phi_rad, W_mm)``: the distance between parallel jaws normal to each direction φ.

    Parameters
    ----------
    xy_mm : (n, 2) float
        The profile (a gap makes the jaws rest on its edges: read with the coverage).
    """
    xy = np.asarray(xy_mm, dtype=float)
    phi = np.arange(n_directions) * (np.pi / n_directions)
    n = np.column_stack([np.cos(phi), np.sin(phi)])
    p = xy @ n.T  # (n_points, n_directions)
    return phi, p.max(axis=0) - p.min(axis=0)


@dataclass(frozen=True)
class Diameters:
    """Two-point diameters, calliper widths and ovality of one section (mm, %, deg)."""

    d_mean_mm: float
    d_min_mm: float
    d_max_mm: float
    phi_d_min_deg: float
    phi_d_max_deg: float
    ovality_mm: float
    ovality_over_sum_pct: float
    ovality_over_mean_pct: float
    n_directions_measured: int
    calliper_min_mm: float
    calliper_max_mm: float
    phi_rad: np.ndarray
    d_mm: np.ndarray
    calliper_mm: np.ndarray


def diameters(profile: BinnedProfile, *, n_directions: int = DEFAULT_DIRECTIONS,
              gap_deg: float = DEFAULT_GAP_DEG) -> Diameters:
    """Every diameter quantity of a section from its binned profile."""
    phi, d = two_point_diameters(profile, n_directions=n_directions, gap_deg=gap_deg)
    _, w = calliper_widths(profile.xy_mm, n_directions=n_directions)
    ok = np.isfinite(d)
    nan = float("nan")
    if not ok.any():
        return Diameters(nan, nan, nan, nan, nan, nan, nan, nan, 0, float(w.min()),
                         float(w.max()), phi, d, w)
    i_min = int(np.nanargmin(d))
    i_max = int(np.nanargmax(d))
    dmin, dmax, dmean = float(d[i_min]), float(d[i_max]), float(np.nanmean(d))
    ov = dmax - dmin
    return Diameters(dmean, dmin, dmax, float(np.degrees(phi[i_min])),
                     float(np.degrees(phi[i_max])), ov, 100.0 * ov / (dmax + dmin),
                     100.0 * ov / dmean, int(ok.sum()), float(w.min()), float(w.max()),
                     phi, d, w)

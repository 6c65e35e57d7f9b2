"""A section's profile from a measured cloud: which points count, the binned profile r(θ)
about a centre, its coverage and its θ gaps.

Only valid points count: finite coordinates and a quality in :data:`ACCEPTED_QUALITY`
(``lts360.recon.triangulation.peaks.Quality``: FOUND and SATURATED, the codes ``lts360
measure`` keeps as points).  Invalid θ samples are never filled in: they make the gaps, and
the gaps are reported with the flags that caused them.

Several views see the same θ where their windows overlap; the binned profile averages every
valid point that falls in a θ bin (about the given centre), so each direction counts once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.recon.triangulation.peaks import Quality

__all__ = ["ACCEPTED_QUALITY", "valid_mask", "BinnedProfile", "bin_profile", "Gap", "gaps",
           "coverage_deg", "interp_profile", "uniform_profile", "gaussian_filter",
           "DEFAULT_BIN_DEG",
           "DEFAULT_GAP_DEG"]

#: Quality codes whose points are measurements (the others are reasons for no point).
ACCEPTED_QUALITY = (int(Quality.FOUND), int(Quality.SATURATED))
#: θ bin of the profile (deg): 720 directions, finer than the ≥ 7 points per undulation that
#: ISO 12181-2 asks for 50 UPR.
DEFAULT_BIN_DEG = 0.5
#: A θ step between neighbouring valid points wider than this is a gap (deg); the same arc
#: that ``lts360 score`` lets one point cover.
DEFAULT_GAP_DEG = 0.5


def valid_mask(points_mm, quality) -> np.ndarray:
    """(n,) bool: finite coordinates and an accepted quality code."""
    pts = np.asarray(points_mm, dtype=float)
    return np.all(np.isfinite(pts), axis=1) & np.isin(np.asarray(quality), ACCEPTED_QUALITY)


@dataclass(frozen=True)
class BinnedProfile:
    """The profile about ``centre_mm`` in equal θ bins (empty bins dropped).

    Attributes
    ----------
    centre_mm : (2,) float
    theta_rad : (m,) float
        Mean θ (about the centre) of the points in each non-empty bin, increasing in [−π, π).
    r_mm : (m,) float
        Mean radius of those points.
    count : (m,) int
        Points per bin.
    bin_rad : float
    """

    centre_mm: np.ndarray
    theta_rad: np.ndarray
    r_mm: np.ndarray
    count: np.ndarray
    bin_rad: float

    @property
    def xy_mm(self) -> np.ndarray:
        """(m, 2) the binned profile's points."""
        return self.centre_mm + np.column_stack([self.r_mm * np.cos(self.theta_rad),
                                                 self.r_mm * np.sin(self.theta_rad)])


def bin_profile(xy_mm, centre_mm, *, bin_deg: float = DEFAULT_BIN_DEG) -> BinnedProfile:
    """Average the points ``xy_mm : (n, 2)`` in θ bins of ``bin_deg`` about ``centre_mm``.

    Bins are centred on ``k · bin_deg`` (so a bin sits on θ = 0 and on every axis direction
    when 90 is a multiple of ``bin_deg``).  Each bin's θ is the mean of the θ of its points
    (unwrapped about the bin centre).
    """
    xy = np.asarray(xy_mm, dtype=float)
    c = np.asarray(centre_mm, dtype=float)
    if not bin_deg > 0 or 360.0 / bin_deg != round(360.0 / bin_deg):
        raise ValueError(f"bin_deg must divide 360, got {bin_deg}")
    d = xy - c
    th = np.arctan2(d[:, 1], d[:, 0])
    r = np.hypot(d[:, 0], d[:, 1])
    w = np.radians(bin_deg)
    nb = int(round(360.0 / bin_deg))
    k = np.round(th / w).astype(int) % nb
    off = np.angle(np.exp(1j * (th - k * w)))  # θ relative to its bin centre, in (−w/2, w/2]
    cnt = np.bincount(k, minlength=nb)
    keep = cnt > 0
    s_off = np.bincount(k, off, minlength=nb)[keep] / cnt[keep]
    s_r = np.bincount(k, r, minlength=nb)[keep] / cnt[keep]
    centres = np.arange(nb)[keep] * w
    theta = np.angle(np.exp(1j * (centres + s_off)))
    order = np.argsort(theta)
    return BinnedProfile(c, theta[order], s_r[order], cnt[keep][order], w)


def interp_profile(profile: BinnedProfile, at_rad, *, gap_deg: float = DEFAULT_GAP_DEG):
    """r (mm) of the binned profile at the directions ``at_rad`` (about its centre), linear
    between neighbouring bins; NaN where those are more than ``gap_deg`` + one bin apart (a
    gap is not filled in)."""
    th, r = profile.theta_rad, profile.r_mm
    at = np.angle(np.exp(1j * np.asarray(at_rad, dtype=float)))
    if len(th) < 2:
        return np.full(at.shape, np.nan)
    t = np.concatenate([th[-1:] - 2 * np.pi, th, th[:1] + 2 * np.pi])
    rr = np.concatenate([r[-1:], r, r[:1]])
    j = np.clip(np.searchsorted(t, at, side="right"), 1, len(t) - 1)
    t0, t1 = t[j - 1], t[j]
    w = (at - t0) / np.maximum(t1 - t0, 1e-300)
    out = (1 - w) * rr[j - 1] + w * rr[j]
    return np.where(t1 - t0 <= np.radians(gap_deg) + profile.bin_rad, out, np.nan)


def uniform_profile(profile: BinnedProfile, *, gap_deg: float = DEFAULT_GAP_DEG):
    """``(theta_rad, r_mm)`` on the bins' uniform grid from −π, NaN inside gaps."""
    nb = int(round(2 * np.pi / profile.bin_rad))
    th = -np.pi + np.arange(nb) * (2 * np.pi / nb)
    return th, interp_profile(profile, th, gap_deg=gap_deg)


def gaussian_filter(profile: BinnedProfile, upr: float, *,
                    gap_deg: float = DEFAULT_GAP_DEG) -> BinnedProfile:
    """The profile through the ISO 16610-21 / ISO 12181-2 Gaussian low-pass filter.

    ``upr``: the cut-off in undulations per revolution (50 % transmission); order k passes
    with ``exp(−π (α k / upr)²)``, ``α = √(ln 2 / π)``.  Applied on the bins' uniform grid as a
    normalised periodic convolution, so a gap is neither filled in nor pulls its edges towards
    zero; the result keeps only the measured directions.
    """
    if not upr > 0:
        raise ValueError(f"filter cut-off must be > 0 UPR, got {upr}")
    th, r = uniform_profile(profile, gap_deg=gap_deg)
    w = np.isfinite(r).astype(float)
    k = np.arange(len(th) // 2 + 1)
    H = np.exp(-np.pi * (np.sqrt(np.log(2) / np.pi) * k / upr) ** 2)
    num = np.fft.irfft(H * np.fft.rfft(np.where(w > 0, r, 0.0)), n=len(th))
    den = np.fft.irfft(H * np.fft.rfft(w), n=len(th))
    keep = w > 0
    return BinnedProfile(profile.centre_mm, th[keep], num[keep] / den[keep],
                         np.full(int(keep.sum()), float(np.mean(profile.count))),
                         profile.bin_rad)


@dataclass(frozen=True)
class Gap:
    """An arc with no valid point.

    Attributes
    ----------
    start_deg, end_deg : float
        The valid θ on either side (counter-clockwise from start to end), in [−180, 180).
    width_deg : float
    flags : dict str → int
        Quality names of the invalid θ samples inside the gap and how many of each.
    """

    start_deg: float
    end_deg: float
    width_deg: float
    flags: dict


def gaps(theta_valid_rad, *, theta_invalid_rad=None, quality_invalid=None,
         gap_deg: float = DEFAULT_GAP_DEG) -> list[Gap]:
    """The θ arcs (periodic) between neighbouring valid points wider than ``gap_deg``.

    Parameters
    ----------
    theta_valid_rad : (n,) float
        θ of the valid points (any centre, usually the measurement frame's axis).
    theta_invalid_rad, quality_invalid : (m,) float and (m,) int, optional
        The invalid samples, to name why each gap has no point.
    """
    t = np.sort(np.mod(np.asarray(theta_valid_rad, dtype=float), 2 * np.pi))
    if t.size == 0:
        return [Gap(-180.0, 180.0, 360.0, _flag_counts(quality_invalid))]
    nxt = np.append(t[1:], t[0] + 2 * np.pi)
    step = nxt - t
    out = []
    for i in np.flatnonzero(step > np.radians(gap_deg)):
        a, b = t[i], nxt[i]
        flags = {}
        if theta_invalid_rad is not None and quality_invalid is not None:
            ti = np.mod(np.asarray(theta_invalid_rad, float) - a, 2 * np.pi)
            flags = _flag_counts(np.asarray(quality_invalid)[(ti > 0) & (ti < b - a)])
        out.append(Gap(_deg(a), _deg(b), float(np.degrees(b - a)), flags))
    return out


def _deg(a: float) -> float:
    return float((np.degrees(a) + 180.0) % 360.0 - 180.0)


def _flag_counts(q) -> dict:
    if q is None:
        return {}
    vals, cnt = np.unique(np.asarray(q, dtype=int), return_counts=True)
    names = {int(x): x.name for x in Quality}
    return {names.get(int(v), f"code_{int(v)}"): int(c) for v, c in zip(vals, cnt)}


def coverage_deg(theta_valid_rad, *, gap_deg: float = DEFAULT_GAP_DEG) -> float:
    """The angle covered by valid points: each covers the arc to its next neighbour up to
    ``gap_deg`` (as ``lts360 score`` counts it)."""
    t = np.sort(np.mod(np.asarray(theta_valid_rad, dtype=float), 2 * np.pi))
    if t.size == 0:
        return 0.0
    step = np.append(t[1:], t[0] + 2 * np.pi) - t
    return float(np.degrees(np.minimum(step, np.radians(gap_deg)).sum()))

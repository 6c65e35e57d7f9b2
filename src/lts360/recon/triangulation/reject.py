"""Truth-free rejection of spurious points: continuity along θ, fading lines, notches,
flanks along the axis and agreement with the neighbouring sections.

A point whose radius lies off a robust local fit of its own view's profile ``r(θ)`` by more
than ``k·σ`` is flagged ``DISCONTINUOUS`` and dropped from the valid points.  The local fit is
the running median of the view's valid radii over ``±half_window_deg``; ``σ`` is the robust
scatter (1.4826 × the median absolute deviation) of all the view's residuals, floored at
``floor_mm`` so that a noise-free section does not reject its pixel-locking ripple.  It uses
only the measurement: it runs on real images.

Where it stops: a spurious run longer than half the window (a whole hidden valley seen on a
neighbouring flank over several degrees) moves the median itself and is not caught.

Two criteria catch those runs (:func:`reject_spurious`, on by default in ``lts360 measure``),
from the measurement alone:

``FADING``
    A valid point within ``fade_margin_mm`` of arc of a stretch of at least ``fade_gap_mm``
    inside its view's own window where the view has no valid point.  Inside the window the
    calibration predicts the surface faces the (virtual) camera; a line that fades out there
    does so because the surface turns into the laser's shadow or behind a neighbouring flank,
    and the last points before the gap lie on the sheet's tail (measured: the spurious points
    of the grooved shaft's helix and of a cable's valleys sit within 0.5 mm of such a gap).  A
    round section's lines end at the window's edges, never inside, so it loses nothing here
    unless its surface turns dim for light: a specular pipe between glints.  In a scan
    (:func:`reject_scan`) such a stretch is kept when the section's profile bulges across it
    at least ``convex_fraction`` of a circle's sagitta on both flanks (chords
    ``convex_reach_mm`` beyond them), stays within ``round_tol_mm`` of the section's circle,
    *and* the surface runs straight along the axis there (``|dr/dz|`` to the neighbouring
    sections below ``max_axial_slope``): a corner bulges too, and a section is round at a
    shoulder or a groove's flank, where the line fades for geometry (:func:`convex_gaps`).
    In a scan a narrower tier also flags the line's last 0.07 mm before any faded stretch of
    0.1 mm or more (``short_margin_mm``, ``short_gap_mm``; same exemption).  Measured on the
    examples with realistic noise (STUDIES.md): the alu pipe's FADING 1141 → 168 points,
    cable-6's spurious points still valid 641 → 515, the undercut shaft's 926 → 806.
``NOTCH``
    A valid point whose θ lies in a notch of the section's measured profile: the profile (the
    median of the views per θ, a running median and mean over ±5 samples) lies more than
    ``notch_depth_mm`` below the chord joining the profile at ±L of arc, for L in
    ``notch_scales_mm``.  A notch narrower than about twice the sheet's thickness seen at the
    camera's angle is not resolved: its bottom is hidden or shaded and the detector finds the
    flanks' sheet tails, 0.1–0.5 mm off.  A convex section lies above every chord (a circle
    by L²/2R), so only the noise of the smoothed profile can reach the depth; measured on
    rendered round objects with realistic noise the 80 µm default rejects ≤ 0.3 % of their
    points.  In a scan, no notch is called where the profile stays within
    ``notch_round_tol_mm`` of the section's least-squares circle: there a "notch" is a glint's
    structured error or noise (the alu pipe's 159 NOTCH points → 33), while a cable's valleys
    lie farther off the circle; behind that test a scan calls a notch from
    60 µm (:attr:`RejectionTolerances.scan_notch_depth_mm`; one frame: 80 µm).
``FLANK``
    In a scan only: a valid point whose section's profile differs from *both* neighbouring
    sections' by an axial slope ``|dr/dz|`` above ``max_flank_slope`` over at least
    ``min_flank_arc_mm`` of arc.  The section lies on a flank that turns along the axis (a
    groove's or a shoulder's side): the sheet spans a radial range there that the section does
    not hold, and the stripe's centre is not the surface in the plane (measured: the undercut
    shaft's section on its groove's 45° flank reads −39 µm over its whole turn, 781 of its 806
    spurious points).  A section beside a flank differs from one neighbour only and is kept;
    so is a cone, whose slope does not change from section to section (only a flank short
    enough for the sheet to span its turn is flagged: :func:`flank_slopes`).  A scan's end
    section has one neighbour: it is flagged where it differs from it by that slope and the
    surface turns between them (the neighbour's slope beyond differs by as much), for it lies
    on the flank or past it and no section beyond tells which (measured: the undercut
    shaft's 5-section scan, whose end sections lie on its groove's flanks;
    :attr:`RejectionTolerances.flank_end_sections`).  The neighbours' profiles are first turned back by the
    scan's screw rate (:func:`screw_rate`), so that a cable's strands or a helical groove,
    which turn between sections, are compared along the helix, where they do not change.
``NEIGHBOURS``
    In a scan only, after the others: a valid point whose θ both neighbouring sections,
    turned back by the screw rate, rejected in the same view, where the section is not round
    (:func:`reject_like_neighbours`).  Along the helix it is the same valley seen from the
    same camera; the line there fades or notches in one section and bridges the valley on the
    sheet's tail in the next (measured: cable-6 2.8 mm off the axis, 303 → 172 spurious
    points still valid).

Every threshold, with its reason and the measurement that set it, is a field of
:class:`~lts360.recon.triangulation.reject_tolerances.RejectionTolerances`; the functions'
defaults read :data:`TOLERANCES`.

Agreement between views is not used as a criterion: on rendered round objects the views'
radii where they overlap (grazing points at the windows' ends) differ by up to 80 µm
noise-free and 150 µm with realistic noise, as much as a cable's spurious points.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from lts360.recon.triangulation.inverse import InverseResult
from lts360.recon.triangulation.peaks import Quality
from lts360.recon.triangulation.reject_tolerances import TOLERANCES, RejectionTolerances

__all__ = ["continuity_outliers", "reject_discontinuous", "fading_points", "section_profile",
           "notch_depth", "reject_spurious", "rejection_counts", "REJECTION_CODES",
           "convex_gaps", "mark_hidden", "ProfileGeometry", "TOLERANCES",
           "RejectionTolerances"]

#: Samples each side of the profile's running median and mean.
_PROFILE_HALF = 5
#: Truth-free rejections, by the name ``lts360 score`` and the cloud's header give them.
REJECTION_CODES = {"continuity": Quality.DISCONTINUOUS, "fading": Quality.FADING,
                   "notch": Quality.NOTCH, "hidden": Quality.HIDDEN, "flank": Quality.FLANK,
                   "neighbours": Quality.NEIGHBOURS,
                   "truncated": Quality.TRUNCATED,
                   "saturated_plateau": Quality.SATURATED_PLATEAU}


def continuity_outliers(r_mm, *, half_window: int, k: float = TOLERANCES.continuity_k,
                        floor_mm: float = TOLERANCES.continuity_floor_mm,
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


def reject_discontinuous(result: InverseResult, *, k: float = TOLERANCES.continuity_k,
                         half_window_deg: float = TOLERANCES.continuity_window_deg,
                         floor_mm: float = TOLERANCES.continuity_floor_mm) -> InverseResult:
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


def _windows(n: int, half: int, periodic: bool) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``i - half … i + half`` per sample and whether each lies inside ``[0, n)``."""
    k = np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :]
    if periodic:
        return k % n, np.ones(k.shape, bool)
    return np.clip(k, 0, n - 1), (k >= 0) & (k < n)


def _dilate(mask: np.ndarray, half: int, periodic: bool) -> np.ndarray:
    """Samples within ``half`` of a True sample (a running count by cumulative sums)."""
    n = mask.size
    if periodic:
        h = min(half, n)
        ext = np.concatenate([mask[n - h:], mask, mask[:h]]) if h else mask
    else:
        h = half
        ext = np.concatenate([np.zeros(h, bool), mask, np.zeros(h, bool)])
    c = np.concatenate([[0], np.cumsum(ext, dtype=np.int64)])
    i = np.arange(n) + h
    lo = np.clip(i - half, 0, ext.size)
    hi = np.clip(i + half + 1, 0, ext.size)
    return (c[hi] - c[lo]) > 0


@dataclasses.dataclass(frozen=True, eq=False)
class ProfileGeometry:
    """A section's profile made ready for :func:`convex_gaps`, once per section: gaps bridged
    along θ (``filled``), its points, and each point's distance from the profile's
    least-squares circle."""

    theta_rad: np.ndarray
    filled_mm: np.ndarray
    points_mm: np.ndarray
    off_circle_mm: np.ndarray
    radius_mm: float
    n_measured: int

    @classmethod
    def of(cls, theta_rad, profile_mm, *, periodic: bool = True) -> "ProfileGeometry":
        from lts360.geometry.fit import fit_circle

        th = np.asarray(theta_rad, float)
        prof = np.asarray(profile_mm, float)
        ok = np.isfinite(prof)
        if ok.sum() < 3:
            nan = np.full(th.size, np.nan)
            return cls(th, nan, np.column_stack([nan, nan]), nan, float("nan"), int(ok.sum()))
        filled = np.interp(th, th[ok], prof[ok], period=2 * np.pi if periodic else None)
        pts = np.column_stack([filled * np.cos(th), filled * np.sin(th)])
        circ = fit_circle(pts[ok])
        off = np.abs(np.hypot(pts[:, 0] - circ.center_mm[0], pts[:, 1] - circ.center_mm[1])
                     - circ.radius_mm)
        return cls(th, filled, pts, off, float(np.median(prof[ok])), int(ok.sum()))


def _chord_depth(pts: np.ndarray, i: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """How far the profile point ``i`` lies below the chord from profile point ``a`` to ``b``
    (mm, negative above it: convex), the chord's outward side being away from the origin."""
    e = pts[b] - pts[a]
    norm = np.linalg.norm(e, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        nrm = np.column_stack([e[:, 1], -e[:, 0]]) / norm[:, None]
        return np.where(norm > 0, np.einsum("ij,ij->i", pts[a] - pts[i], nrm), np.nan)


def convex_gaps(gap: np.ndarray, profile_mm: np.ndarray, theta_rad: np.ndarray, *,
                margin: int, reach: int, fraction: float = TOLERANCES.convex_fraction,
                periodic: bool = True, axial_slope=None,
                max_axial_slope: float = TOLERANCES.max_axial_slope,
                round_tol_mm: float = TOLERANCES.round_tol_mm) -> np.ndarray:
    """(n,) bool: the samples of each stretch of ``gap`` across which the section's profile is
    convex and the surface runs straight along the axis, so that the line cannot have faded
    there for geometry.

    ``axial_slope`` (n,): ``|dr/dz|`` per θ from the neighbouring sections
    (:func:`axial_slopes`); a stretch whose median over it and its flanks is unknown or above
    ``max_axial_slope`` is never convex here (a section is round at a shoulder or a groove's
    flank too: there the surface turns away along the axis, which one section cannot see).
    Nor is one where the profile leaves the section's least-squares circle by more than
    ``round_tol_mm`` over the chord: a corner or a strand bulges too, but its neighbouring
    face or strand can hide the line; only a round surface cannot.

    For a stretch ``[a, b]`` the chord joins the profile ``reach`` samples beyond its ends; its
    flanks (``margin`` samples each side, where FADING would reject) must lie above it by at
    least ``fraction`` of what a circle of the profile's radius would (``s₁s₂ / 2R`` at arc
    distances ``s₁, s₂`` from the chord's ends), on both sides.  A valley, a groove or a
    shoulder's shadow puts a flank below its chord; a round surface that only turns dim (a
    specular pipe away from its glint) keeps both above.  Gaps in the profile are bridged
    along θ for the chords' ends.
    """
    n = gap.size
    out = np.zeros(n, bool)
    if axial_slope is None or not gap.any() or margin < 1 or reach < 1:
        return out
    geo = profile_mm if isinstance(profile_mm, ProfileGeometry) else \
        ProfileGeometry.of(theta_rad, profile_mm, periodic=periodic)
    if geo.n_measured < 3:
        return out
    slope = np.asarray(axial_slope, float)
    pts, R, off_circle = geo.points_mm, geo.radius_mm, geo.off_circle_mm
    step = float(np.median(np.diff(geo.theta_rad)))
    from scipy.ndimage import label

    tiled = np.concatenate([gap, gap, gap]) if periodic else gap
    lab, nlab = label(tiled)
    offset = n if periodic else 0
    for k in range(1, nlab + 1):
        idx = np.flatnonzero(lab == k)
        lo, hi = int(idx[0]), int(idx[-1])
        if periodic and not (n <= lo < 2 * n):  # each stretch once: the one starting in the middle
            continue
        lo, hi = lo - offset, hi - offset
        if hi - lo + 1 >= n:
            continue
        ca, cb = lo - margin - reach, hi + margin + reach
        left = np.arange(lo - margin, lo)
        right = np.arange(hi + 1, hi + 1 + margin)
        if not periodic and (ca < 0 or cb >= n):
            continue
        zone = slope[np.arange(lo - margin, hi + 1 + margin) % n]
        if not (np.isfinite(zone).mean() > 0.5
                and np.nanmedian(zone) < max_axial_slope):
            continue
        if np.max(off_circle[np.arange(ca, cb + 1) % n]) > round_tol_mm:
            continue
        fl = []
        for side in (left, right):
            i = side % n
            d = _chord_depth(pts, i, np.full(i.size, ca % n), np.full(i.size, cb % n))
            s1 = (side - ca) * step * R
            s2 = (cb - side) * step * R
            circle = s1 * s2 / (2.0 * R)
            fl.append(np.nanmean(d + fraction * circle))
        if all(np.isfinite(v) and v < 0 for v in fl):
            out[np.arange(lo, hi + 1) % n] = True
    return out


def fading_points(r_mm, window, theta_step_rad: float, *,
                  margin_mm: float = TOLERANCES.fade_margin_mm,
                  gap_mm: float = TOLERANCES.fade_gap_mm,
                  periodic: bool = True, profile_mm=None, theta_rad=None,
                  convex_reach_mm: float = TOLERANCES.convex_reach_mm,
                  convex_fraction: float = TOLERANCES.convex_fraction, axial_slope=None,
                  max_axial_slope: float = TOLERANCES.max_axial_slope,
                  round_tol_mm: float = TOLERANCES.round_tol_mm,
                  short_gap_mm: float = TOLERANCES.short_gap_mm,
                  short_margin_mm: float = TOLERANCES.short_margin_mm) -> np.ndarray:
    """(n,) bool: valid radii within ``margin_mm`` of arc of a stretch of at least ``gap_mm``
    of the window (``window``) with no valid radius.

    With the section's profile (``profile_mm`` on ``theta_rad``) and the surface's axial slope
    from the scan (``axial_slope``), a stretch across which the profile is convex and the
    surface straight along the axis (:func:`convex_gaps`, chords ``convex_reach_mm`` beyond
    the flanks) does not count: the line faded there for light, not for geometry.

    Parameters
    ----------
    r_mm : (n,) float
        One view's radii on uniform θ; NaN where it has no valid point.
    window : (n,) bool
        θ the view measures (its window).
    theta_step_rad : float
    margin_mm, gap_mm : float, >= 0
    periodic : bool
    short_gap_mm, short_margin_mm : float
        A second, narrower tier: the valid radii within ``short_margin_mm`` of a stretch of at
        least ``short_gap_mm`` (a valley a cable hides only in part; 0 turns it off).
    """
    r = np.asarray(r_mm, dtype=float).ravel()
    win = np.asarray(window, dtype=bool).ravel()
    if r.shape != win.shape or not theta_step_rad > 0 or margin_mm < 0 or gap_mm < 0:
        raise ValueError("fading_points: r_mm and window must match, theta_step_rad > 0, "
                         "margin_mm and gap_mm >= 0")
    valid = np.isfinite(r)
    if not valid.any():
        return np.zeros(r.size, bool)
    arc = float(np.median(r[valid])) * theta_step_rad  # mm per sample at the view's radius
    faded = win & ~valid
    # Stretches of at least g faded samples (a periodic θ: the stretch may wrap round).
    from scipy.ndimage import label

    n = r.size
    tiled = np.concatenate([faded, faded, faded]) if periodic else faded
    lab, _ = label(tiled)
    size = np.bincount(lab.ravel())
    size[0] = 0
    out = np.zeros(n, bool)
    tiers = [(gap_mm, margin_mm)]
    if short_gap_mm > 0 and short_margin_mm > 0:
        tiers.append((short_gap_mm, short_margin_mm))
    if profile_mm is not None and axial_slope is not None \
            and not isinstance(profile_mm, ProfileGeometry):
        profile_mm = ProfileGeometry.of(theta_rad, profile_mm, periodic=periodic)
    for gap_t, margin_t in tiers:
        g = max(1, int(round(gap_t / arc)))
        long_ = size[lab] >= g
        gap = long_[n:2 * n] if periodic else long_
        m = max(1, int(round(margin_t / arc)))
        if profile_mm is not None and axial_slope is not None and convex_reach_mm > 0:
            # the flanks judged over the main margin in both tiers (a few samples are noise)
            m_judge = max(m, int(round(margin_mm / arc)))
            gap = gap & ~convex_gaps(gap, profile_mm, np.asarray(theta_rad, float),
                                     margin=m_judge,
                                     reach=max(1, int(round(convex_reach_mm / arc))),
                                     fraction=convex_fraction, periodic=periodic,
                                     axial_slope=axial_slope, max_axial_slope=max_axial_slope,
                                     round_tol_mm=round_tol_mm)
        out |= _dilate(gap, m, periodic)
    return valid & out


def _nanmedian_rows(a: np.ndarray) -> np.ndarray:
    """Median of each row's finite values (NaN where none); ``np.nanmedian`` by a sort."""
    srt = np.sort(a, axis=1)  # NaN last
    k = np.isfinite(a).sum(axis=1)
    rows = np.arange(a.shape[0])
    lo = srt[rows, np.maximum((k - 1) // 2, 0)]
    hi = srt[rows, np.maximum(k // 2, 0)]
    return np.where(k > 0, 0.5 * (lo + hi), np.nan)


def section_profile(theta_rad, radii_mm, *, periodic: bool = True,
                    half: int = _PROFILE_HALF) -> np.ndarray:
    """(n,) the section's measured profile: per θ the median of the views' radii, then a
    running median and a running mean over ±``half`` samples; NaN where no view measured."""
    R = np.atleast_2d(np.asarray(radii_mm, dtype=float))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = _nanmedian_rows(R.T)
        k, inside = _windows(r.size, half, periodic)
        med = _nanmedian_rows(np.where(inside, r[k], np.nan))
        mean = np.nanmean(np.where(inside, med[k], np.nan), axis=1)
    return np.where(np.isfinite(r), mean, np.nan)


def notch_depth(theta_rad, profile_mm, *, scales_mm=TOLERANCES.notch_scales_mm,
                periodic: bool = True) -> np.ndarray:
    """(n,) mm: how far the profile lies below its chord at ±L of arc (the largest over the
    scales ``L``); negative where it lies above (convex).  NaN where the profile is NaN.

    Gaps in the profile are bridged by linear interpolation along θ for the chords' ends."""
    th = np.asarray(theta_rad, dtype=float).ravel()
    r = np.asarray(profile_mm, dtype=float).ravel()
    ok = np.isfinite(r)
    out = np.full(r.size, np.nan)
    if ok.sum() < 3:
        return out
    filled = np.interp(th, th[ok], r[ok], period=2 * np.pi if periodic else None)
    step = float(np.median(np.diff(th)))
    i = np.arange(r.size)
    pts = np.column_stack([filled * np.cos(th), filled * np.sin(th)])
    depth = np.full(r.size, -np.inf)
    for L in scales_mm:
        k = np.maximum(1, np.round(L / (np.maximum(filled, 1e-3) * step))).astype(int)
        a, b = i - k, i + k
        if periodic:
            a, b = a % r.size, b % r.size
        else:
            a, b = np.clip(a, 0, r.size - 1), np.clip(b, 0, r.size - 1)
        e = pts[b] - pts[a]
        norm = np.linalg.norm(e, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            nrm = np.column_stack([e[:, 1], -e[:, 0]]) / norm[:, None]  # outward for θ increasing
            d = np.einsum("ij,ij->i", pts[a] - pts, nrm)
        depth = np.fmax(depth, np.where(norm > 0, d, -np.inf))
    out[ok] = depth[ok]
    return out


def reject_spurious(result: InverseResult, *, fade_margin_mm: float = TOLERANCES.fade_margin_mm,
                    fade_gap_mm: float = TOLERANCES.fade_gap_mm,
                    notch_depth_mm: float | None = TOLERANCES.notch_depth_mm,
                    notch_scales_mm=TOLERANCES.notch_scales_mm,
                    convex_reach_mm: float = TOLERANCES.convex_reach_mm,
                    convex_fraction: float = TOLERANCES.convex_fraction,
                    axial_slope=None,
                    max_axial_slope: float = TOLERANCES.max_axial_slope,
                    round_tol_mm: float = TOLERANCES.round_tol_mm,
                    short_gap_mm: float = TOLERANCES.short_gap_mm,
                    short_margin_mm: float = TOLERANCES.short_margin_mm,
                    notch_round_tol_mm: float = TOLERANCES.notch_round_tol_mm,
                    flank_slope=None,
                    max_flank_slope: float | None = TOLERANCES.max_flank_slope,
                    min_flank_arc_mm: float = TOLERANCES.min_flank_arc_mm) -> InverseResult:
    """The result with fading points flagged ``FADING`` and points in a notch ``NOTCH`` (see
    the module docstring), both dropped from the valid points.

    ``flank_slope`` (nθ,): the section's ``|dr/dz|`` to both neighbours
    (:func:`flank_slopes`); its stretches above ``max_flank_slope`` of at least
    ``min_flank_arc_mm`` are flagged ``FLANK`` (``max_flank_slope = None``: off).

    ``fade_margin_mm = 0`` or ``notch_depth_mm = None`` turns a criterion off.  Both are
    decided on the points as measured (before either rejects anything); a point both would
    reject is counted ``FADING``.  With ``axial_slope`` (a scan's section, :func:`reject_scan`)
    a faded stretch of a round, convex, axially straight surface is kept and the narrow
    ``FADING`` tier is on; without it (one frame) neither: a round section's dim stretches
    could not be told from a hidden valley, and the narrow tier would cost a gauge 0.6 % of
    its points (measured, realistic noise).
    """
    grid = result.grid
    if grid.n_theta < 3:
        return result
    periodic = grid.is_full_turn
    step = grid.theta_step_rad
    depth = None
    prof = section_profile(grid.theta_rad, [v.r_mm for v in result.views.values()],
                           periodic=periodic)
    if notch_depth_mm is not None:
        if not notch_depth_mm > 0:
            raise ValueError(f"notch_depth_mm must be > 0 or None, got {notch_depth_mm}")
        depth = notch_depth(grid.theta_rad, prof, scales_mm=notch_scales_mm, periodic=periodic)
    scan = axial_slope is not None and bool(np.isfinite(np.asarray(axial_slope, float)).any())
    geo = ProfileGeometry.of(grid.theta_rad, prof, periodic=periodic) if scan else None
    flank = None
    if flank_slope is not None and max_flank_slope is not None:
        if not max_flank_slope > 0:
            raise ValueError(f"max_flank_slope must be > 0 or None, got {max_flank_slope}")
        slope = np.asarray(flank_slope, float)
        flank = _long_runs(slope > max_flank_slope,  # NaN: kept
                           int(np.ceil(min_flank_arc_mm / (np.nanmedian(prof) * step)))
                           if np.isfinite(prof).any() else slope.size + 1, periodic)
    views = {}
    for name, v in result.views.items():
        q = v.quality.copy()
        valid = v.valid
        if flank is not None:
            q[valid & flank] = Quality.FLANK
        if depth is not None:
            notch = depth > notch_depth_mm
            if geo is not None:  # a scan: a round section's shallow notch is noise or glint
                notch &= ~(geo.off_circle_mm <= notch_round_tol_mm)
            q[valid & notch] = Quality.NOTCH
        if fade_margin_mm > 0:
            fade = fading_points(v.r_mm, v.window, step, margin_mm=fade_margin_mm,
                                 gap_mm=fade_gap_mm, periodic=periodic,
                                 profile_mm=prof if geo is None else geo,
                                 theta_rad=grid.theta_rad, convex_reach_mm=convex_reach_mm,
                                 convex_fraction=convex_fraction,
                                 axial_slope=axial_slope if scan else None,
                                 max_axial_slope=max_axial_slope, round_tol_mm=round_tol_mm,
                                 short_gap_mm=short_gap_mm,
                                 # the narrow tier only where a round surface's dim stretches
                                 # can be told apart (a scan: the axial slope is known)
                                 short_margin_mm=short_margin_mm if geo is not None else 0.0)
            q[fade] = Quality.FADING
        out = valid & ((q == Quality.NOTCH) | (q == Quality.FADING) | (q == Quality.FLANK))
        views[name] = dataclasses.replace(v, r_mm=np.where(out, np.nan, v.r_mm), quality=q)
    return dataclasses.replace(result, views=views)


def _scan_profiles(results) -> list:
    """Each section's profile (:func:`section_profile`), its gaps bridged along θ."""
    profs = []
    for res in results:
        g = res.grid
        p = section_profile(g.theta_rad, [v.r_mm for v in res.views.values()],
                            periodic=g.is_full_turn)
        ok = np.isfinite(p)
        profs.append(np.interp(g.theta_rad, g.theta_rad[ok], p[ok],
                               period=2 * np.pi if g.is_full_turn else None)
                     if ok.sum() >= 3 else np.full(g.n_theta, np.nan))
    return profs


def _comparable(results, zs, keys, profs, k: int, j: int) -> bool:
    return 0 <= j < len(results) and keys[j] == keys[k] and zs[j] != zs[k] \
        and profs[j].size == profs[k].size and bool(np.isfinite(profs[j]).all()) \
        and bool(np.isfinite(profs[k]).all()) \
        and np.allclose(results[j].grid.theta_rad, results[k].grid.theta_rad)


def screw_rate(results, z_mm, *, frames=None,
               max_shift_deg: float = TOLERANCES.max_screw_shift_deg, _profiles=None) -> float:
    """rad/mm: how fast the sections' profiles turn about the axis along the scan (a cable's
    lay, a helical groove's lead), 0 for a surface of revolution or a prism.

    For each pair of neighbouring sections (full turns, same frame), the shift of θ within
    ``±max_shift_deg`` that best aligns the later profile with the earlier one (least mean
    absolute difference about their median difference); the scan's rate is the median of the
    pairs' shift per mm.  A round profile aligns equally at every shift: its pairs' shifts are
    noise about 0 and move a round neighbour by nothing that matters."""
    zs = [float(z) for z in z_mm]
    keys = list(frames) if frames is not None else [None] * len(results)
    profs = _scan_profiles(results) if _profiles is None else _profiles
    rates = []
    for k in range(len(results) - 1):
        g = results[k].grid
        if not g.is_full_turn or not _comparable(results, zs, keys, profs, k, k + 1):
            continue
        m = int(round(np.radians(max_shift_deg) / g.theta_step_rad))
        a, b = profs[k], profs[k + 1]
        shifts = np.arange(-m, m + 1)
        cost = np.array([np.mean(np.abs(d - np.median(d)))
                         for d in (b - np.roll(a, sh) for sh in shifts)])
        sh = int(shifts[np.lexsort((np.abs(shifts), cost))[0]])  # a tie: the smallest turn
        rates.append(sh * g.theta_step_rad / (zs[k + 1] - zs[k]))
    return float(np.median(rates)) if rates else 0.0


def _aligned(profs, results, zs, keys, k: int, j: int, screw: float):
    """Section ``j``'s profile on section ``k``'s θ, turned back by ``screw·(z_j − z_k)``
    (the same surface along the helix), or None where the two cannot be compared."""
    if not _comparable(results, zs, keys, profs, k, j):
        return None
    g = results[k].grid
    if not screw or not g.is_full_turn:
        return profs[j]
    # r_j(θ) ≈ r_k(θ − screw·(z_j − z_k)): sample r_j at θ + screw·Δz
    th = g.theta_rad
    return np.interp(th + screw * (zs[j] - zs[k]), th, profs[j], period=2 * np.pi)


def _side_slopes(results, z_mm, frames=None, *, screw: float = 0.0, _profiles=None) -> list:
    """Per section, the ``|dr/dz|`` per θ to each neighbour it can be compared with: a
    (sides, nθ) array (0–2 rows).  ``screw`` (rad/mm, :func:`screw_rate`): the neighbour's
    profile is first turned back by ``screw·Δz`` (the slope along the helix)."""
    zs = [float(z) for z in z_mm]
    keys = list(frames) if frames is not None else [None] * len(results)
    profs = _scan_profiles(results) if _profiles is None else _profiles
    out = []
    for k, res in enumerate(results):
        sides = []
        for j in (k - 1, k + 1):
            pj = _aligned(profs, results, zs, keys, k, j, screw)
            if pj is not None:
                sides.append(np.abs(pj - profs[k]) / abs(zs[j] - zs[k]))
        out.append(np.array(sides).reshape(len(sides), res.grid.n_theta))
    return out


def axial_slopes(results, z_mm, *, frames=None, _profiles=None) -> list:
    """Per section, ``|dr/dz|`` per θ between its profile and its neighbours' (the larger of
    the two sides; NaN where unknown): the surface's slope along the axis, from the scan.

    ``results``: the sections' :class:`InverseResult` as measured (before any rejection);
    ``z_mm``: their stage heights; ``frames``: an optional key per section (the centre it was
    measured about): sections in different frames, or on different θ grids, are not compared.
    """
    return [_fmax_rows(s) for s in _side_slopes(results, z_mm, frames, _profiles=_profiles)]


def flank_slopes(results, z_mm, *, frames=None, _profiles=None, _screw=None,
                 min_change: float = TOLERANCES.max_flank_slope,
                 end_sections: bool = TOLERANCES.flank_end_sections) -> list:
    """Per section, ``|dr/dz|`` per θ to *both* neighbours (the smaller of the two sides; NaN
    where a side is unknown, so never at a scan's ends) where the section lies on a *short*
    flank (:data:`Quality.FLANK`), 0 elsewhere.

    A flank is short where, on at least one side, the slope beyond the neighbour (between it
    and the next section) differs from the slope to it by more than ``min_change``: the
    surface turns along the axis within two pitches, as at a groove's or a shoulder's side,
    and the sheet there may span the turn.  A cone keeps its slope from section to section
    and is measured (the sheet's centre on a straight slope is the surface's); where neither
    side's next section is known the flank counts as short.

    ``end_sections``: a scan's end section (one neighbour) gets its slope to that neighbour
    where the surface turns between them (the neighbour's slope beyond differs by more than
    ``min_change``): it lies on the flank or past it, and with no section beyond the scan
    cannot tell which (:attr:`RejectionTolerances.flank_end_sections`).  Arguments as
    :func:`axial_slopes`."""
    zs = [float(z) for z in z_mm]
    keys = list(frames) if frames is not None else [None] * len(results)
    profs = _scan_profiles(results) if _profiles is None else _profiles
    screw = screw_rate(results, z_mm, frames=frames, _profiles=profs) if _screw is None \
        else _screw
    out = []
    for k, res in enumerate(results):
        n = res.grid.n_theta
        inner, changes = [], []
        for j, jj in ((k - 1, k - 2), (k + 1, k + 2)):
            pj = _aligned(profs, results, zs, keys, k, j, screw)
            if pj is None:
                continue
            s_in = (profs[k] - pj) / (zs[k] - zs[j])
            inner.append(np.abs(s_in))
            pjj = _aligned(profs, results, zs, keys, k, jj, screw) \
                if _comparable(results, zs, keys, profs, j, jj) else None
            if pjj is not None:
                changes.append(np.abs(s_in - (pj - pjj) / (zs[j] - zs[jj])))
        if len(inner) == 1 and len(changes) == 1 and end_sections:
            # a scan's end section: its only neighbour's slope beyond it is known, and the
            # surface turns between them (a flank within the last two pitches): the end
            # section lies on the flank or past it, and no section beyond tells which
            out.append(np.where(changes[0] > min_change, inner[0], 0.0))
            continue
        if len(inner) < 2:
            out.append(np.full(n, np.nan))
            continue
        short = np.any(np.array(changes) > min_change, axis=0) if changes \
            else np.ones(n, bool)
        out.append(np.where(short, np.minimum(inner[0], inner[1]), 0.0))
    return out


def _long_runs(mask: np.ndarray, n_min: int, periodic: bool) -> np.ndarray:
    """The samples of ``mask`` in runs of at least ``n_min`` (a periodic run may wrap)."""
    from scipy.ndimage import label

    n = mask.size
    if not mask.any():
        return mask
    if periodic and mask.all():
        return mask if n >= n_min else np.zeros(n, bool)
    tiled = np.concatenate([mask, mask, mask]) if periodic else mask
    lab, _ = label(tiled)
    size = np.bincount(lab.ravel())
    size[0] = 0
    keep = size[lab] >= n_min
    return keep[n:2 * n] if periodic else keep


def _fmax_rows(a: np.ndarray) -> np.ndarray:
    out = np.full(a.shape[1], np.nan)
    for row in a:
        out = np.fmax(out, row)
    return out


def reject_scan(results, z_mm, *, frames=None, continuity_k: float | None = None,
                neighbour_dilation: int | None = TOLERANCES.neighbour_dilation, **kwargs) -> list:
    """:func:`reject_spurious` (then :func:`reject_discontinuous` with ``continuity_k``) on
    every section of a scan, with each section's axial slope from its neighbours
    (:func:`axial_slopes`), so that a faded stretch on a convex, axially straight surface is
    kept (:func:`convex_gaps`), and its slope to both neighbours (:func:`flank_slopes`), so
    that a section on a flank is flagged ``FLANK``; then :func:`reject_like_neighbours`
    (``neighbour_dilation``; ``None``: off).  ``notch_depth_mm`` defaults to
    :attr:`RejectionTolerances.scan_notch_depth_mm` here (a scan keeps round sections out of ``NOTCH``)."""
    profs = _scan_profiles(results)  # once for all
    screw = screw_rate(results, z_mm, frames=frames, _profiles=profs)
    slopes = axial_slopes(results, z_mm, frames=frames, _profiles=profs)
    flanks = flank_slopes(results, z_mm, frames=frames, _profiles=profs, _screw=screw)
    out = []
    kwargs.setdefault("notch_depth_mm", TOLERANCES.scan_notch_depth_mm)
    for res, sl, fl in zip(results, slopes, flanks):
        r = reject_spurious(res, axial_slope=sl, flank_slope=fl, **kwargs)
        out.append(r if continuity_k is None else reject_discontinuous(r, k=continuity_k))
    if neighbour_dilation is None:
        return out
    return reject_like_neighbours(out, z_mm, frames=frames, screw_rad_per_mm=screw,
                                  profiles=profs, dilation=neighbour_dilation,
                                  round_tol_mm=kwargs.get("notch_round_tol_mm",
                                                          TOLERANCES.notch_round_tol_mm))


#: What a neighbouring section's row must have been flagged for :func:`reject_like_neighbours`.
_NEIGHBOUR_CODES = (Quality.FADING, Quality.NOTCH, Quality.HIDDEN, Quality.FLANK)


def reject_like_neighbours(results, z_mm, *, frames=None, screw_rad_per_mm: float = 0.0,
                           profiles=None, dilation: int = TOLERANCES.neighbour_dilation,
                           round_tol_mm: float = TOLERANCES.notch_round_tol_mm) -> list:
    """The scan's results with a view's valid point flagged ``NEIGHBOURS`` where both
    neighbouring sections (same frame, same θ grid), turned back by the screw rate, rejected
    that θ (± ``dilation`` samples) in the same view as ``FADING``, ``NOTCH``, ``HIDDEN`` or
    ``FLANK``, and the section's profile lies more than ``round_tol_mm`` off its
    least-squares circle there.

    Along the helix a cable is the same surface from section to section, and each view sees
    it from the same camera turned by only the screw × pitch (1.4° on cable-6): a valley both
    neighbours found hidden, faded or notched is there in between too, and a point measured
    there bridges it on the sheet's tail (measured: cable-6 2.8 mm off the axis, 131 of 263
    such points spurious, and the rest on the valleys' flanks).  A round section, where a
    specular pipe's dim stretches recur along the axis, is left alone, as are a scan's end
    sections.  Decided on the results as given (one pass: a point flagged here does not
    flag its neighbours).  ``profiles``: the sections' profiles (:func:`section_profile`,
    bridged) as measured, before any rejection; computed from ``results`` if not given."""
    keys = list(frames) if frames is not None else [None] * len(results)
    zs = [float(z) for z in z_mm]
    profs = _scan_profiles(results) if profiles is None else profiles
    out = []
    for k, res in enumerate(results):
        g = res.grid
        nbrs = [j for j in (k - 1, k + 1) if 0 <= j < len(results) and keys[j] == keys[k]
                and zs[j] != zs[k] and results[j].grid.n_theta == g.n_theta
                and np.allclose(results[j].grid.theta_rad, g.theta_rad)]
        if len(nbrs) < 2 or not g.is_full_turn or np.isfinite(profs[k]).sum() < 3:
            out.append(res)
            continue
        off_round = ProfileGeometry.of(g.theta_rad, profs[k]).off_circle_mm > round_tol_mm
        views = {}
        for name, v in res.views.items():
            both = off_round & v.valid
            for j in nbrs:
                vj = results[j].views.get(name)
                if vj is None:
                    both[:] = False
                    break
                m = np.isin(vj.quality, _NEIGHBOUR_CODES)
                # r_j(θ) ≈ r_k(θ − screw·(z_j − z_k)): row i of k is row i + shift of j
                m = np.roll(m, -int(round(screw_rad_per_mm * (zs[j] - zs[k])
                                          / g.theta_step_rad)))
                both &= _dilate(m, dilation, True) if dilation > 0 else m
            if not both.any():
                views[name] = v
                continue
            q = v.quality.copy()
            q[both] = Quality.NEIGHBOURS
            views[name] = dataclasses.replace(v, r_mm=np.where(both, np.nan, v.r_mm), quality=q)
        out.append(dataclasses.replace(res, views=views))
    return out


def mark_hidden(result: InverseResult, hidden: dict) -> InverseResult:
    """The result with each view's valid points in ``hidden`` (view name → (nθ,) bool: θ its
    first-pass profile hides from the view, :func:`lts360.recon.triangulation.band.hidden_rows`)
    flagged ``HIDDEN`` and invalid: the line found there is another surface's.  Being invalid
    inside the window, hidden rows count as faded for :func:`fading_points`: the line's last
    points before them are judged as before any stretch where it faded."""
    views = {}
    for name, v in result.views.items():
        m = hidden.get(name)
        if m is None or not np.any(m):
            views[name] = v
            continue
        m = np.asarray(m, bool) & v.window & v.valid
        q = v.quality.copy()
        q[m] = Quality.HIDDEN
        views[name] = dataclasses.replace(v, r_mm=np.where(m, np.nan, v.r_mm), quality=q)
    return dataclasses.replace(result, views=views)


def rejection_counts(quality) -> dict[str, int]:
    """Rows of each truth-free rejection (:data:`REJECTION_CODES`) among ``quality``."""
    q = np.asarray(quality)
    return {name: int(np.sum(q == code)) for name, code in REJECTION_CODES.items()}

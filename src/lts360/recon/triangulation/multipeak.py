"""A choice between several lines along one radial direction (interreflections), truth-free.

Laser light the object scatters onto itself (a shiny groove's shoulders lighting each other, a
metal pipe's glint carried back by a mirror) draws secondary stripes in the image.  Where one
crosses a view's radial line inside the band, the profile holds two runs above the threshold.
The detector takes the strongest (:func:`lts360.recon.triangulation.peaks.main_run`) and calls
the row ``SEVERAL_PEAKS`` (never a point) only when the other reaches half of it, so a weaker
secondary line is ignored even where it is the true one, and a stronger one is taken.

:func:`choose_peaks` looks again at every row whose second run reaches
:attr:`MultiPeakTolerances.fraction` of its main one.  It finds every run of the row's profile
(their thresholded centroids, as the detector's), and compares them with the radius the
section's *unambiguous* rows around it read (all views, ±``reference_half_deg`` of θ: a
running median of the valid rows that have no such second run):

* one run lies within ``match_mm`` of that radius and every other run (farther than
  ``same_line_mm`` from it: a line split by a dark speckle is one line) lies more than
  ``match_mm + margin_mm`` from it: that run is the point (``FOUND``, or ``SATURATED`` /
  ``SATURATED_PLATEAU`` by its own samples; a run touching the band's end or a NaN sample is
  never chosen).  Where the closest run is the one the detector already kept (its second
  stayed below half), no margin is asked: the choice only confirms it;
* a row decided joins the reference of the next pass, so a long stretch with two lines is
  followed in from its ends (up to 180 passes);
* otherwise the row is ``SEVERAL_PEAKS`` (no point): two lines and nothing to tell which;
* no reference (fewer than ``min_reference`` unambiguous rows around it): the detector's
  result stays.

It uses the image and the measurement alone.  Where the secondary line is the only one on a
stretch (the true line too dim to cross the threshold), its rows are unambiguous and the
reference follows them: that case is not caught here.  The choice runs before the other
rejections (:mod:`lts360.recon.triangulation.reject`), in ``lts360 measure`` and the studies
whenever they reject (``reject=True``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from lts360.recon.triangulation.interp import sample_cubic
from lts360.recon.triangulation.inverse import (
    InversePlan,
    InverseResult,
    assemble_view,
    compensation_of,
)
from lts360.recon.triangulation.peaks import (
    DEFAULT_MAX_PLATEAU_MM,
    SATURATION_RTOL,
    PeakResult,
    Quality,
    plateau_samples,
)

__all__ = ["MultiPeakTolerances", "MULTIPEAK", "profile_runs", "choose_run", "choose_peaks"]


@dataclass(frozen=True)
class MultiPeakTolerances:
    """The thresholds of :func:`choose_peaks`, each with its reason.

    Attributes
    ----------
    fraction : float
        Rows whose second run reaches this fraction of the main run's maximum are examined
        (the detector's ``SEVERAL_PEAKS`` starts at 0.5; a secondary stripe at 0.2–0.5 of the
        primary one still wins nothing and can be the true line where the primary is a glint).
    reference_half_deg : float
        Half-width of the θ window of the reference radius (±2°: 20 rows at the studies'
        0.2° each side, 0.35 mm of arc on a Ø20 section; the speckle's 33 µm per point
        averages down to ~8 µm).
    min_reference : int
        Fewest unambiguous valid rows (all views) that make a reference.
    match_mm : float
        A run within this of the reference is the section's line (the speckle floor is 33 µm
        rms per point, the views differ by up to 0.15 mm where they overlap at grazing angles).
    margin_mm : float
        Every other run must lie this much farther from the reference.
    same_line_mm : float
        Runs whose centres lie this close to the chosen one are the same line split by a dark
        speckle grain (the stripe's width along the radius is 0.1–0.2 mm on the paper rig).
    """

    fraction: float = 0.2
    reference_half_deg: float = 2.0
    min_reference: int = 5
    match_mm: float = 0.1
    margin_mm: float = 0.1
    same_line_mm: float = 0.12

    def __post_init__(self) -> None:
        if not 0 < self.fraction <= 1:
            raise ValueError(f"fraction must be in (0, 1], got {self.fraction}")
        for name in ("reference_half_deg", "match_mm", "same_line_mm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.margin_mm >= 0:
            raise ValueError(f"margin_mm must be >= 0, got {self.margin_mm}")
        if int(self.min_reference) < 1:
            raise ValueError(f"min_reference must be >= 1, got {self.min_reference}")


MULTIPEAK = MultiPeakTolerances()
#: Passes of the choice grown from the unambiguous rows (each reaches ``reference_half_deg``
#: further: 180 follow a second line round a whole turn at ±2°).
_MAX_PASSES = 180


def profile_runs(profiles, threshold: float):
    """Every run above ``threshold`` of every profile, vectorised.

    Returns
    -------
    row, start, stop : (m,) int
        The profile and the samples ``start … stop − 1`` of each run (in profile order).
    centre : (m,) float
        Thresholded centroid in samples (weights ``I − threshold``, as the detector's).
    peak : (m,) float
        The run's largest sample.
    cut : (m,) bool
        The run touches the profile's first or last sample or a NaN sample.
    """
    p = np.asarray(profiles, dtype=float)
    n, nr = p.shape
    nan = np.isnan(p)
    above = np.where(nan, False, p > threshold)
    pad = np.zeros((n, 1), dtype=bool)
    edge = np.diff(np.concatenate([pad, above, pad], axis=1).astype(np.int8), axis=1)
    rs, start = np.nonzero(edge == 1)
    re, stop = np.nonzero(edge == -1)  # same order: row-major, one stop per start
    if not np.array_equal(rs, re):
        raise AssertionError("profile_runs: unmatched run ends")
    label = np.cumsum(edge == 1, axis=1)[:, :nr]  # run number within the row, 0 before
    offset = np.concatenate([[0], np.cumsum((edge == 1).sum(axis=1))[:-1]])
    run_id = np.where(above, offset[:, None] + label - 1, -1)
    ids = run_id[above]
    w = (p - threshold)[above]
    j = np.broadcast_to(np.arange(nr), p.shape)[above]
    m = len(rs)
    sw = np.bincount(ids, weights=w, minlength=m)
    centre = np.bincount(ids, weights=w * j, minlength=m) / np.where(sw > 0, sw, 1.0)
    peak = np.full(m, -np.inf)
    np.maximum.at(peak, ids, p[above])
    nan_pad = np.concatenate([pad, nan, pad], axis=1)
    cut = (start == 0) | (stop == nr) | nan_pad[rs, start] | nan_pad[rs, stop + 1]
    return rs, start, stop, centre, peak, cut


def choose_run(run_row, run_r_mm, run_cut, reference_mm, *, n_rows: int,
               tol: MultiPeakTolerances = MULTIPEAK, run_kept=None):
    """The run each row's line is, given the runs' radii and the rows' reference radius.

    Parameters
    ----------
    run_row : (m,) int
        Row of each run (ascending).
    run_r_mm : (m,) float
        Radius of each run's centre.
    run_cut : (m,) bool
        Runs that may not be chosen (cut by the band's end or a NaN sample).
    reference_mm : (n_rows,) float
        NaN where there is none.
    run_kept : (m,) bool, optional
        The run the detector already keeps as its row's point (its main run, where the second
        stayed below ``SEVERAL_PEAKS``): chosen as the best within ``match_mm``, it needs no
        margin over the others — the choice only confirms it.

    Returns
    -------
    chosen : (n_rows,) int
        Index of the chosen run; −1 where the row is ambiguous, −2 where it has no reference
        (the detector's result stays).
    """
    ref = np.asarray(reference_mm, dtype=float)[run_row]
    d = np.abs(np.asarray(run_r_mm, dtype=float) - ref)
    m = len(run_row)
    chosen = np.where(np.isfinite(np.asarray(reference_mm, dtype=float)), -1, -2)
    if m == 0:
        return chosen
    # best eligible run per row: lexsort by (row, distance), first of each row
    key = np.where(run_cut | ~np.isfinite(d), np.inf, d)
    order = np.lexsort((key, run_row))
    first = np.ones(m, dtype=bool)
    first[1:] = run_row[order][1:] != run_row[order][:-1]
    best = np.full(n_rows, -1)
    best[run_row[order][first]] = order[first]
    has = best >= 0
    best_d = np.where(has, key[np.maximum(best, 0)], np.inf)
    best_r = np.asarray(run_r_mm, dtype=float)[np.maximum(best, 0)]
    # competitors: other runs of the row, not the same line as the best one
    other = (np.arange(m) != best[run_row]) & \
        (np.abs(np.asarray(run_r_mm, dtype=float) - best_r[run_row]) > tol.same_line_mm)
    near = np.full(n_rows, np.inf)
    np.minimum.at(near, run_row[other], np.where(np.isfinite(d), d, np.inf)[other])
    clear = near > tol.match_mm + tol.margin_mm
    if run_kept is not None:
        clear |= np.asarray(run_kept, dtype=bool)[np.maximum(best, 0)] & has
    ok = has & (best_d <= tol.match_mm) & clear
    return np.where(ok & (chosen == -1), best, chosen)


def _reference(grid, radii: np.ndarray, at: np.ndarray, tol: MultiPeakTolerances) -> np.ndarray:
    """(len(at),) the median of ``radii`` (views × nθ, NaN: no reference point) over
    ±``reference_half_deg`` of θ about each row ``at``; NaN where fewer than
    ``min_reference``."""
    n = grid.n_theta
    half = max(1, int(round(np.radians(tol.reference_half_deg) / max(grid.theta_step_rad, 1e-12))))
    k = at[:, None] + np.arange(-half, half + 1)[None, :]
    if grid.is_full_turn:
        k, inside = k % n, np.ones(k.shape, dtype=bool)
    else:
        inside = (k >= 0) & (k < n)
        k = np.clip(k, 0, n - 1)
    win = np.where(inside[None], radii[:, k], np.nan)            # (v, len(at), w)
    win = np.moveaxis(win, 0, 1).reshape(len(at), -1)
    out = np.full(len(at), np.nan)
    enough = np.isfinite(win).sum(axis=1) >= int(tol.min_reference)
    if enough.any():
        out[enough] = np.nanmedian(win[enough], axis=1)
    return out


def _main_runs(run_row: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """(m,) bool: each row's strongest run (the first of equal maxima, as the detector's
    ``argmax``): the run the detector measured, whatever the rounding of its own sampling."""
    m = len(run_row)
    order = np.lexsort((np.arange(m), -peak, run_row))
    first = np.ones(m, dtype=bool)
    first[1:] = run_row[order][1:] != run_row[order][:-1]
    out = np.zeros(m, dtype=bool)
    out[order[first]] = True
    return out


def _assembled(v, vp, grid, local, rows, chosen, prof, start, stop, peak, base, is_main, sat,
               max_plateau_mm, plan, result, compensate):
    """View ``v`` again with each examined row's chosen run (``chosen``: :func:`choose_run`'s
    codes), assembled as :func:`assemble_view` does."""
    q_win = v.quality[vp.theta_index].copy()
    r_win = v.r_raw_mm[vp.theta_index] - grid.r_shift_mm[vp.theta_index]
    i_win = v.intensity[vp.theta_index].copy()
    q, r = q_win[local], r_win[local]
    pick = chosen >= 0
    c = np.maximum(chosen, 0)
    peak_c = peak[c] if len(peak) else np.zeros(len(rows))
    main = pick & (is_main[c] if len(peak) else False)  # the detector's own run
    r = np.where(pick & ~main, base[c] if len(base) else r, r)
    q_pick = np.full(rows.size, Quality.FOUND, dtype=np.uint8)
    if sat is not None and len(peak):
        s_lim = sat * (1.0 - SATURATION_RTOL)
        q_pick[peak_c >= s_lim] = Quality.SATURATED
        lim = plateau_samples(max_plateau_mm, grid.r_mm)
        if lim is not None:
            j = np.arange(prof.shape[1])
            in_run = (j >= start[c][:, None]) & (j < stop[c][:, None])
            wide = (in_run & (np.nan_to_num(prof, nan=-np.inf) >= s_lim)).sum(axis=1) > lim
            q_pick[wide] = Quality.SATURATED_PLATEAU
    q_pick = np.where(main & (q != Quality.SEVERAL_PEAKS), q, q_pick)  # as detected
    q = np.where(pick, q_pick, np.where(chosen == -1, np.uint8(Quality.SEVERAL_PEAKS), q))
    i_win[local] = np.where(pick & ~main, peak_c, i_win[local])  # the chosen line's
    q_win[local], r_win[local] = q, r
    peaks = PeakResult(r_mm=np.where(q_win == Quality.NO_PEAK, np.nan, r_win),
                       quality=q_win.astype(np.uint8), intensity=i_win,
                       second=v.second[vp.theta_index])
    return assemble_view(vp, grid, peaks, accept=result.accept,
                         **compensation_of(plan.cal, v.name, compensate))


def choose_peaks(result: InverseResult, image, plan: InversePlan, *, compensate: bool = False,
                 tol: MultiPeakTolerances = MULTIPEAK,
                 max_plateau_mm: float | None = DEFAULT_MAX_PLATEAU_MM) -> InverseResult:
    """``result`` with a line chosen, or the row called ``SEVERAL_PEAKS``, wherever a second run
    reaches ``tol.fraction`` of the main one (module docstring).

    ``result`` must be the detector's output for ``image`` with ``plan`` (its views carry
    ``second``; a result without it is returned as it is). ``compensate``: as the result was
    assembled (the §4.4 and mastering corrections of ``plan.cal``).
    """
    views = result.views
    if not views or any(v.second is None for v in views.values()):
        return result
    examined = {name: v.window & np.isin(v.quality, (Quality.FOUND, Quality.SATURATED,
                                                      Quality.SEVERAL_PEAKS))
                & (np.nan_to_num(v.second, nan=-np.inf) >= tol.fraction * v.intensity)
                for name, v in views.items()}
    if not any(e.any() for e in examined.values()):
        return result
    grid, img = result.grid, np.asarray(image)
    thr, sat = result.threshold, result.saturation
    names = list(views)
    # Every examined row's runs (one sampling of the image), then the choice, grown from the
    # unambiguous rows: a row decided joins the reference of the next pass, so a long stretch
    # with two lines is followed from its ends.
    data = {}
    for name in names:
        rows = np.flatnonzero(examined[name])
        vp = plan.views[name]
        local = np.searchsorted(vp.theta_index, rows)
        prof = sample_cubic(img, vp.uv[local], interpolation=vp.interpolation)
        run_row, start, stop, centre, peak, cut = profile_runs(prof, thr)
        base = np.interp(centre, np.arange(grid.n_r), grid.r_mm)
        v = views[name]
        is_main = _main_runs(run_row, peak)
        kept = is_main & (v.quality[rows][run_row] != Quality.SEVERAL_PEAKS)
        data[name] = (rows, local, prof, run_row, start, stop, peak, cut, base,
                      base + grid.r_shift_mm[rows][run_row], kept, is_main)
    radii = np.stack([np.where(v.valid & ~examined[n], v.r_raw_mm, np.nan)
                      for n, v in views.items()])
    chosen = {n: np.full(len(data[n][0]), -2) for n in names}
    for _ in range(_MAX_PASSES):
        grown = False
        for i, name in enumerate(names):
            rows, run_row, cut, run_r, kept = (data[name][i] for i in (0, 3, 7, 9, 10))
            open_ = chosen[name] < 0
            if not open_.any():
                continue
            ref = np.full(len(rows), np.nan)
            ref[open_] = _reference(grid, radii, rows[open_], tol)
            now = choose_run(run_row, run_r, cut, ref, n_rows=len(rows), tol=tol, run_kept=kept)
            now = np.where(open_, now, chosen[name])
            new = open_ & (now >= 0)
            radii[i, rows[new]] = run_r[now[new]]
            chosen[name] = now
            grown |= bool(new.any())
        if not grown:
            break
    new_views = dict(views)
    for name in names:
        v, vp = views[name], plan.views[name]
        rows, local, prof, run_row, start, stop, peak, cut, base, _, _, is_main = data[name]
        if rows.size == 0:
            continue
        new_views[name] = _assembled(v, vp, grid, local, rows, chosen[name], prof, start, stop,
                                     peak, base, is_main, sat, max_plateau_mm, plan, result,
                                     compensate)
    return dataclasses.replace(result, views=new_views)

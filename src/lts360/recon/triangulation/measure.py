"""Measure a scan: images at stage positions → one cloud organised by (θ, section).

Inputs are what a real rig gives: grey images and the stage position of each (read from a
rendered frame's ``frame.json`` ``stage.z_mm`` — the stage encoder's reading — or from a pitch).
Nothing here reads the object or its truth.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lts360.folders import image_file, is_frame, is_scan, read_frame_meta, read_scan
from lts360.recon.images import read_image
from lts360.recon.model import Calibration
from lts360.recon.triangulation.cloud import VIEW_CODES, Cloud
from lts360.recon.triangulation.grid import DEFAULT_R_STEP_MM, DEFAULT_THETA_STEP_DEG, CylGrid
from lts360.recon.triangulation.inverse import (
    InversePlan,
    InverseResult,
    inverse_triangulate,
    plan_inverse,
)
from lts360.recon.triangulation.peaks import Quality

__all__ = ["RowTiming", "Section", "collect_sections", "measure_sections", "measure_sections_following",
           "make_runner", "result_to_cloud", "BandLog"]


@dataclass(frozen=True)
class RowTiming:
    """When each image row of a frame was exposed, from the line's acquisition settings and
    the trigger log (what a real line records; never the object's truth).

    ``t_trigger_s``: the frame's trigger; ``exposure_s``; ``line_time_s`` (0: global shutter);
    ``speed_mm_s``: the feed the encoder reports.  Row ``y`` is exposed around
    ``t = t_trigger + y · line_time + exposure / 2``, and the laser plane then cuts the
    object at ``z_trigger − speed · (t − t_trigger)``.
    """

    t_trigger_s: float
    exposure_s: float
    line_time_s: float = 0.0
    speed_mm_s: float = 0.0

    @staticmethod
    def from_motion(motion: dict | None) -> "RowTiming | None":
        """From a frame's ``motion`` record (``frame.json``): its ``acquisition`` and
        ``t_trigger_s`` only."""
        if not motion:
            return None
        acq = motion["acquisition"]
        sh = acq.get("shutter", {})
        return RowTiming(float(motion.get("t_trigger_s", 0.0)), float(acq["exposure_time_s"]),
                         float(sh.get("line_time_s", 0.0)) if sh.get("kind") == "rolling" else 0.0,
                         float(acq.get("motion", {}).get("speed_mm_s", 0.0)))

    def row_time_s(self, rows) -> np.ndarray:
        return self.t_trigger_s + np.asarray(rows, float) * self.line_time_s + 0.5 * self.exposure_s


@dataclass(frozen=True)
class Section:
    """One image of a scan, the stage position it was taken at and, for a moving object, the
    timing of its rows."""

    image_path: Path
    z_mm: float
    timing: RowTiming | None = None
    image: np.ndarray | None = None  # the image itself, when it is not read from image_path

    def read(self) -> np.ndarray:
        return read_image(self.image_path) if self.image is None else self.image


def collect_sections(inputs, *, pitch_mm: float | None = None) -> list[Section]:
    """Sections from frame directories, scan directories (``scan.json``) or image files.

    Frame directories give their own stage position; bare images are placed at
    ``k · pitch_mm`` in the order given.
    """
    out: list[Section] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir() and is_scan(p):
            scan = read_scan(p)
            for s in scan["sections"]:
                timing = None
                if "t_trigger_s" in s and "acquisition" in scan:
                    timing = RowTiming.from_motion({"acquisition": scan["acquisition"],
                                                    "t_trigger_s": s["t_trigger_s"]})
                out.append(Section(image_file(p / s["dir"]), float(s["z_mm"]), timing))
        elif p.is_dir() and image_file(p).is_file():
            z, timing = 0.0, None
            if is_frame(p):
                meta = read_frame_meta(p)
                z = float(meta.get("stage", {}).get("z_mm", 0.0))
                timing = RowTiming.from_motion(meta.get("motion"))
                if timing is not None:  # the section's height at the trigger
                    z -= timing.speed_mm_s * timing.t_trigger_s
            out.append(Section(image_file(p), z, timing))
        elif p.is_file():
            if pitch_mm is None:
                raise ValueError(f"{p}: a bare image needs --pitch-mm to place it on the stage")
            out.append(Section(p, len(out) * float(pitch_mm)))
        else:
            raise ValueError(f"{p}: neither a frame directory, a scan directory nor an image file")
    if not out:
        raise ValueError("no images to measure")
    return out


def result_to_cloud(result: InverseResult, *, z_mm: float, section: int,
                    timing: RowTiming | None = None, cal: Calibration | None = None) -> Cloud:
    """Every θ of every view (valid or not, with its quality) as cloud rows.

    ``timing`` (a moving object; needs ``cal``): each point gets the time of its own image
    row's exposure (the row where its view images it) and ``z`` the section's height then
    (``z_mm`` at the trigger); a θ without a point gets NaN."""
    from lts360.recon.triangulation.views import get_views, project_meas_points

    parts = []
    for name, v in result.views.items():
        m = v.window
        n = int(m.sum())
        r = v.r_mm[m]
        th = v.theta_rad[m]
        z = np.full(n, float(z_mm))
        times = None
        if timing is not None:
            if cal is None:
                raise ValueError("result_to_cloud: timing needs the calibration")
            xyz = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(n)])
            (view,) = get_views(cal, [name])
            times = timing.row_time_s(project_meas_points(xyz, cal, view)[:, 1])
            z = np.where(np.isfinite(times), z - timing.speed_mm_s * (times - timing.t_trigger_s), z)
        pts = np.column_stack([r * np.cos(th), r * np.sin(th), z])
        code = VIEW_CODES.get(name, 255)
        intensity = np.nan_to_num(v.intensity[m]).astype(np.float32)
        quality = v.quality[m].astype(np.uint8)
        parts.append(Cloud(pts, th, r, np.full(n, code, np.uint8), quality,
                           np.full(n, section, np.int32), intensity, time_s=times))
    return Cloud.concatenate(parts)


def classic_to_cloud(res: dict, *, z_mm: float, section: int) -> Cloud:
    """Points of :func:`lts360.recon.triangulation.classic.classic_triangulate` as cloud rows."""
    parts = []
    for name, v in res.items():
        n = len(v["r_mm"])
        pts = np.column_stack([v["points_meas_mm"][:, :2], np.full(n, float(z_mm))])
        parts.append(Cloud(pts, v["theta_rad"], v["r_mm"], np.full(n, VIEW_CODES.get(name, 255), np.uint8),
                           np.zeros(n, np.uint8), np.full(n, section, np.int32),
                           v["intensity"].astype(np.float32)))
    return Cloud.concatenate(parts)


class _Rejecting:
    """``image -> InverseResult`` with one section's truth-free rejections
    (:func:`lts360.recon.triangulation.reject.reject_spurious`, then the continuity test);
    ``last_raw`` keeps the last result as measured, for the scan's own pass
    (:func:`_reject_scan`)."""

    def __init__(self, measure, continuity_k: float | None, hidden: dict | None = None,
                 plan: InversePlan | None = None, compensate: bool = False):
        self.measure = measure
        self.continuity_k = continuity_k
        self.hidden = hidden
        self.plan = plan
        self.compensate = compensate
        self.last_raw = None

    def __call__(self, img):
        from lts360.recon.triangulation.reject import (
            mark_hidden,
            reject_discontinuous,
            reject_spurious,
        )

        raw = self.measure(img)
        if self.plan is not None:  # a second line along the radius: choose, or say so
            from lts360.recon.triangulation.multipeak import choose_peaks

            raw = choose_peaks(raw, img, self.plan, compensate=self.compensate)
        self.last_raw = raw if not self.hidden else mark_hidden(raw, self.hidden)
        res = reject_spurious(self.last_raw)
        k = self.continuity_k
        return res if k is None else reject_discontinuous(res, k=k)


def _reject_scan(done: list, raws: list, continuity_k: float | None, frames=None) -> list:
    """The sections' results rejected again as a scan (each with its neighbours' axial slope,
    :func:`lts360.recon.triangulation.reject.reject_scan`) when every section kept its raw
    result and there are several; else ``done``'s results as they are."""
    results = [d[2] for d in done]
    if len(done) < 2 or any(r is None for r in raws):
        return results
    from lts360.recon.triangulation.reject import reject_scan

    return reject_scan(raws, [d[1].z_mm for d in done], frames=frames,
                       continuity_k=continuity_k)


def make_runner(cal: Calibration, *, peak: str = "centroid", backend: str = "auto",
                compensate: bool = False, continuity_k: float | None = None,
                reject: bool = False, hidden: dict | None = None, multipeak: bool = True):
    """A function ``plan -> (image -> InverseResult)`` on the chosen backend.

    ``backend``: ``numpy`` (the reference), ``llvm`` or ``cuda`` (the Dr.Jit kernel of the
    centroid detector, :class:`lts360.recon.triangulation.fast.FastInverse`), or ``auto`` (Dr.Jit LLVM for
    the centroid when available, numpy otherwise).  The plan is built without samplers
    (``precompute=False``); the numpy path adds them.  ``continuity_k``: flag points off
    their view's local r(θ) by more than k·σ
    (:func:`lts360.recon.triangulation.reject.reject_discontinuous`; ``None``: off).
    ``reject``: flag fading points and points in notches
    (:func:`lts360.recon.triangulation.reject.reject_spurious`), before the continuity test;
    ``hidden`` (view → (nθ,) bool, with ``reject``): rows the first-pass profile hides from the
    view, flagged ``HIDDEN`` first (:func:`lts360.recon.triangulation.reject.mark_hidden`).
    ``multipeak`` (with ``reject``): where a second line along the radius reaches a fifth of
    the main one, choose the one the section's other rows agree with, or call the row
    ``SEVERAL_PEAKS`` (:func:`lts360.recon.triangulation.multipeak.choose_peaks`), first.
    """
    if reject:
        from lts360.recon.triangulation.reject import reject_discontinuous

        if continuity_k is not None and not continuity_k > 0:
            raise ValueError(f"continuity_k must be > 0, got {continuity_k}")
        inner = make_runner(cal, peak=peak, backend=backend, compensate=compensate)

        return lambda plan: _Rejecting(inner(plan), continuity_k, hidden,
                                       plan=plan if multipeak else None, compensate=compensate)
    if continuity_k is not None:
        from lts360.recon.triangulation.reject import reject_discontinuous

        if not continuity_k > 0:
            raise ValueError(f"continuity_k must be > 0, got {continuity_k}")
        inner = make_runner(cal, peak=peak, backend=backend, compensate=compensate)
        return lambda plan: (lambda m: (lambda img: reject_discontinuous(m(img),
                                                                         k=continuity_k)))(
            inner(plan))
    if backend not in ("auto", "numpy", "llvm", "cuda"):
        raise ValueError(f"backend must be auto, numpy, llvm or cuda, got {backend!r}")
    use_fast = peak == "centroid" and backend != "numpy"
    if backend in ("llvm", "cuda") and peak != "centroid":
        raise ValueError(f"the Dr.Jit backend implements the centroid detector only, not {peak!r}")

    def numpy_runner(plan: InversePlan):
        if plan.views and next(iter(plan.views.values())).sampler is None:
            plan = plan_inverse(plan.cal, plan.grid, windows={n: vp.window for n, vp in
                                                              plan.views.items()},
                                views=tuple(plan.views), precompute=True,
                                interpolation=plan.interpolation)
        return lambda img: inverse_triangulate(img, cal, plan.grid, peak=peak,
                                               compensate=compensate, plan=plan)

    def runner(plan: InversePlan):
        if use_fast:
            from lts360.recon.triangulation.fast import FastInverse

            try:
                fast = FastInverse(plan, backend="llvm" if backend == "auto" else backend)
            except RuntimeError:
                if backend != "auto":
                    raise
            else:
                return lambda img: fast(img, compensate=compensate)
        return numpy_runner(plan)

    return runner


def measure_sections(sections: list[Section], cal: Calibration, grid: CylGrid, *,
                     peak: str = "centroid", compensate: bool = False, backend: str = "auto",
                     method: str = "inverse", progress=None,
                     continuity_k: float | None = None, reject: bool = False,
                     correct=None, multipeak: bool = True) -> Cloud:
    """Inverse triangulation of every section with one plan (a band given by the user).

    ``backend``, ``multipeak``: see :func:`make_runner`.  ``correct``: see :func:`measure_sections_following`.
    """
    if method == "classic":
        from lts360.recon.triangulation.classic import classic_triangulate, view_regions

        regions = view_regions(cal, grid)
        items = list(enumerate(sections))
        return Cloud.concatenate([
            classic_to_cloud(classic_triangulate(s.read(), cal, grid, regions=regions),
                             z_mm=s.z_mm, section=k)
            for k, s in (progress(items) if progress else items)])
    if method != "inverse":
        raise ValueError(f"method must be 'inverse' or 'classic', got {method!r}")
    plan = plan_inverse(cal, grid, precompute=False)
    measure = make_runner(cal, peak=peak, backend=backend, compensate=compensate,
                          continuity_k=continuity_k, reject=reject, multipeak=multipeak)(plan)
    done, raws = [], []
    items = list(enumerate(sections))
    for k, s in (progress(items) if progress else items):
        res = measure(s.read())
        done.append((k, s, res))
        raws.append(getattr(measure, "last_raw", None))
    results = _reject_scan(done, raws, continuity_k)
    fixed = _correct_all(correct, [(res, measure, plan, s.z_mm, (0.0, 0.0))
                                   for (_, s, _), res in zip(done, results)])
    clouds = [result_to_cloud(res, z_mm=s.z_mm, section=k, timing=s.timing, cal=cal)
              for (k, s, _), res in zip(done, fixed)]
    return Cloud.concatenate(clouds)


def _observe(correct, res, z_mm: float, centre) -> None:
    """Show a section to a correction that looks at the whole scan first (``correct.observe``:
    the twin's form along the axis); every section is observed before any is corrected."""
    observe = getattr(correct, "observe", None)
    if observe is not None:
        observe(res, z_mm=z_mm, origin_mm=centre)


def _correct_all(correct, items: list) -> list:
    """Each ``(result, measure, plan, z_mm, centre)`` corrected by ``correct`` (or as it is),
    every section observed first (:func:`_observe`).

    A correction with ``passes() > 1`` (the twin shaped along the axis by its neighbours'
    profiles, which carry the very bias it removes) is run again with the scan observed as
    corrected (``correct.restart()``), each pass on the results as measured."""
    if correct is None:
        return [it[0] for it in items]
    for res, _, _, z, centre in items:
        _observe(correct, res, z, centre)
    out = [correct(res, measure, plan) for res, measure, plan, _, _ in items]
    passes = getattr(correct, "passes", None)
    for _ in range(1, passes() if passes is not None else 1):
        correct.restart()
        for fixed, (_, _, _, z, centre) in zip(out, items):
            _observe(correct, fixed, z, centre)
        out = [correct(res, measure, plan) for res, measure, plan, _, _ in items]
    return out


#: A band still holds the next section when at most this share of its windowed θ is TRUNCATED
#: and it keeps this share of the valid points it had when it was found.
BAND_MAX_TRUNCATED = 0.02
BAND_MIN_KEPT = 0.8


@dataclass
class BandLog:
    """What the band search did over a scan.

    Attributes
    ----------
    coarse : str
        The coarse search in words (:meth:`BandSearch.describe`).
    half_width_mm : float
    searched : list of int
        Sections whose band was found by a coarse pass (the others reused the previous band).
    found : list of bool
        Per section: whether a profile was found (``False``: no stripe in the coarse pass).
    r_range_mm : list of (float, float)
        Per section: the radii its fine band spanned (about its grid's centre).
    centre_mm : list of (float, float)
        Per section: the centre of its polar grid in the measurement frame ((0, 0): the axis;
        otherwise the section was re-centred, see :data:`RECENTRE_MAX_INCIDENCE_DEG`).
    coarse_s, plan_s, fine_s : float
        Seconds in coarse passes, in planning fine bands, in fine measurements.
    """

    coarse: str
    half_width_mm: float
    searched: list = field(default_factory=list)
    found: list = field(default_factory=list)
    r_range_mm: list = field(default_factory=list)
    centre_mm: list = field(default_factory=list)
    coarse_s: float = 0.0
    plan_s: float = 0.0
    fine_s: float = 0.0

    def describe(self) -> str:
        lo = min((a for a, _ in self.r_range_mm), default=float("nan"))
        hi = max((b for _, b in self.r_range_mm), default=float("nan"))
        moved = [c for c in self.centre_mm if c != (0.0, 0.0)]
        centred = (f"; {len(moved)} section(s) measured about the section's own centre, "
                   f"up to {max(math.hypot(*c) for c in moved):.2f} mm off the axis"
                   if moved else "")
        return (f"band found from the image ({self.coarse}; fine band ±{self.half_width_mm:g} mm "
                f"about the profile, r = {lo:.3f}–{hi:.3f} mm{centred})")


#: A section is measured about its own centre (the calibration's origin moved there, the polar
#: grid with it) when the grid's rays would meet its found profile more obliquely than this
#: about the axis: a circle of radius R whose centre is e off the axis is met at up to
#: asin(e / R).  Past ~30° the stripe crosses the rays obliquely and its centre along them is
#: biased; at e ≥ R the axis leaves the section and rays miss it.
RECENTRE_MAX_INCIDENCE_DEG = 20.0


def recentre_point(profile, *, max_incidence_deg: float = RECENTRE_MAX_INCIDENCE_DEG
                   ) -> tuple[float, float]:
    """Where to centre the polar grid for a first-pass ``profile``: ``(0, 0)`` (the axis) when
    its least-squares circle's centre ``e`` is within ``R · sin(max_incidence)`` of the axis,
    else that centre (rounded to 10 µm, so that sections alike share a plan)."""
    from lts360.geometry.fit import fit_circle

    m = np.asarray(profile.measured, bool)
    if m.sum() < 10:
        return (0.0, 0.0)
    th, r = profile.theta_rad[m], profile.r_mm[m]
    fit = fit_circle(np.column_stack([r * np.cos(th), r * np.sin(th)]))
    e = float(np.hypot(*fit.center_mm))
    if not np.isfinite(e) or e <= fit.radius_mm * math.sin(math.radians(max_incidence_deg)):
        return (0.0, 0.0)
    cx, cy = (round(float(v), 2) for v in fit.center_mm)
    return (cx + 0.0, cy + 0.0)


@dataclass
class _Band:
    grid: CylGrid
    measure: object
    n_valid: int
    plan: InversePlan
    centre: tuple


def _about_axis(cloud: Cloud, res: InverseResult, centre) -> Cloud:
    """A cloud measured about ``centre`` moved back into the measurement frame: points
    translated, ``θ`` and ``r`` about the axis again (a row without a point gets the θ of its
    band's middle)."""
    c = np.array([centre[0], centre[1]], dtype=float)
    grid = res.grid
    k = np.rint((cloud.theta_rad - grid.theta_rad[0]) / grid.theta_step_rad).astype(np.int64)
    k = np.clip(np.mod(k, grid.n_theta) if grid.is_full_turn else k, 0, grid.n_theta - 1)
    mid = grid.r_mm[grid.n_r // 2] + grid.r_shift_mm[k]
    rr = np.where(np.isfinite(cloud.radius_mm), cloud.radius_mm, mid)
    xy = c + rr[:, None] * np.column_stack([np.cos(cloud.theta_rad), np.sin(cloud.theta_rad)])
    pts = np.array(cloud.points_mm)
    ok = np.all(np.isfinite(pts), axis=1)
    pts[ok, :2] = xy[ok]
    theta = np.arctan2(xy[:, 1], xy[:, 0])
    radius = np.where(ok, np.hypot(xy[:, 0], xy[:, 1]), np.nan)
    return dataclasses.replace(cloud, points_mm=pts, theta_rad=theta, radius_mm=radius)


def _band_holds(res: InverseResult, n_valid_then: int) -> bool:
    rows = sum(int(v.window.sum()) for v in res.views.values())
    cut = sum(int(np.sum(v.quality == Quality.TRUNCATED)) for v in res.views.values())
    valid = sum(int(v.valid.sum()) for v in res.views.values())
    return rows > 0 and cut <= BAND_MAX_TRUNCATED * rows and valid >= BAND_MIN_KEPT * n_valid_then


def measure_sections_following(sections: list[Section], cal: Calibration, *,
                               theta_step_deg: float = DEFAULT_THETA_STEP_DEG,
                               r_step_mm: float = DEFAULT_R_STEP_MM,
                               half_width_mm: float | None = None, peak: str = "centroid",
                               compensate: bool = False, backend: str = "auto",
                               progress=None, continuity_k: float | None = None,
                               reject: bool = False, correct=None,
                               multipeak: bool = True) -> tuple[Cloud, CylGrid, BandLog]:
    """Inverse triangulation with the radial band found from the image.

    The first section runs the coarse pass (:class:`lts360.recon.triangulation.band.BandSearch`) and
    measures a fine band that follows its profile; each next section reuses that band while it
    holds (at most :data:`BAND_MAX_TRUNCATED` of its θ truncated, at least
    :data:`BAND_MIN_KEPT` of the valid points kept), and otherwise runs the coarse pass again.
    A section where the coarse pass finds no stripe is measured on the last band (or, for the
    first, on a band about the middle of the measurable radii), so that its rows say what was
    searched.

    ``multipeak``: see :func:`make_runner`.  ``correct``: an optional ``(result, measure,
    plan) -> result`` applied to each section's result, given the measuring function and plan
    that made it (a model-based line-centre bias correction, :mod:`lts360.twin`, measures its
    own synthetic image with the same plan).  If it has ``observe(result, z_mm=, origin_mm=)``,
    every section is shown to it (in order, ``origin_mm`` the centre it was measured about)
    before the first is corrected.

    Returns
    -------
    cloud : Cloud
    grid : CylGrid
        The last fine grid (every fine grid has the same θ).
    log : BandLog
    """
    import time

    from lts360.recon.model import shift_origin
    from lts360.recon.triangulation.band import (
        DEFAULT_FOLLOW_HALF_WIDTH_MM,
        BandSearch,
        Profile,
        hidden_rows,
        profile_windows,
    )

    w = DEFAULT_FOLLOW_HALF_WIDTH_MM if half_width_mm is None else float(half_width_mm)
    if not w > 0:
        raise ValueError(f"half_width_mm must be > 0, got {half_width_mm}")
    kw = dict(peak=peak, backend=backend, compensate=compensate, continuity_k=continuity_k,
              reject=reject, multipeak=multipeak)
    t0 = time.perf_counter()
    search = BandSearch(cal, make_runner(cal, peak=peak, backend=backend))
    log = BandLog(coarse=search.describe(), half_width_mm=w, plan_s=time.perf_counter() - t0)
    searches = {(0.0, 0.0): search}  # one coarse search per polar centre

    def search_at(centre):
        if centre not in searches:
            t = time.perf_counter()
            c_cal = shift_origin(cal, centre)
            searches[centre] = BandSearch(c_cal, make_runner(c_cal, peak=peak, backend=backend))
            log.plan_s += time.perf_counter() - t
        return searches[centre]

    current = None  # _Band: grid, measure, n_valid when found, plan, centre
    clouds, done, raws = [], [], []
    items = list(enumerate(sections))
    for k, s in (progress(items) if progress else items):
        img = s.read()
        res = None
        if current is not None:
            t = time.perf_counter()
            res = current.measure(img)
            log.fine_s += time.perf_counter() - t
            if not _band_holds(res, current.n_valid):
                res = None
        if res is None:
            t = time.perf_counter()
            profile = search.profile(img)
            centre = (0.0, 0.0)
            if profile is not None:
                centre = recentre_point(profile)
                if centre != (0.0, 0.0):
                    profile = search_at(centre).profile(img)
                    if profile is None:  # lost about the centre: keep the axis
                        centre, profile = (0.0, 0.0), search.profile(img)
            log.coarse_s += time.perf_counter() - t
            log.searched.append(k)
            log.found.append(profile is not None)
            if profile is None and current is None:
                mid = 0.5 * sum(search.r_range_mm)
                th = search.grid.theta_rad
                profile = Profile(th, np.full(th.size, mid), np.zeros(th.size, bool), True)
            if profile is not None:
                t = time.perf_counter()
                srch = search_at(centre)
                grid = srch.fine_grid(profile, theta_step_deg=theta_step_deg,
                                      r_step_mm=r_step_mm, half_width_mm=w)
                windows = profile_windows(srch.cal, grid, profile)
                plan = plan_inverse(srch.cal, grid, precompute=False, windows=windows)
                hidden = hidden_rows(srch.cal, grid, profile, windows) if reject else None
                measure = make_runner(srch.cal, **kw, hidden=hidden)(plan)
                log.plan_s += time.perf_counter() - t
                current = _Band(grid, measure, 0, plan, centre)
            t = time.perf_counter()
            res = current.measure(img)
            log.fine_s += time.perf_counter() - t
            current.n_valid = sum(int(v.valid.sum()) for v in res.views.values())
        else:
            log.found.append(True)
        log.r_range_mm.append(current.grid.r_range_mm)
        log.centre_mm.append(current.centre)
        done.append((k, s, res, current))
        raws.append(getattr(current.measure, "last_raw", None))
    results = _reject_scan(done, raws, continuity_k, frames=[d[3].centre for d in done])
    fixed = _correct_all(correct, [(res, band.measure, band.plan, s.z_mm, band.centre)
                                   for (_, s, _, band), res in zip(done, results)])
    for (k, s, _, band), res in zip(done, fixed):
        cloud = result_to_cloud(res, z_mm=s.z_mm, section=k, timing=s.timing,
                                cal=band.plan.cal)
        clouds.append(cloud if band.centre == (0.0, 0.0)
                      else _about_axis(cloud, res, band.centre))
    return Cloud.concatenate(clouds), current.grid, log

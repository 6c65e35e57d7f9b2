"""``lts360 study design-space``: the rig's design angles α and β swept over a grid (issue 6).

Every rig of the grid is the paper preset (``presets/paper.toml``) with only
``design.alpha_deg`` (triangulation angle between the laser plane and the camera axis) and
``design.beta_deg`` (angle between the mirrors) changed; everything else — distances, mirror
size, camera, focus, laser, sensor — stays as the preset has it.  One trial is one rig.  A
combination that the rig validation rejects (:class:`~lts360.scenes.rig.RigError`, e.g.
β < 60°) is not an error of the study: its trial records NaN metrics and ``status = 1``.

Metrics of a trial
------------------
Geometry (no rendering; :func:`lts360.scenes.coverage.coverage` of a Ø20 mm section,
``radius_mm = 10``, θ step 0.1°, light paths with up to two mirror reflections):

``coverage_deg``
    Angle of the section measured (seen and lit) in at least one view, double reflections
    included — ``CoverageResult.coverage_deg``.
``coverage_single_deg``
    The same for the views the reconstruction uses: direct and single mirror views.
``overlap_direct_left_deg``, ``overlap_direct_right_deg``, ``overlap_mirror_mirror_deg``
    Angle measured by both views of the pair (``CoverageResult.overlap_deg``);
    ``overlap_direct_mirror_deg`` is the smaller of the two direct/mirror overlaps.
``image_margin_px``
    Smallest distance of a measured point's image from the image border
    (``CoverageResult.image_margin_px``).
``multi_reflection_pct``
    Share of the 360° (in %) at which a point measured by a single view (direct, left or
    right) is *also* measured — seen and lit — through a double reflection (``left-right`` or
    ``right-left``): the frame then holds a second stripe image of that very point, which the
    reconstruction does not use and which may fall into a search band.
``ghost_in_band_pct``
    Share of the 360° (in %) at which, in at least one single view that measures the point,
    the image of the radial search segment (``r ± BAND_MM``) passes within
    :data:`GHOST_TOLERANCE_PX` of a double-reflection stripe image (of any point): the
    inverse triangulation's profile there sees a second line.
``multi_lit_pct``
    Share of the 360° (in %) measured by a single view and reached by the laser along more
    than one path (directly and via a mirror, ...).  Informative only, not a disturbance here:
    the mirrors are parallel to the object axis, so every laser path stays in the sheet plane
    and lights the same curve (the stripe is brighter, not displaced).

Monte Carlo radius uncertainty (``draws = M > 0``): the plug gauge (``build_object
("plug-gauge")``, Ø19.9987 mm, on the axis) is rendered once per rig without noise
(``simulate_frame(noise="none", thin_lens=True)``); then the sensor noise and the speckle
are drawn ``M`` times on that stored radiance (:func:`~lts360.simulator.frame.sensor_image`,
``noise="realistic"``: EMVA 1288 temporal noise and a new speckle pattern per draw, the same
fixed-pattern noise — the same camera — in all) and each image is measured by inverse
triangulation (centroid, Keys; the direct and the single mirror views) with the frame's true
calibration on the grid θ step :data:`THETA_STEP_DEG`, r step :data:`R_STEP_MM`, band
``±BAND_MM`` about the true radius, and a circle is fitted to all valid points:

``radius_error_mm`` (draw)
    Fitted minus true radius, per draw (NaN where fewer than :data:`MIN_POINTS` points).
``radius_std_mm``
    Standard deviation (ddof = 1) of the fitted radius over the draws: **the radius
    uncertainty** of the rig (noise and speckle only; the calibration is exact).
``radius_mean_error_mm``
    Mean of ``radius_error_mm``: the bias left by the optics and the sheet.
``point_rms_mm``
    RMS over all points of all draws of (distance from the true axis − true radius).
``measured_coverage_deg``, ``n_points``
    Mean over the draws of the angle with at least one valid view and of the point count.
``n_failed_draws``
    Draws with fewer than :data:`MIN_POINTS` valid points.

``status`` is 0 (ok), 1 (invalid rig: NaN everywhere) or 2 (rendered, but no draw gave a
measurement); :func:`rig_status` gives the message.  ``seconds_render`` and
``seconds_trial`` are wall times.

The optimum (:data:`OPTIMUM_CRITERION`): among the valid rigs with full single-view
coverage, both overlaps at least ``min_overlap_deg`` and no multiple-reflection share, the
one with the smallest ``radius_std_mm``.  With ``M`` draws the standard deviation itself
is uncertain by about ``1/√(2(M−1))`` (27 % for M = 8): neighbours within that are ties.
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import json
import math
import os
import platform
import re
import time
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from lts360.experiments.runner import (Trial, TrialOutput, grid_params, plan_trials, run_study,
                                       to_grid, trial_path)
from lts360.scenes.coverage import CoverageResult, coverage, mirror_sequences, view_name
from lts360.scenes.rig import Rig, RigError

__all__ = ["parse_range", "design_rig", "rig_status", "geometry_metrics", "design_space_trial",
           "run_design_space_study", "format_design_space", "OptimumCriterion",
           "OPTIMUM_CRITERION", "PAPER_DESIGN", "STATUS", "SECTION_RADIUS_MM", "THETA_STEP_DEG",
           "R_STEP_MM", "BAND_MM", "MIN_POINTS", "GHOST_TOLERANCE_PX", "GAUGE_SPEC"]

#: (alpha_deg, beta_deg) of the paper's rig, marked in the figures.
PAPER_DESIGN = (40.0, 90.0)
#: Radius of the section of the geometry metrics (a Ø20 mm part).
SECTION_RADIUS_MM = 10.0
#: θ step of the geometry metrics (coverage()'s default).
COVERAGE_STEP_DEG = 0.1
#: Object of the Monte Carlo measurement.
GAUGE_SPEC = "plug-gauge"
#: Inverse-triangulation grid of the Monte Carlo measurement: a modest grid (1440 θ × 401 r).
#: The θ step does not matter for the circle fit: paper rig, 24 draws (2026-11-23), radius std
#: 1.54 µm at 0.1°, 0.25° and 0.5° alike (draw-by-draw correlation 0.9998 at 0.1° / 0.25°).
THETA_STEP_DEG = 0.25
R_STEP_MM = 0.005
#: Half-width of the radial search band about the true radius (mm); also the segment of
#: ``ghost_in_band_pct``.
BAND_MM = 1.0
#: Fewest valid points for a circle fit of one draw.
MIN_POINTS = 10
#: A double-reflection stripe image closer than this to a search segment disturbs it: the
#: stripe is ~1 px σ wide, and the centroid integrates the run above a 10 % threshold, ±2σ.
GHOST_TOLERANCE_PX = 3.0
#: Samples along a search segment for ``ghost_in_band_pct`` (< 0.5 px apart for ±1 mm).
_SEGMENT_SAMPLES = 41
#: Values of ``status``.
STATUS = {0: "ok", 1: "invalid rig", 2: "no measurement"}
#: Trial settings recorded in every trial's params (so the plan covers them).
_DEFAULTS = {"draws": 8, "spp": 16, "scale": 1.0}
#: Largest number of values :func:`parse_range` returns.
MAX_RANGE_VALUES = 10_000

_SCALAR_METRICS = ("coverage_deg", "coverage_single_deg", "overlap_direct_left_deg",
                   "overlap_direct_right_deg", "overlap_direct_mirror_deg",
                   "overlap_mirror_mirror_deg", "image_margin_px", "multi_reflection_pct",
                   "ghost_in_band_pct", "multi_lit_pct", "radius_std_mm", "radius_mean_error_mm",
                   "point_rms_mm", "measured_coverage_deg", "n_points", "n_failed_draws",
                   "exposure_time_s", "seconds_render", "seconds_trial")


@dataclasses.dataclass(frozen=True)
class OptimumCriterion:
    """Which rigs qualify for the optimum; the optimum is the qualifying rig with the smallest
    ``radius_std_mm``.

    Attributes
    ----------
    min_coverage_deg : float
        Least ``coverage_single_deg`` (360° less one θ step of the coverage grid: rounding).
    min_overlap_deg : float, >=0
        Least direct/mirror and mirror/mirror overlap: enough common points to register the
        views (the paper's rig has 37.6° and 7.7°).
    max_multi_reflection_pct : float, >=0
        Largest ``multi_reflection_pct``.
    """

    min_coverage_deg: float = 360.0 - COVERAGE_STEP_DEG
    min_overlap_deg: float = 5.0
    max_multi_reflection_pct: float = 0.0

    def describe(self) -> str:
        return (f"single-view coverage ≥ {self.min_coverage_deg:g}°, direct/mirror and "
                f"mirror/mirror overlap ≥ {self.min_overlap_deg:g}°, multiple-reflection share "
                f"≤ {self.max_multi_reflection_pct:g} %; among those the smallest radius "
                "standard deviation")


OPTIMUM_CRITERION = OptimumCriterion()


# --- ranges -------------------------------------------------------------------------------------

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"


def parse_range(text: str) -> np.ndarray:
    """Values of a ``START:STOP:STEP`` range, the end included, or of a single value.

    ``"20:70:5"`` → ``[20, 25, …, 70]``; ``"40"`` → ``[40]``.  The values are
    ``START + k·STEP`` up to STOP (inclusive, within 1e-9 of a step): ``"20:70:7"`` ends at 69.

    Parameters
    ----------
    text : str
        ``START:STOP:STEP`` with ``STEP > 0`` and ``STOP >= START``, or one number.

    Returns
    -------
    (n,) float

    Raises
    ------
    ValueError
        Anything else; the message quotes the text.
    """
    if not isinstance(text, str):
        raise ValueError(f"range: expected a string START:STOP:STEP or a single number, "
                         f"got {text!r}")
    parts = [p.strip() for p in text.strip().split(":")]
    if len(parts) not in (1, 3) or not all(re.fullmatch(_NUMBER, p) for p in parts):
        raise ValueError(f"range {text!r}: expected START:STOP:STEP (e.g. 20:70:5) or a single "
                         "number (e.g. 40)")
    values = [float(p) for p in parts]
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"range {text!r}: values must be finite")
    if len(values) == 1:
        return np.array(values)
    start, stop, step = values
    if not step > 0:
        raise ValueError(f"range {text!r}: STEP must be > 0, got {step:g}")
    if stop < start:
        raise ValueError(f"range {text!r}: STOP ({stop:g}) must be >= START ({start:g})")
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    if n > MAX_RANGE_VALUES:
        raise ValueError(f"range {text!r}: {n} values, more than {MAX_RANGE_VALUES}")
    return np.round(start + step * np.arange(n), 10)


def _range_text(values) -> str:
    """The ``parse_range`` text of a sorted axis (a comma list if it is not uniform)."""
    v = [float(x) for x in values]
    if len(v) == 1:
        return f"{v[0]:g}"
    steps = np.diff(v)
    if np.allclose(steps, steps[0], rtol=0, atol=1e-9 * max(1.0, abs(steps[0]))):
        return f"{v[0]:g}:{v[-1]:g}:{steps[0]:g}"
    return ",".join(f"{x:g}" for x in v)


def _axis(name: str, values) -> list[float]:
    arr = parse_range(values) if isinstance(values, str) else np.asarray(values, dtype=float)
    if arr.ndim != 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be a range text or a non-empty 1-D sequence of finite "
                         f"numbers, got {values!r}")
    if len(np.unique(arr)) != arr.size:
        raise ValueError(f"{name}: values must be unique, got {arr.tolist()}")
    return [float(v) for v in np.sort(arr)]


# --- the rigs -----------------------------------------------------------------------------------

def _preset_dict() -> dict:
    text = resources.files("lts360.scenes").joinpath("presets", "paper.toml").read_text()
    return tomllib.loads(text)


def design_rig(alpha_deg: float, beta_deg: float) -> Rig:
    """The paper preset with ``design.alpha_deg`` and ``design.beta_deg`` replaced.

    Raises
    ------
    RigError
        The combination is not a valid rig (the message names the field).
    """
    from lts360.scenes.rig_io import rig_from_dict

    data = copy.deepcopy(_preset_dict())
    data["design"]["alpha_deg"] = float(alpha_deg)
    data["design"]["beta_deg"] = float(beta_deg)
    data["name"] = f"paper-a{float(alpha_deg):g}-b{float(beta_deg):g}"
    return rig_from_dict(data)


def rig_status(alpha_deg: float, beta_deg: float) -> str:
    """``"ok"``, or ``"invalid rig: <RigError message>"``."""
    try:
        design_rig(alpha_deg, beta_deg)
    except RigError as exc:
        return f"{STATUS[1]}: {exc}"
    return STATUS[0]


# --- geometry -----------------------------------------------------------------------------------

def _view_transform(rig: Rig, seq: tuple[int, ...]) -> np.ndarray:
    """Object → m1 → m2 → camera: the camera sees ``T_m2 · T_m1 · X`` (as coverage() does)."""
    T = np.eye(4)
    for k in seq:
        T = rig.mirrors[k].T @ T
    return T


def _ghost_in_band(rig: Rig, cov: CoverageResult, singles: list[tuple[int, ...]],
                   doubles: list[tuple[int, ...]], band_mm: float) -> np.ndarray:
    """(nθ,) bool: a single view measuring θ has a double-reflection stripe image within
    :data:`GHOST_TOLERANCE_PX` of the image of its search segment ``r ± band_mm``."""
    from lts360.geometry.camera import project_points

    n = len(cov.theta_rad)
    names = [view_name(s, rig.mirrors) for s in doubles]
    ghosts = [cov.image_uv[v][cov.measured[v]] for v in names]
    ghosts = np.concatenate(ghosts) if ghosts else np.zeros((0, 2))
    ghosts = ghosts[np.all(np.isfinite(ghosts), axis=1)]
    disturbed = np.zeros(n, dtype=bool)
    if len(ghosts) == 0:
        return disturbed
    tree = cKDTree(ghosts)
    cam = rig.camera
    radii = cov.radius_mm + np.linspace(-band_mm, band_mm, _SEGMENT_SAMPLES)
    for seq in singles:
        mask = cov.measured[view_name(seq, rig.mirrors)]
        if not mask.any():
            continue
        th = cov.theta_rad[mask]
        pts = np.stack([np.cos(th)[:, None] * radii, np.sin(th)[:, None] * radii,
                        np.zeros((len(th), len(radii)))], -1).reshape(-1, 3)
        uv = project_points(pts, cam.K, cam.distortion, cam.R, cam.t_mm,
                            T_mirror=_view_transform(rig, seq))
        ok = np.all(np.isfinite(uv), axis=1)
        dist = np.full(len(uv), np.inf)
        dist[ok], _ = tree.query(uv[ok], distance_upper_bound=GHOST_TOLERANCE_PX)
        disturbed[np.flatnonzero(mask)] |= np.isfinite(dist).reshape(len(th), -1).any(axis=1)
    return disturbed


def geometry_metrics(rig: Rig, radius_mm: float = SECTION_RADIUS_MM, *,
                     band_mm: float = BAND_MM) -> dict[str, float]:
    """The geometry metrics of the module docstring for one rig (floats; angles in degrees).

    Parameters
    ----------
    rig : Rig
        With two mirrors (any names); views by :func:`~lts360.scenes.coverage.view_name`.
    radius_mm : float, >0
        Section radius.
    band_mm : float, >0
        Half-width of the search segment of ``ghost_in_band_pct``.
    """
    cov = coverage(rig, radius_mm, theta_step_deg=COVERAGE_STEP_DEG, max_bounces=2)
    seqs = mirror_sequences(rig.mirrors, 2)
    singles = [s for s in seqs if len(s) <= 1]
    doubles = [s for s in seqs if len(s) == 2]
    single_names = [view_name(s, rig.mirrors) for s in singles]
    double_names = [view_name(s, rig.mirrors) for s in doubles]
    n = len(cov.theta_rad)
    single = np.logical_or.reduce([cov.measured[v] for v in single_names])
    double = np.logical_or.reduce([cov.measured[v] for v in double_names]) if double_names \
        else np.zeros(n, dtype=bool)
    n_lit = np.sum([m.astype(int) for m in cov.lit.values()], axis=0)
    ghost = _ghost_in_band(rig, cov, singles, doubles, band_mm)
    step = cov.step_deg

    def pct(mask):
        return float(100.0 * mask.sum() / n)

    mirror_names = [m.name for m in rig.mirrors]
    overlaps = {f"overlap_direct_{m}_deg": cov.overlap_deg("direct", m) for m in mirror_names}
    out = {"coverage_deg": cov.coverage_deg, "coverage_single_deg": float(single.sum() * step)}
    out.update({"overlap_direct_left_deg": overlaps.get("overlap_direct_left_deg", math.nan),
                "overlap_direct_right_deg": overlaps.get("overlap_direct_right_deg", math.nan),
                "overlap_direct_mirror_deg": min(overlaps.values(), default=math.nan),
                "overlap_mirror_mirror_deg": cov.overlap_deg(*mirror_names[:2])
                if len(mirror_names) >= 2 else math.nan,
                "image_margin_px": cov.image_margin_px(rig.camera.image_size),
                "multi_reflection_pct": pct(single & double),
                "ghost_in_band_pct": pct(ghost),
                "multi_lit_pct": pct(single & (n_lit > 1))})
    return out


# --- the Monte Carlo measurement ----------------------------------------------------------------

def _draw_seeds(root: int, draws: int) -> tuple[int, list[int]]:
    """Render seed and one sensor seed per draw: independent streams of ``root``."""
    children = np.random.SeedSequence(int(root)).spawn(draws + 1)
    seeds = [int(c.generate_state(1)[0]) for c in children]
    return seeds[0], seeds[1:]


def _measurer(cal, grid):
    """The per-image measurement, planned once: Dr.Jit's kernel, or the numpy reference."""
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse

    try:
        from lts360.recon.triangulation.fast import FastInverse

        return FastInverse(plan_inverse(cal, grid, precompute=False))
    except RuntimeError:  # no Dr.Jit LLVM backend: the precomputed numpy path
        plan = plan_inverse(cal, grid, precompute=True)
        return lambda image: inverse_triangulate(image, cal, grid, plan=plan)


def _measure_draw(result, r_true_mm: float, centre_mm: np.ndarray) -> dict:
    from lts360.geometry.fit import fit_circle

    pts = [v.points_meas_mm[v.valid, :2] for v in result.views.values()]
    pts = np.concatenate(pts) if pts else np.zeros((0, 2))
    out = {"n_points": len(pts), "coverage_deg": result.coverage_deg, "radius_error_mm": np.nan,
           "sq_sum_mm2": np.nan}
    if len(pts) >= MIN_POINTS:
        fit = fit_circle(pts)
        out["radius_error_mm"] = float(fit.radius_mm - r_true_mm)
        out["sq_sum_mm2"] = float(np.sum((np.hypot(*(pts - centre_mm).T) - r_true_mm) ** 2))
    return out


def _monte_carlo(rig: Rig, *, draws: int, spp: int, scale: float, seed: int) -> dict:
    from lts360.recon.calibration.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.scenes.objects import build_object
    from lts360.simulator.frame import sensor_image, simulate_frame

    obj = build_object(GAUGE_SPEC)
    r_true = obj.params["diameter_mm"] / 2.0
    centre = np.asarray(obj.T_world_object, dtype=float)[:2, 3]
    render_seed, draw_seeds = _draw_seeds(seed, draws)
    t0 = time.perf_counter()
    frame = simulate_frame(rig, obj, spp=spp, seed=render_seed, noise="none", thin_lens=True,
                           scale=scale)
    seconds_render = time.perf_counter() - t0
    # The truth as a file would hold it (plain JSON), as tests/recon/triangulation/test_rendered_gauge.py does.
    truth = json.loads(json.dumps(frame.truth, default=lambda v: np.asarray(v).tolist()))
    cal = calibration_from_frame_truth(truth)
    grid = CylGrid.from_ranges((r_true - BAND_MM, r_true + BAND_MM),
                               theta_step_deg=THETA_STEP_DEG, r_step_mm=R_STEP_MM)
    measure = _measurer(cal, grid)
    per_draw = []
    exposure = math.nan
    for s in draw_seeds:
        image, exposure, _ = sensor_image(rig, frame.render, noise="realistic", seed=s,
                                          scale=scale)
        per_draw.append(_measure_draw(measure(image), r_true, centre))
    err = np.array([d["radius_error_mm"] for d in per_draw])
    ok = np.isfinite(err)
    n_pts = np.array([d["n_points"] for d in per_draw], dtype=float)
    sq = np.array([d["sq_sum_mm2"] for d in per_draw])
    return {"radius_error_mm": err,
            "radius_std_mm": float(np.std(err[ok], ddof=1)) if ok.sum() >= 2 else math.nan,
            "radius_mean_error_mm": float(np.mean(err[ok])) if ok.any() else math.nan,
            "point_rms_mm": float(np.sqrt(sq[ok].sum() / n_pts[ok].sum())) if ok.any()
            else math.nan,
            "measured_coverage_deg": float(np.mean([d["coverage_deg"] for d in per_draw])),
            "n_points": float(n_pts.mean()), "n_failed_draws": int((~ok).sum()),
            "exposure_time_s": float(exposure), "seconds_render": seconds_render}


# --- the trial ----------------------------------------------------------------------------------

def _settings(params: dict) -> dict:
    s = {**_DEFAULTS, **{k: params[k] for k in _DEFAULTS if k in params}}
    draws, spp, scale = s["draws"], s["spp"], s["scale"]
    if not _is_int(draws) or draws < 0 or draws == 1:
        raise ValueError(f"draws: must be 0 (geometry only) or an int >= 2, got {draws!r}")
    if not _is_int(spp) or spp < 1:
        raise ValueError(f"spp: must be an int >= 1, got {spp!r}")
    if isinstance(scale, (bool, np.bool_)) or not isinstance(scale, (int, float, np.number)) \
            or not 0.0 < scale <= 1.0:
        raise ValueError(f"scale: must be in (0, 1], got {scale!r}")
    return {"draws": int(draws), "spp": int(spp), "scale": float(scale)}


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def design_space_trial(trial: Trial) -> TrialOutput:
    """One rig of the grid: geometry metrics, then (``draws > 0``) the Monte Carlo radius
    uncertainty of the plug gauge.

    ``trial.params``: ``alpha_deg``, ``beta_deg`` and optionally ``draws`` (default 8; 0 =
    geometry only), ``spp`` (16), ``scale`` (1.0: the image scale of the render; the true
    calibration follows it).  Sets the Mitsuba variant ``llvm_ad_mono`` if none is set.
    Returns the scalars of the module docstring, ``status`` and ``radius_error_mm(draw)``.
    """
    t0 = time.perf_counter()
    p = trial.params
    s = _settings(p)
    nan = math.nan
    values: dict = {k: nan for k in _SCALAR_METRICS}
    values["n_failed_draws"] = s["draws"]
    values["radius_error_mm"] = np.full(s["draws"], nan)
    try:
        rig = design_rig(p["alpha_deg"], p["beta_deg"])
    except RigError:
        values["status"] = 1
    else:
        values.update(geometry_metrics(rig))
        values["status"] = 0
        if s["draws"] > 0:
            import mitsuba as mi

            if mi.variant() is None:
                mi.set_variant("llvm_ad_mono")
            values.update(_monte_carlo(rig, draws=s["draws"], spp=s["spp"], scale=s["scale"],
                                       seed=trial.seed))
            if values["n_failed_draws"] == s["draws"]:
                values["status"] = 2
    values["seconds_trial"] = time.perf_counter() - t0
    values["n_failed_draws"] = int(values["n_failed_draws"])
    return TrialOutput(values=values, dims={"radius_error_mm": ("draw",)},
                       coords={"draw": np.arange(s["draws"])})


# --- the study ----------------------------------------------------------------------------------

def _grid_array(grid, name: str) -> np.ndarray:
    return np.asarray(grid[name].values, dtype=float)


def _find_optimum(grid, criterion: OptimumCriterion) -> dict | None:
    std = _grid_array(grid, "radius_std_mm")
    ok = (_grid_array(grid, "status") == 0) & np.isfinite(std)
    with np.errstate(invalid="ignore"):
        ok &= _grid_array(grid, "coverage_single_deg") >= criterion.min_coverage_deg - 1e-9
        ok &= _grid_array(grid, "overlap_direct_mirror_deg") >= criterion.min_overlap_deg
        ok &= _grid_array(grid, "overlap_mirror_mirror_deg") >= criterion.min_overlap_deg
        ok &= _grid_array(grid, "multi_reflection_pct") <= criterion.max_multi_reflection_pct
    if not ok.any():
        return None
    i, j = np.unravel_index(np.argmin(np.where(ok, std, np.inf)), std.shape)
    out = _cell(grid, i, j)
    out["n_qualifying"] = int(ok.sum())
    return out


def _cell(grid, i: int, j: int) -> dict:
    out = {"alpha_deg": float(grid["alpha_deg"].values[i]),
           "beta_deg": float(grid["beta_deg"].values[j])}
    for k in _SCALAR_METRICS + ("status",):
        v = float(grid[k].values[i, j])
        out[k] = v if math.isfinite(v) else None
    return out


def _jsonable(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


#: Metrics returned in ``summary["grid"]`` (α rows, β columns).
GRID_METRICS = ("coverage_deg", "coverage_single_deg", "overlap_direct_mirror_deg",
                "overlap_mirror_mirror_deg", "image_margin_px", "multi_reflection_pct",
                "ghost_in_band_pct", "multi_lit_pct", "radius_std_mm", "radius_mean_error_mm",
                "point_rms_mm", "measured_coverage_deg", "status")


def run_design_space_study(out_dir, *, alpha_deg, beta_deg, seed: int = 0, draws: int = 8,
                           spp: int = 16, workers: int | None = 1,
                           dask_address: str | None = None, scale: float = 1.0,
                           criterion: OptimumCriterion = OPTIMUM_CRITERION, say=print) -> dict:
    """Run (or resume) the design-space study; write results, figures and a README.

    Parameters
    ----------
    out_dir : path-like
        ``trials/`` (the runner's study: ``plan.json``, ``trials/*.nc``, ``results.nc``),
        ``grid.nc`` (the results over ``(alpha_deg, beta_deg)``, with ``status_text``),
        ``summary.json``, ``design-space-*.png`` and ``README.md``.
    alpha_deg, beta_deg : str or sequence of float
        Axes of the grid: a :func:`parse_range` text (``"20:70:5"``) or the values (unique).
    seed : int, >=0
        Root seed; trial ``i`` gets an independent stream (:func:`plan_trials`).
    draws : int
        Monte Carlo draws per rig, ``>= 2``; 0 computes the geometry only.
    spp : int, >=1
        Samples per pixel of the one render per rig.
    workers : int, >=1, optional
        Local processes (1: sequential in this process; Mitsuba is multithreaded itself).
        Ignored with ``dask_address``.
    dask_address : str, optional
        Dask scheduler to run the trials on.
    scale : float, (0, 1]
        Image scale of the renders (1: 1280×1024; smaller for quick runs and tests).
    criterion : OptimumCriterion
    say : callable
        Progress messages.

    Returns
    -------
    dict
        ``optimum`` (the best cell's metrics, or None), ``paper`` (the cell at
        :data:`PAPER_DESIGN`, or None), ``criterion``, ``grid`` (``alpha_deg``, ``beta_deg``
        and each of :data:`GRID_METRICS` as α-by-β nested lists, NaN → None; ``status_text``),
        ``invalid`` (the rejected combinations with their messages), ``settings``,
        ``n_trials``, ``n_run`` (trials run by this call; 0 when all were on disk),
        ``seconds`` (this call), ``seconds_per_trial`` (mean stored trial wall time),
        ``files``.
    """
    t0 = time.perf_counter()
    alphas, betas = _axis("alpha_deg", alpha_deg), _axis("beta_deg", beta_deg)
    settings = _settings({"draws": draws, "spp": spp, "scale": scale})
    if not isinstance(criterion, OptimumCriterion):
        raise ValueError(f"criterion: must be an OptimumCriterion, got {criterion!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out_dir: {str(out)!r} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    study = out / "trials"
    params = [dict(p, **settings) for p in grid_params(alpha_deg=alphas, beta_deg=betas)]
    trials = plan_trials(params, seed)
    n_todo = sum(not trial_path(study, t.index).exists() for t in trials)
    say(f"design space: {len(alphas)} α × {len(betas)} β = {len(trials)} rigs, draws={draws}, "
        f"spp={spp}, scale={scale:g}, seed={seed}; {len(trials) - n_todo} on disk, "
        f"{n_todo} to run -> {study}/")
    ds = run_study(study, trials, design_space_trial, name="design-space",
                   workers=None if dask_address is not None else workers,
                   dask_address=dask_address,
                   attrs={**settings, "seed": int(seed),
                          "gauge": GAUGE_SPEC, "section_radius_mm": SECTION_RADIUS_MM})
    grid = to_grid(ds, "alpha_deg", "beta_deg")
    status_text = np.array([[rig_status(a, b) if int(grid["status"].values[i, j]) == 1
                             else STATUS[int(grid["status"].values[i, j])]
                             for j, b in enumerate(grid["beta_deg"].values)]
                            for i, a in enumerate(grid["alpha_deg"].values)], dtype=object)
    grid = grid.assign(status_text=(("alpha_deg", "beta_deg"), status_text.astype(str)))
    from lts360.simulator.io import atomic_path

    with atomic_path(out / "grid.nc") as tmp:
        grid.to_netcdf(tmp, engine="netcdf4")

    summary = _summary(grid, criterion, settings, seed)
    valid = np.asarray(ds["status"].values) != 1
    seconds = np.asarray(ds["seconds_trial"].values, dtype=float)[valid]
    summary.update(n_trials=len(trials), n_run=n_todo,
                   seconds_per_trial=float(seconds.mean()) if seconds.size else math.nan)
    figures = _plot_all(grid, summary, out)
    summary["seconds"] = time.perf_counter() - t0
    summary["files"] = {"results": str(study / "results.nc"), "grid": str(out / "grid.nc"),
                        "summary": str(out / "summary.json"), "readme": str(out / "README.md"),
                        "figures": [str(f) for f in figures]}
    summary["command"] = (f"lts360 study design-space --alpha-deg {_range_text(alphas)} "
                          f"--beta-deg {_range_text(betas)} --draws {draws} --spp {spp} "
                          + (f"--scale {scale:g} " if scale != 1.0 else "")
                          + f"--seed {seed} --out {out}")
    _write_text(out / "summary.json", json.dumps(_jsonable(summary), indent=2) + "\n")
    _write_text(out / "README.md", _readme(summary, criterion))
    best = summary["optimum"]
    say("optimum: " + ("none qualifies" if best is None else
                       f"α = {best['alpha_deg']:g}°, β = {best['beta_deg']:g}°")
        + f"; wrote {out}/ (README.md, summary.json, grid.nc, design-space-*.png, "
        "trials/results.nc)")
    return summary


def _summary(grid, criterion: OptimumCriterion, settings: dict, seed: int) -> dict:
    alphas = [float(a) for a in grid["alpha_deg"].values]
    betas = [float(b) for b in grid["beta_deg"].values]
    g = {"alpha_deg": alphas, "beta_deg": betas}
    for k in GRID_METRICS:
        g[k] = [[(float(v) if math.isfinite(float(v)) else None) for v in row]
                for row in np.asarray(grid[k].values, dtype=float)]
    g["status_text"] = grid["status_text"].values.tolist()
    invalid = [{"alpha_deg": a, "beta_deg": b, "status": g["status_text"][i][j]}
               for i, a in enumerate(alphas) for j, b in enumerate(betas)
               if g["status_text"][i][j] != STATUS[0]]
    paper = None
    if PAPER_DESIGN[0] in alphas and PAPER_DESIGN[1] in betas:
        paper = _cell(grid, alphas.index(PAPER_DESIGN[0]), betas.index(PAPER_DESIGN[1]))
    return {"optimum": _find_optimum(grid, criterion), "paper": paper,
            "criterion": {**dataclasses.asdict(criterion), "text": criterion.describe()},
            "grid": g, "invalid": invalid, "settings": {**settings, "seed": int(seed)}}


def _write_text(path: Path, text: str) -> None:
    from lts360.simulator.io import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(text)


# --- reporting ----------------------------------------------------------------------------------

#: (key, title, scale, format) of the terminal tables.
_TABLES = (("coverage_single_deg", "single-view coverage (°)", 1.0, "{:5.1f}"),
           ("overlap_direct_mirror_deg", "direct/mirror overlap, smaller side (°)", 1.0,
            "{:5.1f}"),
           ("overlap_mirror_mirror_deg", "mirror/mirror overlap (°)", 1.0, "{:5.1f}"),
           ("multi_reflection_pct", "multiple-reflection share (%)", 1.0, "{:5.1f}"),
           ("radius_std_mm", "radius standard deviation over the draws (µm)", 1e3, "{:5.2f}"))


def _fmt_opt(cell: dict | None, label: str) -> str:
    if cell is None:
        return f"{label}: none"

    def um(key):
        v = cell.get(key)
        return "—" if v is None else f"{v * 1e3:.2f} µm"

    def deg(key):
        v = cell.get(key)
        return "—" if v is None else f"{v:.1f}°"

    def pct(key):
        v = cell.get(key)
        return "—" if v is None else f"{v:.1f} %"

    return (f"{label}: α = {cell['alpha_deg']:g}°, β = {cell['beta_deg']:g}° — radius std "
            f"{um('radius_std_mm')}, mean error {um('radius_mean_error_mm')}, point rms "
            f"{um('point_rms_mm')}, coverage {deg('coverage_single_deg')} (measured "
            f"{deg('measured_coverage_deg')}), overlaps {deg('overlap_direct_mirror_deg')} / "
            f"{deg('overlap_mirror_mirror_deg')}, multiple reflections "
            f"{pct('multi_reflection_pct')}")


def format_design_space(summary: dict) -> str:
    """Terminal tables (α rows, β columns) of the main metrics, then the paper rig and the
    optimum."""
    g = summary["grid"]
    betas = g["beta_deg"]
    lines = []
    for key, title, factor, fmt in _TABLES:
        lines.append(f"{title}:")
        lines.append("  α \\ β " + "".join(f"{b:>7g}" for b in betas))
        for a, row in zip(g["alpha_deg"], g[key]):
            cells = "".join(f"{'—':>7s}" if v is None else f"{fmt.format(v * factor):>7s}"
                            for v in row)
            lines.append(f"  {a:>5g} " + cells)
        lines.append("")
    for inv in summary.get("invalid", []):
        lines.append(f"α = {inv['alpha_deg']:g}°, β = {inv['beta_deg']:g}°: {inv['status']}")
    lines.append(_fmt_opt(summary.get("paper"), "paper rig"))
    lines.append(_fmt_opt(summary.get("optimum"), "optimum"))
    lines.append(f"  (criterion: {summary['criterion']['text']})")
    return "\n".join(lines)


def _edges(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if len(v) == 1:
        return np.array([v[0] - 2.5, v[0] + 2.5])
    mid = (v[1:] + v[:-1]) / 2.0
    return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])


#: (file stem, [(variable, colour-bar label, factor)]) of the figures.
_FIGURES = (
    ("design-space-coverage", [("coverage_single_deg", "single-view coverage (°)", 1.0),
                               ("image_margin_px", "image margin (px)", 1.0)]),
    ("design-space-overlap", [("overlap_direct_mirror_deg", "direct/mirror overlap (°)", 1.0),
                              ("overlap_mirror_mirror_deg", "mirror/mirror overlap (°)", 1.0)]),
    ("design-space-multiple-reflections",
     [("multi_reflection_pct", "double-reflection image of a measured point (% of 360°)", 1.0),
      ("ghost_in_band_pct", "double-reflection stripe in a search band (% of 360°)", 1.0)]),
    ("design-space-radius-uncertainty",
     [("radius_std_mm", "radius std over the draws (µm)", 1e3),
      ("point_rms_mm", "per-point rms (µm)", 1e3)]),
)


#: Heat maps with at most this many cells print each cell's value.
_MAX_ANNOTATED_CELLS = 400


def _plot_all(grid, summary: dict, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = np.asarray(grid["alpha_deg"].values, dtype=float)
    b = np.asarray(grid["beta_deg"].values, dtype=float)
    ea, eb = _edges(a), _edges(b)
    opt = summary.get("optimum")
    paths = []
    for stem, panels in _FIGURES:
        fig, axes = plt.subplots(1, len(panels), figsize=(6.0 * len(panels), 4.6), squeeze=False)
        for ax, (var, label, factor) in zip(axes[0], panels):
            z = np.asarray(grid[var].values, dtype=float) * factor
            ax.set_facecolor("0.85")  # NaN: invalid rig or not measured
            mesh = ax.pcolormesh(eb, ea, np.ma.masked_invalid(z), cmap="viridis", shading="flat")
            fig.colorbar(mesh, ax=ax, label=label)
            if z.size <= _MAX_ANNOTATED_CELLS:
                for (i, j), v in np.ndenumerate(z):
                    if np.isfinite(v):
                        ax.text(b[j], a[i], f"{v:.3g}", ha="center", va="center", fontsize=6,
                                color="w" if v < np.nanmean(z) else "k")
            ax.plot(PAPER_DESIGN[1], PAPER_DESIGN[0], marker="*", ms=16, mfc="white", mec="k",
                    ls="none", label=f"paper (α {PAPER_DESIGN[0]:g}°, β {PAPER_DESIGN[1]:g}°)")
            if opt is not None:
                ax.plot(opt["beta_deg"], opt["alpha_deg"], marker="o", ms=12, mfc="none",
                        mec="red", mew=2, ls="none",
                        label=f"optimum (α {opt['alpha_deg']:g}°, β {opt['beta_deg']:g}°)")
            ax.set_xlim(eb[0], eb[-1])
            ax.set_ylim(ea[0], ea[-1])
            ax.set_xlabel("β, angle between the mirrors (°)")
            ax.set_ylabel("α, triangulation angle (°)")
            ax.legend(loc="lower left", fontsize=7, framealpha=0.8)
        fig.suptitle("design space of the paper rig (grey: invalid rig or no value)")
        fig.tight_layout()
        path = out / f"{stem}.png"
        tmp = path.with_name(f".{path.stem}.tmp.png")
        fig.savefig(tmp, dpi=110)
        plt.close(fig)
        tmp.replace(path)
        paths.append(path)
    return paths


def _machine() -> str:
    try:
        import mitsuba as mi

        variant = mi.variant() or "llvm_ad_mono (set by the trials)"
        mitsuba = f"Mitsuba {mi.__version__}, variant {variant}"
    except ImportError:
        mitsuba = "Mitsuba not installed"
    return (f"{platform.node()} — {platform.platform()}, {platform.machine()}, "
            f"{os.cpu_count()} CPUs, Python {platform.python_version()}, {mitsuba}")


def _readme(summary: dict, criterion: OptimumCriterion) -> str:
    s = summary["settings"]
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    g = summary["grid"]
    lines = [
        "# Design space of the 360° laser triangulation rig (α, β)",
        "",
        "Written by `lts360.experiments.design_space.run_design_space_study`.",
        "",
        "```",
        summary["command"],
        "```",
        "",
        f"- date: {now}",
        f"- machine: {_machine()}",
        f"- grid: α = {_range_text(g['alpha_deg'])}° (n = {len(g['alpha_deg'])}), "
        f"β = {_range_text(g['beta_deg'])}° (n = {len(g['beta_deg'])}): "
        f"{summary['n_trials']} rigs; {summary['n_run']} run by this call, "
        f"{summary['n_trials'] - summary['n_run']} already on disk",
        f"- root seed {s['seed']} (trial i: `np.random.SeedSequence(seed).spawn(n)[i]`; in a "
        "trial, stream 0 seeds the render, streams 1..M the draws' noise and speckle)",
        f"- per rig: one render of `{GAUGE_SPEC}` (noise-free, {s['spp']} spp, thin lens, image "
        f"scale {s['scale']:g}), {s['draws']} draws of sensor noise and speckle, each measured "
        f"by inverse triangulation with the true calibration (θ step {THETA_STEP_DEG:g}°, "
        f"r step {R_STEP_MM * 1e3:g} µm, band ±{BAND_MM:g} mm) and a circle fit",
        f"- geometry: coverage() of a Ø{2 * SECTION_RADIUS_MM:g} mm section, θ step "
        f"{COVERAGE_STEP_DEG:g}°, up to two reflections",
        f"- wall time of this call {summary['seconds']:.1f} s; mean wall time of a valid "
        f"rig's trial (as stored, whenever it ran) {summary['seconds_per_trial']:.1f} s",
        "",
        "Every rig is the `paper` preset with only `design.alpha_deg` and `design.beta_deg` "
        "changed.",
        "",
        "## Result",
        "",
        f"Optimum criterion: {criterion.describe()}.",
        "",
        f"- {_fmt_opt(summary['optimum'], 'optimum')}",
        f"- {_fmt_opt(summary['paper'], 'paper rig')}",
    ]
    if summary["optimum"] is not None:
        lines.append(f"- rigs that qualify: {summary['optimum']['n_qualifying']}. With M draws the "
                     "standard deviation is itself uncertain by about 1/√(2(M−1)) "
                     f"({100 / math.sqrt(2 * max(s['draws'] - 1, 1)):.0f} % here): rigs within "
                     "that of the optimum are ties.")
    if summary["invalid"]:
        lines += ["", "Rigs without a result:", ""]
        lines += [f"- α = {i['alpha_deg']:g}°, β = {i['beta_deg']:g}°: {i['status']}"
                  for i in summary["invalid"]]
    lines += ["", "```", format_design_space(summary), "```", "",
              "## Metrics", "",
              "See the docstring of `lts360/experiments/design_space.py` for the exact "
              "definitions. In short:", "",
              "- `coverage_single_deg`: angle of the section measured (seen and lit) by the "
              "direct or a single mirror view; `coverage_deg` counts double reflections too.",
              "- `overlap_direct_mirror_deg` (smaller of direct/left and direct/right) and "
              "`overlap_mirror_mirror_deg`: angle measured by both views.",
              "- `image_margin_px`: least distance of a measured point's image from the border.",
              "- `multi_reflection_pct`: share of 360° where a point measured by a single view "
              "also appears, seen and lit, through a double reflection (a second stripe image "
              "of the point).",
              f"- `ghost_in_band_pct`: share of 360° where a double-reflection stripe image "
              f"lies within {GHOST_TOLERANCE_PX:g} px of a single view's ±{BAND_MM:g} mm search "
              "segment.",
              "- `radius_std_mm`: standard deviation of the fitted gauge radius over the draws "
              "(the radius uncertainty); `radius_mean_error_mm` its mean error; "
              "`point_rms_mm`: rms of the point radii about the true circle; "
              "`measured_coverage_deg`: angle with at least one valid point (mean over draws).",
              "", "## Files", "",
              "- `trials/results.nc`: every trial (runner layout, resumable: run the same "
              "command again to finish an interrupted study)",
              "- `grid.nc`: the results over (alpha_deg, beta_deg), with `status_text`",
              "- `summary.json`: this summary",
              "- " + ", ".join(f"`{Path(f).name}`" for f in summary["files"]["figures"])
              + ": heat maps (star: the paper's design, red circle: the optimum)", ""]
    return "\n".join(lines)

"""One design: its rig, its geometry (coverage, overlaps, ghosts) and its Monte Carlo measurement."""

from __future__ import annotations

import copy
import json
import math
import time
import tomllib
from importlib import resources

import numpy as np
from scipy.spatial import cKDTree

from lts360.experiments.design_space.settings import (
    _DEFAULTS,
    _SCALAR_METRICS,
    _SEGMENT_SAMPLES,
    BAND_MM,
    COVERAGE_STEP_DEG,
    GAUGE_SPEC,
    GHOST_TOLERANCE_PX,
    MIN_POINTS,
    R_STEP_MM,
    SECTION_RADIUS_MM,
    STATUS,
    THETA_STEP_DEG,
)
from lts360.experiments.runner import Trial, TrialOutput
from lts360.scenes.coverage import CoverageResult, coverage, mirror_sequences, view_name
from lts360.scenes.rig import Rig, RigError

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
    from lts360.recon.model import calibration_from_frame_truth
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
    # The truth as a file would hold it (plain JSON), as
    # tests/recon/triangulation/test_rendered_gauge.py does.
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
    calibration follows it).  Sets the Mitsuba variant (:func:`~lts360.simulator.render.default_variant`)
    if none is set.
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
            from lts360.simulator.render import ensure_variant

            ensure_variant()
            values.update(_monte_carlo(rig, draws=s["draws"], spp=s["spp"], scale=s["scale"],
                                       seed=trial.seed))
            if values["n_failed_draws"] == s["draws"]:
                values["status"] = 2
    values["seconds_trial"] = time.perf_counter() - t0
    values["n_failed_draws"] = int(values["n_failed_draws"])
    return TrialOutput(values=values, dims={"radius_error_mm": ("draw",)},
                       coords={"draw": np.arange(s["draws"])})

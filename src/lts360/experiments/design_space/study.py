"""The grid of designs run as a study (resumable trials), its optimum and summary."""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np

from lts360.experiments.design_space.report import _plot_all, _readme
from lts360.experiments.design_space.settings import (
    _SCALAR_METRICS,
    GAUGE_SPEC,
    OPTIMUM_CRITERION,
    PAPER_DESIGN,
    SECTION_RADIUS_MM,
    STATUS,
    OptimumCriterion,
    _axis,
    _range_text,
)
from lts360.experiments.design_space.trial import (
    _settings,
    design_space_trial,
    rig_status,
)
from lts360.experiments.runner import (
    grid_params,
    plan_trials,
    run_study,
    to_grid,
    trial_path,
)

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

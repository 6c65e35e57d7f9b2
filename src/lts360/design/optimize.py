"""Rig optimisation on the model: a coarse grid of the model seeds a multi-start L-BFGS-B.

The objective of a design is the model's worst case over the conditions' diameters and
placements of ``U(k=2)`` of the radius plus the constraint penalties (coverage, overlaps,
multiple reflections, the rig's own validity), in µm (:func:`lts360.design.model.evaluate`).
L-BFGS-B (scipy) runs in the scaled coordinates ``s ∈ [0, 1]`` on the model's values and
reverse-mode gradients.  A start counts only if its end is a valid rig and meets the
constraints on the *hard* coverage (:func:`lts360.scenes.coverage.coverage`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time

import numpy as np

from lts360.design.model import Conditions, evaluate, evaluate_batch
from lts360.design.params import DesignError, DesignSpace
from lts360.scenes.checks import RigError
from lts360.scenes.coverage import coverage

__all__ = ["Candidate", "OptimizeResult", "grid_search", "optimize", "hard_metrics",
           "InfeasibleError"]


#: Objective returned for a design the model cannot evaluate (µm).
_UNUSABLE = 1e12


class InfeasibleError(DesignError):
    """No design meets the constraints."""


@dataclasses.dataclass
class Candidate:
    """One design with its model values and (when it is a valid rig) its hard coverage."""

    label: str
    x: np.ndarray
    objective: float
    U_um: float
    sigma_R_um: float
    point_rms_um: float
    coverage_deg: float
    penalty_um: float
    hard: dict | None
    evaluations: int = 0
    sigma_R_noise_um: float = float("nan")
    sigma_R_comp_um: float = float("nan")
    sigma_R_cal_um: float = float("nan")
    sigma_R_bias_um: float = float("nan")
    bias_um: float = float("nan")
    seconds: float = 0.0
    reach_grid_best: list | None = None

    def feasible(self, cond: Conditions) -> bool:
        return self.hard is not None and self.hard["ok"]

    def as_dict(self, space: DesignSpace) -> dict:
        return {"label": self.label, "parameters": dict(zip(space.free, map(float, self.x))),
                "objective_um": self.objective, "U_um": self.U_um,
                "sigma_R_um": self.sigma_R_um, "sigma_R_noise_um": self.sigma_R_noise_um,
                "sigma_R_compensation_um": self.sigma_R_comp_um,
                "sigma_R_calibration_um": self.sigma_R_cal_um,
                "sigma_R_bias_left_um": self.sigma_R_bias_um,
                "line_centre_bias_um": self.bias_um, "point_rms_um": self.point_rms_um,
                "coverage_smooth_deg": self.coverage_deg, "penalty_um": self.penalty_um,
                "hard": self.hard, "evaluations": self.evaluations, "seconds": self.seconds,
                "evaluations_seconds_to_beat_grid_best": self.reach_grid_best}


@dataclasses.dataclass
class OptimizeResult:
    space: DesignSpace
    conditions: Conditions
    paper: Candidate
    grid_best: Candidate
    optimum: Candidate
    starts: list
    grid_points: int


def hard_metrics(space: DesignSpace, x, cond: Conditions, *, theta_step_deg: float = 0.5
                 ) -> dict | None:
    """Hard coverage of every case of a design (``None`` if it is not a valid rig).

    Returns the worst case's single-view coverage, overlaps, image margin and multiple-reflection
    share, and ``ok``: whether they meet the conditions' constraints.
    """
    try:
        rig = space.rig(x)
    except RigError:
        return None
    worst = dict(coverage_deg=math.inf, overlap_direct_mirror_deg=math.inf,
                 overlap_mirror_mirror_deg=math.inf, image_margin_px=math.inf,
                 multi_reflection_pct=0.0)
    names = [m.name for m in rig.mirrors]
    for r, cx, cy in cond.cases():
        cov = coverage(rig, r, theta_step_deg=theta_step_deg, max_bounces=2,
                       max_incidence_deg=cond.max_incidence_deg, margin_px=cond.margin_px,
                       center_xy_mm=(cx, cy))
        single = cov.measured["direct"] | cov.measured[names[0]] | cov.measured[names[1]]
        double = np.zeros_like(single)
        for v in cov.measured:
            if v.count("-") == 1:
                double |= cov.measured[v]
        step = cov.step_deg
        worst["coverage_deg"] = min(worst["coverage_deg"], float(single.sum() * step))
        worst["overlap_direct_mirror_deg"] = min(worst["overlap_direct_mirror_deg"],
                                                 cov.overlap_deg("direct", names[0]),
                                                 cov.overlap_deg("direct", names[1]))
        worst["overlap_mirror_mirror_deg"] = min(worst["overlap_mirror_mirror_deg"],
                                                 cov.overlap_deg(*names))
        margin = cov.image_margin_px(rig.camera.image_size)
        worst["image_margin_px"] = min(worst["image_margin_px"], margin)
        worst["multi_reflection_pct"] = max(worst["multi_reflection_pct"],
                                            float(100.0 * (single & double).mean()))
    # One θ step of the hard grid is rounding (as the design-space study's criterion).
    worst["ok"] = bool(worst["coverage_deg"] >= cond.min_coverage_deg - theta_step_deg
                       and worst["overlap_direct_mirror_deg"] >= cond.min_overlap_deg
                       - theta_step_deg
                       and worst["overlap_mirror_mirror_deg"] >= cond.min_overlap_deg
                       - theta_step_deg
                       and worst["multi_reflection_pct"] <= cond.max_multi_reflection_pct)
    return {k: (float(v) if not isinstance(v, bool) else v) for k, v in worst.items()}


def _candidate(space, cond, x, label, *, evaluations=0, seconds=0.0) -> Candidate:
    e = evaluate(space, x, cond, gradient=False)
    k = e.worst_case
    return Candidate(label=label, x=np.asarray(x, dtype=float), objective=e.objective,
                     U_um=float(np.max(e.U_um)), sigma_R_um=float(np.max(e.sigma_R_um)),
                     point_rms_um=float(e.point_rms_um[k]),
                     coverage_deg=float(np.min(e.coverage_deg)), penalty_um=float(e.penalty_um[k]),
                     hard=hard_metrics(space, x, cond), evaluations=evaluations, seconds=seconds,
                     sigma_R_noise_um=float(e.sigma_R_noise_um[k]),
                     sigma_R_comp_um=float(e.sigma_R_comp_um[k]),
                     sigma_R_cal_um=float(e.sigma_R_cal_um[k]),
                     sigma_R_bias_um=float(e.sigma_R_bias_um[k]), bias_um=float(e.bias_um[k]))


def grid_search(space: DesignSpace, cond: Conditions, *, points_per_axis: int = 3,
                max_points: int = 4096, rng: np.random.Generator | int | None = 0):
    """The model on a coarse grid of the scaled box (a random subset when it is too large).

    Returns
    -------
    (s, objective) : ((m, n_free) float, (m,) float)
        Scaled designs sorted by objective (best first).
    """
    n = len(space.free)
    axis = (np.arange(points_per_axis) + 0.5) / points_per_axis
    total = points_per_axis ** n
    if total <= max_points:
        s = np.array(list(itertools.product(axis, repeat=n)))
    else:
        gen = np.random.default_rng(rng)
        s = axis[gen.integers(0, points_per_axis, size=(max_points, n))]
    f = evaluate_batch(space, space.from_scaled(s), cond)["objective"]
    order = np.argsort(f)
    return s[order], f[order]


def optimize(space: DesignSpace, cond: Conditions, *, starts: int = 6, points_per_axis: int = 3,
             max_grid_points: int = 512, max_iterations: int = 200, seed: int = 0,
             progress=None) -> OptimizeResult:
    """Multi-start L-BFGS-B from the best points of a coarse grid of the model.

    Parameters
    ----------
    space, cond
    starts : int, >=1
        Number of local optimisations (from the grid's best distinct points).
    points_per_axis, max_grid_points
        The grid: ``points_per_axis`` values per free parameter, at most ``max_grid_points``
        designs (a seeded random subset when there are more).
    max_iterations : int
        L-BFGS-B iterations per start.
    seed : int
        Seed of the grid's subset.
    progress : callable, optional
        Called with one line of text per stage.

    Raises
    ------
    InfeasibleError
        No start ends in a valid rig meeting the hard constraints.
    """
    from scipy.optimize import minimize

    say = progress or (lambda _msg: None)
    t0 = time.perf_counter()
    s_grid, f_grid = grid_search(space, cond, points_per_axis=points_per_axis,
                                 max_points=max_grid_points, rng=seed)
    t_grid = time.perf_counter() - t0
    say(f"grid: {len(s_grid)} designs of the model in {t_grid:.1f} s, best {f_grid[0]:.3f} µm")
    grid_best = None
    for s in s_grid:  # the grid's best design that is a feasible rig
        c = _candidate(space, cond, space.from_scaled(s), "grid best",
                       evaluations=len(s_grid), seconds=t_grid)
        if c.feasible(cond):
            grid_best = c
            break
    width = space.hi - space.lo
    results = []
    n_eval_total = len(s_grid)
    # Distinct starts: grid points whose objective differs from every chosen one (free
    # parameters without effect make ties).
    chosen, values = [], []
    for s, f in zip(s_grid, f_grid):
        if all(abs(f - v) > 1e-9 * max(1.0, abs(v)) for v in values):
            chosen.append(s)
            values.append(f)
        if len(chosen) == starts:
            break
    # The base rig is a start too: how many gradient evaluations from it reach the grid's best?
    target = grid_best.objective if grid_best is not None else -math.inf
    s_base = np.clip(space.to_scaled(space.base_x()), 0.0, 1.0)
    f_base = evaluate(space, space.from_scaled(s_base), cond, gradient=False).objective
    for k, (s0, f0) in enumerate(list(zip(chosen, values)) + [(s_base, f_base)]):
        n_eval = [0]
        reach = [None, None]  # evaluations and seconds to beat the grid's best (feasible or not)
        t1 = time.perf_counter()

        def fun(s, n_eval=n_eval, reach=reach, t1=t1):
            n_eval[0] += 1
            e = evaluate(space, space.from_scaled(s), cond, gradient=True)
            if not (np.isfinite(e.objective) and np.all(np.isfinite(e.gradient))):
                return _UNUSABLE, np.zeros_like(s)  # let the line search step back
            if reach[0] is None and e.objective <= target:
                reach[:] = [n_eval[0], time.perf_counter() - t1]
            return e.objective, e.gradient * width

        res = minimize(fun, s0, jac=True, method="L-BFGS-B", bounds=[(0.0, 1.0)] * len(s0),
                       options={"maxiter": max_iterations})
        n_eval_total += n_eval[0]
        label = f"start {k + 1}" if k < len(chosen) else "start from the base rig"
        c = _candidate(space, cond, space.from_scaled(res.x), label,
                       evaluations=n_eval[0], seconds=time.perf_counter() - t1)
        c.reach_grid_best = reach
        hard = "invalid rig" if c.hard is None else f"{c.hard['coverage_deg']:.1f}°"
        beat = ("" if reach[0] is None else
                f", below the grid's best after {reach[0]} evaluations ({reach[1]:.2f} s)")
        say(f"{label}: {f0:.3f} → {c.objective:.3f} µm in {n_eval[0]} evaluations "
            f"({c.seconds:.1f} s; {res.message}), hard coverage {hard}, "
            f"{'feasible' if c.feasible(cond) else 'not feasible'}{beat}")
        results.append(c)
    feasible = [c for c in results if c.feasible(cond)]
    if not feasible:
        raise InfeasibleError("design: no start reached a valid rig with the required coverage, "
                              "overlaps and multiple-reflection share; widen the bounds or "
                              "relax --min-coverage-deg / --min-overlap-deg")
    best = min(feasible, key=lambda c: c.objective)
    best = dataclasses.replace(best, label="gradient optimum", evaluations=n_eval_total,
                               seconds=time.perf_counter() - t0)
    paper = _candidate(space, cond, space.base_x(), "base rig")
    if grid_best is None:
        grid_best = dataclasses.replace(paper, label="grid best (none feasible: base rig)")
    return OptimizeResult(space=space, conditions=cond, paper=paper, grid_best=grid_best,
                          optimum=best, starts=results, grid_points=len(s_grid))


def report_dict(res: OptimizeResult) -> dict:
    sp, cond = res.space, res.conditions
    return {"base_rig": sp.base.name, "free": list(sp.free),
            "bounds": {k: list(v) for k, v in sp.bounds.items()},
            "conditions": conditions_dict(cond), "grid_points": res.grid_points,
            "designs": [c.as_dict(sp) for c in (res.paper, res.grid_best, res.optimum)],
            "starts": [c.as_dict(sp) for c in res.starts],
            "not_modelled": (["the calibration's share (no covariance given)"]
                             if cond.calibration is None else [])
            + ([] if cond.compensate else ["the §4.4 compensation"])
            + ["saturation and the exposure range", "glossy materials"]}


def conditions_dict(cond: Conditions) -> dict:
    """The conditions as JSON-ready values (a calibration covariance by its source and size)."""
    out = {f.name: getattr(cond, f.name) for f in dataclasses.fields(cond)}
    cal = cond.calibration
    out["calibration"] = None if cal is None else {
        "source": cal.source, "parameters": list(cal.names),
        "sigma": ([float(v) for v in np.sqrt(np.clip(np.diag(cal.matrix), 0.0, None))]
                  if hasattr(cal, "matrix") else "predicted per design")}
    out["diameters_mm"] = list(cond.diameters_mm)
    return out


def report_text(res: OptimizeResult) -> str:
    sp = res.space
    rows = [res.paper, res.grid_best, res.optimum]
    head = f"{'':36s}" + "".join(f"{c.label:>20s}" for c in rows)
    lines = [f"Rig design on the model (base rig {sp.base.name!r}; diameters "
             f"{', '.join(f'{d:g}' for d in res.conditions.diameters_mm)} mm, placement "
             f"{res.conditions.placement_mm:g} mm; worst case)", "", head]

    def row(name, fmt, get):
        lines.append(f"{name:36s}" + "".join(f"{fmt.format(get(c)):>20s}" for c in rows))

    for name in sp.free:
        i = sp.free.index(name)
        row(name, "{:.4g}", lambda c, i=i: c.x[i])
    row("U(k=2) radius, model (µm)", "{:.3f}", lambda c: c.U_um)
    row("σ radius, model (µm)", "{:.3f}", lambda c: c.sigma_R_um)
    row("  share: image noise (µm)", "{:.3f}", lambda c: c.sigma_R_noise_um)
    row("  share: §4.4 compensation (µm)", "{:.3f}", lambda c: c.sigma_R_comp_um)
    row("  share: calibration (µm)", "{:.3f}", lambda c: c.sigma_R_cal_um)
    row("  share: line-centre bias left (µm)", "{:.3f}", lambda c: c.sigma_R_bias_um)
    row("line-centre bias, uncorrected (µm)", "{:+.2f}", lambda c: c.bias_um)
    row("σ per point, rms (µm)", "{:.2f}", lambda c: c.point_rms_um)
    row("coverage, smooth (°)", "{:.1f}", lambda c: c.coverage_deg)
    row("penalty (µm)", "{:.3g}", lambda c: c.penalty_um)
    for key, fmt in (("coverage_deg", "{:.1f}"), ("overlap_direct_mirror_deg", "{:.1f}"),
                     ("overlap_mirror_mirror_deg", "{:.1f}"), ("image_margin_px", "{:.1f}"),
                     ("multi_reflection_pct", "{:.2f}")):
        row(f"hard {key}", fmt,
            lambda c, key=key: float("nan") if c.hard is None else c.hard[key])
    row("model evaluations", "{:d}", lambda c: int(c.evaluations))
    row("seconds", "{:.1f}", lambda c: c.seconds)
    c = res.conditions
    comp = (f"the §4.4 compensation's noise (Ø{c.compensation_diameter_mm:g} mm reference, "
            f"{c.compensation_shots} shot{'s' if c.compensation_shots > 1 else ''})"
            if c.compensate else "no §4.4 compensation")
    cal = (f"the calibration's share ({c.calibration.source or 'given covariance'})"
           if c.calibration is not None else "no calibration share (a perfect calibration)")
    fix = " + ".join((["a master of that diameter"] if c.compensate and c.master else [])
                     + (["the twin"] if c.bias_model == "twin" else [])) or "no correction"
    lines += ["", f"U is the model's: speckle, sensor noise and pixel locking through the circle "
              f"fit, {comp}, {cal}, the line-centre bias {fix} leaves (docs/design.md)."]
    return "\n".join(lines)

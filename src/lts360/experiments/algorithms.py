"""``lts360 study algorithms``: inverse vs classic triangulation and the three peak detectors on
the same images, across objects and noise levels — bias, spread, coverage, time.

Each object is rendered once (noise-free radiance at z = 0, the true calibration of the frame);
a trial is one (object, noise level, repetition): the sensor noise and speckle are drawn on the
stored radiance (``none``: the expected 8-bit image; ``realistic``: EMVA 1288 noise and speckle)
and the *same* image is measured by every method:

* ``inverse-centroid`` (the paper), ``inverse-gauss``, ``inverse-steger`` — inverse
  triangulation on the standard θ grid with each detector (numpy reference path, so the
  detectors are timed alike), and ``inverse-centroid-drjit`` (the Dr.Jit kernel);
* ``classic`` — Steger 2-D line centres, rays ∩ laser plane.

Errors are the analytic radial errors r − r_true(θ, z) of the valid points (µm): mean (bias),
standard deviation, rms; coverage in degrees (0.5° bins); time per image (s).
"""

from __future__ import annotations

import functools
import json
import time
from pathlib import Path

import numpy as np

from lts360.experiments.runner import Trial, TrialOutput, grid_params, plan_trials, run_study
from lts360.folders import is_frame, read_frame_meta

__all__ = ["METHODS", "DEFAULT_OBJECTS", "algorithms_trial", "run_algorithms_study",
           "format_algorithms"]

METHODS = ("inverse-centroid", "inverse-gauss", "inverse-steger", "inverse-centroid-drjit",
           "classic")
DEFAULT_OBJECTS = ("plug-gauge", "alu-pipe", "grooved-shaft", "cable-8", "cube")
METRICS = ("bias_um", "std_um", "rms_um", "coverage_deg", "n_points", "seconds")


def _render(out: Path, name: str, *, rig: str, spp: int, seed: int) -> Path:
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame, write_frame
    from lts360.simulator.render import ensure_variant

    d = out / "renders" / name
    if not is_frame(d):
        ensure_variant()
        obj = build_object(name)
        zc = float(np.mean(obj.measured_zone_z_mm))
        write_frame(d, simulate_frame(load_rig(rig), obj, z_mm=zc, spp=spp, seed=seed,
                                      noise="none"))
    return d


@functools.lru_cache(maxsize=8)
def _setup(frame_dir: str, theta_step_deg: float, r_step_mm: float):
    """Radiance, truth object, calibration, grid and the per-method plans — once per process."""
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.classic import view_regions
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import plan_inverse
    from lts360.scenes.objects import build_object
    from lts360.simulator.io import read_exr

    d = Path(frame_dir)
    meta = read_frame_meta(d)
    ch = read_exr(d / "radiance.exr")
    obj = build_object(meta["object"]["spec"])
    z = float(meta["stage"]["z_mm"])
    th = np.linspace(-np.pi, np.pi, 1441)
    r = obj.radius_fn(th, np.full_like(th, z))
    r = r[np.isfinite(r)]
    grid = CylGrid.from_ranges((max(0.5, r.min() - 1.0), r.max() + 1.0),
                               theta_step_deg=theta_step_deg, r_step_mm=r_step_mm)
    cal = calibration_from_frame_truth(meta)
    plan = plan_inverse(cal, grid, precompute=True)
    fast = None
    try:
        from lts360.recon.triangulation.fast import FastInverse

        fast = FastInverse(plan_inverse(cal, grid, precompute=False))
    except RuntimeError:
        pass
    return ch["Y"], ch["laser"], obj, z, cal, grid, plan, fast, view_regions(cal, grid)


def _errors(points_mm: np.ndarray, theta: np.ndarray, obj, z_mm: float) -> np.ndarray:
    pts = np.asarray(points_mm, float).copy()
    pts[:, 2] = z_mm
    return obj.radial_error(pts)


def algorithms_trial(trial: Trial) -> TrialOutput:
    """Measure one noisy image of one object with every method."""
    from types import SimpleNamespace

    from lts360.recon.triangulation.classic import classic_triangulate
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import sensor_image

    p = trial.params
    Y, L, obj, z, cal, grid, plan, fast, regions = _setup(p["frame_dir"], p["theta_step_deg"],
                                                          p["r_step_mm"])
    image, _, _ = sensor_image(load_rig(p["rig"]), SimpleNamespace(radiance_W_m2_sr=Y,
                                                                   laser_W_m2_sr=L),
                               noise=p["noise"], seed=trial.seed)
    rows = []
    for method in METHODS:
        t0 = time.perf_counter()
        if method == "classic":
            res = classic_triangulate(image, cal, grid, regions=regions)
            seconds = time.perf_counter() - t0
            pts = np.concatenate([v["points_meas_mm"] for v in res.values()]) if res else \
                np.zeros((0, 3))
        else:
            if method == "inverse-centroid-drjit":
                if fast is None:
                    rows.append([np.nan] * len(METRICS))
                    continue
                res = fast(image)
            else:
                peak = method.split("-")[1]
                opts = {"line_width_mm": 0.6} if peak == "steger" else None
                res = inverse_triangulate(image, cal, grid, peak=peak, plan=plan, peak_options=opts)
            seconds = time.perf_counter() - t0
            pts = np.concatenate([v.points_meas_mm[v.valid] for v in res.views.values()])
        # Points are in the measurement frame = world frame of the frame's truth (section at z).
        pts = pts.copy()
        pts[:, 2] = z
        err = obj.radial_error(pts) * 1e3
        err = err[np.isfinite(err)]
        th = np.degrees(np.arctan2(pts[:, 1], pts[:, 0])) % 360.0
        if len(th):
            t = np.sort(th)
            cov = float(np.minimum(np.diff(np.append(t, t[0] + 360.0)), 0.5).sum())
        else:
            cov = 0.0
        rows.append([float(err.mean()) if err.size else np.nan,
                     float(err.std()) if err.size else np.nan,
                     float(np.sqrt(np.mean(err**2))) if err.size else np.nan, cov, float(err.size),
                     seconds])
    arr = np.array(rows, float)
    return TrialOutput(values={m: arr[:, k] for k, m in enumerate(METRICS)},
                       dims={m: ("method",) for m in METRICS}, coords={"method": np.array(METHODS)})


def run_algorithms_study(out_dir, *, objects=DEFAULT_OBJECTS, noises=("none", "realistic"),
                         repeats: int = 3, seed: int = 0, rig: str = "paper", spp: int = 16,
                         theta_step_deg: float = 0.1, r_step_mm: float = 0.005,
                         workers: int | None = 1, dask_address: str | None = None,
                         say=print) -> dict:
    """Render each object once, then measure ``repeats`` noise draws per noise level with every
    method; returns the table (mean over repetitions) written to ``table.json``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frames = {}
    for k, name in enumerate(objects):
        say(f"rendering {name}")
        frames[name] = str(_render(out, name, rig=rig, spp=spp, seed=seed * 100 + k).resolve())
    params = [dict(q, frame_dir=frames[q["object"]], rig=rig, theta_step_deg=theta_step_deg,
                   r_step_mm=r_step_mm)
              for q in grid_params(object=list(objects), noise=list(noises),
                                   repeat=list(range(repeats)))]
    ds = run_study(out / "trials", plan_trials(params, seed), algorithms_trial, name="algorithms",
                   workers=workers, dask_address=dask_address)
    table = {}
    for name in objects:
        for noise in noises:
            sel = (ds["object"].values == name) & (ds["noise"].values == noise)
            sub = ds.isel(trial=np.flatnonzero(sel))
            for j, method in enumerate(ds["method"].values):
                row = {m: float(np.nanmean(sub[m].values[:, j])) for m in METRICS}
                row["bias_spread_um"] = float(np.nanstd(sub["bias_um"].values[:, j]))
                table.setdefault(name, {}).setdefault(noise, {})[str(method)] = row
    (out / "table.json").write_text(json.dumps(table, indent=2))
    (out / "table.txt").write_text(format_algorithms(table) + "\n")
    return table


def format_algorithms(table: dict) -> str:
    lines = [f"{'object':14s} {'noise':10s} {'method':22s} {'bias µm':>8s} {'std µm':>7s} "
             f"{'rms µm':>7s} {'coverage':>8s} {'points':>7s} {'time ms':>8s}"]
    for name, by_noise in table.items():
        for noise, by_method in by_noise.items():
            for method, r in by_method.items():
                lines.append(f"{name:14s} {noise:10s} {method:22s} {r['bias_um']:+8.1f} "
                             f"{r['std_um']:7.1f} {r['rms_um']:7.1f} {r['coverage_deg']:7.1f}° "
                             f"{int(r['n_points']):7d} {r['seconds'] * 1e3:8.1f}")
    lines.append("(mean over the repetitions; errors are analytic radial errors of the points)")
    return "\n".join(lines)

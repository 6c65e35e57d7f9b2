"""GPU check: render rate, recon kernel and Monte Carlo wall time, printed as one table.

Three measurements, each with its target (the targets hold for the full sizes on an H100/H200;
``--quick`` shrinks every size so that the same code runs in seconds on a CPU, and marks the
targets "n/a"):

1. **Rendering** (``--variant``, default ``cuda_ad_mono``): the standard frame — paper rig,
   plug gauge, 1280×1024, thin lens, laser integrator, noise-free radiance — rendered by
   :func:`lts360.simulator.render.render_radiance` at 16 and 64 spp.  Frames/s are
   ``1 / median`` of the warm calls (the first call, which traces and compiles the kernels, is
   listed apart): once for the whole call (scene build + render + read-back, what a caller
   pays per frame) and once for ``mi.render`` + read-back alone (``RenderResult.seconds``).
   Target: ≥ 100 frames/s at 16 spp.
   **Stripe check**: on the 64-spp radiance, the stripe centre across the projected true
   section (the plug gauge's circle in the laser plane, projected through each view's mirror
   matrix with the rig's true camera) — the check of
   ``tests/simulator/test_render_physics.py`` on the library functions
   (:func:`lts360.scenes.coverage.coverage`, :func:`lts360.geometry.project_points`).
   RMS offset per view, target ≤ 0.05 px (the test's bound, there with a pinhole camera).
   **1b. Render what is measured** (issue 30): the same scene built once
   (:class:`lts360.simulator.reuse.SceneCache`) and rendered by
   :func:`lts360.simulator.frame.render_frame` — the full frame at 16 spp (target ≥ 150
   frames/s: no scene build per frame) and the pixel support alone at 16 and 256 spp (target
   ≥ 500 frames/s at 256 spp), whole calls, warm medians.
2. **Recon kernel** (``--backend``, default ``cuda``):
   :class:`lts360.recon.triangulation.fast.FastInverse` on the standard section grid of
   ``benchmarks/bench_recon.py`` (3600 θ × 801 r, r = 8..12 mm, three views), applied to the
   16-spp frame with realistic sensor noise and speckle, true calibration.  Milliseconds per
   section: whole call (upload, kernel, read-back, numpy assembly) and kernel alone
   (``FastInverse.peaks``), warm medians.  Target: ≤ 0.3 ms per section (issue 30; 1 ms before).  Agreement with the
   LLVM backend on the same image (and with the numpy reference ``inverse_triangulate(...,
   peak="centroid")``): max |Δr| in µm over the points valid in both, and the number of grid
   θ (summed over the views) whose validity differs.
3. **Monte Carlo**: wall time of 1000 trials of
   :func:`lts360.experiments.monte_carlo.mc_trial` with every input varying (``vary="all"``,
   the trial of the main run of ``lts360 study monte-carlo``, θ step 0.5°), in a pool of
   spawned worker processes (one per CPU core), as ``run_study`` runs them — but without its
   per-trial NetCDF files.  Set-up, timed apart: the study's own placement renders
   (``_render_placements``, 8 placements at 16 spp, with ``--variant``) and the true
   calibration of placement 0 written as the calibration file (it carries no covariance, so
   the drawn calibration equals it; each trial still re-does the §4.4 compensation).  The
   trial function itself is numpy/scipy on the CPU (sensor noise, speckle, inverse
   triangulation; on a 2-core VM ~90 % of a trial is its two speckle patterns, scipy FFTs):
   the GPU only renders the placements.  Target: 1000 trials ≤ 15 s (issue 30; 60 s before).  The trials stop at
   ``--mc-deadline`` seconds (or earlier, to keep the whole check within ``--budget``); then
   the row gives the trials done and the time for 1000 extrapolated from them, and says so.

``--quick`` (:data:`SIZES`): images at ¼ scale (320×256), a 4° θ step (90 θ × 801 r), 2 trials
at a 5° θ step on one 4-spp placement, one or two warm repeats.  ``--trials N`` changes the
number of Monte Carlo trials (the last row is scaled to 1000).

Usage (repository root; see ``benchmarks/gpu_check.sh``)::

    python3 benchmarks/gpu_check.py [--variant cuda_ad_mono] [--backend cuda] [--quick]
                                    [--json OUT]

On a machine without CUDA the same code paths run with
``--variant llvm_ad_mono --backend llvm --quick``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import importlib.util
import json
import multiprocessing
import os
import platform
import signal
import statistics
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

#: Python modules the check imports (directly or through lts360), by import name → wheel name.
REQUIRED_MODULES = {
    "numpy": "numpy", "scipy": "scipy", "trimesh": "trimesh", "manifold3d": "manifold3d",
    "OpenEXR": "OpenEXR",
    "cv2": "opencv-python-headless", "xarray": "xarray", "pandas": "pandas", "tqdm": "tqdm",
    "mitsuba": "mitsuba", "drjit": "drjit",
}

VIEWS = ("direct", "left", "right")

#: Sizes of a full check and of a quick one (CPU, CI): image scale, spp, repeats, grid, trials.
SIZES = {
    "full": {"scale": 1.0, "spps": (16, 64), "render_repeats": 5, "theta_step_deg": 0.1,
             "recon_repeats": 20, "mc_trials": 1000, "mc_placements": 8, "mc_spp": 16,
             "mc_theta_step_deg": 0.5, "stripe_step": 5},
    "quick": {"scale": 0.25, "spps": (16, 64), "render_repeats": 1, "theta_step_deg": 4.0,
              "recon_repeats": 2, "mc_trials": 2, "mc_placements": 1, "mc_spp": 4,
              "mc_theta_step_deg": 5.0, "stripe_step": 20},
}

#: Targets of the full check: row key → (comparison, bound).  Issue 30's: a full frame at
#: 16 spp on a scene built once ≥ 150 frames/s, a support-only frame at 256 spp ≥ 500 frames/s,
#: the recon call ≤ 0.3 ms, 1000 Monte Carlo trials ≤ 15 s.
TARGETS = {
    "render_fps_16": (">=", 100.0),
    "full_cached_fps_16": (">=", 150.0),
    "support_fps_256": (">=", 500.0),
    "stripe_rms_px": ("<=", 0.05),
    "recon_ms": ("<=", 0.3),
    "mc_1000_s": ("<=", 15.0),
}


# --- helpers --------------------------------------------------------------------------------


def missing_modules(modules: dict[str, str] = REQUIRED_MODULES) -> list[str]:
    """Wheel names of the required modules that cannot be imported here."""
    return [wheel for name, wheel in modules.items() if importlib.util.find_spec(name) is None]


def timed(fn, repeats: int) -> dict:
    """Wall times (s) of ``fn()``: the first call apart, then the median of ``repeats`` calls.

    Returns ``{"first_s", "median_s", "warm_s": [...], "last": <fn()'s last result>}``.
    """
    t0 = time.perf_counter()
    last = fn()
    first = time.perf_counter() - t0
    warm = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        last = fn()
        warm.append(time.perf_counter() - t0)
    return {"first_s": first, "median_s": statistics.median(warm), "warm_s": warm, "last": last}


def row(key: str, what: str, value, unit: str, note: str = "", target: str | None = None
        ) -> dict:
    """One line of the table (``value`` a number, or None when it could not be measured);
    ``target`` names its entry of :data:`TARGETS` (default: ``key``)."""
    return {"key": key, "what": what, "value": None if value is None else float(value),
            "unit": unit, "note": note, "target": key if target is None else target}


def error_row(key: str, what: str, exc: BaseException) -> dict:
    """A row for a part that failed: the exception in one line."""
    msg = f"{type(exc).__name__}: {exc}".splitlines()[0][:120]
    return row(key, what, None, "", f"FAILED {msg}")


def verdict(key: str, value, quick: bool) -> str:
    """``yes``/``no`` against :data:`TARGETS`, ``n/a`` in quick mode or without a target."""
    if key not in TARGETS or value is None:
        return ""
    op, bound = TARGETS[key]
    if quick:
        return "n/a"
    ok = value >= bound if op == ">=" else value <= bound
    return "yes" if ok else "NO"


def format_table(rows: list[dict], quick: bool) -> str:
    """The rows as one plain-text table: what | value | unit | target | met | note."""
    head = ("what", "value", "unit", "target", "met", "note")
    lines = []
    for r in rows:
        v = r["value"]
        val = "—" if v is None else (f"{v:.4g}" if abs(v) < 1e4 else f"{v:.0f}")
        tgt = TARGETS.get(r["target"])
        tgt_s = f"{tgt[0]} {tgt[1]:g}" if tgt else ""
        lines.append((r["what"], val, r["unit"], tgt_s, verdict(r["target"], v, quick),
                      r["note"]))
    widths = [max(len(head[i]), *(len(l[i]) for l in lines)) for i in range(len(head))]
    fmt = " | ".join(f"{{:{'>' if i == 1 else '<'}{w}}}" for i, w in enumerate(widths))
    out = [fmt.format(*head), "-+-".join("-" * w for w in widths)]
    out += [fmt.format(*l).rstrip() for l in lines]
    return "\n".join(out)


# --- 1. rendering ---------------------------------------------------------------------------


def standard_scene(rig, obj):
    """The standard frame's scene: the object alone, no ambient light."""
    from lts360.simulator.scene import SceneSpec, object_meshes

    return SceneSpec(rig, object_meshes(obj), ambient="off")


def render_rate(spec, spp: int, scale: float, repeats: int) -> dict:
    """Frames/s of :func:`render_radiance` (whole call and ``mi.render`` + read-back alone).

    Returns ``{"first_s", "fps", "render_fps", "result"}``; the rates are 1 / median of the
    warm calls (s⁻¹); ``result`` is the last :class:`RenderResult`.
    """
    from lts360.simulator.render import render_radiance

    seconds = []

    def call():
        res = render_radiance(spec, spp=spp, seed=1, scale=scale)
        seconds.append(res.seconds)
        return res

    t = timed(call, repeats)
    return {"first_s": t["first_s"], "fps": 1.0 / t["median_s"],
            "render_fps": 1.0 / statistics.median(seconds[1:]), "result": t["last"]}


def _view_matrix(rig, view: str) -> np.ndarray:
    """Product of the mirror matrices of ``view`` (object → first mirror → … → camera)."""
    T = np.eye(4)
    if view != "direct":
        for name in view.split("-"):
            T = rig.mirror(name).T @ T
    return T


def stripe_offsets_px(radiance: np.ndarray, K: np.ndarray, rig, radius_mm: float, view: str, *,
                      inset_deg: float = 12.0, every: int = 5, half_px: float = 8.0
                      ) -> np.ndarray:
    """Stripe centre minus the projected true section, across the stripe (px), per θ sample.

    The circle of ``radius_mm`` in the laser plane is projected into ``view`` with the rig's
    true camera and intrinsics ``K`` (those of the rendered image).  At every ``every``-th θ
    of the view's measured window (0.1° steps, ``inset_deg`` inside each end, where the stripe
    is grazing or occluded), the radiance is sampled (bilinear) along the normal of the
    projected curve over ±``half_px`` px and the centroid's offset is returned.
    """
    from scipy.ndimage import map_coordinates

    from lts360.geometry import project_points
    from lts360.scenes.coverage import coverage

    cam = rig.camera
    cov = coverage(rig, radius_mm)
    seen = cov.measured[view]
    mask = seen.copy()
    for s in range(1, int(round(inset_deg / cov.step_deg)) + 1):
        mask &= np.roll(seen, s) & np.roll(seen, -s)
    theta = cov.theta_rad[mask][::every]

    def project(th):
        pts = radius_mm * np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
        return project_points(pts, K, cam.distortion, cam.R, cam.t_mm,
                              T_mirror=_view_matrix(rig, view))

    uv = project(theta)
    tangent = project(theta + 1e-4) - uv
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    s = np.linspace(-half_px, half_px, int(round(40 * half_px)) + 1)
    xy = uv[:, None, :] + s[None, :, None] * normal[:, None, :]
    prof = map_coordinates(radiance, [xy[..., 1].ravel(), xy[..., 0].ravel()], order=1,
                           mode="constant").reshape(len(theta), len(s))
    total = prof.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, (prof * s).sum(axis=1) / total, np.nan)


def stripe_rms_px(res, rig, obj, every: int) -> dict[str, float]:
    """RMS stripe-centre offset (px) per view of a rendered plug gauge (NaN: unlit samples)."""
    radius = obj.params["diameter_mm"] / 2.0
    out = {}
    for view in VIEWS:
        off = stripe_offsets_px(res.radiance_W_m2_sr, res.K, rig, radius, view, every=every)
        out[view] = float(np.sqrt(np.mean(off**2))) if off.size else float("nan")
    return out


def render_rows(rig, obj, size: dict) -> tuple[list[dict], dict]:
    """Rows of part 1; also returns the raw numbers."""
    spec = standard_scene(rig, obj)
    rows, raw = [], {}
    last = None
    for spp in size["spps"]:
        r = render_rate(spec, spp, size["scale"], size["render_repeats"])
        last = r["result"]
        raw[f"render_{spp}spp"] = {k: v for k, v in r.items() if k != "result"}
        rows += [row(f"render_first_{spp}", f"render {spp} spp: first call (compiles)",
                     r["first_s"], "s"),
                 row(f"render_fps_{spp}", f"render {spp} spp: render_radiance, warm", r["fps"], "frames/s"),
                 row(f"render_only_fps_{spp}", f"render {spp} spp: mi.render + read-back",
                     r["render_fps"], "frames/s")]
    spp = size["spps"][-1]
    rms = stripe_rms_px(last, rig, obj, size["stripe_step"])
    raw["stripe_rms_px"] = rms
    rows += [row(f"stripe_rms_px_{v}", f"stripe centre vs projected section, {v} ({spp} spp)",
                 rms[v], "px RMS", target="stripe_rms_px") for v in VIEWS]
    return rows, raw


def support_rows(rig, obj, size: dict) -> tuple[list[dict], dict]:
    """Rows of part 1b: frames rendered on a scene built once (:class:`SceneCache`), the full
    frame and the pixel support side by side (:func:`lts360.simulator.frame.render_frame`:
    whole call, support looked up in the cache, render, read-back)."""
    from lts360.simulator.frame import render_frame
    from lts360.simulator.reuse import SceneCache

    spec = standard_scene(rig, obj)
    rows, raw = [], {}
    for support, spp in (("full", 16), ("geometric", 16), ("geometric", 256)):
        cache = SceneCache()
        out = {}

        def call():
            res, sup = render_frame(spec, spp=spp, seed=1, scale=size["scale"], support=support,
                                    scenes=cache)
            out["pixels"] = int(sup.mask.sum())
            return res

        t = timed(call, size["render_repeats"])
        key = f"{'full_cached' if support == 'full' else 'support'}_fps_{spp}"
        raw[key] = {"first_s": t["first_s"], "median_s": t["median_s"], "pixels": out["pixels"]}
        what = ("full frame, scene built once" if support == "full"
                else f"support only ({out['pixels']} px), scene built once")
        rows.append(row(key, f"render {spp} spp: {what}", 1.0 / t["median_s"], "frames/s"))
    return rows, raw


# --- 2. recon kernel ------------------------------------------------------------------------


def standard_frame(rig, obj, scale: float):
    """The 16-spp frame with realistic noise and speckle, and its true calibration."""
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.simulator.frame import simulate_frame

    frame = simulate_frame(rig, obj, spp=16, seed=1, noise="realistic", scale=scale)
    truth = json.loads(json.dumps(frame.truth, default=lambda v: v.tolist()))
    return frame.image, calibration_from_frame_truth(truth)


def compare_results(a, b) -> tuple[float, int]:
    """Max |Δr| (µm) over the points valid in both, and the count of θ whose validity differs
    (summed over the views)."""
    worst, differ = 0.0, 0
    for name, va in a.views.items():
        vb = b.views[name]
        both = va.valid & vb.valid
        if both.any():
            worst = max(worst, float(np.max(np.abs(va.r_mm[both] - vb.r_mm[both]))) * 1e3)
        differ += int(np.count_nonzero(va.valid != vb.valid))
    return worst, differ


def section_grid(theta_step_deg: float):
    """The standard section grid of ``bench_recon.py`` (r = 8..12 mm, 5 µm) at ``theta_step_deg``."""
    from lts360.recon.triangulation.grid import CylGrid

    return CylGrid.from_ranges((8.0, 12.0), theta_step_deg=theta_step_deg, r_step_mm=0.005)


def recon_rows(image, cal, backend: str, size: dict) -> tuple[list[dict], dict]:
    """Rows of part 2: plan and setup times, ms per section, agreement with LLVM and numpy."""
    from lts360.recon.images import default_saturation, default_threshold
    from lts360.recon.triangulation.fast import FastInverse
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse

    grid = section_grid(size["theta_step_deg"])
    t0 = time.perf_counter()
    plan = plan_inverse(cal, grid, precompute=False)
    plan_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    fast = FastInverse(plan, backend=backend)
    setup_s = time.perf_counter() - t0
    call = timed(lambda: fast(image), size["recon_repeats"])
    thr = default_threshold(image)
    sat = default_saturation(image)
    if sat is not None and sat <= thr:
        sat = None
    kernel = timed(lambda: fast.peaks(image, threshold=thr, saturation=sat),
                   size["recon_repeats"])
    result = call["last"]
    tag = f"{grid.shape[0]}θ×{grid.shape[1]}r"
    rows = [row("recon_plan_s", f"recon plan ({tag}, once per calibration)", plan_s, "s"),
            row("recon_setup_s", f"recon {backend} setup (once per plan)", setup_s, "s"),
            row("recon_first_ms", f"recon {backend}: first call (compiles)",
                call["first_s"] * 1e3, "ms"),
            row("recon_ms", f"recon {backend}: ms per section, whole call",
                call["median_s"] * 1e3, "ms"),
            row("recon_kernel_ms", f"recon {backend}: kernel alone (peaks)",
                kernel["median_s"] * 1e3, "ms")]
    raw = {"grid": list(grid.shape), "plan_s": plan_s, "setup_s": setup_s,
           "call": {k: v for k, v in call.items() if k != "last"},
           "kernel": {k: v for k, v in kernel.items() if k != "last"}}
    refs = {"llvm": lambda: FastInverse(plan, backend="llvm")(image),
            "numpy": lambda: inverse_triangulate(image, cal, grid, peak="centroid", plan=plan)}
    for name, ref in refs.items():
        what = f"recon {backend} vs {name}"
        try:
            dr_um, differ = compare_results(result, ref())
        except Exception as exc:  # e.g. no libLLVM on the GPU machine
            rows.append(error_row(f"recon_vs_{name}", f"{what}: max |Δr|", exc))
            continue
        raw[f"vs_{name}"] = {"max_dr_um": dr_um, "validity_differs": differ}
        rows += [row(f"recon_vs_{name}_um", f"{what}: max |Δr|, valid in both", dr_um, "µm"),
                 row(f"recon_vs_{name}_n", f"{what}: θ whose validity differs", differ,
                     "points")]
    return rows, raw


# --- 3. Monte Carlo -------------------------------------------------------------------------


def mc_setup(out_dir: Path, placements: int, spp: int, rig_name: str = "paper") -> dict:
    """The study's placement renders and a calibration file (the truth of placement 0).

    Returns the base trial parameters of the main run (``vary="all"``, compensated), as
    :func:`run_monte_carlo_study` builds them, minus ``theta_step_deg``.
    """
    from lts360.experiments.monte_carlo import _render_placements
    from lts360.recon.model import calibration_from_frame_truth, save_calibration

    renders = _render_placements(out_dir, placements, rig=rig_name, seed=0, spp=spp,
                                 say=lambda _msg: None)
    truth = json.loads((renders / "placement_00" / "frame.json").read_text())
    cal_path = out_dir / "calibration.json"
    save_calibration(cal_path, calibration_from_frame_truth(truth))
    return {"calibration": str(cal_path.resolve()), "renders": str(renders.resolve()),
            "placements": placements, "rig": rig_name, "compensate": True,
            "compensation_shots": 1, "vary": "all"}


def mc_wall_time(base: dict, n_trials: int, theta_step_deg: float, workers: int,
                 deadline_s: float) -> dict:
    """Wall time (s) of ``n_trials`` :func:`mc_trial` calls in a spawn pool of ``workers``.

    Timed from the pool's creation (worker start-up and imports included) to the last trial's
    result, or to ``deadline_s``, when the pending trials are cancelled.  Returns
    ``{"done", "wall_s", "per_1000_s", "cut", "finite_y"}``; ``per_1000_s`` is the wall time
    scaled to 1000 trials (exact when ``n_trials`` is 1000 and nothing was cut).
    """
    from lts360.experiments.monte_carlo import mc_trial
    from lts360.experiments.runner import plan_trials

    trials = plan_trials([dict(base, theta_step_deg=theta_step_deg)] * n_trials, seed=0)
    ys = []
    t0 = time.perf_counter()
    pool = concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = [pool.submit(mc_trial, t) for t in trials]
        for f in concurrent.futures.as_completed(futures, timeout=max(1.0, deadline_s)):
            ys.append(f.result().values["y_um"])
    except concurrent.futures.TimeoutError:
        pass
    finally:
        wall = time.perf_counter() - t0
        pool.shutdown(wait=False, cancel_futures=True)  # running trials end on their own
    done = len(ys)
    return {"done": done, "wall_s": wall, "cut": done < n_trials,
            "per_1000_s": wall * 1000.0 / done if done else None,
            "finite_y": int(np.count_nonzero(np.isfinite(ys)))}


def mc_rows(size: dict, workers: int, deadline_s: float) -> tuple[list[dict], dict]:
    """Rows of part 3: set-up time and the wall time of the trials."""
    with tempfile.TemporaryDirectory(prefix="lts360-gpu-check-") as tmp:
        t0 = time.perf_counter()
        base = mc_setup(Path(tmp), size["mc_placements"], size["mc_spp"])
        setup_s = time.perf_counter() - t0
        r = mc_wall_time(base, size["mc_trials"], size["mc_theta_step_deg"], workers,
                         deadline_s)
    n = size["mc_trials"]
    note = (f"CUT at {deadline_s:.0f} s after {r['done']}/{n} trials: extrapolated"
            if r["cut"] else f"{r['done']} trials measured" + ("" if n == 1000 else
                                                                ", scaled to 1000"))
    rows = [row("mc_setup_s", f"MC set-up: {size['mc_placements']} placement renders "
                              f"({size['mc_spp']} spp) + calibration file", setup_s, "s"),
            row("mc_wall_s", f"MC {r['done']} trials, {workers} worker processes", r["wall_s"],
                "s", f"{r['finite_y']} finite y"),
            row("mc_1000_s", "MC: 1000 trials, wall", r["per_1000_s"], "s", note)]
    return rows, dict(r, setup_s=setup_s, workers=workers, trials=n)


# --- driver ---------------------------------------------------------------------------------


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variant", default="cuda_ad_mono", help="Mitsuba variant (rendering)")
    ap.add_argument("--backend", default="cuda", choices=("cuda", "llvm"),
                    help="Dr.Jit backend of the recon kernel")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (CPU / CI)")
    ap.add_argument("--workers", type=int, default=None,
                    help="Monte Carlo worker processes (default: CPU cores, ≤ trials)")
    ap.add_argument("--trials", type=int, default=None,
                    help="Monte Carlo trials (default 1000, quick 2; the row scales to 1000)")
    ap.add_argument("--mc-deadline", type=float, default=180.0,
                    help="stop the Monte Carlo trials after this many seconds (extrapolate)")
    ap.add_argument("--budget", type=float, default=390.0,
                    help="seconds for the whole check: the trials stop in time for it")
    ap.add_argument("--json", default=None, help="write rows and raw numbers here")
    return ap.parse_args(argv)


class Stopped(BaseException):
    """Raised by the SIGTERM handler (``timeout``): the rows so far are still printed."""


def _stop(signum, frame):
    raise Stopped(f"signal {signum}")


def run_check(variant: str, backend: str, quick: bool, workers: int | None = None,
              mc_deadline_s: float = 180.0, budget_s: float = 390.0,
              trials: int | None = None, rows: list | None = None) -> dict:
    """Run the three parts; a part that fails leaves a FAILED row and the others still run.

    The Monte Carlo trials stop at ``mc_deadline_s`` (s) or when ``budget_s`` (s, counted
    from this call) is nearly spent, whichever comes first.  Rows are appended to ``rows``
    as they are measured (pass a list to keep them should the check be interrupted).
    Returns ``{"rows": [...], "raw": {...}, "meta": {...}}``.
    """
    import mitsuba as mi

    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig

    t_start = time.perf_counter()
    mi.set_variant(variant)
    size = dict(SIZES["quick" if quick else "full"])
    if trials is not None:
        size["mc_trials"] = int(trials)
    rig, obj = load_rig("paper"), build_object("plug-gauge")
    rows = [] if rows is None else rows
    raw = {}
    parts_s = {}

    def part(name: str, what: str, fn) -> None:
        """Run one part; its rows, raw numbers and wall time (s) are kept, or a FAILED row."""
        t0 = time.perf_counter()
        try:
            r, raw[name] = fn()
            rows.extend(r)
        except Exception as exc:
            traceback.print_exc()
            rows.append(error_row(name, what, exc))
        parts_s[name] = time.perf_counter() - t0

    part("render", f"render ({variant})", lambda: render_rows(rig, obj, size))
    part("support", f"render on the support ({variant})", lambda: support_rows(rig, obj, size))
    part("recon", f"recon ({backend})",
         lambda: recon_rows(*standard_frame(rig, obj, size["scale"]), backend, size))
    n_workers = workers or max(1, min(os.cpu_count() or 1, size["mc_trials"]))
    left = budget_s - (time.perf_counter() - t_start) - 30.0  # set-up and shut-down margin
    part("mc", "Monte Carlo",
         lambda: mc_rows(size, n_workers, max(10.0, min(mc_deadline_s, left))))
    meta = {"variant": variant, "backend": backend, "quick": quick, "size": size,
            "machine": f"{platform.node()} {os.cpu_count()} cores {platform.processor()}",
            "python": sys.version.split()[0], "parts_s": parts_s,
            "total_s": time.perf_counter() - t_start}
    return {"rows": rows, "raw": raw, "meta": meta}


def main(argv=None) -> int:
    args = parse_args(argv)
    missing = missing_modules()
    if missing:
        print("MISSING (fetch their cp312 wheels with ../shared/tools/gpu-wheels.sh): "
              + " ".join(missing))
        if {"mitsuba", "drjit", "numpy"} & set(missing):
            return 2
    previous = signal.signal(signal.SIGTERM, _stop)
    rows = []
    t0 = time.perf_counter()
    try:
        out = run_check(args.variant, args.backend, args.quick, args.workers, args.mc_deadline,
                        args.budget, args.trials, rows)
    except (Stopped, KeyboardInterrupt) as exc:
        rows.append(row("stopped", "check interrupted", None, "", f"STOPPED ({exc})"))
        out = {"rows": rows, "raw": {}, "meta": {
            "variant": args.variant, "backend": args.backend, "quick": args.quick,
            "machine": f"{platform.node()} {os.cpu_count()} cores {platform.processor()}",
            "total_s": time.perf_counter() - t0}}
    finally:
        signal.signal(signal.SIGTERM, previous)
    m = out["meta"]
    print(f"lts360 GPU check — variant {m['variant']}, backend {m['backend']}"
          f"{', QUICK sizes (targets n/a)' if m['quick'] else ''}; {m['machine']}; "
          f"{m['total_s']:.0f} s"
          + "".join(f", {k} {v:.0f} s" for k, v in m.get("parts_s", {}).items()))
    print(format_table(out["rows"], args.quick))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())

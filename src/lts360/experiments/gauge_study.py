"""``lts360 study plug-gauge``: the measurement uncertainty evaluation of paper §4.5.

The Ø19.9987 mm plain plug gauge is placed ``n`` times (random offset and tilt within a
placement tolerance), imaged with realistic noise (EMVA 1288 sensor and speckle) and measured
by inverse triangulation with a calibration *estimated from rendered chessboard images*
(``lts360 calibrate``), with the residual compensation of §4.4 (view offsets from one
measurement of the gauge at the nominal position).  Each measurement gives, as in the paper,
a circle fit and the radius of every point about the fitted centre: the radius error (fitted
minus true radius) and the standard deviation of the point radii.

By default the study measures as a user of the rig would: beside §4.4 the compensation is
mastered with the gauge's known diameter (one Ø20 master, :func:`~lts360.recon.calibration.
compensation.master_fit`) and each placement's line-centre bias is removed by its twin
(:mod:`lts360.twin`); each is switchable (``master``, ``bias_model``).  Every placement's
image is also measured with each step on and off (:data:`STEPS`, the same image), so the
table shows the paper's method (§4.4 alone) beside ours and U with and without each step.

The table puts the paper's numbers beside ours: mean radius error, worst-case standard
deviation, the temperature and resolution terms, the combined expanded uncertainty (k = 2)
and the maximum error |mean| + U.  The recipe is the paper's: U = k·√(s_worst² + u_T² + u_res²),
u_T from a ±5 °C change of a steel gauge (rectangular), u_res from the 1 µm resolution
(rectangular, half-width 0.5 µm).
"""

from __future__ import annotations

import functools
import json
import math
import os
from pathlib import Path

import numpy as np

from lts360.experiments.runner import Trial, TrialOutput, plan_trials, run_study, trial_setup

__all__ = ["GAUGE_DIAMETER_MM", "STEPS", "DEFAULT_PLACEMENT_MM", "placement_band_mm", "by_offset",
           "PAPER_TABLE", "gauge_placements", "plug_gauge_trial",
           "gauge_table", "run_plug_gauge_study", "measure_gauge_image", "format_gauge_table",
           "ensure_calibration"]

GAUGE_DIAMETER_MM = 19.9987
#: Paper §4.5 (mm).
PAPER_TABLE = {"mean_radius_error_mm": 0.015, "worst_std_mm": 0.025,
               "temperature_mm": 0.0003, "resolution_mm": 0.001,
               "expanded_uncertainty_mm": 0.05, "max_error_mm": 0.067}
#: Linear expansion of gauge steel (1/K) and the temperature band of the paper (K).
STEEL_ALPHA_PER_K = 11.5e-6
DELTA_T_K = 5.0
RESOLUTION_MM = 0.001
VIEWS = ("direct", "left", "right")
#: The steps every placement is measured with (``steps=True``): key, label, (§4.4, master,
#: bias model).  The master is the gauge itself at the nominal position (its known diameter).
STEPS = (("none", "no compensation", (False, False, "none")),
         ("c44", "§4.4 (the paper's method)", (True, False, "none")),
         ("c44_master", "§4.4 + master", (True, True, "none")),
         ("c44_twin", "§4.4 + twin", (True, False, "twin")),
         ("c44_master_twin", "§4.4 + master + twin", (True, True, "twin")))
#: Radius (mm) of the disc the gauge's placements are drawn in (a V-block put back by hand).
DEFAULT_PLACEMENT_MM = 0.3


def placement_band_mm(placement_mm: float) -> float:
    """Half-width of the fixed radial band about the gauge's radius that holds every placement
    within ``placement_mm`` of the axis: ±1 mm about the true radius at the nominal
    ``DEFAULT_PLACEMENT_MM``, widened by the placement beyond it."""
    if not 0 <= placement_mm <= 20:
        raise ValueError(f"placement_mm must be in [0, 20], got {placement_mm}")
    return 1.0 + max(0.0, float(placement_mm) - DEFAULT_PLACEMENT_MM)


def by_offset(ds, *, bins: int = 4) -> list[dict]:
    """Results against the gauge's distance from the axis (``offset_mm`` of each trial):
    per bin of equal width up to the largest offset, the trials, the mean radius error and the
    spread of the per-view mean errors (largest minus smallest, mean over the trials)."""
    if "offset_mm" not in ds:
        return []
    off = np.asarray(ds["offset_mm"].values, float)
    err = np.asarray(ds["radius_error_mm"].values, float)
    spread = np.full(off.size, np.nan)
    if "view_mean_mm" in ds:
        vm = np.asarray(ds["view_mean_mm"].values, float)
        with np.errstate(all="ignore"):
            spread = np.nanmax(vm, axis=1) - np.nanmin(vm, axis=1)
    hi = float(np.nanmax(off)) if off.size else 0.0
    edges = np.linspace(0.0, hi if hi > 0 else 1.0, bins + 1)
    rows = []
    for k in range(bins):
        m = (off >= edges[k]) & ((off < edges[k + 1]) if k < bins - 1 else (off <= edges[k + 1]))
        if not m.any():
            continue
        rows.append({"offset_from_mm": float(edges[k]), "offset_to_mm": float(edges[k + 1]),
                     "n": int(m.sum()), "mean_radius_error_mm": float(np.nanmean(err[m])),
                     "view_spread_mm": float(np.nanmean(spread[m]))
                     if np.isfinite(spread[m]).any() else None})
    return rows


def gauge_placements(n: int, seed: int, *, offset_mm: float = DEFAULT_PLACEMENT_MM,
                     tilt_deg: float = 0.3,
                     diameter_mm: float = GAUGE_DIAMETER_MM) -> list[dict]:
    """Trial parameters: the gauge put in its V-block ``n`` times.

    Offsets uniform in a disc of radius ``offset_mm``, tilt uniform in [0, ``tilt_deg``] at a
    uniform azimuth — a realistic tolerance for putting a gauge back by hand (paper: "placed
    ten times for the approximately same place").
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x6A06E]))
    out = []
    for _ in range(n):
        r = offset_mm * math.sqrt(rng.uniform())
        phi = rng.uniform(0.0, 2.0 * math.pi)
        x, y = r * math.cos(phi), r * math.sin(phi)
        tilt = rng.uniform(0.0, tilt_deg)
        az = rng.uniform(0.0, 360.0)
        out.append({"spec": f"plug-gauge:d={diameter_mm},x={x:.6f},y={y:.6f},"
                            f"tilt_deg={tilt:.6f},tilt_azimuth_deg={az:.4f}"})
    return out


def _plan(cal_path, r_mm: float, band_mm: float, theta_step_deg: float, r_step_mm: float):
    """Calibration, grid and the Dr.Jit kernel (or the numpy plan) — once per process and
    calibration file version (a file rewritten under the same name is read again)."""
    st = os.stat(cal_path)
    return _cached_plan(str(cal_path), (st.st_mtime_ns, st.st_size), float(r_mm), band_mm,
                        theta_step_deg, r_step_mm)


@functools.lru_cache(maxsize=4)
def _cached_plan(cal_path: str, version: tuple, r_mm: float, band_mm: float,
                 theta_step_deg: float, r_step_mm: float):
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import plan_inverse

    cal = load_calibration(cal_path)
    grid = CylGrid.from_ranges((r_mm - band_mm, r_mm + band_mm), theta_step_deg=theta_step_deg,
                               r_step_mm=r_step_mm)
    try:
        from lts360.recon.triangulation.fast import FastInverse

        return cal, grid, FastInverse(plan_inverse(cal, grid, precompute=False))
    except RuntimeError:  # no Dr.Jit LLVM: the numpy reference
        return cal, grid, plan_inverse(cal, grid, precompute=True)


@functools.lru_cache(maxsize=4)
def _window_pixels(cal_path: str, version: tuple, r_mm: float, band_mm: float,
                   theta_step_deg: float, r_step_mm: float) -> np.ndarray:
    """The pixels :func:`measure_gauge_image` reads with this calibration (the trials render
    only these: the band's projection in every view, a fifth of the image)."""
    from lts360.recon.model import load_calibration
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import plan_inverse, plan_pixels

    grid = CylGrid.from_ranges((r_mm - band_mm, r_mm + band_mm), theta_step_deg=theta_step_deg,
                               r_step_mm=r_step_mm)
    return plan_pixels(plan_inverse(load_calibration(cal_path), grid, precompute=False))


def gauge_window_pixels(cal_path, r_mm: float, *, band_mm: float = 1.0,
                        theta_step_deg: float = 0.1, r_step_mm: float = 0.005) -> np.ndarray:
    """(n, 2) int: the pixels a gauge of radius ``r_mm`` is measured from with the
    calibration ``cal_path`` (see :func:`measure_gauge_image`)."""
    st = os.stat(cal_path)
    return _window_pixels(str(cal_path), (st.st_mtime_ns, st.st_size), float(r_mm),
                          float(band_mm), float(theta_step_deg), float(r_step_mm))


def measure_gauge_image(image, cal_path: str, *, r_true_mm: float, band_mm: float = 1.0,
                        theta_step_deg: float = 0.1, r_step_mm: float = 0.005,
                        compensate: bool = True, cloud_path=None,
                        bias_model: str = "none") -> dict:
    """Measure one image of a round section and score it as the paper does (no truth but
    the nominal radius): circle fit, radius error, and the point radii about the centre.
    ``bias_model="twin"``: the line-centre bias removed by the section's twin (the rig the
    calibration records)."""
    from lts360.geometry.fit import fit_circle
    from lts360.recon.triangulation.inverse import InversePlan, inverse_triangulate

    cal, grid, kernel = _plan(str(cal_path), float(r_true_mm), band_mm, theta_step_deg, r_step_mm)

    def measure(img):
        if isinstance(kernel, InversePlan):
            return inverse_triangulate(img, cal, grid, plan=kernel, compensate=compensate)
        return kernel(img, compensate=compensate)

    res = measure(image)
    if bias_model == "twin":
        from lts360.twin import TwinCorrector
        from lts360.twin.rig import twin_design

        twin = TwinCorrector(cal, twin_design(cal), input_u=None)
        res = twin(res, measure, kernel if isinstance(kernel, InversePlan) else kernel.plan)
    elif bias_model != "none":
        raise ValueError(f"bias_model must be none or twin, got {bias_model!r}")
    if cloud_path is not None:
        from lts360.recon.triangulation.cloud import write_cloud
        from lts360.recon.triangulation.measure import result_to_cloud

        Path(cloud_path).parent.mkdir(parents=True, exist_ok=True)
        write_cloud(cloud_path, result_to_cloud(res, z_mm=0.0, section=0))
    pts, labels = [], []
    for name, v in res.views.items():
        ok = v.valid  # accepted qualities, compensated
        pts.append(v.points_meas_mm[ok, :2])
        labels += [name] * int(ok.sum())
    pts = np.concatenate(pts) if pts else np.zeros((0, 2))
    labels = np.array(labels)
    out = {"n_points": len(pts)}
    if len(pts) < 10:
        out.update(radius_error_mm=np.nan, point_std_mm=np.nan, coverage_deg=0.0)
        return out
    fit = fit_circle(pts)
    r = np.hypot(*(pts - fit.center_mm).T)
    theta = np.degrees(np.arctan2(*(pts - fit.center_mm).T[::-1])) % 360.0
    gaps = np.diff(np.append(np.sort(theta), np.sort(theta)[0] + 360.0))
    out.update(radius_error_mm=float(fit.radius_mm - r_true_mm), point_std_mm=float(r.std()),
               form_range_mm=float(r.max() - r.min()),
               point_rms_mm=float(np.sqrt(np.mean((r - r_true_mm) ** 2))),
               max_abs_error_mm=float(np.abs(r - r_true_mm).max()),
               coverage_deg=float(np.minimum(gaps, 0.5).sum()),
               center_x_mm=float(fit.center_mm[0]), center_y_mm=float(fit.center_mm[1]))
    out["view_mean_mm"] = np.array([float(np.mean(r[labels == v] - r_true_mm))
                                    if np.any(labels == v) else np.nan for v in VIEWS])
    out["view_std_mm"] = np.array([float(np.std(r[labels == v])) if np.any(labels == v)
                                   else np.nan for v in VIEWS])
    out["view_n"] = np.array([int(np.sum(labels == v)) for v in VIEWS])
    return out


def _step_key(compensate: bool, master: bool, bias_model: str) -> str | None:
    """The :data:`STEPS` key of a configuration (None: not one of them)."""
    for key, _, conf in STEPS:
        if conf == (bool(compensate), bool(master) and bool(compensate), bias_model):
            return key
    return None


def _config_label(compensate: bool, master: bool, bias_model: str) -> str:
    """What a configuration does, in words (e.g. ``no compensation + twin``)."""
    parts = ["§4.4" if compensate else "no compensation"]
    parts += ["master"] if master and compensate else []
    parts += ["twin"] if bias_model == "twin" else []
    return " + ".join(parts)


def plug_gauge_trial(trial: Trial) -> TrialOutput:
    """Render the gauge at the trial's placement (realistic noise) and measure it: with the
    study's configuration and, with ``steps``, with each of :data:`STEPS` (the same image)."""
    from lts360.simulator.frame import simulate_frame

    p = trial.params
    rig, obj = trial_setup(p, spec=p["spec"])
    r_mm = obj.params["diameter_mm"] / 2
    band = placement_band_mm(float(p.get("placement_mm", DEFAULT_PLACEMENT_MM)))
    # Only the pixels the measurement reads are rendered (the rest of the image is not used).
    frame = simulate_frame(rig, obj, spp=int(p["spp"]), seed=trial.seed,
                           noise=p["noise"],
                           pixels_xy=gauge_window_pixels(p["calibration"], r_mm, band_mm=band),
                           max_scatter=int(p.get("max_scatter", 0)))
    cloud = Path(p["clouds"]) / f"placement_{trial.index:02d}.ply" if p.get("clouds") else None
    ours_key = _step_key(bool(p["compensate"]), bool(p.get("master", False)),
                         p.get("bias_model", "none"))
    steps = {}
    if p.get("steps"):
        for key, _, (comp, _, bias) in STEPS:
            steps[key] = measure_gauge_image(
                frame.image, p[f"cal_{key}"], r_true_mm=r_mm, band_mm=band, compensate=comp,
                bias_model=bias, cloud_path=cloud if key == ours_key else None)
    m = steps.get(ours_key) if ours_key in steps else measure_gauge_image(
        frame.image, p["calibration"], r_true_mm=r_mm, band_mm=band,
        compensate=bool(p["compensate"]), cloud_path=cloud,
        bias_model=p.get("bias_model", "none"))
    m = dict(m)
    m["offset_mm"] = float(np.hypot(obj.placement.x_mm, obj.placement.y_mm))
    arrays = {k: m.pop(k) for k in ("view_mean_mm", "view_std_mm", "view_n") if k in m}
    values = {k: float(v) for k, v in m.items()}
    values.update(arrays)
    dims = {k: ("view",) for k in arrays}
    coords = {"view": np.array(VIEWS)} if arrays else {}
    if steps:
        for name in ("radius_error_mm", "point_std_mm", "form_range_mm"):
            values[f"step_{name}"] = np.array([steps[k].get(name, np.nan) for k, _, _ in STEPS])
            dims[f"step_{name}"] = ("step",)
        coords["step"] = np.array([k for k, _, _ in STEPS])
    return TrialOutput(values=values, dims=dims, coords=coords)


def _uncertainty(err: np.ndarray, std: np.ndarray, form: np.ndarray | None) -> dict:
    """The paper's recipe on radius errors ``err`` and point-radius stds ``std`` (mm)."""
    d = GAUGE_DIAMETER_MM
    temp_mm = STEEL_ALPHA_PER_K * d * DELTA_T_K  # diameter change over ±5 K
    u_t = (temp_mm / 2.0) / math.sqrt(3.0)  # radius, rectangular
    u_res = (RESOLUTION_MM / 2.0) / math.sqrt(3.0)
    s_worst = float(np.nanmax(std))
    U = 2.0 * math.sqrt(s_worst**2 + u_t**2 + u_res**2)
    mean = float(np.nanmean(err))
    out = {"mean_radius_error_mm": mean, "worst_std_mm": s_worst, "temperature_mm": temp_mm,
           "resolution_mm": RESOLUTION_MM, "expanded_uncertainty_mm": U,
           "max_error_mm": abs(mean) + U}
    if form is not None:
        # VDI/VDE 2634-2 style: probing error form P_F (range of the radial residuals about the
        # fitted circle) and size P_S (diameter error), the worst over the placements.
        out.update(probing_form_PF_mm=float(np.nanmax(form)),
                   probing_size_PS_mm=float(2.0 * err[np.nanargmax(np.abs(err))]))
    return out


def gauge_table(ds) -> dict:
    """The §4.5 table from the study's results (mm); with the steps measured, ``steps``: the
    same table per step of :data:`STEPS` (the same images)."""
    err = np.asarray(ds["radius_error_mm"].values, float)
    std = np.asarray(ds["point_std_mm"].values, float)
    form = np.asarray(ds["form_range_mm"].values, float) if "form_range_mm" in ds else None
    table = _uncertainty(err, std, form)
    table.update({"n_measurements": int(np.isfinite(err).sum()),
                  "std_of_radius_error_mm": float(np.nanstd(err, ddof=1)) if err.size > 1
                  else None,
                  "mean_coverage_deg": float(np.nanmean(ds["coverage_deg"].values)),
                  "by_offset": by_offset(ds)})
    if "step_radius_error_mm" in ds:
        keys = [str(k) for k in ds["step"].values]
        labels = {k: label for k, label, _ in STEPS}
        table["steps"] = {}
        for j, key in enumerate(keys):
            e = np.asarray(ds["step_radius_error_mm"].values, float)[:, j]
            table["steps"][key] = dict(
                _uncertainty(e, np.asarray(ds["step_point_std_mm"].values, float)[:, j],
                             np.asarray(ds["step_form_range_mm"].values, float)[:, j]),
                label=labels.get(key, key))
    if ds.attrs.get("ours"):
        table["ours"] = str(ds.attrs["ours"])
    if ds.attrs.get("ours_label"):
        table["ours_label"] = str(ds.attrs["ours_label"])
    return table


def format_gauge_table(ours: dict) -> str:
    """The §4.5 table: the paper's published column, then ours; with the steps measured, the
    paper's method (§4.4 alone) on our images between them, and a table of the steps."""
    rows = [("mean radius error", "mean_radius_error_mm", "{:+.4f}"),
            ("worst-case std of the point radii", "worst_std_mm", "{:.4f}"),
            ("gauge diameter change, ±5 °C", "temperature_mm", "±{:.4f}"),
            ("resolution", "resolution_mm", "{:.4f}"),
            ("expanded uncertainty U (k = 2)", "expanded_uncertainty_mm", "±{:.4f}"),
            ("maximum error |mean| + U", "max_error_mm", "±{:.4f}")]
    steps = ours.get("steps") or {}
    cols = [("paper", PAPER_TABLE)]
    if "c44" in steps and ours.get("ours") != "c44":
        cols.append(("§4.4", steps["c44"]))
    cols.append(("lts360", ours))
    lines = [f"{'plug gauge Ø19.9987 mm (mm)':38s} " + " ".join(f"{c:>9s}" for c, _ in cols)]
    for label, key, fmt in rows:
        lines.append(f"{label:38s} " + " ".join(f"{fmt.format(t[key]):>9s}" for _, t in cols))
    for label, key, fmt in (("VDI/VDE 2634-2: probing form P_F (worst)", "probing_form_PF_mm",
                             "{:9.4f}"),
                            ("VDI/VDE 2634-2: probing size P_S (worst)", "probing_size_PS_mm",
                             "{:+9.4f}")):
        if key in ours:
            lines.append(f"{label:38s} " + " ".join(
                f"{'—':>9s}" if key not in t else fmt.format(t[key]) for _, t in cols))
    label = dict((k, lb) for k, lb, _ in STEPS).get(ours.get("ours"), ours.get("ours_label"))
    if label:
        lines.append(f"(lts360: {label}"
                     + ("; §4.4: the paper's method on the same images)" if len(cols) == 3
                        else ")"))
    if steps:
        lines.append("each step on the same images (µm): mean radius error, worst std, "
                     "U (k = 2), maximum error, P_F")
        for key, t in steps.items():
            mark = "  <- lts360" if key == ours.get("ours") else ""
            lines.append(f"  {t['label']:28s} {1e3 * t['mean_radius_error_mm']:+7.1f} "
                         f"{1e3 * t['worst_std_mm']:6.1f} ±{1e3 * t['expanded_uncertainty_mm']:5.1f} "
                         f"±{1e3 * t['max_error_mm']:5.1f} {1e3 * t['probing_form_PF_mm']:6.1f}{mark}")
    if ours.get("by_offset"):
        lines.append("against the distance from the axis (mm): placements, mean radius error, "
                     "spread of the views' mean errors")
        for b in ours["by_offset"]:
            spread = "—" if b["view_spread_mm"] is None else f"{b['view_spread_mm'] * 1e3:.1f} µm"
            lines.append(f"  {b['offset_from_mm']:.2f}–{b['offset_to_mm']:.2f}: {b['n']:4d}  "
                         f"{b['mean_radius_error_mm'] * 1e3:+7.1f} µm  {spread}")
    lines.append(f"(ours: {ours['n_measurements']} placements, mean coverage "
                 f"{ours['mean_coverage_deg']:.1f}°; the paper's temperature term is its own "
                 "figure, ours is α·d·ΔT for steel)")
    return "\n".join(lines)


def _compensated_calibration(cal_path: Path, out: Path, *, rig: str, noise: str, spp: int,
                             seed: int, shots: int = 1, master: bool = False,
                             bias_model: str = "none", max_scatter: int = 0,
                             shot_cache: dict | None = None) -> Path:
    """§4.4: measure the gauge at the nominal position (``shots`` times, turned about its axis
    between shots: new speckle, new sensor noise), put the mirror views on one circle with the
    direct view (:func:`lts360.recon.calibration.compensation.joint_view_offsets`, all shots jointly),
    store their offsets in a copy of the calibration."""
    import dataclasses

    from lts360.recon.calibration.compensation import joint_view_offsets
    from lts360.recon.model import load_calibration, save_calibration
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.render import ensure_variant

    if not 1 <= int(shots) <= 100:
        raise ValueError(f"compensation shots must be in [1, 100], got {shots}")
    path = out / ("calibration-compensated.json" if shots == 1
                  else f"calibration-compensated-{int(shots)}shots.json")
    if master:  # mastered with the gauge's known diameter (and its twin: the bias it leaves)
        path = path.with_name(path.stem + ("-master-twin" if bias_model == "twin"
                                           else "-master") + ".json")
    if path.is_file():
        return path
    ensure_variant()
    cal = load_calibration(cal_path)
    obj = build_object(f"plug-gauge:d={GAUGE_DIAMETER_MM}")
    r = GAUGE_DIAMETER_MM / 2
    grid = CylGrid.from_ranges((r - 1.0, r + 1.0), theta_step_deg=0.1, r_step_mm=0.005)
    results = []
    for k in range(int(shots)):
        # a study's compensations (§4.4, master, master with twin) read the same shots
        key = (str(Path(cal_path).resolve()), os.stat(cal_path).st_mtime_ns, str(rig), noise,
               int(spp), seed + 777_777 + k, int(max_scatter))
        cache = {} if shot_cache is None else shot_cache
        if key not in cache:
            cache[key] = simulate_frame(load_rig(rig), obj, spp=spp, seed=key[5], noise=noise,
                                        pixels_xy=gauge_window_pixels(cal_path, r),
                                        max_scatter=max_scatter).image
        res = inverse_triangulate(cache[key], cal, grid)
        if master and bias_model == "twin":
            from lts360.twin import TwinCorrector, twin_corrected_raw
            from lts360.twin.rig import twin_design

            res = twin_corrected_raw(res, cal, grid,
                                     TwinCorrector(cal, twin_design(cal), input_u=None))
        results.append(res)
    if master:
        from lts360.recon.calibration.compensation import master_fit

        fit = master_fit(results, GAUGE_DIAMETER_MM)
        cal = dataclasses.replace(cal, view_offsets_mm=fit.offsets_mm,
                                  view_radial_offsets_mm=fit.radial_offset_mm,
                                  view_scales=fit.scale, master=fit.to_dict())
    else:
        cal = dataclasses.replace(cal, view_offsets_mm=joint_view_offsets(results))
    save_calibration(path, cal)
    return path


def check_calibration_rig(calibration, rig: str) -> None:
    """Refuse, in one line, a calibration made with another rig than the one a study renders
    with (``rig``: a preset name or a TOML file): its camera, mirrors and optics would then not
    be the images'.  The rig the calibration records (``optics.rig_toml``) is compared with
    ``rig`` as TOML, names aside; a calibration without a record is taken as it is."""
    from lts360.recon.model import load_calibration
    from lts360.scenes.rig_io import load_rig, rig_to_toml
    from lts360.twin.rig import recorded_rig

    cal = load_calibration(calibration)
    made = recorded_rig(cal)
    if made is None:
        return

    def body(r) -> str:
        return "\n".join(line for line in rig_to_toml(r).splitlines()
                         if not line.startswith("name ="))

    if body(made) != body(load_rig(rig)):
        raise ValueError(f"--rig {rig!r} is not the rig the calibration {str(calibration)!r} "
                         f"was made with ({cal.optics.get('rig', made.name)!r}): the study "
                         f"renders with --rig; pass that rig")


def ensure_calibration(out: Path, calibration=None, *, rig: str = "paper", noise: str = "realistic",
                       seed: int = 0, spp: int = 16, compensate: bool = True,
                       calibrate_options: dict | None = None, compensation_shots: int = 1,
                       master: bool = False, bias_model: str = "none", say=print,
                       max_scatter: int = 0, shot_cache: dict | None = None) -> Path:
    """The calibration a study measures with: ``calibration`` if given, else one estimated from
    rendered chessboard images into ``out/calibration/`` (kept for the next run); with
    ``compensate``, a copy with the §4.4 view offsets from ``compensation_shots`` shots of the
    gauge (``out/calibration-compensated[-Kshots].json``); ``shot_cache``: a dict the
    compensations of one study share their rendered reference shots through."""
    from lts360.experiments.calibration_run import run_calibrate

    if calibration is None:
        cal_dir = out / "calibration"
        calibration = cal_dir / "calibration.json"
        if not calibration.is_file():
            say(f"calibrating from rendered chessboard images ({noise} noise) -> {cal_dir}/")
            run_calibrate(cal_dir, rig_name=rig, noise=noise, seed=seed, say=say,
                          **(calibrate_options or {}))
    calibration = Path(calibration)
    check_calibration_rig(calibration, rig)
    if compensate:
        calibration = _compensated_calibration(calibration, out, rig=rig, noise=noise, spp=spp,
                                               seed=seed, shots=compensation_shots,
                                               master=master, bias_model=bias_model,
                                               max_scatter=max_scatter, shot_cache=shot_cache)
    return calibration


def run_plug_gauge_study(out_dir, *, trials: int = 10, seed: int = 0, calibration=None,
                         noise: str = "realistic", spp: int = 16, rig: str = "paper",
                         compensate: bool = True, workers: int | None = 1,
                         dask_address: str | None = None, calibrate_options: dict | None = None,
                         compensation_shots: int = 1, placement_mm: float = DEFAULT_PLACEMENT_MM,
                         master: bool = True, bias_model: str = "twin", steps: bool = True,
                         say=print, max_scatter: int = 0) -> dict:
    """Calibrate (unless ``calibration``), compensate, measure ``trials`` placements (offsets
    drawn in a disc of radius ``placement_mm``), tabulate (also against the offset).
    ``compensate``: §4.4; ``master``: the compensation mastered with the gauge's known
    diameter (needs ``compensate``); ``bias_model`` ``"twin"``: each placement (and the
    master's shots) corrected by its twin.  ``steps``: each placement also measured with
    every step of :data:`STEPS` on and off (the table's ``steps``).
    ``max_scatter`` > 0 renders the gauge's shots (compensation and placements, not the
    chessboards) with interreflected laser light."""
    if bias_model not in ("none", "twin"):
        raise ValueError(f"bias_model must be none or twin, got {bias_model!r}")
    placement_band_mm(placement_mm)  # validates
    master = bool(master) and bool(compensate)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kw = dict(rig=rig, noise=noise, seed=seed, spp=spp, calibrate_options=calibrate_options,
              compensation_shots=compensation_shots, say=say, max_scatter=max_scatter,
              shot_cache={})
    raw = ensure_calibration(out, calibration, compensate=False, **kw)
    if bias_model == "twin" or steps:
        from lts360.recon.model import load_calibration
        from lts360.twin.rig import twin_design

        twin_design(load_calibration(raw))  # one line if the calibration records no optics
    cals = {}
    for key, _, (comp, mast, bias) in (STEPS if steps else ()):
        cals[f"cal_{key}"] = str(ensure_calibration(out, raw, compensate=comp, master=mast,
                                                    bias_model=bias, **kw).resolve())
    calibration = ensure_calibration(out, raw, compensate=compensate, master=master,
                                     bias_model=bias_model, **kw)
    params = [dict(p, calibration=str(calibration.resolve()), noise=noise, spp=spp, rig=rig,
                   compensate=compensate, bias_model=bias_model, clouds=str((out / "clouds").resolve()),
                   placement_mm=float(placement_mm), master=master, steps=bool(steps), **cals)
              for p in gauge_placements(trials, seed, offset_mm=placement_mm)]
    if max_scatter:  # only then: the trials of earlier studies keep their parameters
        params = [dict(p, max_scatter=int(max_scatter)) for p in params]
    ours = _step_key(compensate, master, bias_model)
    ds = run_study(out / "trials", plan_trials(params, seed), plug_gauge_trial, name="plug-gauge",
                   workers=workers, dask_address=dask_address,
                   attrs={"noise": noise, "spp": spp, "rig": rig, "ours": ours or "",
                          "ours_label": _config_label(compensate, master, bias_model)})
    table = gauge_table(ds)
    table["paper"] = PAPER_TABLE
    (out / "table.json").write_text(json.dumps(table, indent=2))
    (out / "table.txt").write_text(format_gauge_table(table) + "\n")
    _plot(ds, out / "plug-gauge.png")
    return table


def _plot(ds, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    err = ds["radius_error_mm"].values * 1e3
    std = ds["point_std_mm"].values * 1e3
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    k = np.arange(len(err))
    ax[0].errorbar(k, err, yerr=std, fmt="o", capsize=3)
    ax[0].axhline(PAPER_TABLE["mean_radius_error_mm"] * 1e3, color="r", ls="--", label="paper mean")
    ax[0].set_xlabel("placement")
    ax[0].set_ylabel("radius error (µm), bars: std of point radii")
    ax[0].legend()
    if "view_mean_mm" in ds:
        vm = ds["view_mean_mm"].values * 1e3
        for j, v in enumerate(ds["view"].values):
            ax[1].plot(k, vm[:, j], "o-", label=str(v))
        ax[1].set_xlabel("placement")
        ax[1].set_ylabel("mean radius error per view (µm)")
        ax[1].legend()
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)

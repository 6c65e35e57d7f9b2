"""``lts360 study line-speed``: what the line's speed, the exposure and the shutter do to a
single-image section.

For each object (default: a stranded cable and the grooved shaft), speed, exposure (default
"auto": what auto-exposure sets for the still object, so that the stripe is as bright as in a
still frame) and shutter type, one frame of the object moving along its axis is rendered
(:func:`lts360.simulator.motion.simulate_moving_frame`), measured by inverse triangulation
with the rig's true calibration (so that only the motion is studied), each point tagged with
its own row's time (:class:`lts360.recon.triangulation.measure.RowTiming`), and scored two
ways against the object's analytic surface:

* **as one instant** — against the object at the middle of the first row's exposure, what a
  measurement that takes the image as one section assumes;
* **row-aware** — against the object where it was when the point's own row was exposed (what
  the points' ``time`` and ``z`` carry).

Errors are robust: the median radial error (bias) and 1.4826 × the median absolute deviation
(spread), combined as ``√(bias² + spread²)`` ("robust RMS"), so that the few points a
cable's hidden valleys give (100–500 µm off, see the examples study) do not hide the motion.
Per view both ways; between views: the spread of the views' biases as one instant (their
disagreement).  Every speed of one object, shutter and exposure is rendered with the same seed
(common random numbers: the differences along a sweep are the motion's).  From the sweep: the
largest speed at which the robust RMS as one instant stays within ``--accuracy-um`` of the
still frame's (what the motion may add).  And in
closed form, the lumps a scan misses: sections every ``v / f`` mm (``--profile-rate-hz``) miss
a lump of length ``L`` with probability ``max(0, 1 − L f / v)`` (the lump's position uniform).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from lts360.experiments.runner import Trial, TrialOutput, plan_trials, run_study, trial_setup

__all__ = ["line_speed_trial", "run_line_speed_study", "lumps_missed", "format_line_speed",
           "DEFAULT_OBJECTS"]

DEFAULT_OBJECTS = ("cable-8", "grooved-shaft")
VIEWS = ("direct", "left", "right")


def lumps_missed(speed_mm_s, profile_rate_hz: float, lump_mm) -> np.ndarray:
    """Probability that no section falls on a lump of length ``lump_mm``: sections every
    ``v / f`` mm, the lump's position uniform."""
    spacing = np.asarray(speed_mm_s, float) / float(profile_rate_hz)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = 1.0 - np.asarray(lump_mm, float) / spacing
    return np.clip(np.nan_to_num(p, nan=0.0, neginf=0.0), 0.0, 1.0)


def _object_frame_points(points_world_mm, times_s, motion, T_placed) -> np.ndarray:
    """World points at their times → the object's own frame (undo the motion, then the
    placement); vectorised over points."""
    p = np.asarray(points_world_mm, float) - motion.offset_mm(times_s)
    a = -np.radians(motion.rotation_rate_deg_s) * np.asarray(times_s, float)
    c, s = np.cos(a), np.sin(a)
    p = np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1], p[:, 2]])
    Ti = np.linalg.inv(T_placed)
    return p @ Ti[:3, :3].T + Ti[:3, 3]


def line_speed_trial(trial: Trial) -> TrialOutput:
    """Render one moving frame, measure it with the true calibration, score it two ways."""
    from lts360.experiments.score import true_radius_band
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.recon.triangulation.measure import RowTiming, result_to_cloud
    from lts360.scenes.motion import Acquisition, Motion, Shutter
    from lts360.simulator.frame import stage_transform
    from lts360.simulator.motion import simulate_moving_frame

    p = trial.params
    rig, obj = trial_setup(p)
    shutter = (Shutter("rolling", p["line_time_us"] * 1e-6) if p["shutter"] == "rolling"
               else Shutter())
    exposure_s = p["exposure_us"] * 1e-6
    if exposure_s == 0:  # "auto": what auto-exposure sets for the still object
        from lts360.simulator.frame import simulate_frame

        exposure_s = simulate_frame(rig, obj, spp=int(p["spp"]), seed=int(p["render_seed"]),
                                    scale=float(p["scale"])).exposure_time_s
    acq = Acquisition(exposure_s, shutter=shutter,
                      motion=Motion(speed_mm_s=p["speed_mm_s"]))
    kw = dict(spp=int(p["spp"]), seed=int(p["render_seed"]), noise=p["noise"],
              scale=float(p["scale"]))
    frame = simulate_moving_frame(rig, obj, acq, **kw)
    cal = calibration_from_frame_truth(frame.truth)
    lo, hi = true_radius_band(obj, np.array([0.0]))
    grid = CylGrid.from_ranges((lo, hi), theta_step_deg=0.25, r_step_mm=0.005)
    T_placed = stage_transform(0.0) @ np.asarray(obj.T_world_object, float)

    def measured(fr):
        res = inverse_triangulate(fr.image, cal, grid)
        timing = RowTiming.from_motion(fr.truth["motion"])
        cloud = result_to_cloud(res, z_mm=0.0, section=0, timing=timing, cal=cal)
        ok = cloud.valid
        # The measurement frame of the true calibration is the world frame here (the laser
        # plane z = 0): every point lies in it when its row is exposed.  (The cloud's z is the
        # height on the object that RowTiming gives: −v t.)
        world = cloud.points_mm[ok].copy()
        world[:, 2] = 0.0
        return world, cloud.time_s[ok], cloud.view[ok], timing

    def radial_error(world, times):
        q = _object_frame_points(world, times, acq.motion, T_placed)
        r_true = obj.radius_fn(np.arctan2(q[:, 1], q[:, 0]), q[:, 2])
        return np.hypot(q[:, 0], q[:, 1]) - r_true

    world, t, view, timing = measured(frame)
    t0 = float(timing.row_time_s(0.0))
    e_instant = radial_error(world, np.full(len(world), t0))  # all taken at the one instant t0
    e_rows = radial_error(world, t)
    values = {"n_points": float(len(world)), "renders": float(frame.truth["motion"]["renders"]),
              "exposure_used_us": exposure_s * 1e6,
              "render_s": float(frame.render.seconds)}
    # The same sub-frames and samples with the object held at the trigger's pose: its error is
    # the render's and the detector's alone, so the difference is what the motion adds (a
    # still frame's own sampling differs, and at a few spp that moves its rms by 20-40 µm).
    if acq.motion.still:
        values["rms_frozen_mm"] = _robust(e_instant[np.isfinite(e_instant)])[2]
    else:
        frozen = simulate_moving_frame(rig, obj, acq, freeze=True, **kw)
        fw, _, _, ft = measured(frozen)
        ef = radial_error(fw, np.full(len(fw), float(ft.t_trigger_s)))
        values["rms_frozen_mm"] = _robust(ef[np.isfinite(ef)])[2]
        values["render_s"] += float(frozen.render.seconds)
    rms_i, rms_r, mean_i = [], [], []
    from lts360.recon.triangulation.cloud import VIEW_CODES

    for name in VIEWS:
        m = (view == VIEW_CODES[name]) & np.isfinite(e_instant) & np.isfinite(e_rows)
        rms_i.append(_robust(e_instant[m])[2])
        rms_r.append(_robust(e_rows[m])[2])
        mean_i.append(_robust(e_instant[m])[0])
    values["rms_instant_mm"] = _robust(e_instant[np.isfinite(e_instant)])[2]
    values["rms_rows_mm"] = _robust(e_rows[np.isfinite(e_rows)])[2]
    values["view_disagreement_mm"] = float(np.nanmax(mean_i) - np.nanmin(mean_i))
    arrays = {"view_rms_instant_mm": np.array(rms_i), "view_rms_rows_mm": np.array(rms_r),
              "view_mean_instant_mm": np.array(mean_i)}
    values.update(arrays)
    return TrialOutput(values=values, dims={k: ("view",) for k in arrays},
                       coords={"view": np.array(VIEWS)})


def _robust(e: np.ndarray) -> tuple[float, float, float]:
    """Median, 1.4826 × MAD and their root-sum-square (NaN for no point), mm."""
    if len(e) == 0:
        return np.nan, np.nan, np.nan
    med = float(np.median(e))
    spread = 1.4826 * float(np.median(np.abs(e - med)))
    return med, spread, float(math.hypot(med, spread))


def _added(rms_mm: float, frozen_mm: float) -> float:
    """What the motion adds to the robust rms: its quadrature excess over the frozen frame's
    (0 where the moving frame is no worse)."""
    return float(math.sqrt(max(rms_mm ** 2 - frozen_mm ** 2, 0.0)))


def _largest_speed(speeds, rms, limit) -> float:
    """The largest swept speed up to which every RMS stays within ``limit`` (NaN: none)."""
    best = np.nan
    for v, e in sorted(zip(speeds, rms)):
        if not (np.isfinite(e) and e <= limit):
            break
        best = v
    return float(best)


def run_line_speed_study(out_dir, *, objects=DEFAULT_OBJECTS, speeds_mm_s=(0.0, 100.0, 500.0),
                         exposures_us=(0.0,), shutters=("global", "rolling"),
                         line_time_us: float = 10.0, scale: float = 0.5, spp: int = 16,
                         noise: str = "none", rig: str = "paper", accuracy_um: float = 20.0,
                         profile_rate_hz: float = 200.0, lumps_mm=(0.5, 1.0, 2.0, 5.0),
                         seed: int = 0, workers: int | None = 1,
                         dask_address: str | None = None) -> dict:
    """Sweep objects × speeds × exposures × shutters; write ``trials/results.nc``,
    ``table.json``, ``table.txt`` and ``line-speed.png``; return the table."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    params = [dict(object=o, speed_mm_s=float(v), exposure_us=float(e), shutter=s,
                   line_time_us=float(line_time_us), scale=float(scale), spp=int(spp),
                   noise=noise, rig=rig, render_seed=int(seed) * 1000 + k)
              for k, o in enumerate(objects) for s in shutters for e in exposures_us
              for v in speeds_mm_s]
    ds = run_study(out / "trials", plan_trials(params, seed), line_speed_trial, name="line-speed",
                   workers=workers, dask_address=dask_address,
                   attrs={"noise": noise, "spp": spp, "scale": scale, "rig": rig,
                          "line_time_us": line_time_us})
    rows = []
    for i in range(ds.sizes["trial"]):
        d = ds.isel(trial=i)
        rows.append({k: (d[k].item() if d[k].ndim == 0 else d[k].values.tolist())
                     for k in ("object", "speed_mm_s", "exposure_us", "exposure_used_us",
                               "shutter", "n_points",
                               "rms_instant_mm", "rms_rows_mm", "rms_frozen_mm",
                               "view_disagreement_mm",
                               "view_rms_instant_mm", "renders", "render_s") if k in d})
    limits = []
    for o in objects:
        for s in shutters:
            for e in exposures_us:
                sel = [r for r in rows if (r["object"], r["shutter"], r["exposure_us"]) == (o, s, e)]
                still = [r["rms_instant_mm"] for r in sel if r["speed_mm_s"] == 0]
                limits.append({"object": o, "shutter": s, "exposure_us": e,
                               "still_rms_mm": still[0] if still else None,
                               "largest_speed_mm_s": _largest_speed(
                                   [r["speed_mm_s"] for r in sel],
                                   [_added(r["rms_instant_mm"], r["rms_frozen_mm"])
                                    for r in sel], accuracy_um * 1e-3)})
    lumps = {"profile_rate_hz": profile_rate_hz, "lump_mm": list(lumps_mm),
             "speed_mm_s": [float(v) for v in speeds_mm_s],
             "p_missed": lumps_missed(np.asarray(speeds_mm_s, float)[:, None], profile_rate_hz,
                                      np.asarray(lumps_mm, float)[None, :]).tolist()}
    table = {"rows": rows, "largest_speed": limits, "accuracy_um": accuracy_um, "lumps": lumps,
             "settings": {"line_time_us": line_time_us, "scale": scale, "spp": spp,
                          "noise": noise, "rig": rig}}
    (out / "table.json").write_text(json.dumps(table, indent=2))
    (out / "table.txt").write_text(format_line_speed(table) + "\n")
    _plot(table, out / "line-speed.png")
    return table


def format_line_speed(table: dict) -> str:
    s = table["settings"]
    lines = [f"line speed: true calibration, {s['noise']} noise, {s['spp']} spp, scale "
             f"{s['scale']:g}, rolling line time {s['line_time_us']:g} µs",
             f"{'object':14s} {'shutter':8s} {'exp µs':>7s} {'v mm/s':>8s} {'points':>7s} "
             f"{'robust rms, one instant':>24s} {'row-aware':>10s} {'frozen':>9s} "
             f"{'added':>9s} {'views apart':>12s}"]
    for r in table["rows"]:
        lines.append(f"{r['object']:14s} {r['shutter']:8s} {r['exposure_used_us']:7.0f} "
                     f"{r['speed_mm_s']:8.0f} {r['n_points']:7.0f} "
                     f"{r['rms_instant_mm'] * 1e3:21.1f} µm {r['rms_rows_mm'] * 1e3:7.1f} µm "
                     f"{r['rms_frozen_mm'] * 1e3:6.1f} µm "
                     f"{_added(r['rms_instant_mm'], r['rms_frozen_mm']) * 1e3:6.1f} µm "
                     f"{r['view_disagreement_mm'] * 1e3:9.1f} µm")
    lines.append(f"largest swept speed at which the motion adds at most {table['accuracy_um']:g} "
                 f"µm (in quadrature) to the robust rms as one instant, against the same "
                 f"sub-frames with the object held still:")
    for L in table["largest_speed"]:
        v = L["largest_speed_mm_s"]
        lines.append(f"  {L['object']:14s} {L['shutter']:8s} "
                     + ("auto" if L["exposure_us"] == 0 else f"{L['exposure_us']:.0f} µs") + ": "
                     + ("none of the swept speeds" if not math.isfinite(v) else f"{v:g} mm/s"))
    lu = table["lumps"]
    lines.append(f"lumps missed at {lu['profile_rate_hz']:g} profiles/s (P, lump length "
                 + ", ".join(f"{x:g}" for x in lu["lump_mm"]) + " mm):")
    for v, p in zip(lu["speed_mm_s"], lu["p_missed"]):
        lines.append(f"  {v:8.0f} mm/s (spacing {v / lu['profile_rate_hz']:.3g} mm): "
                     + ", ".join(f"{x:.2f}" for x in p))
    return "\n".join(lines)


def _exp(us: float) -> str:
    return "auto exposure" if us == 0 else f"{us:g} µs"


def _plot(table: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    keys = sorted({(r["object"], r["shutter"], r["exposure_us"]) for r in table["rows"]})
    for key in keys:
        sel = sorted((r for r in table["rows"]
                      if (r["object"], r["shutter"], r["exposure_us"]) == key),
                     key=lambda r: r["speed_mm_s"])
        v = [r["speed_mm_s"] for r in sel]
        ax.plot(v, [r["rms_instant_mm"] * 1e3 for r in sel], "o-",
                label=f"{key[0]}, {key[1]}, {_exp(key[2])} (as one instant)")
        ax.plot(v, [r["rms_rows_mm"] * 1e3 for r in sel], "x--", alpha=0.6,
                label=f"{key[0]}, {key[1]}, {_exp(key[2])} (row-aware)")
    ax.set_xlabel("line speed (mm/s)")
    ax.set_ylabel("robust RMS radial error (µm)")
    ax.set_title("single-image section of a moving object")
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

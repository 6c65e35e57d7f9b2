"""``lts360 design check --pipeline``: the design model against the whole user pipeline.

For each rig and each calibration seed, the plug-gauge study (:func:`run_plug_gauge_study`)
renders the chessboards, runs ``lts360 calibrate`` on them, compensates on one shot of the
centred gauge with the gauge as master (§4.4 + a master of known diameter, its shot corrected
by its twin) and measures ``placements`` noisy images (EMVA 1288 + speckle, 16 spp) of the
gauge placed at random ≤ ``placement_mm`` off the axis, each corrected by its twin.  Every
seed has its own boards, renders, noise, calibration and placements.

The radius error of a section is ``e`` = fitted radius − true radius.  Over all placements of
all seeds (their calibrations included) the measured **U(k=2) = 2·rms(e)** (the mean error
counts: the pipeline's systematic part is part of what a user's section reads), with a 95 %
interval from χ² with ``n`` degrees of freedom; beside it the mean and the sd.

The model's U for the same measurement: :func:`lts360.design.model.evaluate` for the gauge
(the worst of the centred case and the four at ±``placement_mm``), the compensation on one
shot of it as master, the twin, and the calibration's covariance predicted for
``lts360 calibrate``'s plan of the rig (:func:`lts360.design.calib_covariance.plan_covariance`).

A seed's study is kept in ``OUT/<rig>/seed<S>/`` and reused when its ``table.json`` exists
with the asked placements, so a run can be extended (more seeds) or resumed.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

__all__ = ["check_pipeline", "format_pipeline", "rig_label"]

GAUGE_DIAMETER_MM = 19.9987


def rig_label(rig: str) -> str:
    """A folder name for a preset or a rig file: the preset, or the file's stem."""
    p = Path(rig)
    return p.stem if p.suffix == ".toml" else str(rig)


def _seed_errors(out: Path, *, rig: str, seed: int, placements: int, placement_mm: float,
                 say) -> tuple[np.ndarray, float]:
    """The radius errors (mm) of one seed's placements, running its study unless it is done."""
    import xarray as xr

    from lts360.experiments.gauge_study import run_plug_gauge_study

    nc = out / "trials" / "results.nc"
    t0 = time.perf_counter()
    done = (out / "table.json").is_file() and nc.is_file()
    if done:
        with xr.open_dataset(nc) as ds:
            done = int(ds.sizes["trial"]) == int(placements)
    if not done:
        run_plug_gauge_study(out, trials=int(placements), seed=int(seed), rig=rig,
                             noise="realistic", placement_mm=float(placement_mm), master=True,
                             bias_model="twin", steps=False, say=say)
    with xr.open_dataset(nc) as ds:
        err = np.asarray(ds["radius_error_mm"].values, dtype=float)
    return err, time.perf_counter() - t0


def _model(rig: str, placement_mm: float) -> dict:
    """The design model's U and shares for the pipeline's measurement (µm)."""
    from lts360.design.calib_covariance import plan_covariance
    from lts360.design.model import Conditions, evaluate
    from lts360.design.params import DesignSpace
    from lts360.scenes.rig_io import load_rig

    base = load_rig(rig)
    cond = Conditions(diameters_mm=(GAUGE_DIAMETER_MM,), placement_mm=float(placement_mm),
                      n_theta=360, compensate=True, compensation_diameter_mm=GAUGE_DIAMETER_MM,
                      compensation_shots=1, master=True, bias_model="twin",
                      calibration=plan_covariance(base))
    e = evaluate(DesignSpace.create(base), None, cond, gradient=False)
    k = int(np.argmax(e.U_um))
    return {"U_um": float(e.U_um[k]), "sigma_R_um": float(e.sigma_R_um[k]),
            "noise_um": float(e.sigma_R_noise_um[k]), "compensation_um": float(e.sigma_R_comp_um[k]),
            "calibration_um": float(e.sigma_R_cal_um[k]), "bias_left_um": float(e.bias_left_um[k]),
            "bias_uncorrected_um": float(e.bias_um[k]), "case": list(e.cases[k])}


def _measured(err_mm: np.ndarray) -> dict:
    from scipy.stats import chi2

    e = err_mm[np.isfinite(err_mm)] * 1e3
    n = len(e)
    out = {"n": n, "failed": int(len(err_mm) - n)}
    if n < 2:
        return out
    rms = float(np.sqrt(np.mean(e ** 2)))
    out.update(mean_um=float(np.mean(e)), sd_um=float(np.std(e, ddof=1)), rms_um=rms,
               U_um=2.0 * rms,
               U_95_um=[2.0 * rms * math.sqrt(n / chi2.ppf(0.975, n)),
                        2.0 * rms * math.sqrt(n / chi2.ppf(0.025, n))])
    return out


def check_pipeline(rigs, out, *, seeds=(0, 1, 2), placements: int = 5,
                   placement_mm: float = 0.3, say=print) -> dict:
    """Model and whole-pipeline measurement of the section's radius U(k=2), rig by rig (µm);
    with two or more rigs, the first rig's U over each other's (measured and modelled)."""
    from lts360.experiments.gauge_study import placement_band_mm

    if not rigs:
        raise ValueError("rigs: at least one rig")
    if isinstance(placements, bool) or not isinstance(placements, int) or placements < 2:
        raise ValueError(f"placements: must be an integer >= 2, got {placements!r}")
    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds: must be distinct integers, got {seeds}")
    placement_band_mm(placement_mm)  # validates (one line)
    labels = [rig_label(r) for r in rigs]
    if len(set(labels)) != len(labels):
        raise ValueError(f"rigs: two rigs share the folder name {labels}")
    out = Path(out)
    rows = []
    for rig, label in zip(rigs, labels):
        errs, per_seed = [], []
        for s in seeds:
            e, sec = _seed_errors(out / label / f"seed{s}", rig=str(rig), seed=s,
                                  placements=placements, placement_mm=placement_mm, say=say)
            errs.append(e)
            per_seed.append({"seed": s, "radius_errors_um": (1e3 * e).tolist(),
                             "mean_um": float(np.nanmean(e)) * 1e3, "seconds": sec})
        meas = _measured(np.concatenate(errs))
        model = _model(str(rig), placement_mm)
        ratio = model["U_um"] / meas["U_um"] if meas.get("U_um") else None
        rows.append({"rig": str(rig), "label": label, "measured": meas, "model": model,
                     "model_over_measured": ratio,
                     "model_within_25pct": None if ratio is None else bool(0.75 <= ratio <= 1.25),
                     "seeds": per_seed})
    res = {"placements": int(placements), "seeds": seeds, "placement_mm": float(placement_mm),
           "gauge_diameter_mm": GAUGE_DIAMETER_MM, "rigs": rows}
    if len(rows) >= 2 and all(r["measured"].get("U_um") for r in rows):
        ref = rows[0]
        res["improvement_over_first"] = [
            {"rig": r["label"], "measured": ref["measured"]["U_um"] / r["measured"]["U_um"],
             "model": ref["model"]["U_um"] / r["model"]["U_um"]} for r in rows[1:]]
    (out / "pipeline.json").write_text(json.dumps(res, indent=2))
    return res


def format_pipeline(res: dict) -> list[str]:
    lines = [f"The section's radius U(k=2), the gauge Ø{res['gauge_diameter_mm']} mm ≤ "
             f"{res['placement_mm']:g} mm off the axis, {res['placements']} placements × "
             f"seeds {','.join(map(str, res['seeds']))} (lts360 calibrate → compensate with "
             "the gauge as master → measure with the twin):"]
    for r in res["rigs"]:
        m, md = r["measured"], r["model"]
        if "U_um" not in m:
            lines.append(f"  {r['label']}: too few sections measured ({m['n']})")
            continue
        lines.append(
            f"  {r['label']}: measured U {m['U_um']:.2f} µm [95 % {m['U_95_um'][0]:.2f}, "
            f"{m['U_95_um'][1]:.2f}] (mean {m['mean_um']:+.2f}, sd {m['sd_um']:.2f} µm, "
            f"{m['n']} sections); model U {md['U_um']:.2f} µm (noise {md['noise_um']:.2f}, "
            f"compensation {md['compensation_um']:.2f}, calibration {md['calibration_um']:.2f},"
            f" bias left {md['bias_left_um']:+.2f} µm), model/measured "
            f"{r['model_over_measured']:.2f}"
            + ("" if r["model_within_25pct"] else " (outside ±25 %)"))
    for imp in res.get("improvement_over_first", []):
        lines.append(f"  {res['rigs'][0]['label']} / {imp['rig']}: measured "
                     f"{imp['measured']:.2f}×, model {imp['model']:.2f}×"
                     + ("" if imp["measured"] >= 1.5 else " (below 1.5×)"))
    return lines

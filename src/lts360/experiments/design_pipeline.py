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

Where the error comes from, seed by seed (:func:`components`): the placements of one seed
share its calibration and its master shot, so the errors are split one way (a random-effects
analysis of variance): the pooled sd within the seeds (the image's own noise; the model's
``noise`` share) and the sd of the seeds' means (the model: ``√(compensation² + calibration²
+ noise²/n)``), each with its χ² interval.  And per seed, what its master left
(:func:`master_parts`): a noise-free centred image of the gauge (``CLEAN_SPP`` samples per
pixel) measured with the seed's mastered calibration and the twin; the master makes its own
shot read the known radius, so this image reads minus what the master shot's noise (and the
calibration's error between the shot and this image) put into the correction.  A seed's mean
error minus its master's part is then the placements' own noise, if nothing else is shared.

The renders' sampling noise (thin lens, ``spp`` samples per pixel) is no part of a real
image and no part of the model; at f/1.4 and 16 spp it is as large as the image's physical
noise (STUDIES.md, "The optimum through the whole user pipeline"), hence ``spp`` = 64 by
default.

A seed's calibration is kept in ``OUT/<rig>/seed<S>/calibration/``; its study in
``OUT/<rig>/seed<S>/`` at 16 spp, ``OUT/<rig>/seed<S>-spp<N>/`` otherwise (the calibration
is shared); a study is reused when its ``table.json`` exists with the asked placements, so a
run can be extended (more seeds) or resumed.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

__all__ = ["check_pipeline", "components", "format_pipeline", "master_parts", "rig_label"]

GAUGE_DIAMETER_MM = 19.9987
#: Samples per pixel of the noise-free image each seed's master is checked on (its own
#: sampling noise then a quarter of a 64-spp render's).
CLEAN_SPP = 256
#: The renderer's seed of that image (not one of a study's: its sampling noise is its own).
CLEAN_SEED = 4242
#: The studies' samples per pixel before ``spp`` was an option (their folders keep the name).
LEGACY_SPP = 16


def rig_label(rig: str) -> str:
    """A folder name for a preset or a rig file: the preset, or the file's stem."""
    p = Path(rig)
    return p.stem if p.suffix == ".toml" else str(rig)


def study_dir(out_rig: Path, seed: int, spp: int) -> Path:
    """A seed's study folder: ``seed<S>`` at 16 spp (as before ``spp`` was an option),
    ``seed<S>-spp<N>`` otherwise."""
    return out_rig / (f"seed{seed}" if int(spp) == LEGACY_SPP else f"seed{seed}-spp{int(spp)}")


def _seed_errors(out: Path, *, rig: str, seed: int, placements: int, placement_mm: float,
                 say, spp: int = LEGACY_SPP, calibration=None) -> tuple[np.ndarray, float]:
    """The radius errors (mm) of one seed's placements, running its study unless it is done
    (with ``calibration``, the seed's raw calibration file; else calibrated into ``out``)."""
    import xarray as xr

    from lts360.experiments.gauge_study import run_plug_gauge_study

    nc = out / "trials" / "results.nc"
    t0 = time.perf_counter()
    done = (out / "table.json").is_file() and nc.is_file()
    if done:
        with xr.open_dataset(nc) as ds:
            done = int(ds.sizes["trial"]) == int(placements)
            if done and "spp" in ds.coords:
                done = bool(np.all(np.asarray(ds["spp"].values) == int(spp)))
    if not done:
        run_plug_gauge_study(out, trials=int(placements), seed=int(seed), rig=rig,
                             calibration=calibration, noise="realistic", spp=int(spp),
                             placement_mm=float(placement_mm), master=True,
                             bias_model="twin", steps=False, say=say)
    with xr.open_dataset(nc) as ds:
        err = np.asarray(ds["radius_error_mm"].values, dtype=float)
    return err, time.perf_counter() - t0


def _raw_calibration(out_rig: Path, *, rig: str, seed: int, say) -> Path:
    """The seed's ``lts360 calibrate`` result (rendered boards, realistic noise), calibrated
    into ``OUT/<rig>/seed<S>/calibration/`` unless it is there."""
    from lts360.experiments.gauge_study import ensure_calibration

    return ensure_calibration(out_rig / f"seed{seed}", None, rig=rig, noise="realistic",
                              seed=int(seed), compensate=False, say=say)


def master_parts(rig: str, out_rig: Path, mastered: list, *, placement_mm: float) -> list:
    """Per mastered calibration file, the radius error (mm) of one noise-free centred image of
    the gauge (``CLEAN_SPP`` spp, rendered once per rig and kept in ``OUT/<rig>/``) measured
    with it and the twin: minus what that seed's master put into the correction."""
    from lts360.experiments.gauge_study import measure_gauge_image, placement_band_mm
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    path = out_rig / f"clean-centred-{CLEAN_SPP}spp.npy"
    if path.is_file():
        image = np.load(path)
    else:
        image = simulate_frame(load_rig(rig), build_object(f"plug-gauge:d={GAUGE_DIAMETER_MM}"),
                               spp=CLEAN_SPP, seed=CLEAN_SEED, noise="none").image
        np.save(path, image)
    band = placement_band_mm(float(placement_mm))
    return [float(measure_gauge_image(image, str(c), r_true_mm=GAUGE_DIAMETER_MM / 2,
                                      band_mm=band, compensate=True,
                                      bias_model="twin")["radius_error_mm"])
            for c in mastered]


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


def _sd_interval(sd: float, dof: int) -> list:
    """The 95 % interval of a σ estimated as ``sd`` with ``dof`` degrees of freedom (χ²)."""
    from scipy.stats import chi2

    return [sd * math.sqrt(dof / chi2.ppf(0.975, dof)), sd * math.sqrt(dof / chi2.ppf(0.025, dof))]


def components(errors_um, master_um=None) -> dict:
    """The errors of seeds × placements (µm, a list of per-seed arrays; NaN: a failed
    section) split one way: ``within_sd_um`` (pooled sd within the seeds, Σ(nᵢ − 1) degrees
    of freedom), ``means_sd_um`` (sd of the seeds' means, S − 1), ``between_sd_um`` (the
    seeds' own part, √(sd_means² − within²/n̄), 0 when negative), each sd with its 95 %
    interval; with ``master_um`` (per seed, :func:`master_parts` in µm), ``mean_minus_master_sd_um``
    (the sd of the seeds' means less their masters' parts) and the correlation of the two."""
    groups = [np.asarray(e, dtype=float) for e in errors_um]
    groups = [g[np.isfinite(g)] for g in groups]
    used = [g for g in groups if len(g) >= 1]
    out: dict = {"seeds": len(used)}
    dof_w = int(sum(len(g) - 1 for g in used))
    if dof_w >= 1:
        w = math.sqrt(sum(float(np.sum((g - g.mean()) ** 2)) for g in used) / dof_w)
        out.update(within_sd_um=w, within_sd_95_um=_sd_interval(w, dof_w), within_dof=dof_w)
    if len(used) >= 2:
        means = np.array([g.mean() for g in used])
        sm = float(np.std(means, ddof=1))
        n_bar = float(np.mean([len(g) for g in used]))
        out.update(means_um=means.tolist(), means_sd_um=sm,
                   means_sd_95_um=_sd_interval(sm, len(used) - 1), placements_mean=n_bar)
        if "within_sd_um" in out:
            out["between_sd_um"] = math.sqrt(max(sm ** 2 - out["within_sd_um"] ** 2 / n_bar, 0.0))
        if master_um is not None:
            mk = np.array([float(m) for g, m in zip(groups, master_um) if len(g) >= 1])
            if np.all(np.isfinite(mk)):
                d = means - mk
                out.update(master_um=mk.tolist(),
                           mean_minus_master_sd_um=float(np.std(d, ddof=1)),
                           mean_minus_master_sd_95_um=_sd_interval(float(np.std(d, ddof=1)),
                                                                   len(used) - 1),
                           master_correlation=float(np.corrcoef(means, mk)[0, 1])
                           if np.std(mk) > 0 and sm > 0 else None)
    return out


def _model_components(model: dict, n_bar: float) -> dict:
    """The model's counterparts of :func:`components` (µm): the noise share within a seed,
    the seeds' means' sd (√(compensation² + calibration² + noise²/n̄)) and the seeds' own
    part (√(compensation² + calibration²))."""
    own = math.hypot(model["compensation_um"], model["calibration_um"])
    return {"within_sd_um": model["noise_um"], "between_sd_um": own,
            "means_sd_um": math.sqrt(own ** 2 + model["noise_um"] ** 2 / n_bar),
            "mean_minus_master_sd_um": model["noise_um"] / math.sqrt(n_bar)}


def check_pipeline(rigs, out, *, seeds=(0, 1, 2), placements: int = 5,
                   placement_mm: float = 0.3, spp: int = 64, masters: bool = True,
                   say=print) -> dict:
    """Model and whole-pipeline measurement of the section's radius U(k=2), rig by rig (µm);
    with two or more rigs, the first rig's U over each other's (measured and modelled).
    ``spp``: the studies' samples per pixel (master shot and placements); ``masters``: check
    each seed's master on a noise-free image (:func:`master_parts`)."""
    from lts360.experiments.gauge_study import placement_band_mm

    if not rigs:
        raise ValueError("rigs: at least one rig")
    if isinstance(placements, bool) or not isinstance(placements, int) or placements < 2:
        raise ValueError(f"placements: must be an integer >= 2, got {placements!r}")
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or not 1 <= spp <= 4096:
        raise ValueError(f"spp: must be an integer in [1, 4096], got {spp!r}")
    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds: must be distinct integers, got {seeds}")
    placement_band_mm(placement_mm)  # validates (one line)
    labels = [rig_label(r) for r in rigs]
    if len(set(labels)) != len(labels):
        raise ValueError(f"rigs: two rigs share the folder name {labels}")
    out = Path(out)
    rows = [_check_rig(str(rig), out / label, label, seeds=seeds, placements=placements,
                       placement_mm=placement_mm, spp=int(spp), masters=masters, say=say)
            for rig, label in zip(rigs, labels)]
    res = {"placements": int(placements), "seeds": seeds, "placement_mm": float(placement_mm),
           "spp": int(spp), "gauge_diameter_mm": GAUGE_DIAMETER_MM, "rigs": rows}
    if len(rows) >= 2 and all(r["measured"].get("U_um") for r in rows):
        ref = rows[0]
        res["improvement_over_first"] = [
            {"rig": r["label"], "measured": ref["measured"]["U_um"] / r["measured"]["U_um"],
             "model": ref["model"]["U_um"] / r["model"]["U_um"]} for r in rows[1:]]
    (out / "pipeline.json").write_text(json.dumps(res, indent=2))
    return res


def _check_rig(rig: str, out_rig: Path, label: str, *, seeds, placements: int,
               placement_mm: float, spp: int, masters: bool, say) -> dict:
    """One rig's row of :func:`check_pipeline`."""
    errs, per_seed, mastered = [], [], []
    for s in seeds:
        cal = _raw_calibration(out_rig, rig=rig, seed=s, say=say)
        sdir = study_dir(out_rig, s, spp)
        e, sec = _seed_errors(sdir, rig=rig, seed=s, placements=placements,
                              placement_mm=placement_mm, say=say, spp=spp, calibration=cal)
        errs.append(e)
        mastered.append(sdir / "calibration-compensated-master-twin.json")
        per_seed.append({"seed": s, "radius_errors_um": (1e3 * e).tolist(),
                         "mean_um": float(np.nanmean(e)) * 1e3, "seconds": sec})
    master_um = None
    if masters:
        master_um = [1e3 * v for v in master_parts(rig, out_rig, mastered,
                                                   placement_mm=placement_mm)]
        for row, m in zip(per_seed, master_um):
            row["master_part_um"] = m
    meas = _measured(np.concatenate(errs))
    comp = components([1e3 * e for e in errs], master_um)
    model = _model(rig, placement_mm)
    ratio = model["U_um"] / meas["U_um"] if meas.get("U_um") else None
    return {"rig": rig, "label": label, "measured": meas, "model": model,
            "components": comp,
            "model_components": _model_components(model, comp.get("placements_mean",
                                                                  placements)),
            "model_over_measured": ratio,
            "model_within_25pct": None if ratio is None else bool(0.75 <= ratio <= 1.25),
            "seeds": per_seed}


def _format_components(c: dict, mc: dict) -> list[str]:
    """The split of the errors, measured [95 %] against the model."""
    lines = []
    if "within_sd_um" in c:
        lo, hi = c["within_sd_95_um"]
        lines.append(f"    within a seed (the image's noise): sd {c['within_sd_um']:.2f} µm "
                     f"[95 % {lo:.2f}, {hi:.2f}], model {mc['within_sd_um']:.2f}")
    if "means_sd_um" in c:
        lo, hi = c["means_sd_95_um"]
        lines.append(f"    the seeds' means: sd {c['means_sd_um']:.2f} µm [95 % {lo:.2f}, "
                     f"{hi:.2f}], model {mc['means_sd_um']:.2f} (the seeds' own part "
                     f"{c.get('between_sd_um', float('nan')):.2f}, model: compensation ⊕ "
                     f"calibration {mc['between_sd_um']:.2f})")
    if "master_um" in c:
        lo, hi = c["mean_minus_master_sd_95_um"]
        corr = c.get("master_correlation")
        lines.append("    each seed's master on a noise-free image: "
                     + ", ".join(f"{v:+.2f}" for v in c["master_um"]) + " µm; the seeds' means"
                     f" less it: sd {c['mean_minus_master_sd_um']:.2f} µm [95 % {lo:.2f}, "
                     f"{hi:.2f}] (the placements' noise alone: "
                     f"{mc['mean_minus_master_sd_um']:.2f})"
                     + ("" if corr is None else f", correlation {corr:+.2f}"))
    return lines


def format_pipeline(res: dict) -> list[str]:
    lines = [f"The section's radius U(k=2), the gauge Ø{res['gauge_diameter_mm']} mm ≤ "
             f"{res['placement_mm']:g} mm off the axis, {res['placements']} placements × "
             f"seeds {','.join(map(str, res['seeds']))}, {res.get('spp', LEGACY_SPP)} spp "
             "(lts360 calibrate → compensate with the gauge as master → measure with the "
             "twin):"]
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
        if "components" in r:
            lines += _format_components(r["components"], r["model_components"])
    for imp in res.get("improvement_over_first", []):
        lines.append(f"  {res['rigs'][0]['label']} / {imp['rig']}: measured "
                     f"{imp['measured']:.2f}×, model {imp['model']:.2f}×"
                     + ("" if imp["measured"] >= 1.5 else " (below 1.5×)"))
    return lines

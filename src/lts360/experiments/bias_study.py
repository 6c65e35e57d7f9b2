"""The line-centre bias of the plug gauge over diameters and placements: measured with the
true calibration and no radius given (the band found from the image), as it comes and with the
twin correction (:mod:`lts360.twin`).  ``lts360 study bias``.

Each trial renders the gauge noise-free (the full frame: the band search reads all of it),
measures it with :func:`~lts360.recon.triangulation.measure.measure_sections_following`, then
again with a :class:`~lts360.twin.TwinCorrector`, and scores both against the gauge's exact
circle: the least-squares radius bias and each view's mean radial error.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lts360.experiments.runner import Trial, TrialOutput, plan_trials, run_study, trial_setup

__all__ = ["DEFAULT_DIAMETERS_MM", "DEFAULT_PLACEMENTS_MM", "run_bias_study", "bias_trial",
           "format_bias_table"]

DEFAULT_DIAMETERS_MM = (6.0, 12.0, 20.0, 28.0)
DEFAULT_PLACEMENTS_MM = ((0.0, 0.0), (3.0, 0.0), (0.0, -3.0))
VIEWS = ("direct", "left", "right")


def _score(cloud, center, r_true: float) -> dict:
    from lts360.geometry.fit import fit_circle
    from lts360.recon.triangulation.cloud import VIEW_CODES

    ok = cloud.valid
    p = cloud.points_mm[ok, :2]
    if len(p) < 10:
        return {"n": int(len(p)), "fit_bias_um": np.nan,
                "view_mean_um": np.full(len(VIEWS), np.nan)}
    r = np.hypot(*(p - center).T)
    views = cloud.view[ok]
    means = np.array([1e3 * np.mean(r[views == VIEW_CODES[v]] - r_true)
                      if np.any(views == VIEW_CODES[v]) else np.nan for v in VIEWS])
    return {"n": int(len(p)), "fit_bias_um": 1e3 * (fit_circle(p).radius_mm - r_true),
            "view_mean_um": means}


def bias_trial(trial: Trial) -> TrialOutput:
    """Render one gauge, measure it plain and twin-corrected, score both."""
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.simulator.frame import simulate_frame
    from lts360.twin import TwinCorrector

    p = trial.params
    d = float(p["diameter_mm"])
    rig, obj = trial_setup(p, spec=f"plug-gauge:d={d},x={p['x_mm']},y={p['y_mm']}")
    frame = simulate_frame(rig, obj, spp=int(p["spp"]), seed=trial.seed, noise=p["noise"])
    cal = calibration_from_frame_truth(frame.truth)
    sec = [Section(Path("memory"), 0.0, image=frame.image)]
    center = np.array([float(p["x_mm"]), float(p["y_mm"])])
    plain, _, _ = measure_sections_following(sec, cal, reject=True)
    twin = TwinCorrector(cal, rig, material=obj.material.name, spp=int(p["twin_spp"]))
    corrected, _, _ = measure_sections_following(sec, cal, reject=True, correct=twin)
    a, b = _score(plain, center, d / 2), _score(corrected, center, d / 2)
    values = {"n_valid": a["n"], "bias_plain_um": a["fit_bias_um"],
              "bias_twin_um": b["fit_bias_um"], "twin_render_s": twin.log.render_s,
              "offset_mm": float(np.hypot(*center)),
              "view_plain_um": a["view_mean_um"], "view_twin_um": b["view_mean_um"]}
    return TrialOutput(values=values, dims={"view_plain_um": ("view",),
                                            "view_twin_um": ("view",)},
                       coords={"view": np.array(VIEWS)})


def _spread(v) -> float:
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(np.ptp(v)) if v.size > 1 else float("nan")


def run_bias_study(out_dir, *, diameters_mm=DEFAULT_DIAMETERS_MM,
                   placements_mm=DEFAULT_PLACEMENTS_MM, spp: int = 16, twin_spp: int = 64,
                   noise: str = "none", rig: str = "paper", seed: int = 0,
                   workers: int | None = 1, dask_address: str | None = None,
                   variant: str | None = None) -> dict:
    """Every diameter × placement; write ``trials/results.nc``, ``table.json``, ``table.txt``;
    return the table."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    params = [dict(diameter_mm=float(d), x_mm=float(x), y_mm=float(y), spp=int(spp),
                   twin_spp=int(twin_spp), noise=noise, rig=rig, variant=variant or "")
              for d in diameters_mm for x, y in placements_mm]
    ds = run_study(out / "trials", plan_trials(params, seed), bias_trial, name="bias",
                   workers=workers, dask_address=dask_address,
                   attrs={"noise": noise, "spp": spp, "twin_spp": twin_spp, "rig": rig})
    rows = []
    for i in range(ds.sizes["trial"]):
        t = ds.isel(trial=i)
        vp, vt = t["view_plain_um"].values, t["view_twin_um"].values
        rows.append({"diameter_mm": float(t["diameter_mm"]), "x_mm": float(t["x_mm"]),
                     "y_mm": float(t["y_mm"]), "n_valid": int(t["n_valid"]),
                     "bias_plain_um": float(t["bias_plain_um"]),
                     "bias_twin_um": float(t["bias_twin_um"]),
                     "views_plain_um": [float(v) for v in vp],
                     "views_twin_um": [float(v) for v in vt],
                     "spread_plain_um": _spread(vp), "spread_twin_um": _spread(vt),
                     "twin_render_s": float(t["twin_render_s"])})
    fin = lambda key: [abs(r[key]) for r in rows if np.isfinite(r[key])]  # noqa: E731
    table = {"rows": rows, "settings": {"noise": noise, "spp": spp, "twin_spp": twin_spp,
                                        "rig": rig, "seed": seed},
             "max_abs_bias_plain_um": max(fin("bias_plain_um"), default=float("nan")),
             "max_abs_bias_twin_um": max(fin("bias_twin_um"), default=float("nan")),
             "max_spread_plain_um": max(fin("spread_plain_um"), default=float("nan")),
             "max_spread_twin_um": max(fin("spread_twin_um"), default=float("nan"))}
    (out / "table.json").write_text(json.dumps(table, indent=2))
    (out / "table.txt").write_text(format_bias_table(table) + "\n")
    return table


def format_bias_table(table: dict) -> str:
    s = table["settings"]
    lines = [f"line-centre bias of the plug gauge: rig {s['rig']}, {s['noise']} noise, "
             f"{s['spp']} spp, true calibration, no radius given; twin at {s['twin_spp']} spp",
             f"{'Ø mm':>5s} {'x mm':>5s} {'y mm':>5s} {'points':>6s} | {'bias µm':>8s} "
             f"{'views µm (direct/left/right)':>28s} | {'twin µm':>8s} {'views µm':>22s} "
             f"{'render s':>8s}"]
    f = lambda v: "   —" if not np.isfinite(v) else f"{v:+5.1f}"  # noqa: E731
    for r in table["rows"]:
        lines.append(f"{r['diameter_mm']:5.0f} {r['x_mm']:5.1f} {r['y_mm']:5.1f} "
                     f"{r['n_valid']:6d} | {r['bias_plain_um']:+8.2f} "
                     f"{' '.join(f(v) for v in r['views_plain_um']):>28s} | "
                     f"{r['bias_twin_um']:+8.2f} "
                     f"{' '.join(f(v) for v in r['views_twin_um']):>22s} "
                     f"{r['twin_render_s']:8.1f}")
    lines.append(f"largest |bias|: {table['max_abs_bias_plain_um']:.2f} µm as measured, "
                 f"{table['max_abs_bias_twin_um']:.2f} µm twin-corrected; views apart (largest "
                 f"spread of the view means): {table['max_spread_plain_um']:.2f} → "
                 f"{table['max_spread_twin_um']:.2f} µm")
    return "\n".join(lines)

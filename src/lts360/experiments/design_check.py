"""The design model against full simulation: predicted and simulated radius σ and per-point σ.

For each rig: the model (:mod:`lts360.design`) predicts, for the plug gauge's section
(Ø19.9987 mm, centred), the radius σ after the circle fit and the rms per-point σ_r; the
simulation renders the gauge once (thin lens, ``spp``) and measures ``draws`` images, each
with new EMVA 1288 sensor noise and a new speckle pattern, with the *true* calibration
(:func:`lts360.experiments.design_space.trial._monte_carlo`, as the design-space study) — the
model has no calibration term either.  The simulated σ of the radius is the standard deviation
over the draws, with its 95 % interval (χ² with draws − 1 degrees of freedom); the simulated
per-point σ is the rms of the points' radial errors (which also holds the render's fixed
errors: defocus bias, pixel locking, sampling).

Run: ``PYTHONPATH=src python3 -m lts360.experiments.design_check RIG [RIG ...] --draws 200``.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from lts360.design.model import Conditions, evaluate
from lts360.design.params import DesignSpace
from lts360.scenes.rig_io import load_rig

__all__ = ["check_rig", "main"]

GAUGE_DIAMETER_MM = 19.9987


def check_rig(rig, *, draws: int = 200, spp: int = 16, seed: int = 0) -> dict:
    """Model and simulation side by side for one rig (µm)."""
    import mitsuba as mi
    from scipy.stats import chi2

    from lts360.experiments.design_space.trial import _monte_carlo

    if mi.variant() is None:
        mi.set_variant("llvm_ad_mono")
    space = DesignSpace.create(rig)
    out = {"rig": rig.name}
    for speckle in ("pixel", "dorsch"):
        e = evaluate(space, None, Conditions(diameters_mm=(GAUGE_DIAMETER_MM,), n_theta=360,
                                             speckle=speckle), gradient=False)
        out[f"model_{speckle}"] = {"sigma_R_um": float(e.sigma_R_um[0]),
                                   "point_rms_um": float(e.point_rms_um[0]),
                                   "speckle_rms_um": float(e.speckle_rms_um[0]),
                                   "coverage_deg": float(e.coverage_deg[0])}
    t0 = time.perf_counter()
    sim = _monte_carlo(rig, draws=draws, spp=spp, scale=1.0, seed=seed)
    err = np.asarray(sim["radius_error_mm"], dtype=float)
    err = err[np.isfinite(err)]
    n = len(err)
    s = float(np.std(err, ddof=1)) * 1e3
    lo = s * math.sqrt((n - 1) / chi2.ppf(0.975, n - 1))
    hi = s * math.sqrt((n - 1) / chi2.ppf(0.025, n - 1))
    out["simulation"] = {"sigma_R_um": s, "sigma_R_95_um": [lo, hi], "draws": n,
                         "point_rms_um": sim["point_rms_mm"] * 1e3,
                         "mean_error_um": sim["radius_mean_error_mm"] * 1e3,
                         "coverage_deg": sim["measured_coverage_deg"],
                         "seconds": time.perf_counter() - t0}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rigs", nargs="+", help="presets or rig TOML files")
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    rows = []
    for src in args.rigs:
        r = check_rig(load_rig(src), draws=args.draws, spp=args.spp, seed=args.seed)
        r["source"] = src
        rows.append(r)
        m, s = r["model_pixel"], r["simulation"]
        print(f"{src}: σ_R model {m['sigma_R_um']:.2f} µm (dorsch "
              f"{r['model_dorsch']['sigma_R_um']:.2f}), simulated {s['sigma_R_um']:.2f} "
              f"[{s['sigma_R_95_um'][0]:.2f}, {s['sigma_R_95_um'][1]:.2f}] µm ({s['draws']} draws); "
              f"per point model {m['point_rms_um']:.1f} µm (dorsch "
              f"{r['model_dorsch']['point_rms_um']:.1f}), simulated {s['point_rms_um']:.1f} µm; "
              f"coverage model {m['coverage_deg']:.1f}°, measured {s['coverage_deg']:.1f}° "
              f"({s['seconds']:.0f} s)", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

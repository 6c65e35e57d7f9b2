"""The two shares of a mastered measurement, drawn shot by shot on one calibration (STUDIES.md,
"The optimum through the whole user pipeline").

    python scripts/design_master_noise.py master RIG RAW_CAL --out DIR --draws N --spp S --noise realistic|none
    python scripts/design_master_noise.py shots RIG MASTERED_CAL --window RAW_CAL --out DIR --draws N --spp S --noise realistic|none

``master``: ``N`` shots of the centred Ø19.9987 mm gauge (renderer seed 500000 + j), each
corrected by its twin and mastered on ``RAW_CAL`` (``lts360 calibrate``'s file), as
``design check --pipeline`` masters; each mastered calibration then measures the noise-free
centred image of ``design check --pipeline`` (256 spp, kept in DIR) with the twin.  The sd of
those radius errors is the compensation's share (the master shot's noise).  ``shots``: ``N``
centred shots (seed 600000 + j) measured with ``MASTERED_CAL`` and the twin: the image's own
noise share.  ``--noise none``: the renderer's sampling noise alone (thin lens, ``S`` spp).
Each draw is appended to DIR/<what>-<noise>-<S>spp.json (a run resumes).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("master", "shots"))
    ap.add_argument("rig")
    ap.add_argument("calibration")
    ap.add_argument("--out", required=True)
    ap.add_argument("--draws", type=int, default=12)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--noise", choices=("realistic", "none"), default="realistic")
    ap.add_argument("--window", default=None, metavar="CAL",
                    help="the calibration whose gauge window is rendered (default: the one "
                         "given; STUDIES' shots used the raw calibration's)")
    a = ap.parse_args(argv)

    from lts360.experiments.design_pipeline import CLEAN_SEED, CLEAN_SPP, GAUGE_DIAMETER_MM
    from lts360.experiments.gauge_study import (
        gauge_window_pixels,
        measure_gauge_image,
        placement_band_mm,
    )
    from lts360.recon.calibration.compensation import master_fit
    from lts360.recon.model import load_calibration, save_calibration
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.render import ensure_variant
    from lts360.twin import TwinCorrector, twin_corrected_raw
    from lts360.twin.rig import twin_design

    ensure_variant()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    r = GAUGE_DIAMETER_MM / 2
    rig = load_rig(a.rig)
    obj = build_object(f"plug-gauge:d={GAUGE_DIAMETER_MM}")
    clean_path = out / f"clean-centred-{CLEAN_SPP}spp.npy"
    if not clean_path.is_file():
        np.save(clean_path, simulate_frame(rig, obj, spp=CLEAN_SPP, seed=CLEAN_SEED,
                                           noise="none").image)
    clean = np.load(clean_path)
    band = placement_band_mm(0.3)
    pixels = gauge_window_pixels(a.window or a.calibration, r)
    grid = CylGrid.from_ranges((r - 1.0, r + 1.0), theta_step_deg=0.1, r_step_mm=0.005)
    path = out / f"{a.what}-{a.noise}-{a.spp}spp.json"
    res = json.loads(path.read_text()) if path.is_file() else {}

    def error(image, cal_path):
        m = measure_gauge_image(image, str(cal_path), r_true_mm=r, band_mm=band,
                                compensate=True, bias_model="twin")
        return 1e3 * m["radius_error_mm"]

    for j in range(a.draws):
        if str(j) in res:
            continue
        t0 = time.perf_counter()
        seed = (500_000 if a.what == "master" else 600_000) + j
        image = simulate_frame(rig, obj, spp=a.spp, seed=seed, noise=a.noise,
                               pixels_xy=pixels).image
        if a.what == "master":
            cal = load_calibration(a.calibration)
            shot = twin_corrected_raw(inverse_triangulate(image, cal, grid), cal, grid,
                                      TwinCorrector(cal, twin_design(cal), input_u=None))
            fit = master_fit([shot], GAUGE_DIAMETER_MM)
            mastered = dataclasses.replace(cal, view_offsets_mm=fit.offsets_mm,
                                           view_radial_offsets_mm=fit.radial_offset_mm,
                                           view_scales=fit.scale, master=fit.to_dict())
            cal_path = out / f"mastered-{a.noise}-{a.spp}spp.json"
            save_calibration(cal_path, mastered)
            e = error(clean, cal_path)
        else:
            e = error(image, a.calibration)
        res[str(j)] = {"radius_error_um": e, "seconds": time.perf_counter() - t0}
        path.write_text(json.dumps(res, indent=1))
        sys.stdout.write(f"{j}: {e:+.3f} µm\n")
        sys.stdout.flush()
    e = np.array([v["radius_error_um"] for v in res.values()])
    sys.stdout.write(f"{a.what}, {a.noise}, {a.spp} spp: {len(e)} draws, mean {e.mean():+.3f} "
                     f"µm, sd {e.std(ddof=1):.3f} µm\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The line-centre bias of the centred gauge under a known image blur (STUDIES.md, "The design
model's line-centre bias"): a pinhole render (no defocus), its radiance blurred by an isotropic
Gaussian of σ px (an exact convolution in the image), the sensor (noise-free), measured with the
true calibration; the closed form's response per px² beside it.

    python scripts/design_bias_blur.py RIG DIAMETER_MM SIGMAS [--spp 64]

e.g. ``python scripts/design_bias_blur.py paper 20 0,1,1.5,2``.  Truth (the frame's
calibration, the gauge's radius) is read here only to score.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rig")
    ap.add_argument("diameter_mm", type=float)
    ap.add_argument("sigmas", help="comma-separated σ of the blur, px (0: none)")
    ap.add_argument("--spp", type=int, default=64)
    a = ap.parse_args(argv)

    from scipy.ndimage import gaussian_filter

    from lts360.design.model import Conditions, evaluate
    from lts360.design.params import DesignSpace
    from lts360.experiments.bias_study import _score
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import render_frame, sensor_image
    from lts360.simulator.io import rig_truth
    from lts360.simulator.materials import material_to_bsdf
    from lts360.simulator.render import ensure_variant
    from lts360.simulator.scene import SceneSpec

    ensure_variant()
    rig = load_rig(a.rig)
    d = a.diameter_mm
    obj = build_object(f"plug-gauge:d={d}")
    spec = SceneSpec(rig, (("object", obj.mesh_world(), material_to_bsdf(obj.material)),))
    res, _ = render_frame(spec, spp=a.spp, seed=11, thin_lens=False, support="full")
    rad = res.radiance_W_m2_sr
    cal = calibration_from_frame_truth(rig_truth(rig, res.K, (rad.shape[1], rad.shape[0])))
    ev = evaluate(DesignSpace.create(rig), None,
                  Conditions(diameters_mm=(d,), compensate=False, bias_model="none",
                             n_theta=360), gradient=False, detail=True)
    slope = []
    for v in ("direct", "left", "right"):
        x = ev.detail[v]
        m = x["measured"][0] > 0.5
        slope.append(float(np.mean(x["bias_um_per_psf2"][0][m])))
    sys.stdout.write("closed form, µm per px² of σ² (direct, left, right): "
                     + ", ".join(f"{s:+.2f}" for s in slope) + "\n")
    rows = []
    for s in (float(v) for v in a.sigmas.split(",")):
        blurred = gaussian_filter(rad, s, mode="constant") if s > 0 else rad
        img, _, _ = sensor_image(rig, dataclasses.replace(res, radiance_W_m2_sr=blurred),
                                 noise="none", seed=11)
        cloud, _, _ = measure_sections_following(
            [Section(Path("memory"), 0.0, image=img)], cal, reject=True)
        sc = _score(cloud, np.zeros(2), d / 2)
        rows.append((s, sc))
        sys.stdout.write(f"σ {s:g} px: radius {sc['fit_bias_um']:+.2f} µm, views "
                         + ", ".join(f"{v:+.2f}" for v in sc["view_mean_um"])
                         + f" µm ({sc['n']} points)\n")
    s0 = [sc for s, sc in rows if s == 0]
    if s0:
        for s, sc in rows:
            if s > 0:
                per = (np.asarray(sc["view_mean_um"]) - s0[0]["view_mean_um"]) / s ** 2
                sys.stdout.write(f"σ {s:g} px: measured µm per px² (direct, left, right): "
                                 + ", ".join(f"{v:+.2f}" for v in per) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""True values beside measured ones: the exact section of a rendered object.

A frame or scan directory written by ``lts360 render`` names its object (spec with placement)
and the stage position of each section.  The true section at stage position ``z`` is the
object's analytic outer surface cut by the world plane at that height (the measurement frame of
the true calibration), found per direction θ by a fixed-point iteration on the radius
(converges in a few steps for tilts of a few degrees).  It is then inspected like a measured
section, so the true ovality, roundness and lobes are computed by the same definitions.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["load_truth", "true_section_xy"]

#: θ step of a true section (deg): as fine as the measurement grid.
TRUE_STEP_DEG = 0.1


def load_truth(truth_dir):
    """``(object, [z_mm …])`` of a frame or scan directory."""
    from lts360.scenes.objects.catalog import object_from_truth

    d = Path(truth_dir)
    if (d / "scan.json").is_file():
        scan = json.loads((d / "scan.json").read_text())
        dirs = [d / s["dir"] for s in scan["sections"]]
    elif (d / "frame.json").is_file():
        dirs = [d]
    else:
        raise ValueError(f"--truth: {str(d)!r} holds neither frame.json nor scan.json")
    frames = [json.loads((f / "frame.json").read_text()) for f in dirs]
    specs = {f["object"]["spec"] for f in frames}
    if len(specs) != 1:
        raise ValueError(f"--truth: the frames hold different objects: {sorted(specs)}")
    return (object_from_truth(frames[0]["object"], dirs[0]),
            [float(f["stage"]["z_mm"]) for f in frames])


def true_section_xy(obj, z_mm: float, *, step_deg: float = TRUE_STEP_DEG,
                    iterations: int = 30) -> np.ndarray | None:
    """(m, 2) the true section of ``obj`` in the world plane at ``z_mm`` (None without an
    analytic radius); directions with no surface are left out."""
    if obj.radius_fn is None:
        return None
    th = np.radians(np.arange(-180.0, 180.0, step_deg))
    r = np.full_like(th, float(np.nanmedian(obj.radius_fn(th, np.full_like(th, z_mm)))))
    for _ in range(iterations):
        P = np.column_stack([r * np.cos(th), r * np.sin(th), np.full_like(th, z_mm)])
        po = obj.to_object_frame(P)
        rho = np.hypot(po[:, 0], po[:, 1])
        r_true = np.asarray(obj.radius_fn(np.arctan2(po[:, 1], po[:, 0]), po[:, 2]), float)
        step = r_true - rho
        r = r + step
        if np.nanmax(np.abs(step)) < 1e-10:
            break
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(th[ok]), r[ok] * np.sin(th[ok])])

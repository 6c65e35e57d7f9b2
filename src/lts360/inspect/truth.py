"""True values beside measured ones: the exact section of a rendered object.

A frame or scan directory written by ``lts360 render`` names its object (spec with placement)
and the stage position of each section.  The true section at stage position ``z`` is the
object's analytic outer surface cut by the world plane at that height (the measurement frame of
the true calibration), found per direction θ by a fixed-point iteration on the radius
(converges in a few steps for tilts of a few degrees).  It is then inspected like a measured
section, so the true ovality, roundness and lobes are computed by the same definitions.
"""

from __future__ import annotations

import numpy as np

from lts360.scenes.frame_truth import load_truth

__all__ = ["load_truth", "true_section_xy"]

#: θ step of a true section (deg): as fine as the measurement grid.
TRUE_STEP_DEG = 0.1


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

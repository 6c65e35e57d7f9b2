"""Classical (forward) laser triangulation: image space → object space, the baseline.

1. Stripe centres in the image, perpendicular to the stripe: Steger's 2-D line detector
   (Steger, IEEE PAMI 20(2), 1998) — Gaussian derivatives of scale ``σ``; where the Hessian
   has a strongly negative eigenvalue its eigenvector is the line normal ``n`` and the centre
   lies at ``t n`` with ``t = −(n·∇I) / (nᵀ H n)``, kept when it falls inside the pixel.
2. Each view's image region comes from the rig geometry: the projection (paper Eq. 4) of the
   view's θ window of the cylindrical band, dilated by a few pixels.
3. Each centre's camera ray, reflected through the view's mirror(s), meets the laser plane:
   with ``T`` the view's transform (``P · T · X`` projects), the object point is
   ``X = T⁻¹ (s d)`` with ``s`` chosen so that ``X`` lies on the laser plane.
The points come out in the measurement frame with their view labels, like the inverse method,
so both are scored the same way.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from lts360.geometry.camera import backproject_pixels
from lts360.recon.lines import steger_centres
from lts360.recon.model import Calibration
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import plan_inverse

__all__ = ["view_regions", "classic_triangulate"]


def view_regions(cal: Calibration, grid: CylGrid, *, dilate_px: int = 3) -> dict[str, np.ndarray]:
    """Per view, the image pixels its windowed band of the grid projects to (dilated)."""
    w, h = cal.image_size
    plan = plan_inverse(cal, grid, precompute=False)
    out = {}
    for name, vp in plan.views.items():
        uv = vp.uv.reshape(-1, 2)
        uv = uv[np.all(np.isfinite(uv), axis=1)]
        m = np.zeros((h, w), dtype=bool)
        iu = np.clip(np.round(uv[:, 0]).astype(int), 0, w - 1)
        iv = np.clip(np.round(uv[:, 1]).astype(int), 0, h - 1)
        m[iv, iu] = True
        out[name] = ndimage.binary_dilation(m, iterations=dilate_px) if dilate_px else m
    return out, plan


def classic_triangulate(image, cal: Calibration, grid: CylGrid, *, sigma_px: float = 1.5,
                        threshold: float | None = None, regions=None) -> dict[str, dict]:
    """Forward triangulation per view.

    Returns
    -------
    dict view → {"theta_rad", "r_mm", "points_meas_mm", "intensity", "uv"}
        Points in the measurement frame (z = 0 up to rounding), kept when their radius lies in
        the grid's radial band and their angle in the view's θ window.
    """
    img = np.asarray(image)
    if regions is None:
        regions, plan = view_regions(cal, grid)
    else:
        regions, plan = regions
    union = np.logical_or.reduce(list(regions.values()))
    centres = steger_centres(img, sigma_px=sigma_px, threshold=threshold, mask=union)
    rays = backproject_pixels(centres.uv, cal.K, cal.dist)
    n_l, d_l = cal.laser_plane
    T_meas_cam = cal.T_meas_cam
    step = grid.theta_step_rad
    out = {}
    for name, vp in plan.views.items():
        reg = regions[name]
        sel = reg[np.clip(np.round(centres.uv[:, 1]).astype(int), 0, reg.shape[0] - 1),
                  np.clip(np.round(centres.uv[:, 0]).astype(int), 0, reg.shape[1] - 1)]
        d = rays[sel]
        Tinv = np.linalg.inv(vp.view.T_cam)
        A, b = Tinv[:3, :3], Tinv[:3, 3]
        Ad = d @ A.T
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (d_l - n_l @ b) / (Ad @ n_l)
        X_cam = s[:, None] * Ad + b
        X = X_cam @ T_meas_cam[:3, :3].T + T_meas_cam[:3, 3]
        theta = np.arctan2(X[:, 1], X[:, 0])
        r = np.hypot(X[:, 0], X[:, 1])
        k = np.round((theta - grid.theta_rad[0]) / step).astype(int) % grid.n_theta
        keep = (s > 0) & (r >= grid.r_mm[0]) & (r <= grid.r_mm[-1]) & vp.window[k]
        out[name] = {"theta_rad": theta[keep], "r_mm": r[keep], "points_meas_mm": X[keep],
                     "intensity": centres.intensity[sel][keep], "uv": centres.uv[sel][keep]}
    return out

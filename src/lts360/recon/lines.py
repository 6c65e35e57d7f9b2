"""Sub-pixel centres of a bright laser line in an image (Steger 1998), read by the laser-plane
calibration and by the classical triangulation alike."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from lts360.recon.images import default_threshold

__all__ = ["StripeCentres", "steger_centres"]


@dataclass(frozen=True)
class StripeCentres:
    """Sub-pixel stripe centres: ``uv`` (n, 2), unit normals (n, 2), smoothed intensity (n,)."""

    uv: np.ndarray
    normal: np.ndarray
    intensity: np.ndarray


def steger_centres(image, *, sigma_px: float = 1.5, threshold: float | None = None,
                   mask: np.ndarray | None = None, line_ratio: float = 0.5) -> StripeCentres:
    """Stripe centre points of a bright line on a dark background (Steger 1998, 2-D).

    Parameters
    ----------
    image : (h, w) array
    sigma_px : float, (0, 20]
        Scale of the Gaussian derivatives (≈ the line's half-width / √3 for a bar profile).
    threshold : float, optional
        Smoothed intensity a centre must exceed (default 10 % of full scale / of the maximum).
    mask : (h, w) bool, optional
        Pixels to consider.
    line_ratio : float, (0, 1]
        Largest ratio of the Hessian's along-line to across-line eigenvalue magnitudes
        (rejects blobs, stripe ends and edges).
    """
    img = np.asarray(image, dtype=float)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D, got shape {img.shape}")
    if not 0 < sigma_px <= 20:
        raise ValueError(f"sigma_px must be in (0, 20], got {sigma_px}")
    thr = default_threshold(np.asarray(image)) if threshold is None else float(threshold)
    g = ndimage.gaussian_filter(img, sigma_px)
    gy = ndimage.gaussian_filter(img, sigma_px, order=(1, 0))
    gx = ndimage.gaussian_filter(img, sigma_px, order=(0, 1))
    gyy = ndimage.gaussian_filter(img, sigma_px, order=(2, 0))
    gxx = ndimage.gaussian_filter(img, sigma_px, order=(0, 2))
    gxy = ndimage.gaussian_filter(img, sigma_px, order=(1, 1))
    cand = g > thr
    if mask is not None:
        cand &= mask
    ys, xs = np.nonzero(cand)
    hxx, hxy, hyy = gxx[ys, xs], gxy[ys, xs], gyy[ys, xs]
    # Most negative eigenvalue of [[hxx, hxy], [hxy, hyy]] and its eigenvector (the normal).
    half_tr = 0.5 * (hxx + hyy)
    disc = np.sqrt(0.25 * (hxx - hyy) ** 2 + hxy**2)
    lam = half_tr - disc
    nx = np.where(np.abs(hxy) > 1e-12, hxy, np.where(hxx <= hyy, 1.0, 0.0))
    ny = np.where(np.abs(hxy) > 1e-12, lam - hxx, np.where(hxx <= hyy, 0.0, 1.0))
    norm = np.hypot(nx, ny)
    nx, ny = nx / norm, ny / norm
    curv = nx * nx * hxx + 2 * nx * ny * hxy + ny * ny * hyy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -(nx * gx[ys, xs] + ny * gy[ys, xs]) / curv
    lam_other = half_tr + disc
    # A line, not a blob or an edge: strongly curved across (λ < 0), little along (|λ₂| ≪ |λ|).
    ok = (lam < 0) & (curv < 0) & np.isfinite(t) & (np.abs(t * nx) <= 0.5) & (np.abs(t * ny) <= 0.5)
    ok &= np.abs(lam_other) < line_ratio * np.abs(lam)
    uv = np.column_stack([xs + t * nx, ys + t * ny])[ok]
    return StripeCentres(uv=uv, normal=np.column_stack([nx, ny])[ok], intensity=g[ys, xs][ok])

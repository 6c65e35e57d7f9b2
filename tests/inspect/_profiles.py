"""Constructed profiles with known answers, and a synthetic scan as a Cloud."""

from __future__ import annotations

import numpy as np

from lts360.recon.triangulation.cloud import Cloud

STEP_DEG = 0.1  # the measurement grid's θ step


def polar(r_fn, *, centre=(0.0, 0.0), step_deg=STEP_DEG):
    th = np.radians(np.arange(-180.0, 180.0, step_deg))
    r = r_fn(th)
    return np.column_stack([centre[0] + r * np.cos(th), centre[1] + r * np.sin(th)])


def ellipse(a, b, *, centre=(0.0, 0.0), step_deg=STEP_DEG):
    th = np.radians(np.arange(-180.0, 180.0, step_deg))
    return np.column_stack([centre[0] + a * np.cos(th), centre[1] + b * np.sin(th)])


def constant_width(R, a, *, lobes=3, n=3600):
    """A curve of constant width 2R from its support function h(φ) = R + a cos(lobes·φ)
    (lobes odd, a < R / (lobes² − 1) keeps it convex): x = h n + h′ t."""
    phi = np.linspace(-np.pi, np.pi, n, endpoint=False)
    h = R + a * np.cos(lobes * phi)
    dh = -lobes * a * np.sin(lobes * phi)
    n_ = np.column_stack([np.cos(phi), np.sin(phi)])
    t_ = np.column_stack([-np.sin(phi), np.cos(phi)])
    return h[:, None] * n_ + dh[:, None] * t_


def scan_cloud(n_sections=12, pitch_mm=0.68, *, R=10.0, ovality_mm=0.2, dent_mm=0.0,
               dent_z_mm=0.0, dent_sigma_z_mm=1.5, noise_mm=0.0, tilt_x=0.0, gap_deg=(100, 104),
               seed=0):
    """A scan of an oval section with an optional dent at θ = −90°, tilted along x, with one θ
    gap flagged NO_PEAK; z from the stage."""
    rng = np.random.default_rng(seed)
    th = np.radians(np.arange(-180.0, 180.0, STEP_DEG))
    parts = []
    for k in range(n_sections):
        z = (k - (n_sections - 1) / 2) * pitch_mm
        r = (R + ovality_mm / 4 * np.cos(2 * th)
             - dent_mm * np.exp(-(1 - np.cos(th + np.pi / 2)) * 30)
             * np.exp(-(z - dent_z_mm) ** 2 / (2 * dent_sigma_z_mm**2))
             + noise_mm * rng.normal(size=th.size))
        pts = np.column_stack([r * np.cos(th) + tilt_x * z, r * np.sin(th), np.full(th.size, z)])
        q = np.zeros(th.size, np.uint8)
        if gap_deg is not None:
            g = (th > np.radians(gap_deg[0])) & (th < np.radians(gap_deg[1]))
            pts[g] = np.nan
            q[g] = 1  # NO_PEAK
        parts.append(Cloud(pts, th, r, (np.arange(th.size) % 3).astype(np.uint8), q,
                           np.full(th.size, k, np.int32), np.ones(th.size, np.float32)))
    return Cloud.concatenate(parts)


def noisy_section_cloud(seed, *, noise_mm, rho=0.0, R=16.0, ovality_mm=0.8, dent_mm=0.6,
                        dent_sigma_arc_mm=3.0, step_deg=STEP_DEG):
    """One section of the PVC pipe's shape (oval, a dent at θ = −90°) with seeded noise on the
    radius of each point, white or AR(1) along θ with lag-1 correlation ``rho`` (point to
    point), as a Cloud; and the same section without noise (its truth)."""
    rng = np.random.default_rng(seed)
    th = np.radians(np.arange(-180.0, 180.0, step_deg))
    r0 = (R + ovality_mm / 4 * np.cos(2 * th)
          - dent_mm * np.exp(-(1 - np.cos(th + np.pi / 2)) * (R / dent_sigma_arc_mm) ** 2))
    e = rng.normal(size=th.size)
    if rho > 0:
        from scipy.signal import lfilter

        e = lfilter([np.sqrt(1 - rho**2)], [1, -rho], e)
    out = []
    for r in (r0 + noise_mm * e, r0):
        pts = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(th.size)])
        out.append(Cloud(pts, th, r, (np.arange(th.size) % 3).astype(np.uint8),
                         np.zeros(th.size, np.uint8), np.zeros(th.size, np.int32),
                         np.ones(th.size, np.float32)))
    return out[0], out[1]

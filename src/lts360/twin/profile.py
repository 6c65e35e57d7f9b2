"""A measured section as a closed profile, the prism that extrudes it, and the exact radii of
that profile along the measurement's rays.

The profile is polar about the least-squares centre of the measured points: ``ρ(φ)`` on a
regular φ grid, each bin the mean of its points, a circular median then a moving average over
``smooth_deg``, gaps closed by periodic interpolation.  It is the twin's geometry: it must be
right to a few µm where the bias varies (millimetres), not to the noise of one point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

from lts360.geometry.fit import fit_circle

__all__ = ["SectionProfile", "section_profile", "prism_mesh", "ray_radii"]


@dataclass(frozen=True, eq=False)
class SectionProfile:
    """A closed star-shaped section profile (measurement frame, mm).

    ``center_mm`` (2,); ``phi_rad`` (n,) regular on [0, 2π); ``rho_mm`` (n,) the distance from
    the centre; ``coverage`` the share of φ bins that held a measured point; ``largest_gap_deg``.
    """

    center_mm: np.ndarray
    phi_rad: np.ndarray
    rho_mm: np.ndarray
    coverage: float
    largest_gap_deg: float

    @property
    def vertices_mm(self) -> np.ndarray:
        """(n, 2) the polygon, counter-clockwise."""
        return self.center_mm + self.rho_mm[:, None] * np.column_stack(
            [np.cos(self.phi_rad), np.sin(self.phi_rad)])


def _largest_gap(filled: np.ndarray) -> int:
    """Longest circular run of False."""
    if filled.all():
        return 0
    if not filled.any():
        return filled.size
    k = int(np.argmax(filled))
    f = np.roll(filled, -k)  # starts on a filled bin
    idx = np.flatnonzero(f)
    return int(np.max(np.diff(np.append(idx, f.size)) - 1))


def section_profile(points_xy_mm, *, n_bins: int = 1440, smooth_deg: float = 1.0,
                    min_points: int = 50) -> SectionProfile:
    """The closed profile of one section's measured points ``(k, 2)``.

    Raises
    ------
    ValueError
        Fewer than ``min_points`` finite points.
    """
    p = np.asarray(points_xy_mm, float).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < min_points:
        raise ValueError(f"section profile: {len(p)} measured points, need {min_points}")
    if not 0 < smooth_deg <= 30:
        raise ValueError(f"smooth_deg must be in (0, 30], got {smooth_deg}")
    c = fit_circle(p).center_mm
    d = p - c
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    rho = np.hypot(d[:, 0], d[:, 1])
    b = np.minimum((phi / (2 * np.pi) * n_bins).astype(np.int64), n_bins - 1)
    cnt = np.bincount(b, minlength=n_bins)
    mean = np.bincount(b, weights=rho, minlength=n_bins) / np.maximum(cnt, 1)
    grid = (np.arange(n_bins) + 0.5) * 2 * np.pi / n_bins
    filled = cnt > 0
    rho_b = np.interp(grid, grid[filled], mean[filled], period=2 * np.pi)
    k = max(1, int(round(smooth_deg / 360.0 * n_bins)))
    rho_b = median_filter(rho_b, size=k | 1, mode="wrap")
    rho_b = uniform_filter1d(rho_b, size=k, mode="wrap")
    return SectionProfile(center_mm=c, phi_rad=grid, rho_mm=rho_b,
                          coverage=float(filled.mean()),
                          largest_gap_deg=_largest_gap(filled) * 360.0 / n_bins)


def prism_mesh(profile: SectionProfile, *, half_length_mm: float = 30.0):
    """A watertight prism: the profile extruded along the measurement z over ±half_length_mm
    (outward normals)."""
    import trimesh

    v2 = profile.vertices_mm
    n = len(v2)
    bottom = np.column_stack([v2, np.full(n, -half_length_mm)])
    top = np.column_stack([v2, np.full(n, half_length_mm)])
    c = profile.center_mm
    verts = np.vstack([bottom, top, [[c[0], c[1], -half_length_mm], [c[0], c[1], half_length_mm]]])
    i = np.arange(n)
    j = (i + 1) % n
    cb, ct = 2 * n, 2 * n + 1
    faces = np.vstack([
        np.column_stack([i, j, n + j]),          # sides (counter-clockwise profile, +z up)
        np.column_stack([i, n + j, n + i]),
        np.column_stack([np.full(n, ct), n + i, n + j]),  # top cap, normal +z
        np.column_stack([np.full(n, cb), j, i]),           # bottom cap, normal −z
    ])
    return trimesh.Trimesh(vertices=verts, faces=faces, process=False)


def ray_radii(vertices_mm, theta_rad, near_mm=None, *, chunk: int = 512) -> np.ndarray:
    """Where the rays from the origin at angles ``theta_rad`` cross the closed polygon
    ``vertices_mm`` (n, 2): the distance along each ray, the crossing nearest ``near_mm``
    (per ray; default: the farthest).  NaN for a ray that crosses nothing."""
    v = np.asarray(vertices_mm, float).reshape(-1, 2)
    e = np.roll(v, -1, axis=0) - v
    th = np.asarray(theta_rad, float).ravel()
    near = None if near_mm is None else np.broadcast_to(np.asarray(near_mm, float), th.shape)
    out = np.full(th.size, np.nan)
    pxe = v[:, 0] * e[:, 1] - v[:, 1] * e[:, 0]
    for a in range(0, th.size, chunk):
        u = np.column_stack([np.cos(th[a:a + chunk]), np.sin(th[a:a + chunk])])
        uxe = u[:, :1] * e[None, :, 1] - u[:, 1:] * e[None, :, 0]
        pxu = v[None, :, 0] * u[:, 1:] - v[None, :, 1] * u[:, :1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = pxe[None, :] / uxe
            s = pxu / uxe
        hit = (uxe != 0) & (s >= 0) & (s < 1) & (t > 0)
        t = np.where(hit, t, np.nan)
        if near is None:
            out[a:a + chunk] = np.nanmax(np.where(hit, t, -np.inf), axis=1)
        else:
            dist = np.abs(t - near[a:a + chunk, None])
            k = np.argmin(np.where(hit, dist, np.inf), axis=1)
            out[a:a + chunk] = t[np.arange(len(k)), k]
    out[~np.isfinite(out)] = np.nan
    return out

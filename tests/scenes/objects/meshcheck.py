"""Mesh-versus-truth checks shared by the object tests (imported as a sibling module)."""

from __future__ import annotations

import math

import numpy as np


def _wrap(a):
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


def radial_error(points_mm, radius_fn):
    """(n,) radius of each object-frame point minus the true radius at its (θ, z)."""
    theta = np.arctan2(points_mm[:, 1], points_mm[:, 0])
    return np.hypot(points_mm[:, 0], points_mm[:, 1]) - radius_fn(theta, points_mm[:, 2])


def face_points(tri, weights):
    """(m·k, 3) points of barycentric ``weights`` (k, 3) on triangles ``tri`` (m, 3, 3)."""
    return np.einsum("kj,mjd->mkd", weights, tri).reshape(-1, 3)


def outermost_hit_radius(tri, theta, z):
    """Largest radius at which the horizontal ray from the axis point (0, 0, z) in direction
    θ meets one of the side triangles ``tri`` (m, 3, 3); NaN where it meets none.  Candidates
    are the triangles whose z and angular ranges hold the ray (Möller–Trumbore on those)."""
    zmin, zmax = tri[:, :, 2].min(1), tri[:, :, 2].max(1)
    ang = np.arctan2(tri[..., 1], tri[..., 0])
    rel = _wrap(ang - ang[:, :1])
    a_lo = ang[:, 0] + rel.min(1)
    span = rel.max(1) - rel.min(1)
    out = np.full(len(theta), np.nan)
    for k, (t, zz) in enumerate(zip(theta, z)):
        sel = (zmin <= zz) & (zmax >= zz)
        off = np.mod(t - a_lo[sel], 2.0 * np.pi)
        cand = tri[sel][(off <= span[sel] + 1e-9) | (off >= 2.0 * np.pi - 1e-9)]
        d = np.array([math.cos(t), math.sin(t), 0.0])
        e1, e2 = cand[:, 1] - cand[:, 0], cand[:, 2] - cand[:, 0]
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = np.array([0.0, 0.0, zz]) - cand[:, 0]
            u = np.einsum("ij,ij->i", s, p) * inv
            q = np.cross(s, e1)
            v = (q @ d) * inv
            dist = np.einsum("ij,ij->i", q, e2) * inv
        eps = 1e-12
        hit = (np.abs(det) > 1e-300) & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (dist > 0)
        if hit.any():
            out[k] = dist[hit].max()
    return out

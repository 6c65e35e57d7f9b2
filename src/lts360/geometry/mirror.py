"""Planar mirrors: the mirror matrix ``T_pi`` of paper Eq. 3 and reflections through a plane.

A mirror plane is ``n · X = d`` with unit normal ``n``; all points, rays and poses are
expressed in the frame in which ``(n, d)`` is given.  Lengths in millimetres.
"""

from __future__ import annotations

import numpy as np

from lts360.geometry._checks import as_matrix, as_points, unit

__all__ = [
    "mirror_matrix",
    "reflect_points",
    "reflect_directions",
    "reflect_rays",
    "reflect_pose",
    "transform_plane",
]


def _plane(n, d) -> tuple[np.ndarray, float]:
    n = unit(np.asarray(n, dtype=float).reshape(3), "plane normal n")
    d = float(d)
    if not np.isfinite(d):
        raise ValueError(f"plane offset d must be finite, got {d}")
    return n, d


def mirror_matrix(n, d) -> np.ndarray:
    """Paper Eq. 3: ``T_pi = [[I - 2 n nᵀ, 2 d n], [0, 1]]`` for the plane ``n · X = d``.

    Returns
    -------
    (4, 4) float
        Homogeneous reflection; ``T_pi @ T_pi = I`` and ``det(T_pi) = -1``.
    """
    n, d = _plane(n, d)
    T = np.eye(4)
    T[:3, :3] -= 2.0 * np.outer(n, n)
    T[:3, 3] = 2.0 * d * n
    return T


def reflect_points(points_mm, n, d) -> np.ndarray:
    """Mirror images of (k, 3) points through the plane ``n · X = d``."""
    pts = as_points(points_mm, "points_mm")
    n, d = _plane(n, d)
    s = pts @ n - d
    return pts - 2.0 * s[:, None] * n


def reflect_directions(directions, n) -> np.ndarray:
    """Reflect (k, 3) direction vectors off a plane with normal ``n`` (no translation)."""
    dirs = as_points(directions, "directions")
    n = unit(np.asarray(n, dtype=float).reshape(3), "plane normal n")
    return dirs - 2.0 * (dirs @ n)[:, None] * n


def reflect_rays(origins_mm, directions, n, d) -> tuple[np.ndarray, np.ndarray]:
    """Mirror images of rays ``(origin, direction)`` through the plane ``n · X = d``."""
    return reflect_points(origins_mm, n, d), reflect_directions(directions, n)


def reflect_pose(R, t_mm, n, d) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera pose of the virtual camera seen in a mirror.

    For a camera ``X_cam = R X + t`` and a mirror ``n · X = d`` (world frame), returns
    ``(R', t')`` with ``[R' | t'] = [R | t] · T_pi`` so that projecting a real point with the
    virtual pose equals projecting its mirror image with the real pose.  ``det(R') = -1``:
    the virtual camera is left-handed, as mirror images are.
    """
    R = as_matrix(R, (3, 3), "R")
    t = np.asarray(t_mm, dtype=float).reshape(3)
    T = mirror_matrix(n, d)
    return R @ T[:3, :3], R @ T[:3, 3] + t


def transform_plane(n, d, R, t_mm) -> tuple[np.ndarray, float]:
    """Express the plane ``n · X = d`` in the frame ``X' = R X + t`` (R a rotation)."""
    n, d = _plane(n, d)
    R = as_matrix(R, (3, 3), "R")
    n2 = R @ n
    return n2, float(d + n2 @ np.asarray(t_mm, dtype=float).reshape(3))

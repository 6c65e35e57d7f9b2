"""Pinhole projection ``K[R|t]`` with Brown distortion, and its inverse.

Conventions (OpenCV): camera x right, y down, z forward; pixel centres at integer
coordinates; distortion coefficients ``(k1, k2, p1, p2, k3)`` in OpenCV's order;
``X_cam = R @ X_world + t``.  Lengths in millimetres.
"""

from __future__ import annotations

import numpy as np

from lts360.geometry._checks import as_matrix, as_points

__all__ = [
    "distort_normalized",
    "undistort_normalized",
    "world_to_camera",
    "project_camera_points",
    "project_points",
    "backproject_pixels",
    "camera_center",
    "look_at",
    "scale_intrinsics",
]

_ZERO_DIST = np.zeros(5)


def _dist(dist) -> np.ndarray:
    d = np.zeros(5)
    if dist is None:
        return d
    dist = np.asarray(dist, dtype=float).ravel()
    if dist.size not in (4, 5) or not np.all(np.isfinite(dist)):
        raise ValueError(f"dist must hold 4 or 5 finite numbers (k1, k2, p1, p2[, k3]), got {dist!r}")
    d[: dist.size] = dist
    return d


def distort_normalized(xy: np.ndarray, dist) -> np.ndarray:
    """Apply Brown distortion to normalised image coordinates.

    Parameters
    ----------
    xy : (n, 2) float
        Ideal normalised coordinates ``(X/Z, Y/Z)``.
    dist : (5,) float
        ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    (n, 2) float
        Distorted normalised coordinates.
    """
    xy = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = _dist(dist)
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def _distortion_jacobian(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(n, 2, 2) Jacobian of :func:`distort_normalized` with respect to ``xy``."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    jac = np.empty(xy.shape[:-1] + (2, 2))
    jac[..., 0, 0] = radial + 2.0 * x * x * dradial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x
    jac[..., 0, 1] = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    jac[..., 1, 0] = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    jac[..., 1, 1] = radial + 2.0 * y * y * dradial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x
    return jac


def undistort_normalized(xy_distorted: np.ndarray, dist, *, max_iterations: int = 50,
                         tol: float = 1e-15) -> np.ndarray:
    """Invert Brown distortion by Newton's method (vectorised over points).

    Converges quadratically for any distortion that is monotonic over the field of view; the
    result is exact to ~1e-15 in normalised units (far below 1e-6 px).

    Parameters
    ----------
    xy_distorted : (n, 2) float
        Distorted normalised coordinates.
    dist : (5,) float
        ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    (n, 2) float
        Ideal normalised coordinates ``xy`` with ``distort_normalized(xy) == xy_distorted``.
    """
    target = np.asarray(xy_distorted, dtype=float)
    d = _dist(dist)
    if not np.any(d):
        return target.copy()
    xy = target.copy()
    for _ in range(max_iterations):
        residual = distort_normalized(xy, d) - target
        jac = _distortion_jacobian(xy, d)
        # The 2 × 2 systems solved in closed form (np.linalg.solve's batched LU is ~10 times
        # slower on many small systems).
        a, b, c, e = jac[..., 0, 0], jac[..., 0, 1], jac[..., 1, 0], jac[..., 1, 1]
        det = a * e - b * c
        step = np.stack([(e * residual[..., 0] - b * residual[..., 1]) / det,
                         (a * residual[..., 1] - c * residual[..., 0]) / det], axis=-1)
        xy = xy - step
        if np.max(np.abs(step), initial=0.0) < tol:
            break
    return xy


def world_to_camera(points_world_mm: np.ndarray, R: np.ndarray, t_mm: np.ndarray) -> np.ndarray:
    """``X_cam = R @ X_world + t`` for (n, 3) points."""
    pts = as_points(points_world_mm, "points_world_mm")
    R = as_matrix(R, (3, 3), "R")
    t = np.asarray(t_mm, dtype=float).reshape(3)
    return pts @ R.T + t


def project_camera_points(points_cam_mm: np.ndarray, K: np.ndarray, dist=None) -> np.ndarray:
    """Project points given in the camera frame to pixels.

    Parameters
    ----------
    points_cam_mm : (n, 3) float
        Points in the camera frame; ``z`` must be positive for a meaningful result
        (points behind the camera give NaN).
    K : (3, 3) float
        Intrinsic matrix.
    dist : (5,) float, optional
        Brown distortion ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    (n, 2) float
        Pixel coordinates (OpenCV convention: pixel centres at integers).
    """
    pts = as_points(points_cam_mm, "points_cam_mm")
    K = as_matrix(K, (3, 3), "K")
    z = pts[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = pts[:, :2] / np.where(z > 0, z, np.nan)[:, None]
    xy = distort_normalized(xy, dist)
    u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
    v = K[1, 1] * xy[:, 1] + K[1, 2]
    return np.stack([u, v], axis=-1)


def project_points(points_world_mm: np.ndarray, K: np.ndarray, dist, R: np.ndarray,
                   t_mm: np.ndarray, T_mirror: np.ndarray | None = None) -> np.ndarray:
    """Paper Eq. 4: ``g = P · T_pi · G`` with distortion.

    Parameters
    ----------
    points_world_mm : (n, 3) float
        Points in the world (or measurement) frame.
    K, dist, R, t_mm
        Camera intrinsics, distortion and world-to-camera pose.
    T_mirror : (4, 4) float, optional
        Mirror matrix (:func:`lts360.geometry.mirror.mirror_matrix`) or a product of them,
        expressed in the same frame as the points. ``None`` is the identity (direct view).

    Returns
    -------
    (n, 2) float
        Pixel coordinates.
    """
    pts = as_points(points_world_mm, "points_world_mm")
    if T_mirror is not None:
        T = as_matrix(T_mirror, (4, 4), "T_mirror")
        pts = pts @ T[:3, :3].T + T[:3, 3]
    return project_camera_points(world_to_camera(pts, R, t_mm), K, dist)


def backproject_pixels(pixels: np.ndarray, K: np.ndarray, dist=None) -> np.ndarray:
    """Unit ray directions in the camera frame through the given pixels.

    Parameters
    ----------
    pixels : (n, 2) float
        Pixel coordinates (distorted, as observed).
    K : (3, 3) float
    dist : (5,) float, optional

    Returns
    -------
    (n, 3) float
        Unit vectors with positive ``z``.
    """
    px = np.asarray(pixels, dtype=float).reshape(-1, 2)
    K = as_matrix(K, (3, 3), "K")
    yd = (px[:, 1] - K[1, 2]) / K[1, 1]
    xd = (px[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
    xy = undistort_normalized(np.stack([xd, yd], axis=-1), dist)
    rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def camera_center(R: np.ndarray, t_mm: np.ndarray) -> np.ndarray:
    """Camera centre in the world frame, ``C = -Rᵀ t`` (works for reflected poses too)."""
    R = as_matrix(R, (3, 3), "R")
    return -np.linalg.solve(R, np.asarray(t_mm, dtype=float).reshape(3))


def look_at(position_mm, target_mm, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera pose ``(R, t)`` of an OpenCV camera at ``position`` looking at ``target``.

    The image ``y`` axis (down) is the projection of ``-up`` onto the image plane.
    """
    c = np.asarray(position_mm, dtype=float).reshape(3)
    z = np.asarray(target_mm, dtype=float).reshape(3) - c
    norm = np.linalg.norm(z)
    if norm == 0:
        raise ValueError("look_at: target coincides with the camera position")
    z /= norm
    up = np.asarray(up, dtype=float).reshape(3)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-12:
        raise ValueError("look_at: viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ c


def scale_intrinsics(K: np.ndarray, scale: float) -> np.ndarray:
    """Intrinsics of the same camera sampled on a grid ``scale`` times as fine.

    Pixel centres stay at integers: ``f' = s f``, ``c' = (c + 0.5) s − 0.5``.
    """
    K = as_matrix(K, (3, 3), "K")
    if not scale > 0:
        raise ValueError(f"scale must be > 0, got {scale}")
    out = K.copy()
    out[0, 0] *= scale
    out[0, 1] *= scale
    out[1, 1] *= scale
    out[0, 2] = (K[0, 2] + 0.5) * scale - 0.5
    out[1, 2] = (K[1, 2] + 0.5) * scale - 0.5
    return out

"""Least-squares plane and circle fits."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from lts360.geometry._checks import as_points

__all__ = ["PlaneFit", "CircleFit", "fit_plane", "fit_circle"]


@dataclass(frozen=True)
class PlaneFit:
    """Plane ``normal · X = offset_mm`` fitted to points; ``residuals_mm`` are signed distances."""

    normal: np.ndarray
    offset_mm: float
    residuals_mm: np.ndarray
    singular_values: np.ndarray

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm**2)))


@dataclass(frozen=True)
class CircleFit:
    """Circle fitted to 2-D points (geometric least squares)."""

    center_mm: np.ndarray
    radius_mm: float
    residuals_mm: np.ndarray

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm**2)))


def fit_plane(points_mm, *, min_spread_ratio: float = 1e-6) -> PlaneFit:
    """Total-least-squares plane through (n, 3) points (orthogonal distances).

    The fit has no preferred side; the normal is returned with its largest-magnitude
    component positive.

    Raises
    ------
    ValueError
        Fewer than three points, or points (nearly) collinear: the plane is not determined.
        ``min_spread_ratio`` is the smallest accepted ratio of the second to the first
        singular value of the centred points.
    """
    pts = as_points(points_mm, "points_mm")
    if pts.shape[0] < 3:
        raise ValueError(f"fit_plane needs at least 3 points, got {pts.shape[0]}")
    centroid = pts.mean(axis=0)
    _, s, vt = np.linalg.svd(pts - centroid, full_matrices=False)
    if s[0] == 0 or s[1] / s[0] < min_spread_ratio:
        raise ValueError("fit_plane: the points are collinear, the plane is not determined "
                         f"(singular values {s.tolist()})")
    n = vt[2]
    n = n if n[np.argmax(np.abs(n))] > 0 else -n
    d = float(n @ centroid)
    return PlaneFit(normal=n, offset_mm=d, residuals_mm=pts @ n - d, singular_values=s)


def fit_circle(points_mm) -> CircleFit:
    """Geometric least-squares circle through (n, 2) points.

    Starts from the algebraic (Kåsa) fit and refines ``(cx, cy, r)`` minimising the
    orthogonal distances ``|p - c| - r`` with Levenberg–Marquardt.

    Raises
    ------
    ValueError
        Fewer than three points or collinear points.
    """
    pts = as_points(points_mm, "points_mm", dim=2)
    if pts.shape[0] < 3:
        raise ValueError(f"fit_circle needs at least 3 points, got {pts.shape[0]}")
    mean = pts.mean(axis=0)
    q = pts - mean
    A = np.column_stack([2.0 * q, np.ones(len(q))])
    b = np.sum(q * q, axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    _, s, _ = np.linalg.svd(q, full_matrices=False)
    if s[0] == 0 or s[1] / s[0] < 1e-9:
        raise ValueError("fit_circle: the points are collinear, no circle is determined")
    c0 = sol[:2]
    r0 = float(np.sqrt(sol[2] + c0 @ c0))

    def residual(p):
        return np.hypot(q[:, 0] - p[0], q[:, 1] - p[1]) - p[2]

    def jac(p):
        dx, dy = q[:, 0] - p[0], q[:, 1] - p[1]
        rho = np.maximum(np.hypot(dx, dy), 1e-300)
        return np.column_stack([-dx / rho, -dy / rho, -np.ones(len(q))])

    res = least_squares(residual, np.array([c0[0], c0[1], r0]), jac=jac, method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    cx, cy, r = res.x
    return CircleFit(center_mm=np.array([cx, cy]) + mean, radius_mm=float(abs(r)),
                     residuals_mm=residual(res.x))

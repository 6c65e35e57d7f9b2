"""Calibration uncertainty: plane covariances and random draws of a calibration.

A plane ``n · X = d`` is perturbed in a local, minimal parameterisation ``(a, b, δ)``:
``n' = normalise(n + a e1 + b e2)``, ``d' = d + δ``, with ``(e1, e2)`` the tangent basis of
:func:`tangent_basis` (a deterministic function of ``n``, so a covariance stored with a plane
means the same thing when it is read back).  ``a`` and ``b`` are small angles in radians.

The layout of ``Calibration.uncertainty`` (JSON):

* ``camera.std`` — standard deviations of ``fx fy cx cy`` (px) and ``k1 k2 p1 p2 k3``;
  ``camera.std_method`` says whose: ``"jackknife over boards"``
  (:func:`lts360.recon.calibration.camera.intrinsics_jackknife`) or ``"opencv"`` (its
  ``stdDeviationsIntrinsics``, which assume independent corner errors and understate the
  spread when a board's corners share an error); ``camera.std_opencv`` keeps OpenCV's;
* ``camera.cov`` with ``camera.cov_names`` (optional) — the covariance of those parameters
  (the jackknife's): drawn jointly when present (fx and fy, for one, move together);
* ``mirrors.<name>.cov_abd`` and ``laser_plane.cov_abd`` — 3×3 covariances of ``(a, b, δ)``
  (rad, rad, mm).

:func:`sample_calibration` draws a calibration from these (the camera, each mirror and the
laser plane independently, each Gaussian) — the calibration input of the Monte Carlo study
(GUM-S1).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

__all__ = ["tangent_basis", "perturb_plane", "plane_covariance", "jackknife_covariance",
           "sample_calibration", "CAMERA_STD_NAMES"]

CAMERA_STD_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def tangent_basis(n) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to ``n`` and to each other (right-handed with ``n``)."""
    n = np.asarray(n, dtype=float) / np.linalg.norm(n)
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, ref)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def perturb_plane(n, d_mm: float, abd) -> tuple[np.ndarray, float]:
    """The plane moved by ``(a, b, δ)`` (see the module docstring)."""
    e1, e2 = tangent_basis(n)
    a, b, delta = (float(v) for v in abd)
    m = np.asarray(n, dtype=float) + a * e1 + b * e2
    return m / np.linalg.norm(m), float(d_mm) + delta


def plane_covariance(points_mm, n, d_mm: float) -> np.ndarray:
    """Least-squares covariance of ``(a, b, δ)`` for a plane fitted to ``points_mm``.

    ``σ² (JᵀJ)⁻¹`` with ``J = [e1·p, e2·p, −1]`` and ``σ²`` the residual variance.  It assumes
    independent point errors; where the points come in groups sharing an error (one board
    pose each) use :func:`jackknife_covariance` over the groups as well.
    """
    p = np.asarray(points_mm, dtype=float)
    e1, e2 = tangent_basis(n)
    J = np.column_stack([p @ e1, p @ e2, -np.ones(len(p))])
    r = p @ np.asarray(n, float) - d_mm
    dof = max(1, len(p) - 3)
    return np.linalg.pinv(J.T @ J) * float(r @ r) / dof


def jackknife_covariance(estimates_abd) -> np.ndarray:
    """Delete-one jackknife covariance from the ``(m, k)`` leave-one-group-out estimates."""
    e = np.asarray(estimates_abd, dtype=float)
    m = len(e)
    if m < 3:
        raise ValueError(f"jackknife_covariance: need at least 3 groups, got {m}")
    c = e - e.mean(axis=0)
    return (m - 1) / m * c.T @ c


def plane_offset_abd(n_ref, d_ref: float, n, d_mm: float) -> np.ndarray:
    """``(a, b, δ)`` of plane ``(n, d)`` relative to ``(n_ref, d_ref)`` (first order)."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    if n @ n_ref < 0:
        n, d_mm = -n, -d_mm
    e1, e2 = tangent_basis(n_ref)
    return np.array([n @ e1, n @ e2, d_mm - d_ref])


def _camera_draw(camera: dict, rng: np.random.Generator) -> dict[str, float]:
    """Offsets of the intrinsics: jointly from ``cov`` when given, else from ``std``."""
    draw = dict.fromkeys(CAMERA_STD_NAMES, 0.0)
    cov, names = camera.get("cov"), camera.get("cov_names")
    if cov is not None and names is not None:
        cov = np.asarray(cov, dtype=float)
        if cov.shape != (len(names), len(names)) or not set(names) <= set(CAMERA_STD_NAMES):
            raise ValueError(f"uncertainty.camera: cov must be {len(names)}×{len(names)} over "
                             f"{list(CAMERA_STD_NAMES)}, got {cov.shape} over {list(names)}")
        draw.update(zip(names, rng.multivariate_normal(np.zeros(len(names)), cov,
                                                       method="eigh")))
        return draw
    std = camera.get("std") or {}
    draw.update({k: rng.normal(0.0, float(std[k])) for k in CAMERA_STD_NAMES if k in std})
    return draw


def sample_calibration(cal, rng: np.random.Generator):
    """A calibration drawn from ``cal.uncertainty`` (components absent there stay fixed).

    The measurement frame is rebuilt from the drawn laser plane so that it stays valid: its
    origin is projected onto the new plane and its z axis turned onto the new normal.
    """
    from lts360.recon.model import MirrorPlane, make_T_cam_meas

    u = cal.uncertainty or {}
    K, dist = cal.K.copy(), cal.dist.copy()
    draw = _camera_draw(u.get("camera") or {}, rng)
    K[0, 0] += draw["fx"]
    K[1, 1] += draw["fy"]
    K[0, 2] += draw["cx"]
    K[1, 2] += draw["cy"]
    dist = dist + np.array([draw[k] for k in ("k1", "k2", "p1", "p2", "k3")])
    mirrors = []
    for m in cal.mirrors:
        cov = ((u.get("mirrors") or {}).get(m.name) or {}).get("cov_abd")
        n, d = m.n, m.d_mm
        if cov is not None:
            n, d = perturb_plane(n, d, rng.multivariate_normal(np.zeros(3), np.asarray(cov)))
        corners = None
        if m.corners_mm is not None:  # keep the mirror's extent, on the drawn plane
            corners = m.corners_mm - (m.corners_mm @ n - d)[:, None] * n
        mirrors.append(MirrorPlane(name=m.name, n=n, d_mm=d, corners_mm=corners))
    n_l, d_l = cal.laser_plane
    cov = (u.get("laser_plane") or {}).get("cov_abd")
    if cov is not None:
        n_l, d_l = perturb_plane(n_l, d_l, rng.multivariate_normal(np.zeros(3), np.asarray(cov)))
    T = cal.T_cam_meas
    T_new = make_T_cam_meas((n_l, d_l), T[:3, 3], T[:3, 0])
    return replace(cal, K=K, dist=dist, mirrors=tuple(mirrors), laser_plane=(n_l, d_l),
                   T_cam_meas=T_new)

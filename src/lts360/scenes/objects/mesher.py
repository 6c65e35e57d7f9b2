"""Watertight meshes of star-shaped solids of revolution-like shape, from r(θ, z).

A solid is described by its outer radius ``r_out(θ, z)`` (and optionally an inner radius
``r_in(θ, z)`` for a tube) between two flat end caps.  The grid may be *twisted*: vertex
``(i, j)`` sits at ``θ = ψ_i + twist_rad_per_mm · z_j``, so that helically invariant shapes
(threads, helical grooves, stranded cables) have their ridges and cusps on grid lines.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

__all__ = ["n_theta_for_tolerance", "z_grid", "zoned_z_grid", "star_mesh"]


def n_theta_for_tolerance(radius_mm: float, tolerance_mm: float, *, minimum: int = 16) -> int:
    """Number of equal angular segments so that the chord sagitta of a circle of radius
    ``radius_mm`` is at most ``tolerance_mm``: ``r (1 - cos(π / n)) <= tol``."""
    if radius_mm <= 0 or tolerance_mm <= 0:
        raise ValueError("radius_mm and tolerance_mm must be positive")
    if tolerance_mm >= radius_mm:
        return minimum
    return max(minimum, math.ceil(math.pi / math.acos(1.0 - tolerance_mm / radius_mm)))


def z_grid(z_min_mm: float, z_max_mm: float, step_mm: float, *,
           breakpoints_mm=()) -> np.ndarray:
    """Sorted axial grid from ``z_min`` to ``z_max`` with spacing ≤ ``step_mm`` that contains
    every breakpoint (profile kinks, zone limits) inside the range exactly."""
    if not z_max_mm > z_min_mm or step_mm <= 0:
        raise ValueError("z_grid needs z_max > z_min and a positive step")
    knots = np.unique(np.concatenate([[z_min_mm, z_max_mm],
                                      [b for b in breakpoints_mm if z_min_mm < b < z_max_mm]]))
    parts = []
    for a, b in zip(knots[:-1], knots[1:]):
        n = max(1, math.ceil((b - a) / step_mm - 1e-9))
        parts.append(np.linspace(a, b, n + 1)[:-1])
    parts.append([knots[-1]])
    return np.concatenate(parts)


def zoned_z_grid(half_length_mm: float, zone_half_mm: float, step_mm: float,
                 coarse_factor: float) -> np.ndarray:
    """Axial grid of a part centred on z = 0: spacing ``step_mm`` inside the measured zone
    ``|z| <= zone_half_mm`` and ``coarse_factor × step_mm`` outside it, both zone limits exact."""
    coarse = coarse_factor * step_mm
    return np.unique(np.concatenate([z_grid(-half_length_mm, -zone_half_mm, coarse),
                                     z_grid(-zone_half_mm, zone_half_mm, step_mm),
                                     z_grid(zone_half_mm, half_length_mm, coarse)]))


def _ring_faces(n_theta: int, n_z: int, offset: int, outward: bool) -> np.ndarray:
    i = np.arange(n_theta)
    j = np.arange(n_z - 1)
    I, J = np.meshgrid(i, j, indexing="xy")
    a = offset + J * n_theta + I
    b = offset + J * n_theta + (I + 1) % n_theta
    c = offset + (J + 1) * n_theta + (I + 1) % n_theta
    d = offset + (J + 1) * n_theta + I
    tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                          np.stack([a, c, d], -1).reshape(-1, 3)])
    return tri if outward else tri[:, ::-1]


def star_mesh(radius_out, psi_rad: np.ndarray, z_mm: np.ndarray, *, radius_in=None,
              twist_rad_per_mm: float = 0.0) -> trimesh.Trimesh:
    """Watertight mesh of the solid ``r_in(θ, z) <= r <= r_out(θ, z)``, ``z0 <= z <= z1``.

    Parameters
    ----------
    radius_out : callable
        ``r_mm = radius_out(theta_rad, z_mm)`` on arrays; finite and positive on the grid.
    psi_rad : (n_theta,) float
        Increasing angles in ``[0, 2π)`` (the grid wraps around).
    z_mm : (n_z,) float
        Increasing axial positions; the first and last are the end caps.
    radius_in : callable, optional
        Inner radius of a tube (``0 < r_in < r_out``); without it the ends are closed by fans.
    twist_rad_per_mm : float
        Vertex ``(i, j)`` is placed at ``θ = ψ_i + twist · z_j``.

    Returns
    -------
    trimesh.Trimesh
        Outward-oriented, watertight mesh (object frame, millimetres).
    """
    psi = np.asarray(psi_rad, dtype=float)
    z = np.asarray(z_mm, dtype=float)
    if psi.ndim != 1 or psi.size < 3 or np.any(np.diff(psi) <= 0) or psi[-1] - psi[0] >= 2 * np.pi:
        raise ValueError("psi_rad must be increasing, at least 3 values, spanning less than 2π")
    if z.ndim != 1 or z.size < 2 or np.any(np.diff(z) <= 0):
        raise ValueError("z_mm must be increasing with at least 2 values")
    n_t, n_z = psi.size, z.size
    theta = psi[None, :] + twist_rad_per_mm * z[:, None]
    zz = np.broadcast_to(z[:, None], theta.shape)

    def ring(fn):
        r = np.asarray(fn(theta, zz), dtype=float)
        if r.shape != theta.shape or not np.all(np.isfinite(r)) or np.any(r <= 0):
            raise ValueError("radius function must be finite and positive on the mesh grid")
        return np.stack([r * np.cos(theta), r * np.sin(theta), zz], -1).reshape(-1, 3), r

    v_out, r_out = ring(radius_out)
    faces = [_ring_faces(n_t, n_z, 0, outward=True)]
    verts = [v_out]
    i = np.arange(n_t)
    i1 = (i + 1) % n_t
    bottom_out, top_out = i, (n_z - 1) * n_t + i
    if radius_in is None:
        centre = len(v_out)
        verts.append(np.array([[0.0, 0.0, z[0]], [0.0, 0.0, z[-1]]]))
        faces.append(np.stack([np.full(n_t, centre), bottom_out[i1], bottom_out[i]], -1))
        faces.append(np.stack([np.full(n_t, centre + 1), top_out[i], top_out[i1]], -1))
    else:
        v_in, r_in = ring(radius_in)
        if np.any(r_in >= r_out):
            raise ValueError("inner radius must be smaller than the outer radius everywhere")
        off = len(v_out)
        verts.append(v_in)
        faces.append(_ring_faces(n_t, n_z, off, outward=False))
        bottom_in, top_in = off + i, off + (n_z - 1) * n_t + i
        # Annular caps: bottom faces -z, top faces +z.
        faces.append(np.stack([bottom_out[i], bottom_in[i1], bottom_out[i1]], -1))
        faces.append(np.stack([bottom_out[i], bottom_in[i], bottom_in[i1]], -1))
        faces.append(np.stack([top_out[i], top_out[i1], top_in[i1]], -1))
        faces.append(np.stack([top_out[i], top_in[i1], top_in[i]], -1))
    mesh = trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=False)
    return mesh

"""Watertight meshes of star-shaped solids of revolution-like shape, from r(θ, z).

A solid is described by its outer radius ``r_out(θ, z)`` (and optionally an inner radius
``r_in(θ, z)`` for a tube) between two flat end caps.  The grid may be *twisted*: vertex
``(i, j)`` sits at ``θ = ψ_i + twist_rad_per_mm · z_j``, so that helically invariant shapes
(threads, helical grooves, stranded cables) have their ridges and cusps on grid lines:
:func:`helical_resolution` chooses the nodes and the axial step from a profile's curvature and
:func:`helical_star_mesh` meshes such a solid.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import trimesh
from scipy.ndimage import maximum_filter1d

__all__ = ["n_theta_for_tolerance", "z_grid", "zoned_z_grid", "star_mesh", "helical_resolution",
           "helical_star_mesh"]


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


def _profile_derivatives(s, phi, f):
    """``(f', f'')`` with respect to ``φ`` from dense samples along a parameter ``s``."""
    phi_s = np.gradient(phi, s, edge_order=2)
    phi_ss = np.gradient(phi_s, s, edge_order=2)
    f_s = np.gradient(f, s, edge_order=2)
    f_ss = np.gradient(f_s, s, edge_order=2)
    return f_s / phi_s, (f_ss * phi_s - f_s * phi_ss) / phi_s ** 3


def _first_crossing(a, b, c):
    """Smallest positive root of ``a x² + b x + c`` (``a > 0``), elementwise; inf if none."""
    disc = b * b - 4.0 * a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    roots = np.stack([(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)])
    roots = np.where((disc >= 0.0) & (roots > 0.0), roots, np.inf)
    return roots.min(axis=0)


def helical_resolution(pieces, twist_rad_per_mm: float, budget_mm: float):
    """Nodes ``φ_i`` and axial step of a twisted grid for ``r = f(θ − τ z)``.

    The mesh is built by :func:`helical_star_mesh`: its triangles have a *section edge*
    (``Δφ``, same ``z``), a *helix edge* (same ``φ``, ``Δz``) and a *diagonal*
    ``(−Δφ, Δz)`` (sign for ``τ > 0``; the short diagonal, spanning ``Δθ = τ Δz − Δφ``).
    To second order the radial error at the middle of an edge ``(a, b)`` in ``(φ, z)`` is::

        m(a, b) = [E a² + 2 c τ a b + f τ² b²] / 8,
        E = f + 2 f'² / f − f'',   c = f + f'² / f

    (the chord of a curve ``X(s)`` lies ``X'' / 8`` off it; the radial error is that offset
    projected on ``∇(r − f(θ − τ z))``).  The rules, with ``B = budget_mm``:

    * section edges: nodes equidistribute ``sqrt(|E| / (8 · B/2))`` over each smooth
      piece, then any interval where ``|E| Δφ² / 8`` exceeds ``B/2`` at some sample is split
      evenly, so ``|m| ≤ B/2`` (the local ``|E|`` is the largest of five neighbouring
      samples);
    * helix edges: ``f_max τ² Δz² / 8 ≤ B/2`` (exactly: ``f (1 − cos(τ Δz / 2)) ≤ B/2``);
    * diagonals: ``Δz`` is cut at the first ``Δz`` where ``|m| = B`` for some sample of some
      interval.  Where the profile is steep (``|f'| ≫ f``) the cross term ``2 c τ Δφ Δz``
      dominates and this is the binding rule.

    The error inside a triangle is ``Σ 4 λ_i λ_j m_ij`` (``λ`` barycentric), at most ``B`` with
    these three bounds.

    Parameters
    ----------
    pieces : sequence of (s, phi_rad, f_mm)
        Smooth pieces of the profile (kinks only at their ends), each three equal 1-D arrays
        of dense samples: a uniformly spaced increasing parameter ``s`` (≥ 5 samples), the
        increasing angle ``φ(s)`` and the radius ``f(φ(s))``.  Together they cover one period.
    twist_rad_per_mm : float, ≠0
        ``τ`` of the shape.
    budget_mm : float, >0
        Second-order bound ``B`` on the radial error.

    Returns
    -------
    phi_nodes : (n,) float
        Node angles (rad); both ends of every piece are nodes.
    dz_mm : float
        Largest axial step meeting the three rules.
    """
    if not budget_mm > 0 or not twist_rad_per_mm != 0:
        raise ValueError(f"helical_resolution needs budget_mm > 0 and a non-zero twist, got "
                         f"{budget_mm}, {twist_rad_per_mm}")
    tau = abs(float(twist_rad_per_mm))
    half = budget_mm / 2.0
    nodes, samples = [], []
    for s, phi, f in pieces:
        s, phi, f = (np.asarray(x, dtype=float) for x in (s, phi, f))
        if s.ndim != 1 or s.size < 5 or phi.shape != s.shape or f.shape != s.shape:
            raise ValueError(f"helical_resolution: each piece needs three equal 1-D arrays of "
                             f"≥ 5 samples, got {s.shape}, {phi.shape}, {f.shape}")
        f_p, f_pp = _profile_derivatives(s, phi, f)
        e_signed = f + 2.0 * f_p ** 2 / f - f_pp
        e_abs = maximum_filter1d(np.abs(e_signed), size=5, mode="nearest")
        phi_s = np.gradient(phi, s, edge_order=2)
        density = np.sqrt(e_abs / (8.0 * half)) * phi_s  # section edges per unit of s
        steps = (density[1:] + density[:-1]) / 2.0 * np.diff(s)
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        n = max(1, math.ceil(cum[-1] - 1e-9))
        phi_nodes = np.interp(np.interp(np.linspace(0.0, cum[-1], n + 1), cum, s), s, phi)
        phi_nodes[0], phi_nodes[-1] = phi[0], phi[-1]
        # Where |E| varies fast inside an interval, split it until every sample meets B/2.
        k = np.clip(np.searchsorted(phi_nodes, phi, side="right") - 1, 0, n - 1)
        e_max = np.zeros(n)
        np.maximum.at(e_max, k, e_abs)
        width = np.diff(phi_nodes)
        parts = np.maximum(1, np.ceil(width * np.sqrt(e_max / (8.0 * half)) - 1e-9)).astype(int)
        start = np.repeat(phi_nodes[:-1], parts)
        step = np.repeat(width / parts, parts)
        offset = np.arange(parts.sum()) - np.repeat(np.cumsum(parts) - parts, parts)
        phi_nodes = np.append(start + offset * step, phi[-1])
        nodes.append(phi_nodes[:-1])
        k = np.clip(np.searchsorted(phi_nodes, phi, side="right") - 1, 0, phi_nodes.size - 2)
        samples.append((np.diff(phi_nodes)[k], f, e_signed, f + f_p ** 2 / f))
    dphi, f, e_signed, c = (np.concatenate(x) for x in zip(*samples))
    # Helix edges.
    dz = 2.0 * math.acos(1.0 - half / float(f.max())) / tau
    # Diagonals (−Δφ, Δz): m(Δz) = [E Δφ² − 2 c τ Δφ Δz + f τ² Δz²] / 8 must stay in [−B, B].
    a2, a1, a0 = f * tau ** 2, -2.0 * c * tau * dphi, e_signed * dphi ** 2
    for bound in (budget_mm, -budget_mm):
        dz = min(dz, float(_first_crossing(a2, a1, a0 - 8.0 * bound).min()))
    return np.concatenate(nodes), dz


def helical_star_mesh(profile: Callable[[np.ndarray], np.ndarray], phi_nodes_rad: np.ndarray,
                      z_mm: np.ndarray, twist_rad_per_mm: float) -> trimesh.Trimesh:
    """Watertight mesh of the helically invariant solid ``r ≤ f(θ − τ z)``.

    Vertex ``(i, j)`` lies at ``θ = φ_i + τ z_j``, so every node ``φ_i`` (profile kinks,
    cusps) is a helix of the grid.  :func:`star_mesh` splits each grid quad along the diagonal
    from ``(i, j)`` to ``(i + 1, j + 1)``; for ``τ > 0`` that is the long one (its angular span
    is ``Δφ + τ Δz``), so the solid is then meshed mirrored (``y → −y``, which turns the twist
    into ``−τ``) and mirrored back, and every triangle spans at most ``max(Δφ, |τ| Δz)``.

    Parameters
    ----------
    profile : callable
        ``f_mm = profile(phi_rad)``, 2π-periodic, positive.
    phi_nodes_rad : (n,) float
        Distinct node angles (any order, any period; reduced to ``[0, 2π)``).
    z_mm : (n_z,) float
        Increasing axial positions; the first and last are the end caps.
    twist_rad_per_mm : float
        ``τ``; positive for a right-hand helix.

    Returns
    -------
    trimesh.Trimesh
        Outward-oriented, watertight mesh (object frame, millimetres).
    """
    tau = float(twist_rad_per_mm)
    phi = np.unique(np.mod(np.asarray(phi_nodes_rad, dtype=float), 2.0 * np.pi))
    if tau <= 0.0:
        return star_mesh(lambda th, z: profile(th - tau * z), phi, z_mm, twist_rad_per_mm=tau)
    # Mirrored solid: r_m(θ', z) = r(−θ', z) = f(−θ' − τ z); node ψ_m = −φ.
    psi = np.unique(np.mod(2.0 * np.pi - phi, 2.0 * np.pi))
    mesh = star_mesh(lambda th, z: profile(-th - tau * z), psi, z_mm, twist_rad_per_mm=-tau)
    vertices = mesh.vertices * np.array([1.0, -1.0, 1.0])
    return trimesh.Trimesh(vertices, mesh.faces[:, ::-1], process=False)

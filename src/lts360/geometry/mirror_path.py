"""Whether a light path through an ordered sequence of planar mirrors is real (numpy).

A path from surface points to a real target (a camera centre or the laser apex), folded at
mirrors ``m1, m2, …`` (``m1`` nearest the points), is aimed at the *virtual* target
``T_{m1} ⋯ T_{mk} C`` (method of images, paper Eq. 3).  It is real when it meets each mirror
on its reflecting side (``n · X > d``, the side the light comes from), ahead of the last hit,
inside the mirror's extent, and no segment is blocked by the object (the vertical cylinder of
radius ``r`` about the z axis) or by another mirror's extent.

This is the one implementation of that test: the rig's coverage (:mod:`lts360.scenes.coverage`,
world frame, mirror rectangles) and the measurement's θ windows
(:mod:`lts360.recon.triangulation.views`, measurement frame, calibrated mirror corners or an
unknown extent) both call :func:`path_valid`; the design model's smooth version in Dr.Jit
(:mod:`lts360.design.paths`) is tested against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["PathMirror", "rectangle_extent", "quad_extent", "path_valid",
           "segments_blocked_by_cylinder", "segments_blocked_by_mirrors"]

#: A hit must lie this far ahead along the path (mm): a point on a mirror does not hit it.
_EPS_MM = 1e-9


@dataclass(frozen=True, eq=False)
class PathMirror:
    """A planar mirror as the path test sees it.

    Attributes
    ----------
    n : (3,) float
        Unit normal, pointing to the reflecting side.
    d : float
        Plane offset (mm): the plane is ``n · X = d``.
    T : (4, 4) float
        Its reflection (paper Eq. 3).
    contains : callable or None
        ``contains(points (k, 3) on the plane) -> (k,) bool``: inside the mirror's extent;
        ``None`` for a mirror of unknown extent (every hit counts, and it blocks nothing).
    """

    n: np.ndarray
    d: float
    T: np.ndarray
    contains: Callable[[np.ndarray], np.ndarray] | None = None


def rectangle_extent(center_mm, u_axis, v_axis, width_mm: float, height_mm: float):
    """The ``contains`` test of a rectangle: ``|q·u| ≤ w/2`` and ``|q·v| ≤ h/2``."""
    c, u, v = (np.asarray(a, dtype=float) for a in (center_mm, u_axis, v_axis))

    def contains(points: np.ndarray) -> np.ndarray:
        q = points - c
        return (np.abs(q @ u) <= width_mm / 2) & (np.abs(q @ v) <= height_mm / 2)

    return contains


def quad_extent(corners_mm, n):
    """The ``contains`` test of a convex quadrilateral (4 corners in order) on a plane of
    normal ``n``: every edge's cross product with the point has the same sign (1e-9 slack)."""
    c = np.asarray(corners_mm, dtype=float)
    n = np.asarray(n, dtype=float)

    def contains(points: np.ndarray) -> np.ndarray:
        s = np.stack([np.cross(c[(i + 1) % 4] - c[i], points - c[i]) @ n for i in range(4)],
                     axis=1)
        return np.all(s >= -1e-9, axis=1) | np.all(s <= 1e-9, axis=1)

    return contains


def segments_blocked_by_cylinder(a: np.ndarray, b: np.ndarray, radius_mm: float, *,
                                 from_surface: bool = False) -> np.ndarray:
    """Whether segments a→b (n, 3) pass strictly inside the vertical cylinder of radius
    ``radius_mm`` about the z axis.

    ``from_surface``: the segments start on the cylinder; one is then blocked only if it
    re-enters, which for a convex section needs it to leave inwards.
    """
    a2, d = a[:, :2], b[:, :2] - a[:, :2]
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(-np.einsum("ij,ij->i", a2, d) / np.maximum(dd, 1e-300), 0.0, 1.0)
    closest = a2 + t[:, None] * d
    inside = np.einsum("ij,ij->i", closest, closest) < radius_mm**2 * (1.0 - 1e-9)
    if from_surface:
        inside &= np.einsum("ij,ij->i", a2, d) < 0
        inside &= t > 1e-9
    return inside


def segments_blocked_by_mirrors(a: np.ndarray, b: np.ndarray, mirrors, skip) -> np.ndarray:
    """Whether segments a→b (n, 3) cross the extent of a mirror (of known extent) whose
    index is not in ``skip``."""
    blocked = np.zeros(len(a), dtype=bool)
    for k, m in enumerate(mirrors):
        if k in skip or m.contains is None:
            continue
        da, db = a @ m.n - m.d, b @ m.n - m.d
        crosses = da * db < 0
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(crosses, da / (da - db), 0.0)
        blocked |= crosses & m.contains(a + t[:, None] * (b - a))
    return blocked


def path_valid(points_mm, target_mm, seq, mirrors, radius_mm: float, *,
               occlude_first_segment: bool = True
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trace the light path from surface points to a real target through a mirror sequence.

    Parameters
    ----------
    points_mm : (n, 3) float
        Points on the section, in the mirrors' frame.
    target_mm : (3,) float
        The real target (camera centre, laser apex).
    seq : sequence of int
        Indices into ``mirrors`` in the order met when leaving the points.
    mirrors : sequence of PathMirror
        Every mirror (those not in ``seq`` can block).
    radius_mm : float, >= 0
        The occluding cylinder about the z axis (0: no object).
    occlude_first_segment : bool
        Test the segment that leaves the surface for re-entry into the cylinder (True), or
        leave it to the caller's facing test (False: a part off the axis, whose surface is not
        that cylinder).

    Returns
    -------
    valid : (n,) bool
    leave_dir : (n, 3) float
        Unit direction in which the path leaves the points.
    arrive_dir : (n, 3) float
        Unit direction in which the path reaches the target.
    """
    pts = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    virtual = np.asarray(target_mm, dtype=float).reshape(1, 3)
    for k in reversed(tuple(seq)):
        T = mirrors[k].T
        virtual = virtual @ T[:3, :3].T + T[:3, 3]
    direction = virtual - pts
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    leave = direction.copy()
    valid = np.ones(len(pts), dtype=bool)
    p, first, prev = pts, True, None
    for k in seq:
        m = mirrors[k]
        denom = direction @ m.n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (m.d - p @ m.n) / denom
        valid &= (denom < 0) & (t > _EPS_MM)
        t = np.where(valid, t, 0.0)
        hit = p + t[:, None] * direction
        if m.contains is not None:
            valid &= m.contains(hit)
        if occlude_first_segment or not first:
            valid &= ~segments_blocked_by_cylinder(p, hit, radius_mm, from_surface=first)
        valid &= ~segments_blocked_by_mirrors(p, hit, mirrors, {k} if prev is None else {k, prev})
        direction = direction - 2.0 * (direction @ m.n)[:, None] * m.n
        p, first, prev = hit, False, k
    end = np.broadcast_to(np.asarray(target_mm, dtype=float), p.shape)
    if occlude_first_segment or not first:
        valid &= ~segments_blocked_by_cylinder(p, end, radius_mm, from_surface=first)
    valid &= ~segments_blocked_by_mirrors(p, end, mirrors, set() if prev is None else {prev})
    return valid, leave, direction

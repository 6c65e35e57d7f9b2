"""The four ISO 12181-2 / ISO 4291 reference circles of a section and its roundness RONt.

A profile is a set of points ``xy_mm : (n, 2) float`` in the plane of the section.  Each
reference circle gives a centre; the roundness deviation RONt is the radial peak-to-valley of
the profile about that centre:

* **LSCI** (least squares): the circle minimising ``Σ (|p_i − c| − R)²``; RONt is
  ``max − min`` of ``|p_i − c|``.  Gauss–Newton from the algebraic (Kåsa) fit.
* **MZCI** (minimum zone): the two concentric circles enclosing the profile with the
  smallest radial separation; RONt is that separation, the smallest peak-to-valley over every
  centre, so ``RONt_MZ ≤ RONt`` of every other reference.  Sequential linear programming
  (``scipy.optimize.linprog``, HiGHS) with a trust region, started at the LS centre; each step
  uses only the points that can still touch either circle.
* **MCCI** (minimum circumscribed): the smallest circle containing the profile
  (``shapely.minimum_bounding_circle``); RONt is its radius minus the smallest radius about
  its centre.
* **MICI** (maximum inscribed): the largest circle inside the profile's polygon (the points
  joined in angular order; ``shapely.maximum_inscribed_circle``); RONt is the largest radius
  about its centre minus its radius.  A θ gap in the profile is closed by its chord.

The MCCI and MICI are what a ring gauge and a plug gauge would fit; the LSCI is the usual
default.  No filter is applied here (ISO 12181-2's Gaussian filter of N UPR is left to the
caller).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ReferenceCircle", "least_squares_circle", "minimum_zone_circle",
           "minimum_circumscribed_circle", "maximum_inscribed_circle", "reference_circles",
           "REFERENCES", "MZ_TOLERANCE_MM", "inscribed_on_a_chord", "CHORD_SAGITTA_MM"]

#: The four reference circles, in the order they are reported.
REFERENCES = ("LSCI", "MZCI", "MCCI", "MICI")
#: Convergence of the minimum-zone iteration and the MICI's search (mm): far below any
#: measured scatter (µm), far above float64 rounding at these radii.
MZ_TOLERANCE_MM = 1e-7


@dataclass(frozen=True)
class ReferenceCircle:
    """A reference circle and the profile's roundness about it.

    Attributes
    ----------
    name : str
        ``LSCI``, ``MZCI``, ``MCCI`` or ``MICI``.
    centre_mm : (2,) float
    radius_mm : float
        The circle's radius (for the MZCI the mean of its inner and outer radius).
    r_min_mm, r_max_mm : float
        Smallest and largest distance of the profile from ``centre_mm``.
    """

    name: str
    centre_mm: np.ndarray
    radius_mm: float
    r_min_mm: float
    r_max_mm: float

    @property
    def ront_mm(self) -> float:
        """Roundness deviation RONt: peak-to-valley of the radii about the centre."""
        return self.r_max_mm - self.r_min_mm

    @property
    def diameter_mm(self) -> float:
        return 2.0 * self.radius_mm


def _as_xy(xy_mm) -> np.ndarray:
    xy = np.asarray(xy_mm, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"xy_mm must have shape (n, 2), got {xy.shape}")
    if len(xy) < 3 or not np.all(np.isfinite(xy)):
        raise ValueError(f"a reference circle needs at least 3 finite points, got {len(xy)} "
                         f"({int(np.sum(~np.all(np.isfinite(xy), axis=1)))} not finite)")
    return xy


def _radii(xy: np.ndarray, c) -> np.ndarray:
    return np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1])


def _circle(name: str, xy: np.ndarray, c, radius: float) -> ReferenceCircle:
    r = _radii(xy, c)
    return ReferenceCircle(name, np.asarray(c, float), float(radius), float(r.min()),
                           float(r.max()))


def least_squares_circle(xy_mm, *, iterations: int = 8) -> ReferenceCircle:
    """LSCI: geometric least squares (Kåsa start, Gauss–Newton on ``(cx, cy, R)``).

    Parameters
    ----------
    xy_mm : (n, 2) float, n >= 3
    """
    xy = _as_xy(xy_mm)
    m = xy.mean(axis=0)
    q = xy - m
    A = np.column_stack([2.0 * q, np.ones(len(q))])
    sol = np.linalg.solve(np.einsum("ij,ik->jk", A, A), np.einsum("ij,i->j", A, np.sum(q * q, 1)))
    p = np.array([sol[0], sol[1], np.sqrt(max(sol[2] + sol[0] ** 2 + sol[1] ** 2, 0.0))])
    for _ in range(iterations):
        dx, dy = q[:, 0] - p[0], q[:, 1] - p[1]
        rho = np.maximum(np.hypot(dx, dy), 1e-300)
        J = np.column_stack([-dx / rho, -dy / rho, -np.ones(len(q))])
        step = np.linalg.solve(np.einsum("ij,ik->jk", J, J), -np.einsum("ij,i->j", J, rho - p[2]))
        p = p + step
        if np.max(np.abs(step)) < 1e-13:
            break
    return _circle("LSCI", xy, p[:2] + m, float(p[2]))


def minimum_zone_circle(xy_mm, *, start_mm=None, tol_mm: float = MZ_TOLERANCE_MM,
                        max_iterations: int = 60) -> ReferenceCircle:
    """MZCI: the centre minimising ``max |p_i − c| − min |p_i − c|``.

    Sequential LP: at the current centre ``c`` the radii move to first order by ``−u_i · δ``
    (``u_i`` the unit vector from ``c`` to ``p_i``); ``linprog`` minimises ``t_out − t_in``
    subject to ``t_in ≤ r_i − u_i·δ ≤ t_out`` and ``|δ|∞ ≤ ρ``.  A step is kept when the exact
    peak-to-valley falls (``ρ`` then doubles when the step reached it, else shrinks to the
    step), otherwise ``ρ`` is halved; it stops when the LP predicts a gain below
    ``tol_mm / 1000``, when a step inside the trust region gains less than ``tol_mm``, or when
    ``ρ < tol_mm``.  Only
    points within ``2√2 ρ`` of the current extremes can become extreme after a step, so only
    those enter the LP.

    Parameters
    ----------
    xy_mm : (n, 2) float
    start_mm : (2,) float, optional
        Start centre (default: the LS centre).
    """
    from scipy.optimize import linprog

    xy = _as_xy(xy_mm)
    c = least_squares_circle(xy).centre_mm if start_mm is None else np.asarray(start_mm, float)
    r = _radii(xy, c)
    f = r.max() - r.min()
    rho = max(0.1 * f, 10 * tol_mm)
    for _ in range(max_iterations):
        band = 2.0 * np.sqrt(2.0) * rho
        act = (r >= r.max() - band) | (r <= r.min() + band)
        u = (xy[act] - c) / np.maximum(r[act], 1e-300)[:, None]
        ra = r[act]
        k = int(act.sum())
        # variables: dx, dy, t_out, t_in; minimise t_out - t_in
        A = np.block([[-u, -np.ones((k, 1)), np.zeros((k, 1))],
                      [u, np.zeros((k, 1)), np.ones((k, 1))]])
        b = np.concatenate([-ra, ra])
        res = linprog([0.0, 0.0, 1.0, -1.0], A_ub=A, b_ub=b,
                      bounds=[(-rho, rho), (-rho, rho), (None, None), (None, None)],
                      method="highs")
        if res.status != 0 or f - res.fun < tol_mm * 1e-3:
            break  # the linearised zone cannot shrink further: converged
        step = float(np.max(np.abs(res.x[:2])))
        c_new = c + res.x[:2]
        r_new = _radii(xy, c_new)
        f_new = r_new.max() - r_new.min()
        if f_new < f:
            gain = f - f_new
            c, r, f = c_new, r_new, f_new
            if gain < tol_mm and step < 0.99 * rho:
                break  # an interior step that gained less than the tolerance: converged
            rho = 2.0 * rho if step > 0.99 * rho else max(step, tol_mm)
        else:
            rho /= 2.0
        if rho < tol_mm:
            break
    return ReferenceCircle("MZCI", c, float(0.5 * (r.max() + r.min())), float(r.min()),
                           float(r.max()))


def minimum_circumscribed_circle(xy_mm) -> ReferenceCircle:
    """MCCI: the smallest circle that contains every point (shapely)."""
    import shapely

    xy = _as_xy(xy_mm)
    mp = shapely.multipoints(xy)
    radius = float(shapely.minimum_bounding_radius(mp))
    poly = shapely.minimum_bounding_circle(mp)
    ring = np.asarray(poly.exterior.coords)[:-1]
    centre = ring.mean(axis=0)  # the polygon is a regular polygon about the centre
    # polish: the centre of the bounding polygon carries its float rounding only
    return _circle("MCCI", xy, centre, max(radius, float(_radii(xy, centre).max())))


def maximum_inscribed_circle(xy_mm, *, tol_mm: float = 1e-4) -> ReferenceCircle:
    """MICI: the largest circle inside the polygon of the points in angular order (shapely).

    ``tol_mm`` is the search tolerance of ``shapely.maximum_inscribed_circle`` (its result is
    within ``tol_mm`` of the optimum); the radius reported is the exact smallest distance of
    the points from the centre found (the polygon's chords lie inside the circle through
    neighbouring points only up to their sagitta, below 1 µm for 0.5° spacing at r = 20 mm).
    """
    import shapely

    xy = _as_xy(xy_mm)
    c0 = xy.mean(axis=0)
    order = np.argsort(np.arctan2(xy[:, 1] - c0[1], xy[:, 0] - c0[0]), kind="stable")
    poly = shapely.polygons(xy[order])
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
        if poly.geom_type != "Polygon":
            poly = max(getattr(poly, "geoms", [poly]), key=lambda g: g.area)
    line = shapely.maximum_inscribed_circle(poly, tolerance=tol_mm)
    centre = np.asarray(line.coords)[0]
    r = _radii(xy, centre)
    return ReferenceCircle("MICI", centre, float(r.min()), float(r.min()), float(r.max()))


#: A chord across a gap whose sagitta on the circle exceeds this (mm) can hold the MICI where
#: the profile is not measured; below it the chord stands for the part's arc to better than
#: 10 µm (a tenth of the MICI's RONt U on the realistic scans: 80-250 µm), as a point would.
CHORD_SAGITTA_MM = 0.01


def inscribed_on_a_chord(xy_mm, mici: ReferenceCircle, *, tol_mm: float = 1e-3) -> float:
    """The widest gap (deg about the MICI's centre) whose chord holds the MICI: the chord,
    the polygon's edge across the gap, comes within ``tol_mm`` of the circle and its sagitta
    exceeds :data:`CHORD_SAGITTA_MM`.  0 where only measured points hold it (the MICI is
    determined by the points).  The profile behind a chord is not measured: a convex part's
    arc lies outside it, so a MICI held by a chord is smaller than the part's."""
    xy = _as_xy(xy_mm)
    d = xy - mici.centre_mm
    order = np.argsort(np.arctan2(d[:, 1], d[:, 0]), kind="stable")
    a, b = d[order], np.roll(d[order], -1, axis=0)
    seg = b - a
    L2 = np.einsum("ij,ij->i", seg, seg)
    t = np.clip(-np.einsum("ij,ij->i", a, seg) / np.maximum(L2, 1e-300), 0.0, 1.0)
    dist = np.hypot(*(a + t[:, None] * seg).T)
    hold = (L2 / (8.0 * max(mici.radius_mm, 1e-9)) > CHORD_SAGITTA_MM) & \
        (dist < mici.radius_mm + tol_mm)
    if not hold.any():
        return 0.0
    ang = np.abs(np.angle(np.exp(1j * (np.arctan2(b[:, 1], b[:, 0])
                                       - np.arctan2(a[:, 1], a[:, 0])))))
    return float(np.degrees(ang[hold].max()))


def reference_circles(xy_mm) -> dict[str, ReferenceCircle]:
    """All four reference circles, by name (:data:`REFERENCES` order)."""
    xy = _as_xy(xy_mm)
    ls = least_squares_circle(xy)
    return {"LSCI": ls, "MZCI": minimum_zone_circle(xy, start_mm=ls.centre_mm),
            "MCCI": minimum_circumscribed_circle(xy), "MICI": maximum_inscribed_circle(xy)}

"""Sharp corners of a measured section for its twin.

A laser line rounds a sharp corner: the sheet's thickness and the lens's blur spread the line
over a spot, and across a corner the spot takes light from both faces, so the line's centre
along a ray through the corner lies inside it (measured on a 16 mm hexagonal bar, noise-free:
about −70 µm within 1° of each 120° corner, −25 µm at 1–2°, STUDIES.md).  The twin of the
measured, already rounded profile is rounded again by the same chain, but less (a rounded
corner loses less to the spot than a sharp one), so it corrects about half of it.

What a metrology engineer does with such a profile: fit the two faces beside the corner,
where the line is not disturbed, and intersect them.  :func:`sharpen_corners` does that on
the profile the twin is built from (no truth): corners are where the profile's direction turns
by more than ``min_turn_deg`` across ``±window_mm`` of contour; a line is fitted to each side
between 1.5 and 4 windows from the corner (it must leave no more than ``straight_mm`` rms, or
twice the profile's roughness); the lines must turn by ``min_turn_deg`` too, and the profile
within 1.5 windows of their intersection is replaced by them.  Whether the real corner is sharp is then the
twin's to decide (:class:`lts360.twin.debias.TwinCorrector` renders both and keeps, per
corner, the one whose twin measures like the real image).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from lts360.twin.profile import SectionProfile

__all__ = ["Corner", "sharpen_corners", "turning_deg", "DEFAULT_CORNER_WINDOW_MM",
           "DEFAULT_CORNER_TURN_DEG", "CORNER_STRAIGHT_MM"]

#: Half-length of contour over which a corner's turning is measured (mm): about the spot's
#: reach on the part (the hexagon's corners are rounded over ±0.3 mm of contour).
DEFAULT_CORNER_WINDOW_MM = 0.4
#: A corner turns the profile's direction by at least this across ±window (a Ø20 mm circle
#: turns 4.6° over ±0.4 mm; a hexagon's corner 60°).
DEFAULT_CORNER_TURN_DEG = 20.0
#: A side is a straight face when the line fitted to it leaves at most this rms (mm), or twice
#: the profile's own roughness where that is more (a noisy profile's faces are as rough as it).
CORNER_STRAIGHT_MM = 0.02
#: The sides are fitted between these multiples of the window from the corner; the profile
#: within the first is replaced.
_FIT_FROM, _FIT_TO = 1.5, 4.0


@dataclass(frozen=True)
class Corner:
    """A sharpened corner: ``index`` the profile vertex at the apex, ``phi_rad`` its polar
    angle about the profile's centre, ``turn_deg`` the angle between the two faces' directions
    (positive: convex), ``apex_mm`` the faces' intersection, ``half_width_rad`` the half-width
    in φ of the profile replaced, ``fit_rms_mm`` the two line fits' rms."""

    index: int
    phi_rad: float
    turn_deg: float
    apex_mm: np.ndarray
    half_width_rad: float
    fit_rms_mm: tuple


def turning_deg(profile: SectionProfile, k: int) -> np.ndarray:
    """The profile's turning (degrees, positive to the left) at each vertex between the chords
    from ``k`` vertices before it and to ``k`` vertices after it."""
    v = profile.vertices_mm
    a = v - np.roll(v, k, axis=0)
    b = np.roll(v, -k, axis=0) - v
    return np.degrees(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.sum(a * b, axis=1)))


def _fit_line(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Total least squares line through ``p`` (m, 2, in the profile's order): a point, the
    unit direction along the profile, the rms."""
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=False)
    d = vt[0] if float(vt[0] @ (p[-1] - p[0])) >= 0 else -vt[0]
    return c, d, float(s[1] / np.sqrt(len(p)))


def _sides(v: np.ndarray, i: int, k: int):
    """The lines fitted to the two sides of vertex ``i`` (before, after)."""
    n = len(v)
    near, far = int(round(_FIT_FROM * k)), int(round(_FIT_TO * k))
    return [_fit_line(v[(i + np.arange(-far, -near + 1)) % n]),
            _fit_line(v[(i + np.arange(near, far + 1)) % n])]


def _intersect(l1, l2) -> np.ndarray | None:
    (c1, d1, _), (c2, d2, _) = l1, l2
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-6:
        return None
    t = np.linalg.solve(A, c2 - c1)
    return c1 + t[0] * d1


def _ray_to_line(center: np.ndarray, u: np.ndarray, line) -> np.ndarray:
    """Distance from ``center`` along the unit rays ``u`` (m, 2) to ``line`` (NaN: parallel
    or behind)."""
    c, d, _ = line
    nrm = np.array([-d[1], d[0]])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((c - center) @ nrm) / (u @ nrm)
    return np.where(t > 0, t, np.nan)


def _corner_at(profile: SectionProfile, i: int, k: int, min_turn_deg: float,
               straight_mm: float) -> Corner | None:
    """The corner near vertex ``i``: the sides fitted, recentred once on their intersection;
    ``None`` when the sides are not straight, turn too little or meet outside the zone."""
    v = profile.vertices_mm
    n = len(v)
    near = int(round(_FIT_FROM * k))
    for _ in range(2):
        l1, l2 = _sides(v, i, k)
        x = _intersect(l1, l2)
        if x is None:
            return None
        d = x - profile.center_mm
        phi = float(np.mod(np.arctan2(d[1], d[0]), 2 * np.pi))
        j = int(np.argmin(np.abs(np.angle(np.exp(1j * (profile.phi_rad - phi))))))
        moved, i = (j - i + n // 2) % n - n // 2, j
        if abs(moved) > near:  # the faces meet outside the zone: no corner there
            return None
    l1, l2 = _sides(v, i, k)
    x = _intersect(l1, l2)
    if x is None:
        return None
    turn = float(np.degrees(np.arctan2(l1[1][0] * l2[1][1] - l1[1][1] * l2[1][0],
                                       float(l1[1] @ l2[1]))))
    if abs(turn) < min_turn_deg or max(l1[2], l2[2]) > straight_mm:
        return None
    half = near * 2 * np.pi / n
    return Corner(index=i, phi_rad=float(profile.phi_rad[i]), turn_deg=turn, apex_mm=x,
                  half_width_rad=float(half), fit_rms_mm=(l1[2], l2[2]))


def sharpen_corners(profile: SectionProfile, *, window_mm: float = DEFAULT_CORNER_WINDOW_MM,
                    min_turn_deg: float = DEFAULT_CORNER_TURN_DEG,
                    straight_mm: float = CORNER_STRAIGHT_MM) -> tuple[SectionProfile, list]:
    """The profile with its sharp corners restored (module docstring), and the corners.

    A profile without corners comes back as it is, with an empty list.
    """
    if not window_mm > 0 or not 0 < min_turn_deg < 180:
        raise ValueError(f"sharpen_corners: window_mm > 0 and min_turn_deg in (0, 180), got "
                         f"{window_mm}, {min_turn_deg}")
    v = profile.vertices_mm
    n = len(v)
    ds = float(np.median(np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1)))
    k = max(1, int(round(window_mm / ds)))
    if _FIT_TO * k * 2 >= n:
        return profile, []
    # a face is straight within the profile's own roughness (a noisy profile's faces are
    # as rough as its flats): twice the robust spread of its second difference over ±k
    rho0 = profile.rho_mm
    d2 = rho0 - 0.5 * (np.roll(rho0, k) + np.roll(rho0, -k))
    straight_mm = max(straight_mm, 2.0 * 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))))
    turn = turning_deg(profile, k)
    mag = np.abs(turn)
    # local maxima of |turn| over ±k vertices, above the threshold (vectorised window max)
    win = np.stack([np.roll(mag, s) for s in range(-k, k + 1)])
    cand = np.flatnonzero((mag >= min_turn_deg) & (mag >= win.max(axis=0)))
    rho = profile.rho_mm.copy()
    u_all = np.column_stack([np.cos(profile.phi_rad), np.sin(profile.phi_rad)])
    taken = np.zeros(n, bool)
    corners: list[Corner] = []
    for i in cand[np.argsort(-mag[cand])]:
        c = _corner_at(profile, int(i), k, min_turn_deg, straight_mm)
        if c is None:
            continue
        near = int(round(_FIT_TO * k))
        span = (c.index + np.arange(-near, near + 1)) % n
        if taken[span].any():  # another corner's faces: not two corners this close
            continue
        taken[span] = True
        zone = (c.index + np.arange(-int(round(_FIT_FROM * k)), int(round(_FIT_FROM * k)) + 1)) % n
        l1, l2 = _sides(v, c.index, k)
        t = np.stack([_ray_to_line(profile.center_mm, u_all[zone], ln) for ln in (l1, l2)])
        # convex: the part is the intersection of the faces' half-planes; concave: the union
        new = np.nanmin(t, axis=0) if c.turn_deg > 0 else np.nanmax(t, axis=0)
        rho[zone] = np.where(np.isfinite(new), new, rho[zone])
        corners.append(c)
    if not corners:
        return profile, []
    corners.sort(key=lambda c: c.phi_rad)
    return dataclasses.replace(profile, rho_mm=rho), corners

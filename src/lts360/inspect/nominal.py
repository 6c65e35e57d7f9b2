"""Nominal section contours and the deviation of a measured profile from them.

Four sources, each giving a closed contour ``(m, 2)`` in mm:

* a plain **diameter** (``32``): a circle of that diameter;
* an **object spec** (``pvc-pipe:ovality=0,dent_depth=0``): the generator's analytic radius
  ``r(θ, z)`` at the spec's parameters, sampled at each section's z (the shape the generator
  was asked for, not a rendered truth; a placement in the spec is ignored);
* a **CSV** file of ``x, y`` rows or a **DXF** drawing's largest closed curve, read by
  :mod:`lts360.scenes.contour_file` (the reader the ``profile`` object shares; units from the
  CSV header or the DXF's ``$INSUNITS``, curves flattened to 0.1 µm).

The nominal is placed on the measured section by moving its own least-squares centre onto the
section's LS centre (translation only, no rotation).  The deviation of each point is its
signed distance to the nominal contour along the contour's normal (the nearest point on the
polyline), positive outside the material boundary, negative inside.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.inspect.circles import least_squares_circle
from lts360.scenes.contour_file import CLOSURE_MM, UNIT_MM

__all__ = ["Nominal", "ToleranceBand", "load_nominal", "nominal_from_spec", "nominal_circle", "read_contour_csv",
           "read_contour_dxf", "deviations", "UNIT_MM", "CLOSURE_MM"]

#: Sampling of an analytic nominal contour (deg): chord sagitta below 0.1 µm at r = 30 mm.
_SPEC_STEP_DEG = 0.1


@dataclass(frozen=True)
class ToleranceBand:
    """Allowed deviation from the nominal: ``lower_mm ≤ deviation ≤ upper_mm``."""

    upper_mm: float
    lower_mm: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.upper_mm) and np.isfinite(self.lower_mm)):
            raise ValueError(f"tolerance: upper and lower must be finite, got {self.upper_mm}, "
                             f"{self.lower_mm}")
        if not self.upper_mm > self.lower_mm:
            raise ValueError(f"tolerance: upper ({self.upper_mm}) must exceed lower "
                             f"({self.lower_mm})")

    @classmethod
    def symmetric(cls, width_mm: float) -> "ToleranceBand":
        """ISO 1101 profile tolerance: a zone ``width_mm`` wide centred on the nominal."""
        if not width_mm > 0:
            raise ValueError(f"--tolerance-mm: must be > 0, got {width_mm}")
        return cls(width_mm / 2.0, -width_mm / 2.0)


@dataclass(frozen=True)
class Nominal:
    """A nominal contour, fixed or depending on z.

    Attributes
    ----------
    source : str
        What it was made from (spec or file).
    fixed_xy_mm : (m, 2) float or None
        A contour file's closed contour (first point not repeated).
    radius_fn : callable or None
        ``r(θ, z)`` of an object spec.
    """

    source: str
    fixed_xy_mm: np.ndarray | None = None
    radius_fn: object = None

    def contour(self, z_mm: float) -> np.ndarray:
        """(m, 2) the nominal contour for the section at ``z_mm``, counter-clockwise."""
        if self.fixed_xy_mm is not None:
            return self.fixed_xy_mm
        th = np.radians(np.arange(-180.0, 180.0, _SPEC_STEP_DEG))
        r = np.asarray(self.radius_fn(th, np.full_like(th, z_mm)), dtype=float)
        if not np.all(np.isfinite(r)):
            raise ValueError(f"nominal {self.source}: no contour at z = {z_mm:g} mm")
        return np.column_stack([r * np.cos(th), r * np.sin(th)])

    @property
    def is_round(self) -> bool:
        """Whether the nominal is a circle (within 0.1 µm) at z = 0."""
        c = least_squares_circle(self.contour(0.0))
        return c.ront_mm < 1e-4


def nominal_from_spec(spec: str) -> Nominal:
    from lts360.scenes.objects import build_object

    obj = build_object(spec)
    if obj.radius_fn is None:
        raise ValueError(f"--nominal: object {obj.name} has no analytic contour; give a "
                         f"contour file (.csv or .dxf)")
    return Nominal(source=obj.spec, radius_fn=obj.radius_fn)


def read_contour_csv(path) -> Nominal:
    """A closed contour from a CSV file of ``x, y`` rows (see the module docstring)."""
    from lts360.scenes.contour_file import read_csv_ring

    p = Path(path)
    return Nominal(source=str(p), fixed_xy_mm=read_csv_ring(p, f"--nominal {p}"))


def read_contour_dxf(path) -> Nominal:
    """The largest closed curve of a DXF drawing's model space (see the module docstring)."""
    from lts360.scenes.contour_file import read_dxf_ring

    p = Path(path)
    return Nominal(source=str(p), fixed_xy_mm=read_dxf_ring(p, f"--nominal {p}"))


def nominal_circle(diameter_mm: float) -> Nominal:
    """A round nominal of ``diameter_mm`` (> 0)."""
    d = float(diameter_mm)
    if not (np.isfinite(d) and d > 0):
        raise ValueError(f"--nominal: a diameter must be > 0 mm, got {diameter_mm}")
    return Nominal(source=f"Ø {d:g} mm", radius_fn=lambda th, z: np.full_like(th, d / 2.0))


def load_nominal(text: str) -> Nominal:
    """``--nominal``: a plain number (a round nominal of that diameter, mm), a ``.csv`` or
    ``.dxf`` file, else an object spec."""
    try:
        d = float(text)
    except ValueError:
        d = None
    if d is not None:
        return nominal_circle(d)
    suffix = Path(text).suffix.lower()
    if suffix == ".csv":
        if not Path(text).is_file():
            raise ValueError(f"--nominal: {text!r}: no such file")
        return read_contour_csv(text)
    if suffix == ".dxf":
        if not Path(text).is_file():
            raise ValueError(f"--nominal: {text!r}: no such file")
        return read_contour_dxf(text)
    try:
        return nominal_from_spec(text)
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith("--nominal") else f"--nominal: {msg}") from None


def _densify(ring: np.ndarray, step_mm: float) -> np.ndarray:
    seg = np.roll(ring, -1, axis=0) - ring
    n = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / step_mm).astype(int))
    i = np.repeat(np.arange(len(ring)), n)
    start = np.repeat(np.cumsum(n) - n, n)
    t = (np.arange(int(n.sum())) - start) / n[i]
    return ring[i] + t[:, None] * seg[i]


def deviations(points_xy_mm, contour_xy_mm) -> np.ndarray:
    """Signed distance (mm) of each point to the closed counter-clockwise contour, positive
    outside: the nearest point on the polyline (a k-d tree over the densified contour finds
    the neighbourhood, the two adjacent segments give the exact foot point)."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points_xy_mm, float)
    ring = _densify(np.asarray(contour_xy_mm, float), 0.02)
    m = len(ring)
    _, j = cKDTree(ring).query(pts)
    best = np.full(len(pts), np.inf)
    sign = np.ones(len(pts))
    for a_idx in (j - 1, j):  # the segments before and after the nearest vertex
        a = ring[a_idx % m]
        b = ring[(a_idx + 1) % m]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", pts - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        foot = a + t[:, None] * ab
        d = np.hypot(*(pts - foot).T)
        cross = ab[:, 0] * (pts - a)[:, 1] - ab[:, 1] * (pts - a)[:, 0]
        better = d < best
        best = np.where(better, d, best)
        sign = np.where(better, np.where(cross > 0, -1.0, 1.0), sign)  # left of CCW = inside
    return sign * best


def place_nominal(contour_xy_mm, centre_mm) -> np.ndarray:
    """The contour moved so that its LS centre sits at ``centre_mm``."""
    c = least_squares_circle(contour_xy_mm).centre_mm
    return np.asarray(contour_xy_mm, float) + (np.asarray(centre_mm, float) - c)

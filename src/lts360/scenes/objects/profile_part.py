"""A user's part from a drawn section, extruded along z: ``profile:path=section.dxf``.

The section is the largest closed curve of a DXF drawing or the closed point list of a CSV
file, read by :mod:`lts360.scenes.contour_file` exactly as ``inspect --nominal`` reads it
(units from the CSV header or the DXF's ``$INSUNITS``; curves flattened to 0.1 µm).  The
drawing's origin is the part's axis (``centre=1`` moves the section's centroid there
instead), and the part runs from ``z = −length/2`` to ``+length/2``.

Truth is analytic, as for the catalog: the polygon ``P`` itself, and the outer radius
``r(θ) = max {t > 0 : t·u(θ) ∈ ∂P}`` (each edge ``a → b`` meets the ray at
``t = (a × d) / (u × d)``, ``d = b − a``), exact in float64.  It is given only when the
section is star-shaped about the axis (the polar angle increases along every edge:
``v_i × v_{i+1} > 0``); otherwise scoring uses the point-to-mesh distance.

The mesh is exact: the polygon's vertices at both ends, a planar quad per edge, and the end
caps triangulated by a constrained Delaunay triangulation (shapely).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.scenes.contour_file import FLATTEN_MM, read_csv_ring, read_dxf_ring
from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.part import check_path, source_record
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register

__all__ = ["ProfilePartParams", "polygon_radius", "extrude_ring", "read_section"]

NAME = "profile"
SUFFIXES = (".dxf", ".csv")
#: Margin of the measured zone from either end (mm), as for the plug gauge.
END_MARGIN_MM = 1.0
#: Slack on the edge parameter λ ∈ [0, 1]: a ray through a vertex must hit one of its two
#: edges despite rounding (moves a hit by at most 1e-10 of an edge's length).
_LAM_SLACK = 1e-10
#: Largest (queries × edges) block of the vectorised ray–polygon intersection.
_BLOCK = 1_000_000


def read_section(path, where: str = NAME) -> np.ndarray:
    """(m, 2) counter-clockwise ring (mm) of a DXF or CSV section."""
    p = Path(path)
    reader = read_dxf_ring if p.suffix.lower() == ".dxf" else read_csv_ring
    return reader(p, f"{where}: {p}")


def polygon_radius(ring_xy_mm: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
    """Largest distance from the origin along direction ``theta_rad`` (any shape) to the
    boundary of the closed polygon ``ring_xy_mm`` (m, 2); NaN where the ray meets no edge."""
    ring = np.asarray(ring_xy_mm, dtype=float)
    a = ring
    d = np.roll(ring, -1, axis=0) - ring
    a_x_d = a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0]
    theta = np.asarray(theta_rad, dtype=float)
    flat = theta.ravel()
    out = np.full(flat.size, np.nan)
    step = max(1, _BLOCK // len(ring))
    for k in range(0, flat.size, step):
        c, s = np.cos(flat[k:k + step])[:, None], np.sin(flat[k:k + step])[:, None]
        den = c * d[None, :, 1] - s * d[None, :, 0]  # u × d
        with np.errstate(divide="ignore", invalid="ignore"):
            t = a_x_d[None, :] / den
            lam = (a[None, :, 0] * s - a[None, :, 1] * c) / den  # (a × u) / (u × d)
        hit = (den != 0) & (t > 0) & (lam >= -_LAM_SLACK) & (lam <= 1.0 + _LAM_SLACK)
        best = np.where(hit, t, -np.inf).max(axis=1)
        out[k:k + step] = np.where(np.isfinite(best), best, np.nan)
    return out.reshape(theta.shape)


def extrude_ring(ring_xy_mm: np.ndarray, z0_mm: float, z1_mm: float):
    """Watertight, outward-oriented prism over a counter-clockwise polygon (trimesh)."""
    import shapely
    import trimesh
    from scipy.spatial import cKDTree

    ring = np.asarray(ring_xy_mm, dtype=float)
    m = len(ring)
    tris = shapely.constrained_delaunay_triangles(shapely.Polygon(ring))
    corners = np.array([np.asarray(t.exterior.coords)[:3] for t in tris.geoms])  # (k, 3, 2)
    dist, idx = cKDTree(ring).query(corners.reshape(-1, 2))
    if dist.max() > 1e-9 * max(1.0, float(np.abs(ring).max())):
        raise ValueError(f"{NAME}: the end caps could not be triangulated on the section's "
                         f"vertices")
    cap = idx.reshape(-1, 3)
    e1, e2 = ring[cap[:, 1]] - ring[cap[:, 0]], ring[cap[:, 2]] - ring[cap[:, 0]]
    ccw = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0
    cap = np.where(ccw[:, None], cap, cap[:, ::-1])  # counter-clockwise seen from +z
    i = np.arange(m)
    j = (i + 1) % m
    sides = np.concatenate([np.stack([i, j, m + j], -1), np.stack([i, m + j, m + i], -1)])
    faces = np.concatenate([sides, cap[:, ::-1], cap + m])  # bottom faces −z, top faces +z
    vertices = np.concatenate([np.column_stack([ring, np.full(m, z0_mm)]),
                               np.column_stack([ring, np.full(m, z1_mm)])])
    return trimesh.Trimesh(vertices, faces, process=False)


@dataclass(frozen=True)
class ProfilePartParams:
    """A part extruded from a drawn section.

    Attributes
    ----------
    path : str
        DXF drawing or CSV of ``x, y`` rows (stored absolute in the spec; no ``,`` or ``=``).
    length_mm : float, [2, 400]
        Length of the extrusion, centred on ``z = 0``.
    centre : bool
        Put the section's area centroid on the axis (default: the drawing's origin is the axis).
    material : str
        Material preset name.
    """

    path: str = ""
    length_mm: float = 40.0
    centre: bool = False
    material: str = "ground-steel"

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", str(check_path(NAME, self.path, SUFFIXES)))
        check_range(NAME, "length_mm", self.length_mm, 2.0, 400.0)
        get_material(self.material)

    def section(self) -> np.ndarray:
        """(m, 2) the section (mm, object frame), counter-clockwise."""
        ring = read_section(self.path)
        if self.centre:
            import shapely

            c = shapely.Polygon(ring).centroid
            ring = ring - np.array([c.x, c.y])
        return ring

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Read the section, extrude it, and return it with its analytic truth."""
        ring = self.section()
        h = self.length_mm / 2.0
        nxt = np.roll(ring, -1, axis=0)
        star = bool(np.all(ring[:, 0] * nxt[:, 1] - ring[:, 1] * nxt[:, 0] > 0))

        def radius(theta_rad, z_mm):
            theta, z = np.broadcast_arrays(np.asarray(theta_rad, dtype=float),
                                           np.asarray(z_mm, dtype=float))
            return np.where(np.abs(z) <= h, polygon_radius(ring, theta), np.nan)

        notes = {"part": source_record(Path(self.path)), "section_vertices": int(len(ring)),
                 "section_xy_mm": ring}
        if not star:
            notes["truth"] = ("section not star-shaped about the axis: scored by point-to-mesh "
                              "distance only, no r(θ, z)")
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=extrude_ring(ring, -h, h), placement=placement,
            material=get_material(self.material), radius_fn=radius if star else None,
            measured_zone_z_mm=(-h + END_MARGIN_MM, h - END_MARGIN_MM),
            mesh_tolerance_mm=FLATTEN_MM if Path(self.path).suffix.lower() == ".dxf" else 0.0,
            sections=1, pitch_mm=0.0,
            description=f"part extruded {self.length_mm:g} mm from {Path(self.path).name}",
            notes=notes)


register(ObjectType(NAME, "Your part: a closed section (DXF or CSV of x, y) extruded along z",
                    ProfilePartParams, aliases={"length": "length_mm"}, from_file=True))

"""28 mm rusty cube with a V-groove (paper §4.6, Fig. 16).

A cube of edge ``a`` (axis +Z through its centre, faces normal to ±X and ±Y) with a straight
V-groove along Z in the middle of one face: included angle ``2γ``, depth ``t``, width
``w = 2 t tan γ`` at the face.  The section is a polygon of seven vertices (four corners, the
groove's two edges and its bottom), star-shaped with respect to the axis (every edge line has
the axis on its inner side), so the outer radius is exact and analytic: the ray at ``θ`` meets
the polygon edge whose angular range holds ``θ``, at ``r = (n·p) / (n·u(θ))`` (edge normal
``n``, a point ``p`` of the edge, ``u = (cos θ, sin θ)``); on a plain face ``r = (a/2) / cos θ``.

The mesh is exact: one grid angle per polygon vertex, the side faces are planar.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_less, check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import star_mesh
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register
from lts360.scenes.objects.zoned import zone_half_mm

__all__ = ["CubeParams"]

NAME = "cube"
#: The paper's scan of this object (Fig. 16).
SECTIONS = 25
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = zone_half_mm(SECTIONS, PITCH_MM)
#: Faces the groove may be cut into, by the angle of their outward normal.
_FACES_DEG = (0.0, 90.0, 180.0, 270.0)


@dataclass(frozen=True)
class CubeParams:
    """Rusty cube with a V-groove along Z in the middle of one face.

    Attributes
    ----------
    edge_mm : float, [2·ZONE_HALF_MM + 2, 40]
        Edge ``a`` of the cube (paper: 28 mm); also its height along Z, centred on ``z = 0``.
    groove_depth_mm : float, [0.1, 5]
        Depth ``t`` of the V-groove below the face.
    groove_angle_deg : float, [30, 150]
        Included angle ``2γ`` of the V; the width at the face, ``2 t tan γ``, must be smaller
        than ``a / 2``.
    groove_face_deg : float, {0, 90, 180, 270}
        Outward normal of the grooved face, from +X counter-clockwise (0: the +X face).
    mesh_tolerance_mm : float, [1e-5, 0.01]
        Tolerance the object reports; the mesh is exact (float64 rounding only).
    material : str
        Material preset name.
    """

    edge_mm: float = 28.0
    groove_depth_mm: float = 1.5
    groove_angle_deg: float = 90.0
    groove_face_deg: float = 0.0
    mesh_tolerance_mm: float = 0.001
    material: str = "rust"

    def __post_init__(self) -> None:
        check_range(NAME, "edge_mm", self.edge_mm, 2.0 * ZONE_HALF_MM + 2.0, 40.0)
        check_range(NAME, "groove_depth_mm", self.groove_depth_mm, 0.1, 5.0)
        check_range(NAME, "groove_angle_deg", self.groove_angle_deg, 30.0, 150.0)
        check_less(NAME, "groove width 2·groove_depth_mm·tan(groove_angle_deg/2)",
                   self.groove_width_mm, "edge_mm/2", self.edge_mm / 2.0)
        if self.groove_face_deg not in _FACES_DEG or isinstance(self.groove_face_deg, bool):
            raise ValueError(f"{NAME}: groove_face_deg must be one of 0, 90, 180, 270, got "
                             f"{self.groove_face_deg!r}")
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-5, 0.01)
        get_material(self.material)

    @property
    def groove_width_mm(self) -> float:
        """Width ``w = 2 t tan γ`` of the groove at the face."""
        return 2.0 * self.groove_depth_mm * math.tan(math.radians(self.groove_angle_deg) / 2.0)

    def section_vertices(self) -> np.ndarray:
        """(7, 2) polygon vertices (mm, object frame), counter-clockwise from the corner
        before the groove: corner, groove edge, groove bottom, groove edge, three corners."""
        h, t, w = self.edge_mm / 2.0, self.groove_depth_mm, self.groove_width_mm
        local = np.array([[h, -h], [h, -w / 2.0], [h - t, 0.0], [h, w / 2.0],
                          [h, h], [-h, h], [-h, -h]])
        a = math.radians(self.groove_face_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return local @ rot.T

    def _edges(self):
        """Vertex angles in ``[0, 2π)`` sorted, and each edge's ``(n, n·p)`` from that vertex
        to the next."""
        v = self.section_vertices()
        ang = np.mod(np.arctan2(v[:, 1], v[:, 0]), 2.0 * np.pi)
        order = np.argsort(ang)
        v, ang = v[order], ang[order]
        d = np.roll(v, -1, axis=0) - v
        n = np.stack([d[:, 1], -d[:, 0]], -1)  # outward for a counter-clockwise polygon
        return ang, n, np.einsum("ij,ij->i", n, v)

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        NaN beyond the end faces (``|z| > edge_mm / 2``).
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        theta, z = np.broadcast_arrays(theta, z)
        ang, n, c = self._edges()
        th = np.mod(theta, 2.0 * np.pi)
        k = np.searchsorted(ang, th, side="right") - 1  # −1: before the first vertex angle
        k = np.mod(k, ang.size)
        r = c[k] / (n[k, 0] * np.cos(th) + n[k, 1] * np.sin(th))
        return np.where(np.abs(z) <= self.edge_mm / 2.0, r, np.nan)

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Mesh the cube and return it with its analytic truth.

        Parameters
        ----------
        placement : Placement
            Pose of the cube in the world.

        Returns
        -------
        SceneObject
        """
        ang, _, _ = self._edges()
        h = self.edge_mm / 2.0
        zone = ZONE_HALF_MM
        mesh = star_mesh(self.radius, ang, np.array([-h, -zone, zone, h]))
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=mesh, placement=placement, material=get_material(self.material),
            radius_fn=self.radius, measured_zone_z_mm=(-zone, zone),
            mesh_tolerance_mm=self.mesh_tolerance_mm, sections=SECTIONS, pitch_mm=PITCH_MM,
            description=(f"rusty cube {self.edge_mm} mm with a {self.groove_angle_deg:g}° V-groove "
                         f"{self.groove_depth_mm} mm deep in the {self.groove_face_deg:g}° face"),
            notes={"n_theta": int(ang.size), "n_z": 4, "groove_width_mm": self.groove_width_mm,
                   "vertex_angles_rad": tuple(float(a) for a in ang)})


register(ObjectType(NAME, "28 mm rusty cube with a V-groove along one face (paper Fig. 16)",
                    CubeParams, aliases={"a": "edge_mm", "edge": "edge_mm",
                                         "depth": "groove_depth_mm", "angle": "groove_angle_deg",
                                         "face": "groove_face_deg", "tol": "mesh_tolerance_mm"}))

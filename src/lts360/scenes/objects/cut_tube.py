"""Ø25 mm hollow brass cylinder with a diagonal cut (paper §4.6, Fig. 18).

A tube whose top end is cut off by an inclined plane

    z = z_c + tan(α) · (x cos θ_c + y sin θ_c)

that crosses the upper part of the measured zone, so that the upper sections see only part of
the outer circle (partial arcs).  The outer radius is ``R`` below the plane and NaN above it.
The mesh is the exact boolean difference (Manifold, double precision) of a polygonal tube and
a box whose bottom face lies on the plane.  (trimesh's ``difference(engine="manifold")``
passes float32 vertices, about 1 µm at this radius, hence manifold3d directly with
``Mesh64``; ``Manifold.trim_by_plane`` was seen to flatten very shallow planes, e.g. at
α = 1e-6° its cut vertices sit up to ``R tan α`` off the plane.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh
from manifold3d import Error, Manifold, Mesh64

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_less, check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import n_theta_for_tolerance, star_mesh, z_grid
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register
from lts360.scenes.objects.zoned import zone_half_mm

NAME = "cut-tube"
#: The paper's scan of this object (Fig. 18).
SECTIONS = 25
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = zone_half_mm(SECTIONS, PITCH_MM)
#: Largest axial step of the (straight) tube wall (keeps the triangles' aspect moderate).
_MAX_STEP_MM = 2.0
#: Closest approach of the cut plane to either end of the tube.
_END_MARGIN_MM = 1.0
#: No ring of the tube mesh closer than this (axially) to the top or bottom of the band the
#: cut plane sweeps over the wall, where the plane meets a ring (nearly) tangentially: the
#: boolean would leave slivers there.
_RING_CLEARANCE_MM = 0.01


@dataclass(frozen=True)
class CutTubeParams:
    """Hollow brass cylinder with a diagonal (inclined plane) cut at its top end.

    Attributes
    ----------
    outer_diameter_mm : float, [5, 60]
        Outer diameter ``2R`` (paper: 25 mm).
    inner_diameter_mm : float, [1, 59], < outer_diameter_mm
        Inner diameter.
    cut_angle_deg : float, [0, 60]
        Angle ``α`` between the cut plane and the horizontal (the plane ``z = 0``).
    cut_height_mm : float
        Height ``z_c`` at which the cut plane meets the axis.  The plane must stay at least
        1 mm from both tube ends: ``|z_c| + R tan α < length_mm / 2 − 1``.
    cut_azimuth_deg : float, [-180, 180]
        Direction ``θ_c`` (from +X, counter-clockwise) in which the cut plane rises.
    length_mm : float, [2·ZONE_HALF_MM + 2, 200]
        Length of the tube before the cut, centred on ``z = 0``.
    mesh_tolerance_mm : float, [1e-4, 0.01]
        Largest allowed radial distance between mesh and true outer surface.
    material : str
        Material preset name.
    """

    outer_diameter_mm: float = 25.0
    inner_diameter_mm: float = 20.0
    cut_angle_deg: float = 30.0
    cut_height_mm: float = 9.0
    cut_azimuth_deg: float = 0.0
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.001
    material: str = "brass"

    def __post_init__(self) -> None:
        check_range(NAME, "outer_diameter_mm", self.outer_diameter_mm, 5.0, 60.0)
        check_range(NAME, "inner_diameter_mm", self.inner_diameter_mm, 1.0, 59.0)
        check_less(NAME, "inner_diameter_mm", self.inner_diameter_mm,
                   "outer_diameter_mm", self.outer_diameter_mm)
        check_range(NAME, "cut_angle_deg", self.cut_angle_deg, 0.0, 60.0)
        check_range(NAME, "cut_azimuth_deg", self.cut_azimuth_deg, -180.0, 180.0)
        check_range(NAME, "length_mm", self.length_mm, 2.0 * ZONE_HALF_MM + 2.0, 200.0)
        check_range(NAME, "cut_height_mm", self.cut_height_mm, -self.length_mm / 2.0,
                    self.length_mm / 2.0)
        rise = self._cut_rise_mm()
        limit = self.length_mm / 2.0 - _END_MARGIN_MM
        check_less(NAME, "|cut_height_mm| + outer_diameter_mm/2·tan(cut_angle_deg)",
                   abs(self.cut_height_mm) + rise, "length_mm/2 - 1", limit)
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-4, 0.01)
        get_material(self.material)

    def _cut_rise_mm(self) -> float:
        """Height of the cut plane above ``z_c`` at the outer surface, on the rising side."""
        return self.outer_diameter_mm / 2.0 * math.tan(math.radians(self.cut_angle_deg))

    def cut_height_at(self, theta_rad, radius_mm):
        """Height (mm) of the cut plane at polar position ``(theta_rad, radius_mm)``."""
        slope = math.tan(math.radians(self.cut_angle_deg))
        return self.cut_height_mm + slope * np.asarray(radius_mm, dtype=float) * np.cos(
            np.asarray(theta_rad, dtype=float) - math.radians(self.cut_azimuth_deg))

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        ``outer_diameter_mm / 2`` where the outer surface exists; NaN above the cut plane
        and below the bottom end.
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        R = self.outer_diameter_mm / 2.0
        ok = (z >= -self.length_mm / 2.0) & (z <= self.cut_height_at(theta, R))
        return np.where(ok, R, np.nan)

    def _half_space_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(8, 3) vertices and (12, 3) outward faces of a box, wider than the tube, whose
        bottom face lies on the cut plane (corners computed on the plane in float64)."""
        b = self.outer_diameter_mm  # half-width: twice the tube radius
        xy = np.array([[-b, -b], [b, -b], [b, b], [-b, b]])
        z_bottom = self.cut_height_at(np.arctan2(xy[:, 1], xy[:, 0]), np.hypot(xy[:, 0], xy[:, 1]))
        z_top = max(float(z_bottom.max()), self.length_mm / 2.0) + self.length_mm
        vertices = np.vstack([np.column_stack([xy, z_bottom]),
                              np.column_stack([xy, np.full(4, z_top)])])
        faces = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                          [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
        return vertices, faces

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Mesh the cut tube and return it with its analytic truth.

        The polygonal tube (chord sagitta ≤ ``mesh_tolerance_mm``, exact along z) minus a box
        whose bottom face lies on the cut plane, by Manifold in double precision: the original
        vertices are kept bit for bit, the new ones lie on the plane (to float64 rounding).

        Parameters
        ----------
        placement : Placement
            Pose of the tube in the world.

        Returns
        -------
        SceneObject
        """
        R, r_in = self.outer_diameter_mm / 2.0, self.inner_diameter_mm / 2.0
        n_theta = n_theta_for_tolerance(R, self.mesh_tolerance_mm)
        psi = np.arange(n_theta) * (2.0 * np.pi / n_theta)
        h, zone = self.length_mm / 2.0, ZONE_HALF_MM
        z = z_grid(-h, h, _MAX_STEP_MM, breakpoints_mm=(-zone, zone))
        # The wall is straight along z, so rings are free to go: drop those that the cut plane
        # would meet (nearly) tangentially, at the top and bottom of the band it sweeps.
        edge_gap = np.abs(np.abs(z - self.cut_height_mm) - self._cut_rise_mm())
        z = z[(edge_gap >= _RING_CLEARANCE_MM) | (np.abs(z) == h)]
        tube = star_mesh(lambda t, zz: np.full(np.shape(t), R), psi, z,
                         radius_in=lambda t, zz: np.full(np.shape(t), r_in))
        cut = (_manifold(tube.vertices, tube.faces)
               - _manifold(*self._half_space_box())).to_mesh64()
        mesh = trimesh.Trimesh(np.asarray(cut.vert_properties, dtype=float)[:, :3],
                               np.asarray(cut.tri_verts, dtype=np.int64), process=False)
        if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
            raise RuntimeError(f"{NAME}: boolean cut did not give a watertight solid")
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=mesh, placement=placement, material=get_material(self.material),
            radius_fn=self.radius, measured_zone_z_mm=(-zone, zone),
            mesh_tolerance_mm=self.mesh_tolerance_mm, sections=SECTIONS, pitch_mm=PITCH_MM,
            description=(f"hollow brass cylinder Ø{self.outer_diameter_mm}/"
                         f"{self.inner_diameter_mm} mm, cut at {self.cut_angle_deg}°"),
            notes={"n_theta": n_theta, "n_z": int(z.size),
                   "cut_z_range_outer_mm": (self.cut_height_mm - self._cut_rise_mm(),
                                            self.cut_height_mm + self._cut_rise_mm())})


def _manifold(vertices: np.ndarray, faces: np.ndarray) -> Manifold:
    """Double-precision Manifold of a closed, outward-oriented triangle mesh."""
    solid = Manifold(Mesh64(np.ascontiguousarray(vertices, dtype=np.float64),
                            np.ascontiguousarray(faces, dtype=np.uint64)))
    if solid.status() != Error.NoError:
        raise RuntimeError(f"{NAME}: Manifold refused a mesh: {solid.status()}")
    return solid


register(ObjectType(NAME, "Ø25 mm hollow brass cylinder with a diagonal cut (paper Fig. 18)",
                    CutTubeParams, aliases={"od": "outer_diameter_mm", "d": "outer_diameter_mm",
                                            "id": "inner_diameter_mm",
                                            "angle": "cut_angle_deg",
                                            "cut_z": "cut_height_mm",
                                            "cut_azimuth": "cut_azimuth_deg",
                                            "length": "length_mm",
                                            "tol": "mesh_tolerance_mm"}))

"""What every object generator returns: a placed, watertight mesh with its exact truth.

Object frame: the object's nominal axis is +Z, the nominal section is at ``z = 0``.  The
placement maps the object frame into the world frame (offset of the axis in X/Y, tilt of
the axis about a horizontal line through the origin of the object frame).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import trimesh

from lts360.scenes.materials import Material

__all__ = ["Placement", "SceneObject", "RadiusFunction"]

#: ``r_mm = f(theta_rad, z_mm)`` in the object frame, vectorised over equal-shape arrays;
#: NaN where the ray from the axis at ``theta`` meets no outer surface at height ``z``.
RadiusFunction = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Placement:
    """Pose of the object in the world.

    Attributes
    ----------
    x_mm, y_mm : float
        Where the object axis pierces the plane ``z = 0`` of the world.
    tilt_deg : float, [0, 30]
        Angle between the object axis and world +Z.
    tilt_azimuth_deg : float
        Direction, in the world XY plane (from +X, counter-clockwise), towards which the
        top of the axis leans.
    """

    x_mm: float = 0.0
    y_mm: float = 0.0
    tilt_deg: float = 0.0
    tilt_azimuth_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x_mm", "y_mm", "tilt_deg", "tilt_azimuth_deg"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"placement {name} must be finite, got {getattr(self, name)}")
        if not 0.0 <= self.tilt_deg <= 30.0:
            raise ValueError(f"placement tilt_deg must be in [0, 30], got {self.tilt_deg}")
        if abs(self.x_mm) > 20.0 or abs(self.y_mm) > 20.0:
            raise ValueError(f"placement x_mm and y_mm must be in [-20, 20], got "
                             f"({self.x_mm}, {self.y_mm})")

    @property
    def T_world_object(self) -> np.ndarray:
        """(4, 4) homogeneous transform from the object frame to the world frame."""
        tilt = np.radians(self.tilt_deg)
        az = np.radians(self.tilt_azimuth_deg)
        axis = np.array([-np.sin(az), np.cos(az), 0.0])  # z × (cos az, sin az, 0)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(tilt) * K + (1.0 - np.cos(tilt)) * (K @ K)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [self.x_mm, self.y_mm, 0.0]
        return T


@dataclass(frozen=True, eq=False)
class SceneObject:
    """A generated object with its ground truth.

    Attributes
    ----------
    name : str
        Registry name (``plug-gauge``, ``cable-8``, ...).
    spec : str
        Canonical spec string that rebuilds exactly this object.
    params : dict
        The generator's parameters (units in the keys).
    mesh_object : trimesh.Trimesh
        Watertight mesh in the object frame, millimetres.
    placement : Placement
    material : Material
    radius_fn : RadiusFunction or None
        Exact outer radius ``r(theta, z)`` in the object frame, where the shape allows one.
    measured_zone_z_mm : (float, float)
        Axial range (object frame) in which the mesh agrees with the truth to
        ``mesh_tolerance_mm`` and in which sections are measured.
    mesh_tolerance_mm : float
        Bound on the distance between the mesh and the true surface in the measured zone.
    sections : int
        Number of sections of the paper's scan of this object (§4.6).
    pitch_mm : float
        Stage pitch between sections in the paper's scan.
    """

    name: str
    spec: str
    params: dict
    mesh_object: trimesh.Trimesh
    placement: Placement
    material: Material
    radius_fn: RadiusFunction | None
    measured_zone_z_mm: tuple[float, float]
    mesh_tolerance_mm: float
    sections: int
    pitch_mm: float
    description: str = ""
    notes: dict = field(default_factory=dict)

    @property
    def T_world_object(self) -> np.ndarray:
        return self.placement.T_world_object

    def mesh_world(self) -> trimesh.Trimesh:
        """The mesh placed in the world frame (a copy)."""
        mesh = self.mesh_object.copy()
        mesh.apply_transform(self.T_world_object)
        return mesh

    def to_object_frame(self, points_world_mm: np.ndarray) -> np.ndarray:
        """(n, 3) world points → object frame."""
        T = self.T_world_object
        pts = np.asarray(points_world_mm, dtype=float).reshape(-1, 3)
        return (pts - T[:3, 3]) @ T[:3, :3]

    def true_radius_at(self, points_world_mm: np.ndarray) -> np.ndarray:
        """True outer radius at the (θ, z) of each world point, in the object frame.

        Returns NaN where the object has no analytic radius or no surface there.
        """
        pts = self.to_object_frame(points_world_mm)
        if self.radius_fn is None:
            return np.full(len(pts), np.nan)
        theta = np.arctan2(pts[:, 1], pts[:, 0])
        return np.asarray(self.radius_fn(theta, pts[:, 2]), dtype=float)

    def radial_error(self, points_world_mm: np.ndarray) -> np.ndarray:
        """Measured minus true radius (mm) of each world point, in the object frame."""
        pts = self.to_object_frame(points_world_mm)
        return np.hypot(pts[:, 0], pts[:, 1]) - self.true_radius_at(points_world_mm)

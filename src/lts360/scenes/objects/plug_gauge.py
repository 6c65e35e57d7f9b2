"""Plain plug gauge (paper §4.5): a ground steel cylinder of certified diameter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import n_theta_for_tolerance, star_mesh
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register

NAME = "plug-gauge"


@dataclass(frozen=True)
class PlugGaugeParams:
    """Plain plug gauge.

    Attributes
    ----------
    diameter_mm : float, [1, 40]
        Certified diameter (paper: 19.9987 ± 0.0004 mm).
    length_mm : float, [5, 200]
        Length of the gauging cylinder, centred on ``z = 0``.
    mesh_tolerance_mm : float, [1e-5, 0.01]
        Largest allowed distance between mesh and true cylinder.  Default 0.1 µm (1405
        segments): the gauge is the accuracy reference, and flat facets lie on average 2/3 of
        the tolerance inside the circle, which would show up as a radius bias.
    material : str
        Material preset name.
    """

    diameter_mm: float = 19.9987
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.0001
    material: str = "ground-steel"

    def __post_init__(self) -> None:
        check_range(NAME, "diameter_mm", self.diameter_mm, 1.0, 40.0)
        check_range(NAME, "length_mm", self.length_mm, 5.0, 200.0)
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-5, 0.01)
        get_material(self.material)

    def radius(self, theta_rad, z_mm):
        return np.full(np.broadcast(theta_rad, z_mm).shape, self.diameter_mm / 2.0)

    def build(self, placement: Placement = Placement()) -> SceneObject:
        r = self.diameter_mm / 2.0
        n = n_theta_for_tolerance(r, self.mesh_tolerance_mm)
        psi = np.arange(n) * (2.0 * np.pi / n)
        h = self.length_mm / 2.0
        mesh = star_mesh(self.radius, psi, np.array([-h, h]))
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=mesh, placement=placement, material=get_material(self.material),
            radius_fn=self.radius, measured_zone_z_mm=(-h + 1.0, h - 1.0),
            mesh_tolerance_mm=self.mesh_tolerance_mm, sections=1, pitch_mm=0.0,
            description=f"plain plug gauge Ø{self.diameter_mm} mm")


register(ObjectType(NAME, "Plain plug gauge, ground steel (paper §4.5, Ø19.9987 mm)",
                    PlugGaugeParams, aliases={"d": "diameter_mm", "length": "length_mm",
                                              "tol": "mesh_tolerance_mm"}))

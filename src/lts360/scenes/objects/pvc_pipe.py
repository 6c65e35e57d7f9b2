"""1" PVC pipe, deformed (paper §4.6, Fig. 11): an ovalised tube with a smooth local dent.

The outer radius is exact and analytic::

    r(θ, z) = R + (ovality / 4) cos 2(θ − θ_ov)
                − depth · exp(−(1 − cos(θ − θ_d)) (R / σ_arc)²) · exp(−(z − z_d)² / (2 σ_z²))

so that ``D_max − D_min = ovality`` (without the dent).  The circumferential factor is a von
Mises bump: periodic in θ and, for ``σ_arc ≪ R``, a Gaussian of standard deviation ``σ_arc``
in arc length at the nominal radius ``R``.  The wall follows the deformation (``r_in = r − wall``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_less, check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import n_theta_for_tolerance
from lts360.scenes.objects.registry import ObjectType, register
from lts360.scenes.objects.zoned import (
    MESH_SAFETY,
    axial_step_mm,
    chord_radius_mm,
    zone_half_mm,
    zoned_star_object,
)

NAME = "pvc-pipe"
#: The paper's scan of this object (Fig. 11).
SECTIONS = 26
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = zone_half_mm(SECTIONS, PITCH_MM)


@dataclass(frozen=True)
class PvcPipeParams:
    """Deformed 1" PVC pipe (Brazilian soldable PVC "1 polegada": OD 32 mm, wall 2.1 mm).

    Attributes
    ----------
    outer_diameter_mm : float, [10, 60]
        Nominal outer diameter ``2R``.
    wall_mm : float, [0.5, 10]
        Wall thickness; the inner surface is ``r(θ, z) − wall_mm``.
    ovality_mm : float, [0, 0.1·outer_diameter_mm]
        Difference between the largest and the smallest outer diameter.
    ovality_angle_deg : float, [-180, 180]
        Direction of the largest diameter, from +X, counter-clockwise.
    dent_depth_mm : float, [0, 3] and < wall_mm
        Depth of the dent at its centre.
    dent_sigma_arc_mm : float, [2, 20]
        Circumferential standard deviation of the dent, in arc length at radius ``R``.
    dent_sigma_z_mm : float, [2, 20]
        Axial standard deviation of the dent.
    dent_theta_deg : float, [-180, 180]
        Direction of the dent centre (default −90°: facing the camera's direct view).
    dent_z_mm : float, [-ZONE_HALF_MM, ZONE_HALF_MM]
        Axial position of the dent centre (default: middle of the measured zone).
    length_mm : float, [2·ZONE_HALF_MM + 2, 200]
        Pipe length, centred on ``z = 0``.
    mesh_tolerance_mm : float, [1e-4, 0.01]
        Largest allowed radial distance between mesh and true outer surface in the measured
        zone.  Mesh size grows like ``1 / mesh_tolerance_mm``.
    material : str
        Material preset name.
    """

    outer_diameter_mm: float = 32.0
    wall_mm: float = 2.1
    ovality_mm: float = 0.8
    ovality_angle_deg: float = 0.0
    dent_depth_mm: float = 0.6
    dent_sigma_arc_mm: float = 3.0
    dent_sigma_z_mm: float = 3.0
    dent_theta_deg: float = -90.0
    dent_z_mm: float = 0.0
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.001
    material: str = "white-pvc"

    def __post_init__(self) -> None:
        check_range(NAME, "outer_diameter_mm", self.outer_diameter_mm, 10.0, 60.0)
        check_range(NAME, "wall_mm", self.wall_mm, 0.5, 10.0)
        check_range(NAME, "ovality_mm", self.ovality_mm, 0.0, 0.1 * self.outer_diameter_mm)
        check_range(NAME, "ovality_angle_deg", self.ovality_angle_deg, -180.0, 180.0)
        check_range(NAME, "dent_depth_mm", self.dent_depth_mm, 0.0, 3.0)
        check_less(NAME, "dent_depth_mm", self.dent_depth_mm, "wall_mm", self.wall_mm)
        check_range(NAME, "dent_sigma_arc_mm", self.dent_sigma_arc_mm, 2.0, 20.0)
        check_range(NAME, "dent_sigma_z_mm", self.dent_sigma_z_mm, 2.0, 20.0)
        check_range(NAME, "dent_theta_deg", self.dent_theta_deg, -180.0, 180.0)
        check_range(NAME, "dent_z_mm", self.dent_z_mm, -ZONE_HALF_MM, ZONE_HALF_MM)
        check_range(NAME, "length_mm", self.length_mm, 2.0 * ZONE_HALF_MM + 2.0, 200.0)
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-4, 0.01)
        check_less(NAME, "wall_mm + dent_depth_mm + ovality_mm/4", self._thinnest_mm(),
                   "outer_diameter_mm/2", self.outer_diameter_mm / 2.0)
        get_material(self.material)

    def _thinnest_mm(self) -> float:
        return self.wall_mm + self.dent_depth_mm + self.ovality_mm / 4.0

    def _dent_k(self) -> float:
        """Concentration of the circumferential von Mises bump, ``(R / σ_arc)²``."""
        return (self.outer_diameter_mm / 2.0 / self.dent_sigma_arc_mm) ** 2

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        NaN beyond the pipe ends (``|z| > length_mm / 2``).
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        oval = self.ovality_mm / 4.0 * np.cos(2.0 * (theta - math.radians(self.ovality_angle_deg)))
        bump_t = np.exp(-(1.0 - np.cos(theta - math.radians(self.dent_theta_deg))) * self._dent_k())
        bump_z = np.exp(-0.5 * ((z - self.dent_z_mm) / self.dent_sigma_z_mm) ** 2)
        r = self.outer_diameter_mm / 2.0 + oval - self.dent_depth_mm * bump_t * bump_z
        return np.where(np.abs(z) <= self.length_mm / 2.0, r, np.nan)

    def inner_radius(self, theta_rad, z_mm):
        """Inner radius (mm): the outer radius minus the wall thickness."""
        return self.radius(theta_rad, z_mm) - self.wall_mm

    def _resolution(self) -> tuple[int, float]:
        """(n_theta, axial step in the measured zone, mm) meeting ``mesh_tolerance_mm``.

        The radial error of a grid triangle is bounded by ``(K_s Δs² + 2 K_sz Δs Δz + K_z Δz²) / 8``
        with ``K_s`` the curvature of the cross-section (evaluated on a dense θ grid, for dent
        factors 0 … 1), ``K_z = |∂²r/∂z²|`` and ``K_sz = |∂²r/∂s∂z|`` (upper bounds); the
        mixed term is split between the two directions and each direction gets half the budget.
        """
        R = self.outer_diameter_mm / 2.0
        r_min = R - self.ovality_mm / 4.0 - self.dent_depth_mm
        k = self._dent_k()
        # Circumferential part: chord sagitta κ c² / 8 with c ≈ √(r² + r_θ²) Δθ, so the
        # equivalent circle radius is max κ (r² + r_θ²) over the cross-sections.
        theta = np.linspace(0.0, 2.0 * np.pi, 1 << 16, endpoint=False)
        a = 2.0 * (theta - math.radians(self.ovality_angle_deg))
        b = theta - math.radians(self.dent_theta_deg)
        q = self.ovality_mm / 4.0
        g = np.exp(-(1.0 - np.cos(b)) * k)
        g1 = -k * np.sin(b) * g                                  # dg/dθ
        g2 = (k * k * np.sin(b) ** 2 - k * np.cos(b)) * g        # d²g/dθ²
        r_eq = 0.0
        for c in np.linspace(0.0, 1.0, 11) * self.dent_depth_mm:
            r = R + q * np.cos(a) - c * g
            r1 = -2.0 * q * np.sin(a) - c * g1
            r2 = -4.0 * q * np.cos(a) - c * g2
            r_eq = max(r_eq, chord_radius_mm(r, r1, r2))
        sz = self.dent_sigma_z_mm
        r_sz = self.dent_depth_mm * np.max(np.abs(g1)) / r_min * math.exp(-0.5) / sz
        r_zz = self.dent_depth_mm / sz ** 2
        r_max = R + q
        budget = MESH_SAFETY * self.mesh_tolerance_mm / 2.0
        n_theta = n_theta_for_tolerance(r_eq + r_sz * r_max ** 2, budget)
        k_z = r_zz + r_sz
        dz = axial_step_mm(budget, k_z, ZONE_HALF_MM)
        return n_theta, dz

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Mesh the pipe and return it with its analytic truth.

        Parameters
        ----------
        placement : Placement
            Pose of the pipe in the world.

        Returns
        -------
        SceneObject
        """
        n_theta, dz = self._resolution()
        return zoned_star_object(
            NAME, self, placement, radius=self.radius, inner_radius=self.inner_radius,
            n_theta=n_theta, dz_mm=dz, length_mm=self.length_mm, sections=SECTIONS,
            pitch_mm=PITCH_MM,
            description=(f"1\" PVC pipe Ø{self.outer_diameter_mm} mm × {self.wall_mm} mm, "
                         f"ovality {self.ovality_mm} mm, dent {self.dent_depth_mm} mm"))


register(ObjectType(NAME, "1\" PVC pipe, deformed: ovalised with a local dent (paper Fig. 11)",
                    PvcPipeParams, aliases={"od": "outer_diameter_mm", "wall": "wall_mm",
                                            "ovality": "ovality_mm",
                                            "dent": "dent_depth_mm",
                                            "length": "length_mm",
                                            "tol": "mesh_tolerance_mm"}))

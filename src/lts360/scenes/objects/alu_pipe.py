"""Ø22 mm aluminium pipe with undulations (paper §4.6, Fig. 12).

The outer radius is exact and analytic: an axial sinusoidal waviness plus a few
circumferential lobes::

    r(θ, z) = R + A_w cos(2π z / λ + φ_w) + A_l cos(n_l (θ − θ_l))

The wall follows the undulations (``r_in = r − wall``), as in a drawn tube.
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

NAME = "alu-pipe"
#: The paper's scan of this object (Fig. 12).
SECTIONS = 26
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = zone_half_mm(SECTIONS, PITCH_MM)


@dataclass(frozen=True)
class AluPipeParams:
    """Aluminium pipe with undulations.

    Attributes
    ----------
    outer_diameter_mm : float, [6, 60]
        Nominal outer diameter ``2R`` (paper: 22 mm).
    wall_mm : float, [0.3, 10]
        Wall thickness; the inner surface is ``r(θ, z) − wall_mm``.
    waviness_amplitude_mm : float, [0, 0.3]
        Amplitude ``A_w`` of the axial waviness (peak-to-valley ``2 A_w``).
    waviness_wavelength_mm : float, [3, 40]
        Axial wavelength ``λ`` of the waviness.
    waviness_phase_deg : float, [-180, 180]
        Phase ``φ_w``; 0 puts a crest at ``z = 0``.
    lobes : int, [2, 12]
        Number ``n_l`` of circumferential lobes.
    lobe_amplitude_mm : float, [0, 0.2]
        Amplitude ``A_l`` of the lobes.
    lobe_angle_deg : float, [-180, 180]
        Direction ``θ_l`` of one lobe maximum, from +X, counter-clockwise.
    length_mm : float, [2·ZONE_HALF_MM + 2, 200]
        Pipe length, centred on ``z = 0``.
    mesh_tolerance_mm : float, [1e-4, 0.01]
        Largest allowed radial distance between mesh and true outer surface in the measured
        zone.  Mesh size grows like ``1 / mesh_tolerance_mm``.
    material : str
        Material preset name.
    """

    outer_diameter_mm: float = 22.0
    wall_mm: float = 1.5
    waviness_amplitude_mm: float = 0.1
    waviness_wavelength_mm: float = 5.0
    waviness_phase_deg: float = 0.0
    lobes: int = 3
    lobe_amplitude_mm: float = 0.03
    lobe_angle_deg: float = 0.0
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.001
    material: str = "machined-aluminium"

    def __post_init__(self) -> None:
        check_range(NAME, "outer_diameter_mm", self.outer_diameter_mm, 6.0, 60.0)
        check_range(NAME, "wall_mm", self.wall_mm, 0.3, 10.0)
        check_range(NAME, "waviness_amplitude_mm", self.waviness_amplitude_mm, 0.0, 0.3)
        check_range(NAME, "waviness_wavelength_mm", self.waviness_wavelength_mm, 3.0, 40.0)
        check_range(NAME, "waviness_phase_deg", self.waviness_phase_deg, -180.0, 180.0)
        if (isinstance(self.lobes, bool) or not isinstance(self.lobes, int)
                or not 2 <= self.lobes <= 12):
            raise ValueError(f"{NAME}: lobes must be an integer in [2, 12], got {self.lobes!r}")
        check_range(NAME, "lobe_amplitude_mm", self.lobe_amplitude_mm, 0.0, 0.2)
        check_range(NAME, "lobe_angle_deg", self.lobe_angle_deg, -180.0, 180.0)
        check_range(NAME, "length_mm", self.length_mm, 2.0 * ZONE_HALF_MM + 2.0, 200.0)
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-4, 0.01)
        check_less(NAME, "wall_mm + waviness_amplitude_mm + lobe_amplitude_mm",
                   self.wall_mm + self.waviness_amplitude_mm + self.lobe_amplitude_mm,
                   "outer_diameter_mm/2", self.outer_diameter_mm / 2.0)
        get_material(self.material)

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        NaN beyond the pipe ends (``|z| > length_mm / 2``).
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        wave = self.waviness_amplitude_mm * np.cos(
            2.0 * np.pi * z / self.waviness_wavelength_mm + math.radians(self.waviness_phase_deg))
        lobe = self.lobe_amplitude_mm * np.cos(
            self.lobes * (theta - math.radians(self.lobe_angle_deg)))
        r = self.outer_diameter_mm / 2.0 + wave + lobe
        return np.where(np.abs(z) <= self.length_mm / 2.0, r, np.nan)

    def inner_radius(self, theta_rad, z_mm):
        """Inner radius (mm): the outer radius minus the wall thickness."""
        return self.radius(theta_rad, z_mm) - self.wall_mm

    def _resolution(self) -> tuple[int, float]:
        """(n_theta, axial step in the measured zone, mm) meeting ``mesh_tolerance_mm``.

        The shape is a sum of a function of θ and a function of z, so the radial error of a
        grid triangle is bounded by ``(K_s Δs² + K_z Δz²) / 8``: ``K_s`` is the largest
        curvature of a cross-section (dense θ grid), ``K_z = A_w (2π/λ)²``.  Each direction
        gets half the budget.
        """
        R = self.outer_diameter_mm / 2.0
        n, q = self.lobes, self.lobe_amplitude_mm
        a = n * np.linspace(0.0, 2.0 * np.pi / n, 4097)
        r_eq = 0.0
        for w in (-self.waviness_amplitude_mm, self.waviness_amplitude_mm):
            r = R + w + q * np.cos(a)
            r1 = -n * q * np.sin(a)
            r2 = -n * n * q * np.cos(a)
            r_eq = max(r_eq, chord_radius_mm(r, r1, r2))
        budget = MESH_SAFETY * self.mesh_tolerance_mm / 2.0
        n_theta = n_theta_for_tolerance(r_eq, budget)
        k_z = self.waviness_amplitude_mm * (2.0 * np.pi / self.waviness_wavelength_mm) ** 2
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
            description=(f"aluminium pipe Ø{self.outer_diameter_mm} mm with undulations "
                         f"(±{self.waviness_amplitude_mm} mm / {self.waviness_wavelength_mm} mm, "
                         f"{self.lobes} lobes ±{self.lobe_amplitude_mm} mm)"))


register(ObjectType(NAME, "Ø22 mm aluminium pipe with undulations (paper Fig. 12)",
                    AluPipeParams, aliases={"od": "outer_diameter_mm", "d": "outer_diameter_mm",
                                            "wall": "wall_mm",
                                            "wave": "waviness_amplitude_mm",
                                            "wavelength": "waviness_wavelength_mm",
                                            "lobe": "lobe_amplitude_mm",
                                            "length": "length_mm",
                                            "tol": "mesh_tolerance_mm"}))

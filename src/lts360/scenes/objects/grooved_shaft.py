"""Ø13 mm black-oxide steel shaft with a helical groove (paper §4.6, Fig. 13).

A single-start helical groove of lead ``L`` is cut into a cylinder of radius ``R``.  In every
axial section (a half-plane through the axis) the groove is a circular arc of radius ``ρ``,
width ``w`` at the surface and depth ``t`` (``ρ = (w²/4 + t²) / (2t)``).  The shape is
helically invariant::

    r(θ, z) = f(θ − τ z − φ_0),   τ = ±2π / L   (+ for a right-hand groove)

with ``f(φ) = R − t + ρ − sqrt(ρ² − u²)`` for ``|u| < w/2`` and ``R`` elsewhere, where
``u = L · wrap(φ) / (2π)`` is the axial distance to the groove centre line.  ``f`` has a kink
at each groove edge ``φ = ±π w / L``.

The mesh uses the twisted grid of :func:`~lts360.scenes.objects.mesher.star_mesh` (grid lines
of constant ``ψ = φ`` are helices of constant radius, the groove edges lie on two of them).
Grid and mesh come from :func:`~lts360.scenes.objects.mesher.helical_resolution` and
:func:`~lts360.scenes.objects.mesher.helical_star_mesh`, shared with the stranded cable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_less, check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import helical_resolution, helical_star_mesh
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register
from lts360.scenes.objects.zoned import MESH_SAFETY, zone_half_mm

__all__ = ["GroovedShaftParams"]

NAME = "grooved-shaft"
#: The paper's scan of this object (Fig. 13).
SECTIONS = 20
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = zone_half_mm(SECTIONS, PITCH_MM)
#: Dense samples per smooth piece of a profile, to measure its curvature.
_DENSE = 4001
_HANDEDNESS = ("right", "left")


# --- the grooved shaft -------------------------------------------------------------------------

@dataclass(frozen=True)
class GroovedShaftParams:
    """Black-oxide steel shaft with a single-start helical groove of circular-arc profile.

    Attributes
    ----------
    diameter_mm : float, [5, 40]
        Shaft diameter ``2R`` (paper: 13 mm).
    groove_lead_mm : float, [4, 100]
        Lead ``L`` of the groove (axial advance per turn); larger than ``groove_width_mm``.
    groove_width_mm : float, [0.2, 5]
        Width ``w`` of the groove at the shaft surface, measured along the axis.
    groove_depth_mm : float, [0.02, 0.4 w]
        Depth ``t`` of the groove; at most ``0.4 w`` so that the arc (radius
        ``ρ = (w²/4 + t²) / (2t)``) meets the surface at less than 78° and the surface stays a
        function ``r(θ, z)`` with bounded slope.
    handedness : str, {"right", "left"}
        Hand of the helix; right-hand advances along +z when turning counter-clockwise.
    groove_phase_deg : float, [-180, 180]
        Angle ``φ_0`` at which the groove centre line crosses ``z = 0``.
    length_mm : float, [2·ZONE_HALF_MM + 2, 200]
        Shaft length, centred on ``z = 0``.
    mesh_tolerance_mm : float, [1e-4, 0.01]
        Largest allowed radial distance between mesh and true surface in the measured zone.
    material : str
        Material preset name.
    """

    diameter_mm: float = 13.0
    groove_lead_mm: float = 6.0
    groove_width_mm: float = 1.5
    groove_depth_mm: float = 0.4
    handedness: str = "right"
    groove_phase_deg: float = 0.0
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.001
    material: str = "black-oxide-steel"

    def __post_init__(self) -> None:
        check_range(NAME, "diameter_mm", self.diameter_mm, 5.0, 40.0)
        check_range(NAME, "groove_lead_mm", self.groove_lead_mm, 4.0, 100.0)
        check_range(NAME, "groove_width_mm", self.groove_width_mm, 0.2, 5.0)
        check_less(NAME, "groove_width_mm", self.groove_width_mm, "groove_lead_mm",
                   self.groove_lead_mm)
        check_range(NAME, "groove_depth_mm", self.groove_depth_mm, 0.02,
                    0.4 * self.groove_width_mm)
        if self.handedness not in _HANDEDNESS:
            raise ValueError(f"{NAME}: handedness must be one of {', '.join(_HANDEDNESS)}, "
                             f"got {self.handedness!r}")
        check_range(NAME, "groove_phase_deg", self.groove_phase_deg, -180.0, 180.0)
        check_range(NAME, "length_mm", self.length_mm, 2.0 * ZONE_HALF_MM + 2.0, 200.0)
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-4, 0.01)
        get_material(self.material)

    @property
    def twist_rad_per_mm(self) -> float:
        """``τ = ±2π / L``, positive for a right-hand groove."""
        sign = 1.0 if self.handedness == "right" else -1.0
        return sign * 2.0 * math.pi / self.groove_lead_mm

    @property
    def arc_radius_mm(self) -> float:
        """Radius ``ρ`` of the groove arc in the axial section."""
        w, t = self.groove_width_mm, self.groove_depth_mm
        return (w * w / 4.0 + t * t) / (2.0 * t)

    @property
    def groove_half_angle_rad(self) -> float:
        """Half-width of the groove in ``φ``: the kinks are at ``φ_0 ± π w / L``."""
        return math.pi * self.groove_width_mm / self.groove_lead_mm

    def profile(self, phi_rad):
        """Section profile ``f(φ)`` (mm) at ``φ = θ − τ z`` (rad, any range)."""
        phi = np.asarray(phi_rad, dtype=float) - math.radians(self.groove_phase_deg)
        wrapped = np.mod(phi + np.pi, 2.0 * np.pi) - np.pi
        u = np.abs(wrapped) * (self.groove_lead_mm / (2.0 * np.pi))
        R, t, rho = self.diameter_mm / 2.0, self.groove_depth_mm, self.arc_radius_mm
        uu = np.minimum(u, self.groove_width_mm / 2.0)
        arc = R - t + rho - np.sqrt(np.maximum(rho * rho - uu * uu, 0.0))
        return np.where(u < self.groove_width_mm / 2.0, arc, R)

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        NaN beyond the shaft ends (``|z| > length_mm / 2``).
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        r = self.profile(theta - self.twist_rad_per_mm * z)
        return np.where(np.abs(z) <= self.length_mm / 2.0, r, np.nan)

    def _pieces(self):
        """Dense samples ``(s, φ, f)`` of the two smooth pieces of the profile: the groove
        arc and the cylinder, between the kinks at ``φ_0 ± π w / L``."""
        a = self.groove_half_angle_rad
        phi0 = math.radians(self.groove_phase_deg)
        groove = np.linspace(phi0 - a, phi0 + a, _DENSE)
        cylinder = np.linspace(phi0 + a, phi0 + 2.0 * np.pi - a, _DENSE)
        return [(x, x, self.profile(x)) for x in (groove, cylinder)]

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Mesh the shaft and return it with its analytic truth.

        Parameters
        ----------
        placement : Placement
            Pose of the shaft in the world.

        Returns
        -------
        SceneObject
        """
        tau = self.twist_rad_per_mm
        phi, dz = helical_resolution(self._pieces(), tau, MESH_SAFETY * self.mesh_tolerance_mm)
        h = self.length_mm / 2.0
        z = np.linspace(-h, h, math.ceil(self.length_mm / dz - 1e-9) + 1)
        mesh = helical_star_mesh(self.profile, phi, z, tau)
        zone = ZONE_HALF_MM
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=mesh, placement=placement, material=get_material(self.material),
            radius_fn=self.radius, measured_zone_z_mm=(-zone, zone),
            mesh_tolerance_mm=self.mesh_tolerance_mm, sections=SECTIONS, pitch_mm=PITCH_MM,
            description=(f"shaft Ø{self.diameter_mm} mm with a {self.handedness}-hand helical "
                         f"groove, lead {self.groove_lead_mm} mm, {self.groove_width_mm} × "
                         f"{self.groove_depth_mm} mm"),
            notes={"n_theta": int(phi.size), "n_z": int(z.size), "dz_mm": float(z[1] - z[0]),
                   "twist_rad_per_mm": tau, "arc_radius_mm": self.arc_radius_mm,
                   "groove_edges_phi_rad": (math.radians(self.groove_phase_deg)
                                            - self.groove_half_angle_rad,
                                            math.radians(self.groove_phase_deg)
                                            + self.groove_half_angle_rad),
                   "lead_angle_deg": math.degrees(math.atan2(self.groove_lead_mm,
                                                              math.pi * self.diameter_mm))})


register(ObjectType(NAME, "Ø13 mm black-oxide shaft with a helical groove (paper Fig. 13)",
                    GroovedShaftParams, aliases={"d": "diameter_mm", "lead": "groove_lead_mm",
                                                 "width": "groove_width_mm",
                                                 "depth": "groove_depth_mm",
                                                 "hand": "handedness",
                                                 "phase": "groove_phase_deg",
                                                 "length": "length_mm",
                                                 "tol": "mesh_tolerance_mm"}))

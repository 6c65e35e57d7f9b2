"""Ø25 mm shaft with an undercut (paper §4.6, Fig. 17): a DIN 509-like groove.

The groove is rotationally symmetric, ``r(θ, z) = f(|z − z_g|)``, with (from the middle out)
a flat bottom at depth ``t``, a circular fillet of radius ``ρ`` tangent to the bottom, and a
straight flank tangent to the fillet, inclined at ``γ`` to the axis, that meets the shaft
surface at the groove edge ``|z − z_g| = w / 2`` (a kink).  When the fillet reaches the
surface before its tangent reaches ``γ`` there is no flank and the fillet meets the surface
directly.  ``f`` is continuous, C¹ except at the groove edges, and piecewise exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import n_theta_for_tolerance, star_mesh, z_grid
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register
from lts360.scenes.objects.zoned import MESH_SAFETY, zone_half_mm

NAME = "undercut-shaft"
#: The paper's scan of this object (Fig. 17).
SECTIONS = 25
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = zone_half_mm(SECTIONS, PITCH_MM)
#: Largest axial step where the profile is straight (keeps the triangles' aspect moderate).
_MAX_STEP_MM = 2.0
#: Widest groove accepted.
_MAX_WIDTH_MM = 10.0


def fillet_end_angle_rad(depth_mm: float, fillet_radius_mm: float, flank_angle_deg: float) -> float:
    """Angle φ_e (from the groove bottom, rad) at which a fillet ends: where its tangent reaches
    the flank angle, or where it reaches the shaft surface if that comes first."""
    gamma = math.radians(flank_angle_deg)
    if fillet_radius_mm * (1.0 - math.cos(gamma)) >= depth_mm:
        return math.acos(1.0 - depth_mm / fillet_radius_mm)
    return gamma


def min_groove_width_mm(depth_mm: float, fillet_radius_mm: float, flank_angle_deg: float) -> float:
    """Narrowest groove (mm, at the surface) with this depth, fillet radius and flank angle:
    twice the axial run of fillet plus flank, i.e. a flat bottom of zero width."""
    phi_e = fillet_end_angle_rad(depth_mm, fillet_radius_mm, flank_angle_deg)
    flank_rise = depth_mm - fillet_radius_mm * (1.0 - math.cos(phi_e))
    run = fillet_radius_mm * math.sin(phi_e) + max(flank_rise, 0.0) / math.tan(
        math.radians(flank_angle_deg))
    return 2.0 * run


@dataclass(frozen=True)
class UndercutShaftParams:
    """Ground steel shaft with a DIN 509-like undercut.

    Attributes
    ----------
    diameter_mm : float, [5, 60]
        Shaft diameter ``2R`` (paper: 25 mm).
    groove_width_mm : float, [w_min, 10]
        Groove width ``w`` at the shaft surface; ``w_min`` = :func:`min_groove_width_mm`
        (zero-width flat bottom).
    groove_depth_mm : float, [0.05, 2]
        Depth ``t`` of the flat bottom below the surface.
    fillet_radius_mm : float, [0.1, 5]
        Radius ``ρ`` of the fillets at the bottom corners.
    flank_angle_deg : float, [10, 80]
        Angle ``γ`` between the straight flanks and the shaft axis.
    groove_z_mm : float, [-(length_mm − w)/2 + 1, (length_mm − w)/2 − 1]
        Axial position ``z_g`` of the groove centre.
    length_mm : float, [2·ZONE_HALF_MM + 2, 200]
        Shaft length, centred on ``z = 0``.
    mesh_tolerance_mm : float, [1e-4, 0.01]
        Largest allowed radial distance between mesh and true surface in the measured zone.
    material : str
        Material preset name.
    """

    diameter_mm: float = 25.0
    groove_width_mm: float = 3.0
    groove_depth_mm: float = 0.4
    fillet_radius_mm: float = 0.6
    flank_angle_deg: float = 45.0
    groove_z_mm: float = 0.0
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.001
    material: str = "ground-steel"

    def __post_init__(self) -> None:
        check_range(NAME, "diameter_mm", self.diameter_mm, 5.0, 60.0)
        check_range(NAME, "groove_depth_mm", self.groove_depth_mm, 0.05, 2.0)
        check_range(NAME, "fillet_radius_mm", self.fillet_radius_mm, 0.1, 5.0)
        check_range(NAME, "flank_angle_deg", self.flank_angle_deg, 10.0, 80.0)
        w_min = min_groove_width_mm(self.groove_depth_mm, self.fillet_radius_mm,
                                    self.flank_angle_deg)
        if w_min > _MAX_WIDTH_MM:
            raise ValueError(f"{NAME}: groove_depth_mm, fillet_radius_mm and flank_angle_deg need "
                             f"a groove_width_mm of at least {w_min:g}, above the largest "
                             f"allowed ({_MAX_WIDTH_MM:g})")
        check_range(NAME, "groove_width_mm", self.groove_width_mm, w_min, _MAX_WIDTH_MM)
        check_range(NAME, "length_mm", self.length_mm, 2.0 * ZONE_HALF_MM + 2.0, 200.0)
        g = (self.length_mm - self.groove_width_mm) / 2.0 - 1.0
        check_range(NAME, "groove_z_mm", self.groove_z_mm, -g, g)
        check_range(NAME, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-4, 0.01)
        get_material(self.material)

    def _fillet_end_angle_rad(self) -> float:
        return fillet_end_angle_rad(self.groove_depth_mm, self.fillet_radius_mm,
                                    self.flank_angle_deg)

    def profile_breaks_mm(self) -> tuple[float, float, float]:
        """Distances from the groove centre ``(u_c, u_e, w/2)``: end of the flat bottom, end
        of the fillet, groove edge (``u_e == w/2`` when there is no flank)."""
        phi_e = self._fillet_end_angle_rad()
        a = self.groove_width_mm / 2.0
        u_c = a - min_groove_width_mm(self.groove_depth_mm, self.fillet_radius_mm,
                                      self.flank_angle_deg) / 2.0
        u_e = min(u_c + self.fillet_radius_mm * math.sin(phi_e), a)
        return u_c, u_e, a

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        NaN beyond the shaft ends (``|z| > length_mm / 2``).
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        R, t, rho = self.diameter_mm / 2.0, self.groove_depth_mm, self.fillet_radius_mm
        u_c, u_e, a = self.profile_breaks_mm()
        u = np.abs(z - self.groove_z_mm)
        v = np.clip(u - u_c, 0.0, rho)
        fillet = R - t + rho - np.sqrt(np.maximum(rho * rho - v * v, 0.0))
        flank = R - (a - u) * math.tan(math.radians(self.flank_angle_deg))
        r = np.where(u >= a, R, np.where(u >= u_e, flank, np.where(u >= u_c, fillet, R - t)))
        r = np.broadcast_to(r, np.broadcast(theta, z).shape)
        return np.where(np.abs(z) <= self.length_mm / 2.0, r, np.nan)

    def _resolution(self) -> tuple[int, float]:
        """(n_theta, axial step on the fillets, mm) meeting ``mesh_tolerance_mm``.

        Radial error of a grid triangle ≤ chord sagitta ``R (1 − cos(π/n))`` plus the axial
        interpolation error ``|f''| Δz² / 8`` with ``|f''| ≤ 1 / (ρ cos³ φ_e)`` on a fillet
        (zero elsewhere: the profile is straight); each gets half the budget.
        """
        budget = MESH_SAFETY * self.mesh_tolerance_mm / 2.0
        n_theta = n_theta_for_tolerance(self.diameter_mm / 2.0, budget)
        f2 = 1.0 / (self.fillet_radius_mm * math.cos(self._fillet_end_angle_rad()) ** 3)
        return n_theta, math.sqrt(8.0 * budget / f2)

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
        n_theta, dz = self._resolution()
        psi = np.arange(n_theta) * (2.0 * np.pi / n_theta)
        h, zg = self.length_mm / 2.0, self.groove_z_mm
        u_c, u_e, a = self.profile_breaks_mm()
        knots = np.unique([-h, zg - a, zg - u_e, zg - u_c, zg + u_c, zg + u_e, zg + a, h])
        fillets = {(zg - u_e, zg - u_c), (zg + u_c, zg + u_e)}
        z = np.unique(np.concatenate([
            z_grid(lo, hi, dz if (lo, hi) in fillets else _MAX_STEP_MM)
            for lo, hi in zip(knots[:-1], knots[1:])]))
        mesh = star_mesh(self.radius, psi, z)
        zone = ZONE_HALF_MM
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=mesh, placement=placement, material=get_material(self.material),
            radius_fn=self.radius, measured_zone_z_mm=(-zone, zone),
            mesh_tolerance_mm=self.mesh_tolerance_mm, sections=SECTIONS, pitch_mm=PITCH_MM,
            description=(f"shaft Ø{self.diameter_mm} mm with undercut {self.groove_width_mm} × "
                         f"{self.groove_depth_mm} mm, fillets R{self.fillet_radius_mm}"),
            notes={"n_theta": n_theta, "n_z": int(z.size), "dz_fillet_mm": dz,
                   "profile_breaks_z_mm": tuple(float(k) for k in knots[1:-1])})


register(ObjectType(NAME, "Ø25 mm shaft with a DIN 509-like undercut (paper Fig. 17)",
                    UndercutShaftParams, aliases={"d": "diameter_mm", "width": "groove_width_mm",
                                                  "depth": "groove_depth_mm",
                                                  "fillet": "fillet_radius_mm",
                                                  "flank": "flank_angle_deg",
                                                  "length": "length_mm",
                                                  "tol": "mesh_tolerance_mm"}))

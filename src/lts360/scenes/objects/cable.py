"""Stranded aluminium distribution cables (paper §4.6, Figs. 14–15): Ø6 mm and Ø8 mm.

Concentric-lay conductor (AAC / ACSR-like) of ``n`` layers: 7 = 1+6, 19 = 1+6+12 or
37 = 1+6+12+18 round wires.  Only the outer layer is visible: ``N = 6 (n − 1)`` wires, each
a tube of radius ``ρ`` around the helix ``H_k(t) = (R cos(t + β_k), R sin(t + β_k), c t)``
with ``c = ±λ / 2π`` (lay length ``λ``, + for a right-hand lay) and ``β_k = β_0 + 2πk/N``.
Inner layers and the voids between wires are filled (invisible).

Wire size.  The outer wires would just touch their neighbours if they were straight
(``ρ = R sin(π / N)``) and they reach the overall diameter (``R + ρ = d / 2``), so
``ρ = (d/2) s / (1 + s)`` with ``s = sin(π / N)``.  For 7 wires this is the equal-wire
conductor, ``2ρ = d / 3``; for 19 and 37 wires the outer wires come out 2.8 % and 3.6 %
thicker than ``d / (2n − 1)``, which closes the outer layer (as in a compacted conductor;
with equal wires the outer layer of a 19- or 37-wire conductor has gaps).  Because
the oblique cut of a helical wire is ``1 / cos α`` wider than the wire (lay angle ``α``),
neighbours then overlap slightly in every section ``z = const`` and the envelope is
continuous, with a cusp half-way between wires.

Truth.  The visible surface is the outer envelope: ``r(θ, z)`` is the largest ``r`` such that
``(r cos θ, r sin θ, z)`` lies within ``ρ`` of some helix.  It is helically invariant,
``r = f(θ − τ z − β_0)`` with ``τ = 1 / c = ±2π / λ``, and ``f`` is even and
``2π/N``-periodic (the same ``f`` for both lay directions).  The squared distance from the
point ``(r, φ, 0)`` to ``H_0(t)`` (``β_0 = 0``) is ``r² + R² − 2 r R cos(t − φ) + c² t²``,
convex in ``t`` since ``c² > r R`` (true for any lay ratio ≥ 4), so the section's boundary
points are exactly ``P = H_0(t) + ρ (cos ω e_r + sin ω b)`` (``e_r`` radial,
``b`` binormal) with ``P_z = 0``, i.e. ``t = −ρ R sin ω / (c L)``, ``L = sqrt(R² + c²)``::

    f = sqrt((R + ρ cos ω)² + (c ρ sin ω / L)²),
    φ = Θ(ω) = ρ R sin ω / (c L) + atan2(c ρ sin ω / L, R + ρ cos ω)     (c > 0)

on the outer branch ``0 ≤ ω ≤ ω_cusp`` (``Θ(ω_cusp) = π / N``).  ``Θ(ω) = |φ|`` has no
closed form; it is solved by safeguarded Newton iterations to machine precision.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import helical_resolution, helical_star_mesh
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register
from lts360.scenes.objects.zoned import MESH_SAFETY

__all__ = ["CableParams", "StrandSection"]

NAME = "cable"
#: Registered names and the paper's scan of each (sections, pitch_mm); ``cable`` is the
#: generic entry with the defaults of ``cable-8``.
SCANS = {"cable": (39, 0.34), "cable-6": (40, 0.34), "cable-8": (39, 0.34)}
#: Number of layers (centre wire included) of each allowed strand count.
LAYERS = {7: 2, 19: 3, 37: 4}
#: Dense samples of one wire's profile, to measure its curvature.
_DENSE = 4001
#: Newton iterations on ``Θ(ω) = |φ|`` (quadratic convergence from a tabulated guess; a
#: handful suffice, the cap only guards the bisection fallback).
_NEWTON_MAX = 60
_LAY_DIRECTIONS = ("right", "left")


def zone_half_mm(preset: str) -> float:
    """Half-length of the measured zone: the paper's scan centred on z = 0 plus 0.5 mm."""
    sections, pitch = SCANS[preset]
    return (sections - 1) * pitch / 2.0 + 0.5


@dataclass(frozen=True)
class StrandSection:
    """Section ``z = 0`` of one outer wire and the envelope ``f(φ)`` it makes.

    Attributes
    ----------
    helix_radius_mm : float
        ``R``, radius of the wire axis.
    wire_radius_mm : float
        ``ρ``.
    c_mm_per_rad : float, >0
        ``|c| = λ / 2π``.
    n_wires : int
        ``N``, wires in the outer layer.
    omega_tangent_rad : float
        ``ω`` where the ray from the axis grazes the wire section (``Θ`` is largest).
    omega_cusp_rad : float
        ``ω`` of the cusp, ``Θ(ω_cusp) = π / N``.
    """

    helix_radius_mm: float
    wire_radius_mm: float
    c_mm_per_rad: float
    n_wires: int
    omega_tangent_rad: float
    omega_cusp_rad: float

    @staticmethod
    def make(helix_radius_mm: float, wire_radius_mm: float, c_mm_per_rad: float,
             n_wires: int) -> "StrandSection":
        """Solve for the grazing and cusp angles; ``ValueError`` if neighbours do not overlap."""
        R, rho, c = helix_radius_mm, wire_radius_mm, c_mm_per_rad
        probe = StrandSection(R, rho, c, n_wires, math.pi, math.pi)

        def d_theta(w):
            return float(probe.theta_derivative(w))

        # Θ' > 0 at ω = π/2 and Θ' < 0 at ω = π: the grazing ray is in between.
        w_tan = brentq(d_theta, math.pi / 2.0, math.pi, xtol=1e-15)
        if not float(probe.theta(w_tan)) > math.pi / n_wires:
            raise ValueError(f"{NAME}: neighbouring outer wires do not overlap (lay too long for "
                             f"the wire size)")
        w_cusp = brentq(lambda w: float(probe.theta(w)) - math.pi / n_wires, 0.0, w_tan,
                        xtol=1e-15)
        return StrandSection(R, rho, c, n_wires, w_tan, w_cusp)

    def _ab(self):
        R, rho, c = self.helix_radius_mm, self.wire_radius_mm, self.c_mm_per_rad
        L = math.hypot(R, c)
        return rho * R / (c * L), c * rho / L

    def theta(self, omega_rad):
        """``Θ(ω)`` (rad): angle of the boundary point ``ω`` of the section ``z = 0``."""
        R, rho = self.helix_radius_mm, self.wire_radius_mm
        a, b = self._ab()
        w = np.asarray(omega_rad, dtype=float)
        return a * np.sin(w) + np.arctan2(b * np.sin(w), R + rho * np.cos(w))

    def theta_derivative(self, omega_rad):
        """``dΘ/dω``."""
        R, rho = self.helix_radius_mm, self.wire_radius_mm
        a, b = self._ab()
        w = np.asarray(omega_rad, dtype=float)
        return a * np.cos(w) + b * (R * np.cos(w) + rho) / self.radius(w) ** 2

    def radius(self, omega_rad):
        """Distance (mm) from the axis of the boundary point ``ω``."""
        R, rho = self.helix_radius_mm, self.wire_radius_mm
        _, b = self._ab()
        w = np.asarray(omega_rad, dtype=float)
        return np.hypot(R + rho * np.cos(w), b * np.sin(w))

    def omega_of(self, phi_abs_rad):
        """``ω ∈ [0, ω_cusp]`` with ``Θ(ω) = φ`` for ``φ ∈ [0, π/N]`` (bracketed Newton)."""
        target = np.asarray(phi_abs_rad, dtype=float)
        table_w = np.linspace(0.0, self.omega_cusp_rad, 513)
        w = np.interp(target, self.theta(table_w), table_w)
        lo = np.zeros_like(target)
        hi = np.full_like(target, self.omega_cusp_rad)
        for _ in range(_NEWTON_MAX):
            resid = self.theta(w) - target
            lo = np.where(resid <= 0.0, w, lo)
            hi = np.where(resid >= 0.0, w, hi)
            step = resid / self.theta_derivative(w)
            new = w - step
            new = np.where((new > lo) & (new < hi), new, (lo + hi) / 2.0)
            done = np.abs(new - w) <= 4.0 * np.finfo(float).eps * np.maximum(1.0, np.abs(w))
            w = np.where(resid == 0.0, w, new)
            if np.all(done | (resid == 0.0)):
                break
        return w

    def profile(self, phi_rad):
        """Envelope ``f(φ)`` (mm), ``φ`` from the crest of a wire (any range)."""
        period = 2.0 * np.pi / self.n_wires
        phi = np.asarray(phi_rad, dtype=float)
        rel = np.abs(np.mod(phi + period / 2.0, period) - period / 2.0)
        return self.radius(self.omega_of(np.minimum(rel, np.pi / self.n_wires)))


@dataclass(frozen=True)
class CableParams:
    """Concentric-lay stranded aluminium conductor (visible outer layer, filled core).

    Attributes
    ----------
    diameter_mm : float, [3, 30]
        Overall diameter ``d`` over the crests of the outer wires (paper: 6 mm and 8 mm).
    strands : int, {7, 19, 37}
        Number of wires: 7 = 1+6, 19 = 1+6+12, 37 = 1+6+12+18.
    lay_ratio : float, [10, 16]
        Lay length of the outer layer over its diameter ``d`` (stranding standards: about
        10 to 16).
    lay_direction : str, {"right", "left"}
        Hand of the outer layer; right-hand ("Z") is the standard for the outer layer.
    strand_phase_deg : float, [-180, 180]
        Angle ``β_0`` of the crest of one outer wire at ``z = 0``.
    length_mm : float, [2·zone + 2, 200]
        Cable length, centred on ``z = 0`` (``zone``: half the measured zone of ``preset``).
    mesh_tolerance_mm : float, [1e-4, 0.01]
        Largest allowed radial distance between mesh and true surface in the measured zone.
    material : str
        Material preset name.
    preset : str, {"cable", "cable-6", "cable-8"}
        Registered name the object reports (set by the registry entry); selects the paper's
        scan: ``cable-6`` 40 sections, ``cable-8`` and ``cable`` 39 sections, 0.34 mm pitch.
    """

    diameter_mm: float = 8.0
    strands: int = 7
    lay_ratio: float = 13.0
    lay_direction: str = "right"
    strand_phase_deg: float = 0.0
    length_mm: float = 30.0
    mesh_tolerance_mm: float = 0.001
    material: str = "weathered-aluminium"
    preset: str = "cable"

    def __post_init__(self) -> None:
        if self.preset not in SCANS:
            raise ValueError(f"{NAME}: preset must be one of {', '.join(SCANS)}, got "
                             f"{self.preset!r}")
        check_range(self.preset, "diameter_mm", self.diameter_mm, 3.0, 30.0)
        if (isinstance(self.strands, bool) or not isinstance(self.strands, numbers.Integral)
                or self.strands not in LAYERS):
            raise ValueError(f"{self.preset}: strands must be one of 7, 19, 37 (1+6, 1+6+12, "
                             f"1+6+12+18), got {self.strands!r}")
        check_range(self.preset, "lay_ratio", self.lay_ratio, 10.0, 16.0)
        if self.lay_direction not in _LAY_DIRECTIONS:
            raise ValueError(f"{self.preset}: lay_direction must be one of "
                             f"{', '.join(_LAY_DIRECTIONS)}, got {self.lay_direction!r}")
        check_range(self.preset, "strand_phase_deg", self.strand_phase_deg, -180.0, 180.0)
        check_range(self.preset, "length_mm", self.length_mm,
                    2.0 * zone_half_mm(self.preset) + 2.0, 200.0)
        check_range(self.preset, "mesh_tolerance_mm", self.mesh_tolerance_mm, 1e-4, 0.01)
        get_material(self.material)
        self.section()  # the outer layer must close

    # --- derived geometry ------------------------------------------------------------------

    @property
    def layers(self) -> int:
        """Layers, the centre wire included."""
        return LAYERS[self.strands]

    @property
    def outer_wires(self) -> int:
        """``N = 6 (layers − 1)``."""
        return 6 * (self.layers - 1)

    @property
    def wire_radius_mm(self) -> float:
        """``ρ = (d/2) s / (1 + s)``, ``s = sin(π / N)``: outer wires touch and reach ``d/2``."""
        s = math.sin(math.pi / self.outer_wires)
        return self.diameter_mm / 2.0 * s / (1.0 + s)

    @property
    def helix_radius_mm(self) -> float:
        """``R = d/2 − ρ``, radius of the outer wires' axes."""
        return self.diameter_mm / 2.0 - self.wire_radius_mm

    @property
    def lay_length_mm(self) -> float:
        """``λ = lay_ratio · d``."""
        return self.lay_ratio * self.diameter_mm

    @property
    def twist_rad_per_mm(self) -> float:
        """``τ = ±2π / λ``, positive for a right-hand lay."""
        sign = 1.0 if self.lay_direction == "right" else -1.0
        return sign * 2.0 * math.pi / self.lay_length_mm

    @property
    def lay_angle_deg(self) -> float:
        """Angle between the outer wires' axes and the cable axis, ``atan(2π R / λ)``."""
        return math.degrees(math.atan2(2.0 * math.pi * self.helix_radius_mm, self.lay_length_mm))

    def section(self) -> StrandSection:
        """The outer wire's section and envelope (independent of the lay direction)."""
        return StrandSection.make(self.helix_radius_mm, self.wire_radius_mm,
                                  self.lay_length_mm / (2.0 * math.pi), self.outer_wires)

    # --- truth ---------------------------------------------------------------------------

    def radius(self, theta_rad, z_mm):
        """True outer radius (mm) at ``theta_rad``, ``z_mm`` (object frame, broadcast arrays).

        NaN beyond the cable ends (``|z| > length_mm / 2``).
        """
        theta = np.asarray(theta_rad, dtype=float)
        z = np.asarray(z_mm, dtype=float)
        phi = theta - self.twist_rad_per_mm * z - math.radians(self.strand_phase_deg)
        r = self.section().profile(phi)
        return np.where(np.abs(z) <= self.length_mm / 2.0, r, np.nan)

    # --- mesh ----------------------------------------------------------------------------

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Mesh the envelope and return it with its truth.

        Parameters
        ----------
        placement : Placement
            Pose of the cable in the world.

        Returns
        -------
        SceneObject
        """
        sec = self.section()
        tau = self.twist_rad_per_mm
        # One wire, crest in the middle, cusps (kinks) at its ends; the other wires repeat it.
        w = np.linspace(-sec.omega_cusp_rad, sec.omega_cusp_rad, _DENSE)
        phi_w = sec.theta(w)
        phi_w[0], phi_w[-1] = -math.pi / sec.n_wires, math.pi / sec.n_wires
        one, dz = helical_resolution([(w, phi_w, sec.radius(w))], tau,
                                     MESH_SAFETY * self.mesh_tolerance_mm)
        period = 2.0 * math.pi / sec.n_wires
        phi0 = math.radians(self.strand_phase_deg)
        nodes = (phi0 + (np.arange(sec.n_wires) * period)[:, None] + one[None, :]).ravel()
        h = self.length_mm / 2.0
        z = np.linspace(-h, h, math.ceil(self.length_mm / dz - 1e-9) + 1)
        mesh = helical_star_mesh(lambda phi: sec.profile(phi - phi0), nodes, z, tau)
        zone = zone_half_mm(self.preset)
        sections, pitch = SCANS[self.preset]
        rho = self.wire_radius_mm
        return SceneObject(
            name=self.preset, spec=canonical_spec(self.preset, self, placement),
            params=self.__dict__.copy(), mesh_object=mesh, placement=placement,
            material=get_material(self.material), radius_fn=self.radius,
            measured_zone_z_mm=(-zone, zone), mesh_tolerance_mm=self.mesh_tolerance_mm,
            sections=sections, pitch_mm=pitch,
            description=(f"stranded aluminium cable Ø{self.diameter_mm} mm, {self.strands} wires, "
                         f"{self.lay_direction}-hand lay {self.lay_length_mm:g} mm"),
            notes={"strand_diameter_mm": 2.0 * rho,
                   "nominal_strand_diameter_mm": self.diameter_mm / (2 * self.layers - 1),
                   "inner_strand_diameter_mm": 2.0 * (self.helix_radius_mm - rho)
                   / (2 * self.layers - 3),
                   "layers": self.layers, "outer_wires": sec.n_wires,
                   "lay_length_mm": self.lay_length_mm, "lay_angle_deg": self.lay_angle_deg,
                   "helix_radius_mm": self.helix_radius_mm,
                   "cusp_radius_mm": float(sec.radius(sec.omega_cusp_rad)),
                   "twist_rad_per_mm": tau, "n_theta": int(nodes.size), "n_z": int(z.size),
                   "dz_mm": float(z[1] - z[0])})


_ALIASES = {"d": "diameter_mm", "lay": "lay_ratio", "direction": "lay_direction",
            "phase": "strand_phase_deg", "length": "length_mm", "tol": "mesh_tolerance_mm"}

register(ObjectType("cable", "Stranded aluminium cable, generic (defaults of cable-8)",
                    CableParams, aliases=_ALIASES))
register(ObjectType("cable-6", "Ø6 mm stranded aluminium distribution cable (paper Fig. 14)",
                    CableParams, aliases=_ALIASES,
                    defaults={"diameter_mm": 6.0, "preset": "cable-6"}))
register(ObjectType("cable-8", "Ø8 mm stranded aluminium distribution cable (paper Fig. 15)",
                    CableParams, aliases=_ALIASES, defaults={"preset": "cable-8"}))

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
This module also holds the two helpers shared with the stranded cable
(:mod:`lts360.scenes.objects.cable`): :func:`helical_resolution` (grid nodes and axial step
from the curvature of a profile) and :func:`helical_star_mesh` (a twisted star mesh whose
quads are always split along the short diagonal of the twisted grid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import trimesh
from scipy.ndimage import maximum_filter1d

from lts360.scenes.materials import get_material
from lts360.scenes.objects._params import check_less, check_range
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import star_mesh
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register

__all__ = ["GroovedShaftParams", "helical_resolution", "helical_star_mesh"]

NAME = "grooved-shaft"
#: The paper's scan of this object (Fig. 13).
SECTIONS = 20
PITCH_MM = 0.68
#: Half-length of the measured zone: the scan centred on z = 0 plus 0.5 mm either side.
ZONE_HALF_MM = (SECTIONS - 1) * PITCH_MM / 2.0 + 0.5
#: Share of ``mesh_tolerance_mm`` given to the second-order error bound of
#: :func:`helical_resolution`; the rest covers higher-order terms.
_SAFETY = 0.9
#: Dense samples per smooth piece of a profile, to measure its curvature.
_DENSE = 4001
_HANDEDNESS = ("right", "left")


# --- helpers shared with the stranded cable --------------------------------------------------

def _profile_derivatives(s, phi, f):
    """``(f', f'')`` with respect to ``φ`` from dense samples along a parameter ``s``."""
    phi_s = np.gradient(phi, s, edge_order=2)
    phi_ss = np.gradient(phi_s, s, edge_order=2)
    f_s = np.gradient(f, s, edge_order=2)
    f_ss = np.gradient(f_s, s, edge_order=2)
    return f_s / phi_s, (f_ss * phi_s - f_s * phi_ss) / phi_s ** 3


def _first_crossing(a, b, c):
    """Smallest positive root of ``a x² + b x + c`` (``a > 0``), elementwise; inf if none."""
    disc = b * b - 4.0 * a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    roots = np.stack([(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)])
    roots = np.where((disc >= 0.0) & (roots > 0.0), roots, np.inf)
    return roots.min(axis=0)


def helical_resolution(pieces, twist_rad_per_mm: float, budget_mm: float):
    """Nodes ``φ_i`` and axial step of a twisted grid for ``r = f(θ − τ z)``.

    The mesh is built by :func:`helical_star_mesh`: its triangles have a *section edge*
    (``Δφ``, same ``z``), a *helix edge* (same ``φ``, ``Δz``) and a *diagonal*
    ``(−Δφ, Δz)`` (sign for ``τ > 0``; the short diagonal, spanning ``Δθ = τ Δz − Δφ``).
    To second order the radial error at the middle of an edge ``(a, b)`` in ``(φ, z)`` is::

        m(a, b) = [E a² + 2 c τ a b + f τ² b²] / 8,
        E = f + 2 f'² / f − f'',   c = f + f'² / f

    (the chord of a curve ``X(s)`` lies ``X'' / 8`` off it; the radial error is that offset
    projected on ``∇(r − f(θ − τ z))``).  The rules, with ``B = budget_mm``:

    * section edges: nodes equidistribute ``sqrt(|E| / (8 · B/2))`` over each smooth
      piece, then any interval where ``|E| Δφ² / 8`` exceeds ``B/2`` at some sample is split
      evenly, so ``|m| ≤ B/2`` (the local ``|E|`` is the largest of five neighbouring
      samples);
    * helix edges: ``f_max τ² Δz² / 8 ≤ B/2`` (exactly: ``f (1 − cos(τ Δz / 2)) ≤ B/2``);
    * diagonals: ``Δz`` is cut at the first ``Δz`` where ``|m| = B`` for some sample of some
      interval.  Where the profile is steep (``|f'| ≫ f``) the cross term ``2 c τ Δφ Δz``
      dominates and this is the binding rule.

    The error inside a triangle is ``Σ 4 λ_i λ_j m_ij`` (``λ`` barycentric), at most ``B`` with
    these three bounds.

    Parameters
    ----------
    pieces : sequence of (s, phi_rad, f_mm)
        Smooth pieces of the profile (kinks only at their ends), each three equal 1-D arrays
        of dense samples: a uniformly spaced increasing parameter ``s`` (≥ 5 samples), the
        increasing angle ``φ(s)`` and the radius ``f(φ(s))``.  Together they cover one period.
    twist_rad_per_mm : float, ≠0
        ``τ`` of the shape.
    budget_mm : float, >0
        Second-order bound ``B`` on the radial error.

    Returns
    -------
    phi_nodes : (n,) float
        Node angles (rad); both ends of every piece are nodes.
    dz_mm : float
        Largest axial step meeting the three rules.
    """
    if not budget_mm > 0 or not twist_rad_per_mm != 0:
        raise ValueError(f"helical_resolution needs budget_mm > 0 and a non-zero twist, got "
                         f"{budget_mm}, {twist_rad_per_mm}")
    tau = abs(float(twist_rad_per_mm))
    half = budget_mm / 2.0
    nodes, samples = [], []
    for s, phi, f in pieces:
        s, phi, f = (np.asarray(x, dtype=float) for x in (s, phi, f))
        if s.ndim != 1 or s.size < 5 or phi.shape != s.shape or f.shape != s.shape:
            raise ValueError(f"helical_resolution: each piece needs three equal 1-D arrays of "
                             f"≥ 5 samples, got {s.shape}, {phi.shape}, {f.shape}")
        f_p, f_pp = _profile_derivatives(s, phi, f)
        e_signed = f + 2.0 * f_p ** 2 / f - f_pp
        e_abs = maximum_filter1d(np.abs(e_signed), size=5, mode="nearest")
        phi_s = np.gradient(phi, s, edge_order=2)
        density = np.sqrt(e_abs / (8.0 * half)) * phi_s  # section edges per unit of s
        steps = (density[1:] + density[:-1]) / 2.0 * np.diff(s)
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        n = max(1, math.ceil(cum[-1] - 1e-9))
        phi_nodes = np.interp(np.interp(np.linspace(0.0, cum[-1], n + 1), cum, s), s, phi)
        phi_nodes[0], phi_nodes[-1] = phi[0], phi[-1]
        # Where |E| varies fast inside an interval, split it until every sample meets B/2.
        k = np.clip(np.searchsorted(phi_nodes, phi, side="right") - 1, 0, n - 1)
        e_max = np.zeros(n)
        np.maximum.at(e_max, k, e_abs)
        width = np.diff(phi_nodes)
        parts = np.maximum(1, np.ceil(width * np.sqrt(e_max / (8.0 * half)) - 1e-9)).astype(int)
        start = np.repeat(phi_nodes[:-1], parts)
        step = np.repeat(width / parts, parts)
        offset = np.arange(parts.sum()) - np.repeat(np.cumsum(parts) - parts, parts)
        phi_nodes = np.append(start + offset * step, phi[-1])
        nodes.append(phi_nodes[:-1])
        k = np.clip(np.searchsorted(phi_nodes, phi, side="right") - 1, 0, phi_nodes.size - 2)
        samples.append((np.diff(phi_nodes)[k], f, e_signed, f + f_p ** 2 / f))
    dphi, f, e_signed, c = (np.concatenate(x) for x in zip(*samples))
    # Helix edges.
    dz = 2.0 * math.acos(1.0 - half / float(f.max())) / tau
    # Diagonals (−Δφ, Δz): m(Δz) = [E Δφ² − 2 c τ Δφ Δz + f τ² Δz²] / 8 must stay in [−B, B].
    a2, a1, a0 = f * tau ** 2, -2.0 * c * tau * dphi, e_signed * dphi ** 2
    for bound in (budget_mm, -budget_mm):
        dz = min(dz, float(_first_crossing(a2, a1, a0 - 8.0 * bound).min()))
    return np.concatenate(nodes), dz


def helical_star_mesh(profile: Callable[[np.ndarray], np.ndarray], phi_nodes_rad: np.ndarray,
                      z_mm: np.ndarray, twist_rad_per_mm: float) -> trimesh.Trimesh:
    """Watertight mesh of the helically invariant solid ``r ≤ f(θ − τ z)``.

    Vertex ``(i, j)`` lies at ``θ = φ_i + τ z_j``, so every node ``φ_i`` (profile kinks,
    cusps) is a helix of the grid.  :func:`star_mesh` splits each grid quad along the diagonal
    from ``(i, j)`` to ``(i + 1, j + 1)``; for ``τ > 0`` that is the long one (its angular span
    is ``Δφ + τ Δz``), so the solid is then meshed mirrored (``y → −y``, which turns the twist
    into ``−τ``) and mirrored back, and every triangle spans at most ``max(Δφ, |τ| Δz)``.

    Parameters
    ----------
    profile : callable
        ``f_mm = profile(phi_rad)``, 2π-periodic, positive.
    phi_nodes_rad : (n,) float
        Distinct node angles (any order, any period; reduced to ``[0, 2π)``).
    z_mm : (n_z,) float
        Increasing axial positions; the first and last are the end caps.
    twist_rad_per_mm : float
        ``τ``; positive for a right-hand helix.

    Returns
    -------
    trimesh.Trimesh
        Outward-oriented, watertight mesh (object frame, millimetres).
    """
    tau = float(twist_rad_per_mm)
    phi = np.unique(np.mod(np.asarray(phi_nodes_rad, dtype=float), 2.0 * np.pi))
    if tau <= 0.0:
        return star_mesh(lambda th, z: profile(th - tau * z), phi, z_mm, twist_rad_per_mm=tau)
    # Mirrored solid: r_m(θ', z) = r(−θ', z) = f(−θ' − τ z); node ψ_m = −φ.
    psi = np.unique(np.mod(2.0 * np.pi - phi, 2.0 * np.pi))
    mesh = star_mesh(lambda th, z: profile(-th - tau * z), psi, z_mm, twist_rad_per_mm=-tau)
    vertices = mesh.vertices * np.array([1.0, -1.0, 1.0])
    return trimesh.Trimesh(vertices, mesh.faces[:, ::-1], process=False)


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
        phi, dz = helical_resolution(self._pieces(), tau, _SAFETY * self.mesh_tolerance_mm)
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

"""What the generators of the paper's scanned objects share: the measured zone of the scan,
the share of the mesh tolerance a mesher spends, and a tube or solid meshed finely in that
zone and coarsely beyond it."""

from __future__ import annotations

import math

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.mesher import star_mesh, zoned_z_grid
from lts360.scenes.objects.registry import canonical_spec

__all__ = ["MESH_SAFETY", "COARSE_FACTOR", "zone_half_mm", "zoned_star_object",
           "chord_radius_mm", "axial_step_mm"]

#: Share of ``mesh_tolerance_mm`` spent by the meshers' second-order error estimate (half
#: along θ, half along z); the rest covers higher-order terms and radial-vs-normal distance.
MESH_SAFETY = 0.9
#: Axial step outside the measured zone, in multiples of the zone's step.
COARSE_FACTOR = 4.0


def zone_half_mm(sections: int, pitch_mm: float) -> float:
    """Half-length of the measured zone (mm): the paper's scan of ``sections`` sections
    ``pitch_mm`` apart, centred on z = 0, plus 0.5 mm each side."""
    return (sections - 1) * pitch_mm / 2.0 + 0.5


def zoned_star_object(name: str, params, placement: Placement, *, radius, inner_radius,
                      n_theta: int, dz_mm: float, length_mm: float, sections: int,
                      pitch_mm: float, description: str) -> SceneObject:
    """A star-shaped tube (``inner_radius``) or solid (``None``) meshed with ``n_theta``
    angles and the axial step ``dz_mm`` inside the measured zone (:func:`zone_half_mm`),
    :data:`COARSE_FACTOR` times coarser beyond, with its analytic truth ``radius``.

    ``params`` is the generator's frozen parameter dataclass (its ``material`` and
    ``mesh_tolerance_mm`` fields are read)."""
    zone = zone_half_mm(sections, pitch_mm)
    psi = np.arange(n_theta) * (2.0 * np.pi / n_theta)
    z = zoned_z_grid(length_mm / 2.0, zone, dz_mm, COARSE_FACTOR)
    mesh = star_mesh(radius, psi, z, radius_in=inner_radius)
    tol = params.mesh_tolerance_mm
    return SceneObject(
        name=name, spec=canonical_spec(name, params, placement), params=params.__dict__.copy(),
        mesh_object=mesh, placement=placement, material=get_material(params.material),
        radius_fn=radius, measured_zone_z_mm=(-zone, zone), mesh_tolerance_mm=tol,
        sections=sections, pitch_mm=pitch_mm, description=description,
        notes={"n_theta": n_theta, "n_z": int(z.size), "dz_zone_mm": dz_mm,
               "dz_outside_mm": COARSE_FACTOR * dz_mm,
               "error_bound_outside_zone_mm": COARSE_FACTOR ** 2 / 2.0 * MESH_SAFETY * tol
               + MESH_SAFETY * tol / 2.0})


def chord_radius_mm(r, r1, r2) -> float:
    """The equivalent circle radius of a cross-section's chords, ``max κ (r² + r_θ²)``, from
    ``r(θ)`` and its first two θ-derivatives on a dense grid: a chord of angle Δθ then has the
    sagitta of a circle of that radius (κ c² / 8, ``c ≈ √(r² + r_θ²) Δθ``)."""
    kappa = np.abs(r * r + 2.0 * r1 * r1 - r * r2) / (r * r + r1 * r1) ** 1.5
    return float(np.max(kappa * (r * r + r1 * r1)))


def axial_step_mm(budget_mm: float, k_z: float, zone_half: float) -> float:
    """The axial step whose sagitta ``k_z Δz² / 8`` is ``budget_mm`` (the whole zone when the
    surface is straight along the axis, ``k_z = 0``)."""
    return math.sqrt(8.0 * budget_mm / k_z) if k_z > 0 else 2.0 * zone_half

"""A polished aluminium shaft with a deep groove: the concave, shiny part that real rigs struggle
with (not in the paper).

The undercut shaft's geometry (:mod:`lts360.scenes.objects.undercut_shaft`: a rotationally
symmetric groove with a flat bottom, fillets and straight flanks) with steep flanks — inner
shoulders at 70° to the axis — a 1 mm deep bottom, and the ``polished-aluminium`` material:
the laser light the sheet puts on one flank is mirrored onto the other flank and the bottom,
so the section shows secondary stripes when interreflections are rendered (``max_scatter``).
The truth is the undercut shaft's exact ``r(θ, z)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register
from lts360.scenes.objects.undercut_shaft import UndercutShaftParams

NAME = "polished-shaft"


@dataclass(frozen=True)
class PolishedShaftParams(UndercutShaftParams):
    """Polished aluminium shaft with a deep groove; fields and ranges as
    :class:`~lts360.scenes.objects.undercut_shaft.UndercutShaftParams`, other defaults."""

    diameter_mm: float = 20.0
    groove_width_mm: float = 3.0
    groove_depth_mm: float = 1.0
    fillet_radius_mm: float = 0.3
    flank_angle_deg: float = 70.0
    groove_z_mm: float = 0.0
    length_mm: float = 40.0
    mesh_tolerance_mm: float = 0.001
    material: str = "polished-aluminium"

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Mesh the shaft (as the undercut shaft) and return it under its own name and spec."""
        obj = super().build(placement)
        return dataclasses.replace(
            obj, name=NAME, spec=canonical_spec(NAME, self, placement),
            description=(f"polished shaft Ø{self.diameter_mm} mm with a groove "
                         f"{self.groove_width_mm} × {self.groove_depth_mm} mm, flanks at "
                         f"{self.flank_angle_deg}°"))


register(ObjectType(NAME, "Ø20 mm polished aluminium shaft, deep groove with steep shoulders "
                          "(shiny and concave)",
                    PolishedShaftParams, aliases={"d": "diameter_mm", "width": "groove_width_mm",
                                                  "depth": "groove_depth_mm",
                                                  "fillet": "fillet_radius_mm",
                                                  "flank": "flank_angle_deg",
                                                  "length": "length_mm",
                                                  "tol": "mesh_tolerance_mm"}))

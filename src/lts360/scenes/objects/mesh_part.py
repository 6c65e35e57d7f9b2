"""A user's part from a mesh file (STL, PLY, OBJ, read by trimesh): ``mesh:path=part.stl``.

The part's axis is the mesh's z axis and its section at height ``z`` is the mesh cut by the
plane ``z`` (object frame, after ``units``); the placement (x, y, tilt, tilt azimuth) moves
it like any catalog object.  The mesh must be closed (watertight, consistently wound); it is
the ground truth, with the outer radius ``r(θ, z)`` by ray casting where the outer surface is
star-shaped about the axis (:class:`lts360.scenes.objects.part.MeshRadius`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.scenes.materials import get_material
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.part import UNIT_MM, MeshRadius, check_path, source_record
from lts360.scenes.objects.registry import ObjectType, canonical_spec, register

__all__ = ["MeshPartParams", "load_part_mesh"]

NAME = "mesh"
SUFFIXES = (".stl", ".ply", ".obj")
#: Units a mesh file may be in (mm inside).
MESH_UNITS = ("mm", "m", "in", "cm", "um")
#: Margin of the measured zone from either end of the part (mm), at most a quarter of its length.
END_MARGIN_MM = 1.0


def load_part_mesh(path, units: str, where: str = NAME):
    """The watertight mesh (object frame, mm) of a part file, or one line saying why not."""
    import trimesh

    try:
        mesh = trimesh.load(str(path), force="mesh", process=True)
    except Exception as exc:  # trimesh raises many kinds on a bad file
        raise ValueError(f"{where}: {str(path)!r} is not a readable mesh ({exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{where}: {str(path)!r} holds no triangles")
    mesh = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=float) * UNIT_MM[units],
                           np.asarray(mesh.faces), process=False)
    if not mesh.is_watertight:
        edges = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)
        raise ValueError(f"{where}: {str(path)!r} is not watertight ({len(edges)} open edges); "
                         f"close it in CAD or with trimesh.repair.fill_holes(mesh)")
    if not mesh.is_winding_consistent:
        raise ValueError(f"{where}: {str(path)!r} has inconsistently wound faces; fix with "
                         f"trimesh.repair.fix_winding(mesh)")
    if mesh.volume < 0:  # wound inside out: the same solid
        mesh.invert()
    return mesh


@dataclass(frozen=True)
class MeshPartParams:
    """A part from a mesh file.

    Attributes
    ----------
    path : str
        STL, PLY or OBJ file (stored absolute in the spec; no ``,`` or ``=`` in it).
    units : str, {mm, m, in, cm, um}
        Length unit of the file's coordinates.
    material : str
        Material preset name (``lts360 objects`` lists the parameters; materials: see
        ``lts360.scenes.materials``).
    """

    path: str = ""
    units: str = "mm"
    material: str = "ground-steel"

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", str(check_path(NAME, self.path, SUFFIXES)))
        if self.units not in MESH_UNITS:
            raise ValueError(f"{NAME}: units must be one of {', '.join(MESH_UNITS)}, got "
                             f"{self.units!r}")
        get_material(self.material)

    def build(self, placement: Placement = Placement()) -> SceneObject:
        """Read, check and place the part; its truth is the mesh itself."""
        record = source_record(Path(self.path))
        mesh = load_part_mesh(self.path, self.units)
        z0, z1 = (float(v) for v in mesh.bounds[:, 2])
        margin = min(END_MARGIN_MM, (z1 - z0) / 4.0)
        zone = (z0 + margin, z1 - margin)
        radius = MeshRadius(mesh.vertices, mesh.faces)
        re_entrant = radius.re_entrant_fraction(mesh, zone)
        notes = {"part": record, "vertices": int(len(mesh.vertices)),
                 "faces": int(len(mesh.faces))}
        if re_entrant > 0:
            notes["truth"] = (f"outer surface not star-shaped about the z axis ({100 * re_entrant:.2g} "
                              f"% of its side faces lie inside the outer radius): scored by "
                              f"point-to-mesh distance only, no r(θ, z)")
        return SceneObject(
            name=NAME, spec=canonical_spec(NAME, self, placement), params=self.__dict__.copy(),
            mesh_object=mesh, placement=placement, material=get_material(self.material),
            radius_fn=radius if re_entrant == 0 else None, measured_zone_z_mm=zone,
            mesh_tolerance_mm=0.0, sections=1, pitch_mm=0.0,
            description=f"part from {Path(self.path).name} ({self.units})", notes=notes)


register(ObjectType(NAME, "Your part: a closed mesh file (STL, PLY, OBJ), axis = its z axis",
                    MeshPartParams, aliases={}, from_file=True))

"""What the user's parts (the ``mesh`` and ``profile`` objects) share: the source file, its
copy in a frame folder, the part's outer radius from its mesh, and the rig's measurable field.

A part is read from a file (STL, PLY, OBJ; DXF, CSV).  The file *is* the ground truth, so a
frame folder rendered from a part holds a byte copy of it (``part.<suffix>``, with its
SHA-256 in ``frame.json``): ``score`` and ``inspect --truth`` rebuild the part from the copy
and work without the original file (:func:`lts360.scenes.objects.catalog.object_from_truth`).

The truth of a section is the outer radius ``r(θ, z)`` about the part's axis (its z axis),
as for the catalog objects.  It is exact only where the outer surface is *star-shaped* about
the axis (each horizontal ray from the axis leaves the part once); a part whose outer surface
folds back (a pocket, an L-profile) gets no radius function, and scoring falls back to the
point-to-mesh distance (``SceneObject.notes["truth"]`` says so).
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np

from lts360.scenes.contour_file import UNIT_MM

__all__ = ["PART_FILE_STEM", "UNIT_MM", "source_record", "part_truth", "copy_part",
           "check_path", "MeshRadius", "field_excess_mm", "check_in_field"]

#: Name (without suffix) of the part's copy in a frame folder.
PART_FILE_STEM = "part"


def check_path(obj: str, path: str, suffixes: tuple[str, ...]) -> Path:
    """The absolute path of a part file, or one line naming what is wrong with it."""
    if not isinstance(path, str) or not path:
        raise ValueError(f"{obj}: path is required ({obj}:path=FILE; {', '.join(suffixes)})")
    if "," in path or "=" in path:
        raise ValueError(f"{obj}: path must not contain ',' or '=' (the spec separators), got "
                         f"{path!r}")
    p = Path(path).expanduser()
    if p.suffix.lower() not in suffixes:
        raise ValueError(f"{obj}: path must end in {', '.join(suffixes)}, got {path!r}")
    if not p.is_file():
        raise ValueError(f"{obj}: path {path!r}: no such file")
    return p.resolve()


def source_record(path: Path) -> dict:
    """``{"file", "sha256", "source"}``: what a frame folder records about a part's file."""
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return {"file": PART_FILE_STEM + Path(path).suffix.lower(), "sha256": digest,
            "source": str(path)}


def part_truth(obj) -> dict:
    """Entries to add to a frame's ``frame.json["object"]``: ``{"part": record}`` for a part
    read from a file, ``{}`` for a catalog object."""
    record = obj.notes.get("part") if isinstance(obj.notes, dict) else None
    return {"part": dict(record)} if record else {}


def copy_part(object_truth: dict, out_dir) -> None:
    """Copy a part's source file into a frame folder (``object_truth`` is
    ``frame.json["object"]``), checking that it is still the file that was rendered."""
    record = object_truth.get("part")
    if not record:
        return
    src = Path(record["source"])
    data = src.read_bytes() if src.is_file() else b""
    if hashlib.sha256(data).hexdigest() != record["sha256"]:
        raise ValueError(f"object part {str(src)!r} changed or vanished while it was rendered; "
                         f"render again")
    shutil.copyfile(src, Path(out_dir) / record["file"])


class MeshRadius:
    """``r(θ, z)``: the outer radius of a closed mesh about its z axis, by ray casting.

    A horizontal ray comes in from outside (``R = max vertex radius + 1 mm``) towards the axis
    at each ``(θ, z)``; its first hit is the outer surface (Open3D's ``RaycastingScene``, float32:
    ~0.01 µm at these sizes).  NaN where the ray meets nothing (above or below the part).
    """

    def __init__(self, vertices_mm: np.ndarray, faces: np.ndarray) -> None:
        self._vertices = np.asarray(vertices_mm, dtype=np.float32)
        self._faces = np.asarray(faces, dtype=np.uint32)
        self._outside_mm = float(np.hypot(vertices_mm[:, 0], vertices_mm[:, 1]).max()) + 1.0
        self._scene = None

    def _cast(self, rays: np.ndarray) -> np.ndarray:
        import open3d as o3d

        if self._scene is None:
            self._scene = o3d.t.geometry.RaycastingScene()
            self._scene.add_triangles(o3d.core.Tensor(self._vertices),
                                      o3d.core.Tensor(self._faces))
        return self._scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()

    def __call__(self, theta_rad, z_mm) -> np.ndarray:
        theta, z = np.broadcast_arrays(np.asarray(theta_rad, dtype=float),
                                       np.asarray(z_mm, dtype=float))
        c, s = np.cos(theta).ravel(), np.sin(theta).ravel()
        R = self._outside_mm
        rays = np.column_stack([R * c, R * s, z.ravel(), -c, -s, np.zeros_like(c)])
        t = self._cast(rays).astype(float)
        r = np.where(np.isfinite(t) & (t < R), R - t, np.nan)
        return r.reshape(theta.shape)

    def re_entrant_fraction(self, mesh, zone_z_mm: tuple[float, float], *, samples: int = 20000,
                            seed: int = 0, tolerance_mm: float = 1e-3) -> float:
        """Share of the outward-facing side surface in ``zone_z_mm`` (area-weighted samples)
        that lies inside the outer radius by more than ``tolerance_mm``: surface a radius
        function cannot describe (0 for a star-shaped part)."""
        import trimesh

        pts, face = trimesh.sample.sample_surface(mesh, samples, seed=seed)
        normal = mesh.face_normals[face]
        rho = np.hypot(pts[:, 0], pts[:, 1])
        radial = (normal[:, 0] * pts[:, 0] + normal[:, 1] * pts[:, 1]) / np.maximum(rho, 1e-12)
        side = (radial > 0.05) & (pts[:, 2] > zone_z_mm[0]) & (pts[:, 2] < zone_z_mm[1])
        if not side.any():
            return 0.0
        r = self(np.arctan2(pts[side, 1], pts[side, 0]), pts[side, 2])
        inside = ~(rho[side] >= r - tolerance_mm)  # NaN (no outer hit) counts as inside
        return float(inside.mean())


def field_excess_mm(obj, max_radius_mm: float) -> float:
    """How far (mm) the placed part reaches beyond ``max_radius_mm`` from the rig's axis
    (world Z); ≤ 0 when it fits."""
    v = obj.mesh_world().vertices
    return float(np.hypot(v[:, 0], v[:, 1]).max()) - float(max_radius_mm)


def check_in_field(obj, rig) -> None:
    """One line, ``ValueError``, when a part does not fit the rig's measurable field
    (``design.max_object_radius_mm``: the mirrors clear that radius)."""
    limit = float(rig.design.max_object_radius_mm)
    excess = field_excess_mm(obj, limit)
    if excess > 0:
        raise ValueError(f"object {obj.name}: the part reaches {limit + excess:.3f} mm from the "
                         f"rig's axis, {excess:.3f} mm beyond the measurable field "
                         f"(design.max_object_radius_mm = {limit:g} mm); scale it (units) or "
                         f"move it (x, y)")

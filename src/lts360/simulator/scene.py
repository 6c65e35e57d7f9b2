"""Assemble a Mitsuba scene from a rig and an object (or any extra shapes).

The Mitsuba dictionary is the renderer's boundary: everything upstream is our dataclasses.
The caller sets the Mitsuba variant before calling :func:`load_scene`.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import numpy as np
import trimesh

from lts360.scenes.rig import Mirror, Rig
from lts360.simulator.materials import material_to_bsdf, mirror_bsdf

__all__ = ["AMBIENT_RADIANCE_W_M2_SR", "LASER_MIRRORS_CLEARANCE_MM", "SceneSpec", "mirror_shape", "mesh_shape", "chessboard_shape",
           "scene_dict", "load_scene"]

#: Effective in-band radiance of the ambient light (a uniform environment), W m⁻² sr⁻¹.
#: ``bright``: a white surface under it (ρ ≈ 0.8) has ~0.8 W m⁻² sr⁻¹, about an office at
#: 500 lx seen by a camera without filter (the lit calibration images of paper §4.3);
#: ``dim``: the same room through a ~10 nm band-pass filter at 660 nm (1/50 of it).
AMBIENT_RADIANCE_W_M2_SR = {"off": 0.0, "dim": 0.02, "bright": 1.0}
#: How far in front of a laser-side mirror a shadow ray restarts when the laser-side mirrors
#: are not the scene's (mm): a mirror turned by 0.1° about its line in the sheet lies 1.7 µm
#: off the scene's within ±1 mm of the sheet (where the light meets it); 10 µm clears that
#: and moves no shadow test by more than the 1e-4 relative shortening of its segments does.
LASER_MIRRORS_CLEARANCE_MM = 1e-2


@dataclass(frozen=True, eq=False)
class SceneSpec:
    """What to put in front of the camera.

    Attributes
    ----------
    rig : Rig
    meshes : tuple of (name, trimesh.Trimesh, bsdf dict)
        Shapes in world millimetres (the object under test, a calibration board, ...).
    ambient : str
        ``off``, ``dim`` or ``bright``.
    targets : tuple of lts360.scenes.targets.Chessboard
        Printed calibration targets (textured, Lambertian).
    background_z_mm : float, optional
        Height of a matte black base plate (ρ = 0.04, 400 × 400 mm, facing +Z) that the
        object stands on, like the stage's table; ``None``: no background (black void).
    laser_mirrors : tuple of Mirror, optional
        The mirrors the laser light meets (the integrator's method of images), when they are
        not the rig's (which the camera sees): the twin keeps the reflected sheet in its
        plane with mirrors turned perpendicular to it (:func:`lts360.twin.rig.laser_side_mirrors`).
        Each must be within :data:`LASER_MIRRORS_CLEARANCE_MM` of the rig's mirror of the
        same name where the sheet meets it.  ``None``: the rig's mirrors.
    """

    rig: Rig
    meshes: tuple
    ambient: str = "off"
    background_z_mm: float | None = None
    targets: tuple = ()
    laser_mirrors: tuple | None = None

    def __post_init__(self) -> None:
        if self.ambient not in AMBIENT_RADIANCE_W_M2_SR:
            raise ValueError(f"ambient must be one of {', '.join(AMBIENT_RADIANCE_W_M2_SR)}, "
                             f"got {self.ambient!r}")
        if self.laser_mirrors is not None:
            names = sorted(m.name for m in self.laser_mirrors)
            if names != sorted(m.name for m in self.rig.mirrors):
                raise ValueError(f"laser_mirrors: must be the rig's mirrors "
                                 f"{sorted(m.name for m in self.rig.mirrors)}, got {names}")
            object.__setattr__(self, "laser_mirrors", tuple(self.laser_mirrors))


def mirror_shape(m: Mirror) -> dict:
    """A rectangle spanning the mirror, its front face (``+z`` local) towards the object."""
    import mitsuba as mi

    T = np.eye(4)
    T[:3, 0] = m.u_axis * m.width_mm / 2.0
    T[:3, 1] = m.v_axis * m.height_mm / 2.0
    T[:3, 2] = m.normal
    T[:3, 3] = m.center_mm
    return {"type": "rectangle", "to_world": mi.ScalarTransform4f(T.tolist()),
            "bsdf": mirror_bsdf(m.reflectance)}


def mesh_shape(mesh: trimesh.Trimesh, bsdf: dict, directory: str, name: str) -> dict:
    """Write ``mesh`` as binary PLY in ``directory`` and return a flat-shaded ``ply`` shape.

    Flat (face) normals: exact on planar faces and sharp edges; on curved faces tessellated to
    1 µm they deviate from the true normal by at most ~π/n_θ (≈ 0.4° for Ø20 mm).
    """
    path = os.path.join(directory, f"{name}.ply")
    mesh.export(path)
    return {"type": "ply", "filename": path, "face_normals": True, "bsdf": bsdf}


def scene_dict(spec: SceneSpec, sensor: dict, directory: str) -> dict:
    """Mitsuba scene dictionary: sensor, mirrors, meshes, ambient emitter."""
    d: dict = {"type": "scene", "sensor": sensor}
    for m in spec.rig.mirrors:
        d[f"mirror_{m.name}"] = mirror_shape(m)
    for name, mesh, bsdf in spec.meshes:
        d[name] = mesh_shape(mesh, bsdf, directory, name)
    for k, board in enumerate(spec.targets):
        d[f"target_{k}"] = chessboard_shape(board)
    if spec.background_z_mm is not None:
        import mitsuba as mi

        d["background"] = {"type": "rectangle",
                           "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, float(spec.background_z_mm)])
                           @ mi.ScalarTransform4f().scale([200.0, 200.0, 1.0]),
                           "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.04}}}
    radiance = AMBIENT_RADIANCE_W_M2_SR[spec.ambient]
    if radiance > 0:
        d["ambient"] = {"type": "constant", "radiance": {"type": "spectrum", "value": radiance}}
    return d


def chessboard_shape(board, px_per_square: int = 256) -> dict:
    """The printed side of a chessboard: a rectangle with a nearest-neighbour albedo texture.

    The glass plate behind the print is not modelled (it is transparent and behind the print).
    """
    import mitsuba as mi

    # Mitsuba's rectangle maps bitmap row 0 to v = 0, its local y = -1 (the board's y_min);
    # texture() follows the image convention (row 0 at y_max): flip the rows.
    tex = np.ascontiguousarray(board.texture(px_per_square)[::-1])
    return {"type": "rectangle", "to_world": mi.ScalarTransform4f(board.rectangle_transform().tolist()),
            "bsdf": {"type": "diffuse",
                     "reflectance": {"type": "bitmap", "data": mi.TensorXf(tex[:, :, None].astype(np.float32)),
                                     "raw": True, "filter_type": "nearest", "wrap_mode": "clamp"}}}


def load_scene(spec: SceneSpec, sensor: dict):
    """Load the scene (meshes go through a temporary directory that is removed afterwards)."""
    import mitsuba as mi

    with tempfile.TemporaryDirectory(prefix="lts360-scene-") as tmp:
        return mi.load_dict(scene_dict(spec, sensor, tmp))


def object_meshes(obj) -> tuple:
    """The ``meshes`` entry of a :class:`SceneSpec` for a generated object."""
    return (("object", obj.mesh_world(), material_to_bsdf(obj.material)),)

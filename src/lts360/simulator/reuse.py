"""Build a scene once, render it many times: the object moves, the scene and its kernels stay.

A scan, a study's trial or a Monte Carlo loop renders the same rig and the same object (or
the same mesh at another placement or stage height) frame after frame.  Loading a scene costs
the PLY export and load, the acceleration structure and the integrator's set-up; Dr.Jit also
compiles the render kernel for each new scene (its structure is part of the kernel's key).
:class:`SceneCache` keeps the loaded scenes of one loop and, for a frame whose shapes have the
same triangles (same faces, the vertices moved), writes the new vertex positions through
``mi.traverse`` and ``params.update()`` instead of loading anew (and hands the scene's new
bounds to the ambient light, whose sampling uses them: a stale sphere changed the image).  The render of a pixel list
(:func:`lts360.simulator.render.render_pixels`) takes its pixels as kernel data, so the same
compiled kernel serves every frame of the loop.

Where reuse does not hold (a new scene is loaded): another rig, material, ambient setting,
base plate or calibration target; another sample count, scale, bounce limit, lens or laser
state; a mesh with other faces (another object, another tessellation).  ``drjit.freeze`` is
not used: the render's wavefront size follows the support's pixel count, which changes from
frame to frame (a frozen function would re-record for each new size); the compiled-kernel
cache of Dr.Jit already reuses the kernel across those calls.

No global state: a cache lives as long as the loop that owns it.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

__all__ = ["SceneCache"]


def _fingerprint_rig(rig) -> str:
    from lts360.simulator.io import rig_truth

    truth = rig_truth(rig, rig.camera.K, rig.camera.image_size)
    extra = {"laser": {k: np.asarray(getattr(rig.laser, k)).tolist() for k in
                       ("origin_mm", "direction", "normal", "fan_angle_deg", "waist_um",
                        "waist_distance_mm", "rayleigh_range_mm", "wavelength_nm", "power_mW",
                        "fan_profile")},
             "camera": {k: np.asarray(getattr(rig.camera, k)).tolist() for k in
                        ("f_number", "focus_distance_mm", "focal_length_mm", "distortion")},
             "mirrors": [float(m.reflectance) for m in rig.mirrors]}
    text = json.dumps([truth, extra], sort_keys=True, default=lambda v: np.asarray(v).tolist())
    return hashlib.sha1(text.encode()).hexdigest()


def _faces_digest(mesh) -> str:
    faces = np.ascontiguousarray(np.asarray(mesh.faces, np.int64))
    return hashlib.sha1(faces.tobytes()).hexdigest() + f":{len(mesh.vertices)}"


class SceneCache:
    """Loaded scenes of one loop, reused when only the shapes' vertices change.

    Parameters
    ----------
    max_scenes : int, >= 1
        Scenes kept (least recently used dropped first).

    Attributes
    ----------
    loads, reuses : int
        How many :meth:`prepare` calls loaded a scene, and how many moved the vertices of
        one already loaded.
    """

    def __init__(self, max_scenes: int = 2) -> None:
        if not (isinstance(max_scenes, int) and max_scenes >= 1):
            raise ValueError(f"max_scenes must be an integer >= 1, got {max_scenes!r}")
        self.max_scenes = max_scenes
        self._scenes: dict[str, tuple] = {}
        self._supports: dict[str, object] = {}
        self.loads = 0
        self.reuses = 0

    def _key(self, spec, render_kw: dict) -> str:
        shapes = [(name, _faces_digest(mesh), json.dumps(bsdf, sort_keys=True, default=repr))
                  for name, mesh, bsdf in spec.meshes]
        text = json.dumps([_fingerprint_rig(spec.rig), shapes, spec.ambient,
                           spec.background_z_mm, len(spec.targets), repr(spec.laser_mirrors),
                           sorted(render_kw.items())], default=repr)
        return hashlib.sha1(text.encode()).hexdigest()

    def support(self, spec, make, **key_kw):
        """The pixel support ``make()`` returns for ``spec``, computed once per scene state:
        the same rig, shapes (vertices included) and ``key_kw`` give the cached support (a
        static object's frames, a Monte Carlo's repeats), a moved object a new one."""
        verts = hashlib.sha1()
        for _, mesh, _ in spec.meshes:
            verts.update(np.ascontiguousarray(np.asarray(mesh.vertices, np.float64)).tobytes())
        key = self._key(spec, key_kw) + verts.hexdigest()
        sup = self._supports.pop(key, None)
        if sup is None:
            sup = make()
        self._supports[key] = sup
        while len(self._supports) > self.max_scenes:
            self._supports.pop(next(iter(self._supports)))
        return sup

    def prepare(self, spec, **render_kw):
        """``(scene, integrator)`` for ``spec`` as :func:`lts360.simulator.render.prepare_scene`
        with ``render_kw`` would load it, from the cache when possible (vertices updated)."""
        import mitsuba as mi

        from lts360.simulator.render import prepare_scene

        if spec.targets:  # textured boards are not moved here: always load
            self.loads += 1
            return prepare_scene(spec, **render_kw)
        key = self._key(spec, render_kw)
        hit = self._scenes.pop(key, None)
        if hit is None:
            prepared = prepare_scene(spec, **render_kw)
            self.loads += 1
        else:
            prepared = hit
            params = mi.traverse(prepared[0])
            for name, mesh, _ in spec.meshes:
                params[f"{name}.vertex_positions"] = mi.Float(
                    np.asarray(mesh.vertices, np.float32).ravel())
            params.update()
            env = prepared[0].environment()
            if env is not None:  # the ambient light's bounding sphere follows the moved shapes
                env.set_scene(prepared[0])
            self.reuses += 1
        self._scenes[key] = prepared
        while len(self._scenes) > self.max_scenes:
            self._scenes.pop(next(iter(self._scenes)))
        return prepared

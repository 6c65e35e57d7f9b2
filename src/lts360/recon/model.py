"""The calibration the reconstruction works from: camera, mirror planes, laser plane, frames.

Everything is expressed in the **camera frame** (OpenCV: x right, y down, z forward,
millimetres), as a real calibration delivers it: ``K`` and the distortion from Zhang's method,
the mirror planes from the real/virtual chessboard symmetry (paper §4.2), the laser plane from
laser-line points on the board (§4.3).  The **measurement frame** (DESIGN.md, "Frames and
units") is given by ``T_cam_meas`` (``X_cam = R X_meas + t``): its origin lies on the nominal
object axis in the laser plane, its z axis is the laser-plane normal, θ = 0 along its +X.

Files are JSON with OpenCV's names for the camera (``camera_matrix``, ``distortion_coefficients``
in the order k1 k2 p1 p2 k3, ``image_width``, ``image_height``); :func:`load_calibration` also
reads the ``frame.json`` truth written beside a rendered frame (a perfect calibration).
This module never imports the simulator: it reads that file as plain JSON.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from lts360.geometry.mirror import transform_plane

__all__ = ["MirrorPlane", "Calibration", "load_calibration", "save_calibration", "shift_origin",
           "calibration_from_dict", "calibration_to_dict", "calibration_from_frame_truth",
           "make_T_cam_meas", "FORMAT_NAME", "FORMAT_VERSION"]

FORMAT_NAME = "lts360-calibration"
FORMAT_VERSION = 1

#: Largest angle (rad) between the measurement z axis and the laser-plane normal, and largest
#: distance (mm) of the measurement origin from the laser plane, accepted as "in the plane".
#: A calibration builds ``T_cam_meas`` from its laser plane, so the two agree to rounding; the
#: bound leaves room for values printed with ~8 significant digits.
FRAME_ANGLE_TOL_RAD = 1e-6
FRAME_OFFSET_TOL_MM = 1e-5
#: Largest distance (mm) of a mirror corner from its plane.
CORNER_TOL_MM = 1e-3


def _ro(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float)
    arr.setflags(write=False)
    return arr


def _finite_array(value, shape: tuple[int, ...], name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be numbers of shape {shape}, got {value!r}") from None
    if arr.shape != shape:
        raise ValueError(f"{name}: must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite, got {arr.tolist()}")
    return arr


def _unit_normal(value, name: str) -> np.ndarray:
    n = _finite_array(value, (3,), name)
    norm = float(np.linalg.norm(n))
    if norm < 1e-12:
        raise ValueError(f"{name}: must be a non-zero vector, got {n.tolist()}")
    return n / norm


@dataclass(frozen=True, eq=False)
class MirrorPlane:
    """A calibrated planar mirror in the camera frame.

    Attributes
    ----------
    name : str
        View name of the mirror (``"left"``, ``"right"``); not ``"direct"``, no ``"-"``.
    n : (3,) float
        Unit normal pointing to the reflecting side, i.e. towards the camera.
    d_mm : float, <0
        Plane ``n · X_cam = d_mm``; the camera centre (the origin) is on the reflecting side,
        so ``d_mm < 0``.  A plane given with the opposite orientation is flipped on construction.
    corners_mm : (4, 3) float or None
        Corners of the reflecting rectangle (a convex quadrilateral, in order around it) in the
        camera frame, when the calibration knows the mirror's extent; ``None`` = unbounded.
    """

    name: str
    n: np.ndarray
    d_mm: float
    corners_mm: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name == "direct" or \
                "-" in self.name:
            raise ValueError(f"mirror name: must be a non-empty string other than 'direct' and "
                             f"without '-', got {self.name!r}")
        n = _unit_normal(self.n, f"mirrors[{self.name}].n")
        d = self.d_mm
        if not isinstance(d, (int, float, np.floating, np.integer)) or not math.isfinite(float(d)):
            raise ValueError(f"mirrors[{self.name}].d_mm: must be a finite number, got {d!r}")
        d = float(d)
        if abs(d) < 1e-9:
            raise ValueError(f"mirrors[{self.name}].d_mm: the camera centre lies on the mirror "
                             "plane (d_mm = 0)")
        if d > 0:  # same plane, normal turned towards the camera
            n, d = -n, -d
        object.__setattr__(self, "n", _ro(n))
        object.__setattr__(self, "d_mm", d)
        if self.corners_mm is not None:
            c = _finite_array(self.corners_mm, (4, 3), f"mirrors[{self.name}].corners_mm")
            off = np.abs(c @ n - d)
            if off.max() > CORNER_TOL_MM:
                raise ValueError(f"mirrors[{self.name}].corners_mm: corners must lie on the plane "
                                 f"(largest distance {off.max():.3g} mm > {CORNER_TOL_MM:g} mm)")
            object.__setattr__(self, "corners_mm", _ro(c))

    @property
    def plane(self) -> tuple[np.ndarray, float]:
        """``(n, d_mm)`` in the camera frame."""
        return self.n.copy(), self.d_mm


@dataclass(frozen=True, eq=False)
class Calibration:
    """Calibrated camera, mirrors and laser plane (camera frame) and the measurement frame.

    Attributes
    ----------
    image_size : (int, int)
        ``(width, height)`` in pixels of the images this calibration applies to.
    K : (3, 3) float
        Intrinsic matrix (pixel centres at integer coordinates).
    dist : (5,) float
        Brown distortion ``(k1, k2, p1, p2, k3)`` (OpenCV order); 4 values are padded with k3 = 0.
    mirrors : tuple of MirrorPlane
        Mirror planes in the camera frame, names unique.
    laser_plane : (n (3,), d_mm)
        Laser sheet ``n · X_cam = d_mm`` in the camera frame (``n`` normalised on construction).
    T_cam_meas : (4, 4) float
        Rigid transform measurement → camera, ``X_cam = R X_meas + t``: origin on the nominal
        object axis in the laser plane, z along ±(laser normal), θ = 0 along +X_meas.
    view_offsets_mm : mapping str → (2,) float
        Residual compensation (paper §4.4): an (x, y) translation in the measurement frame
        added to the points of each mirror view (key = view name, e.g. ``"left"`` or
        ``"left-right"``).  Every mirror is present after construction (zeros by default).
    uncertainty : dict
        Free-form (JSON-serialisable) uncertainty information, e.g. covariances; not used yet.
    view_radial_offsets_mm, view_scales : mapping str → float
        Mastering (references of known diameter, :func:`lts360.recon.calibration.compensation.
        master_fit`): per view (``"direct"`` too) its radii become ``scale·r + offset`` along
        their rays before the view's translation; absent views: 0 and 1.
    master : dict
        The mastering's record (masters, shots, fit, uncertainties), empty without one.
    optics : dict
        The optics the calibration was made with, for the line-centre bias twin (recon does
        not read it): ``rig`` (the preset name or rig file given) and ``rig_toml`` (that rig's
        full TOML: design, lens, sheet, sensor).  Empty for a calibration that does not know
        (an older file).
    """

    image_size: tuple[int, int]
    K: np.ndarray
    dist: np.ndarray
    mirrors: tuple[MirrorPlane, ...]
    laser_plane: tuple[np.ndarray, float]
    T_cam_meas: np.ndarray
    view_offsets_mm: Mapping[str, np.ndarray] = field(default_factory=dict)
    uncertainty: dict = field(default_factory=dict)
    optics: dict = field(default_factory=dict)
    view_radial_offsets_mm: Mapping[str, float] = field(default_factory=dict)
    view_scales: Mapping[str, float] = field(default_factory=dict)
    master: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        size = self.image_size
        if not isinstance(size, (tuple, list)) or len(size) != 2 or not all(
                isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 1 <= v <= 100_000
                for v in size):
            raise ValueError(f"image_size: must be two integers (width, height) in [1, 100000], "
                             f"got {size!r}")
        object.__setattr__(self, "image_size", (int(size[0]), int(size[1])))

        K = _finite_array(self.K, (3, 3), "camera_matrix")
        if not (K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1]) and K[1, 0] == 0):
            raise ValueError("camera_matrix: must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with "
                             f"fx, fy > 0, got {K.tolist()}")
        object.__setattr__(self, "K", _ro(K))

        dist = np.asarray(self.dist, dtype=float).ravel() if self.dist is not None else np.zeros(5)
        if dist.size not in (4, 5) or not np.all(np.isfinite(dist)):
            raise ValueError("distortion_coefficients: must be 4 or 5 finite numbers "
                             f"(k1, k2, p1, p2[, k3]), got {np.asarray(self.dist).tolist()}")
        object.__setattr__(self, "dist", _ro(np.concatenate([dist, np.zeros(5 - dist.size)])))

        mirrors = tuple(self.mirrors)
        if not all(isinstance(m, MirrorPlane) for m in mirrors):
            raise ValueError("mirrors: must be MirrorPlane instances")
        names = [m.name for m in mirrors]
        if len(set(names)) != len(names):
            raise ValueError(f"mirrors: names must be unique, got {names}")
        object.__setattr__(self, "mirrors", mirrors)

        try:
            n_l, d_l = self.laser_plane
        except (TypeError, ValueError):
            raise ValueError(f"laser_plane: must be (n, d_mm), got {self.laser_plane!r}") from None
        n_l = _unit_normal(n_l, "laser_plane.n")
        d_l = float(_finite_array(d_l, (), "laser_plane.d_mm"))
        object.__setattr__(self, "laser_plane", (_ro(n_l), d_l))

        T = _finite_array(self.T_cam_meas, (4, 4), "T_cam_meas")
        R, t = T[:3, :3], T[:3, 3]
        if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
                or np.linalg.det(R) <= 0:
            raise ValueError("T_cam_meas: must be a rigid transform [[R, t], [0, 0, 0, 1]] with R "
                             "a proper rotation")
        sin_angle = float(np.linalg.norm(np.cross(R[:, 2], n_l)))
        if sin_angle > FRAME_ANGLE_TOL_RAD:
            raise ValueError(f"T_cam_meas: its z axis must be the laser-plane normal, they differ "
                             f"by {math.degrees(math.asin(min(sin_angle, 1.0))):.4g} deg")
        if abs(float(n_l @ t) - d_l) > FRAME_OFFSET_TOL_MM:
            raise ValueError(f"T_cam_meas: its origin must lie in the laser plane, it is "
                             f"{float(n_l @ t) - d_l:.4g} mm off")
        object.__setattr__(self, "T_cam_meas", _ro(T))

        offsets = {m.name: np.zeros(2) for m in mirrors}
        if not isinstance(self.view_offsets_mm, Mapping):
            raise ValueError("view_offsets_mm: must be a mapping view name -> [dx, dy]")
        for key, value in self.view_offsets_mm.items():
            parts = str(key).split("-")
            if key == "direct" or not all(p in names for p in parts) or \
                    any(a == b for a, b in zip(parts[:-1], parts[1:])):
                raise ValueError(f"view_offsets_mm: {key!r} is not a mirror view of this "
                                 f"calibration (mirrors {names}; the direct view is the reference)")
            offsets[str(key)] = _finite_array(value, (2,), f"view_offsets_mm[{key}]")
        object.__setattr__(self, "view_offsets_mm", {k: _ro(v) for k, v in offsets.items()})

        if self.uncertainty is None:
            object.__setattr__(self, "uncertainty", {})
        if not isinstance(self.uncertainty, dict):
            raise ValueError("uncertainty: must be a dict")
        for attr, lo, hi in (("view_radial_offsets_mm", -1.0, 1.0), ("view_scales", 0.9, 1.1)):
            value = getattr(self, attr)
            if not isinstance(value, Mapping):
                raise ValueError(f"{attr}: must be a mapping view name -> number")
            clean = {}
            for key, v in value.items():
                parts = str(key).split("-")
                if key != "direct" and not all(p in names for p in parts):
                    raise ValueError(f"{attr}: {key!r} is not a view of this calibration "
                                     f"(direct, mirrors {names})")
                v = float(_finite_array(v, (), f"{attr}[{key}]"))
                if not lo <= v <= hi:
                    raise ValueError(f"{attr}[{key}]: must be in [{lo:g}, {hi:g}], got {v}")
                clean[str(key)] = v
            object.__setattr__(self, attr, clean)
        if self.master is None:
            object.__setattr__(self, "master", {})
        if not isinstance(self.master, dict):
            raise ValueError("master: must be a dict")
        if self.optics is None:
            object.__setattr__(self, "optics", {})
        if not isinstance(self.optics, dict):
            raise ValueError("optics: must be a JSON object {rig, rig_toml}")
        for key in ("rig", "rig_toml"):
            if key in self.optics and not (isinstance(self.optics[key], str)
                                           and self.optics[key]):
                raise ValueError(f"optics.{key}: must be a non-empty string")

    # -- convenience -------------------------------------------------------------------------
    @property
    def R_cam_meas(self) -> np.ndarray:
        return self.T_cam_meas[:3, :3].copy()

    @property
    def t_cam_meas_mm(self) -> np.ndarray:
        return self.T_cam_meas[:3, 3].copy()

    @property
    def T_meas_cam(self) -> np.ndarray:
        """Inverse of :attr:`T_cam_meas` (camera → measurement)."""
        R, t = self.R_cam_meas, self.t_cam_meas_mm
        T = np.eye(4)
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ t
        return T

    @property
    def mirror_names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.mirrors)

    def mirror(self, name: str) -> MirrorPlane:
        for m in self.mirrors:
            if m.name == name:
                return m
        raise KeyError(f"no mirror named {name!r}; have {list(self.mirror_names)}")


def make_T_cam_meas(laser_plane: tuple, origin_cam_mm, x_axis_cam) -> np.ndarray:
    """Measurement frame from a laser plane, a point on the object axis and a θ = 0 direction.

    Parameters
    ----------
    laser_plane : (n (3,), d_mm)
        Laser plane in the camera frame; the measurement z axis is ``n``.
    origin_cam_mm : (3,) float
        A point of the nominal object axis (projected onto the plane to give the origin).
    x_axis_cam : (3,) float
        Direction of θ = 0 (its component along ``n`` is removed).

    Returns
    -------
    (4, 4) float
        ``T_cam_meas`` with ``X_cam = R X_meas + t``.
    """
    n = _unit_normal(laser_plane[0], "laser_plane.n")
    d = float(laser_plane[1])
    p = _finite_array(origin_cam_mm, (3,), "origin_cam_mm")
    x = _finite_array(x_axis_cam, (3,), "x_axis_cam")
    x = x - (x @ n) * n
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("x_axis_cam: must not be parallel to the laser-plane normal")
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(n, x), n])
    T[:3, 3] = p - (p @ n - d) * n
    return T


# -- JSON --------------------------------------------------------------------------------------

def _opencv_matrix(value, name: str):
    """Accept a nested list or OpenCV FileStorage's ``{"rows", "cols", "data"}`` form."""
    if isinstance(value, dict):
        try:
            rows, cols, data = int(value["rows"]), int(value["cols"]), value["data"]
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{name}: an OpenCV matrix needs 'rows', 'cols' and 'data'") from None
        arr = np.asarray(data, dtype=float)
        if arr.size != rows * cols:
            raise ValueError(f"{name}: 'data' has {arr.size} values, expected {rows}x{cols}")
        return arr.reshape(rows, cols)
    return value


def _require(data: Mapping, key: str, where: str = "") -> Any:
    if not isinstance(data, Mapping) or key not in data:
        raise ValueError(f"{where}{key}: missing")
    return data[key]


def calibration_to_dict(cal: Calibration) -> dict:
    """The JSON layout written by :func:`save_calibration` (plain lists and numbers)."""
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "image_width": cal.image_size[0],
        "image_height": cal.image_size[1],
        "camera_matrix": cal.K.tolist(),
        "distortion_coefficients": cal.dist.tolist(),
        "mirrors": [{"name": m.name, "normal": m.n.tolist(), "d_mm": m.d_mm,
                     "corners_mm": None if m.corners_mm is None else m.corners_mm.tolist()}
                    for m in cal.mirrors],
        "laser_plane": {"normal": cal.laser_plane[0].tolist(), "d_mm": cal.laser_plane[1]},
        "T_cam_meas": cal.T_cam_meas.tolist(),
        "view_offsets_mm": {k: v.tolist() for k, v in cal.view_offsets_mm.items()},
        "uncertainty": cal.uncertainty,
        "view_radial_offsets_mm": dict(cal.view_radial_offsets_mm),
        "view_scales": dict(cal.view_scales),
        "master": cal.master,
        "optics": cal.optics,
    }


def calibration_from_dict(data: Mapping) -> Calibration:
    """Build a :class:`Calibration` from the saved layout or from a ``frame.json`` truth dict."""
    if not isinstance(data, Mapping):
        raise ValueError("calibration: the file must hold a JSON object")
    if isinstance(data.get("camera"), Mapping) and "K" in data["camera"]:
        return calibration_from_frame_truth(data)
    w = _require(data, "image_width")
    h = _require(data, "image_height")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (w, h)):
        raise ValueError(f"image_width/image_height: must be integers, got {w!r}, {h!r}")
    K = _opencv_matrix(_require(data, "camera_matrix"), "camera_matrix")
    dist = np.asarray(_opencv_matrix(_require(data, "distortion_coefficients"),
                                     "distortion_coefficients"), dtype=float).ravel()
    mirrors_raw = _require(data, "mirrors")
    if not isinstance(mirrors_raw, list):
        raise ValueError("mirrors: must be a list")
    mirrors = []
    for i, m in enumerate(mirrors_raw):
        where = f"mirrors[{i}]."
        corners = m.get("corners_mm") if isinstance(m, Mapping) else None
        mirrors.append(MirrorPlane(name=_require(m, "name", where), n=_require(m, "normal", where),
                                   d_mm=_require(m, "d_mm", where), corners_mm=corners))
    laser = _require(data, "laser_plane")
    laser_plane = (_require(laser, "normal", "laser_plane."),
                   _require(laser, "d_mm", "laser_plane."))
    T = _opencv_matrix(_require(data, "T_cam_meas"), "T_cam_meas")
    offsets = data.get("view_offsets_mm") or {}
    uncertainty = data.get("uncertainty") or {}
    # absent in files older than the optics record and the mastering
    optics = data.get("optics") or {}
    return Calibration(image_size=(w, h), K=K, dist=dist, mirrors=tuple(mirrors),
                       laser_plane=laser_plane, T_cam_meas=T, view_offsets_mm=offsets,
                       uncertainty=uncertainty, optics=optics,
                       view_radial_offsets_mm=data.get("view_radial_offsets_mm") or {},
                       view_scales=data.get("view_scales") or {},
                       master=data.get("master") or {})


def shift_origin(cal: Calibration, xy_mm) -> Calibration:
    """The same calibration with the measurement frame's origin moved to ``(x, y, 0)`` of the
    current frame (axes unchanged: the origin stays in the laser plane).  The §4.4 view offsets
    are translations and carry over as they are."""
    x, y = (float(v) for v in np.asarray(xy_mm, dtype=float).reshape(2))
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"shift_origin: the new origin must be finite, got ({x}, {y})")
    T = np.array(cal.T_cam_meas)
    T[:3, 3] = T[:3, :3] @ np.array([x, y, 0.0]) + T[:3, 3]
    return dataclasses.replace(cal, T_cam_meas=T)


def calibration_from_frame_truth(data: Mapping) -> Calibration:
    """A perfect calibration from the world-frame truth in a rendered frame's ``frame.json``.

    Mirror and laser planes (and mirror corners) are moved into the camera frame;
    ``T_cam_meas`` is the world → camera pose, so the measurement frame is the world frame
    (whose ``z = 0`` is the laser plane and whose origin is on the nominal axis).  Should the
    world laser plane not be ``z = 0`` (a perturbed rig), the frame is re-based onto it: origin
    where the world Z axis pierces the sheet, θ = 0 along world +X projected into it.
    """
    cam = _require(data, "camera")
    K = _require(cam, "K", "camera.")
    dist = _require(cam, "dist", "camera.")
    R = _finite_array(_require(cam, "R", "camera."), (3, 3), "camera.R")
    t = _finite_array(_require(cam, "t", "camera."), (3,), "camera.t")
    size = _require(cam, "image_size", "camera.")
    if not isinstance(size, (list, tuple)) or len(size) != 2:
        raise ValueError(f"camera.image_size: must be [width, height], got {size!r}")
    mirrors = []
    mirrors_raw = _require(data, "mirrors")
    if not isinstance(mirrors_raw, list):
        raise ValueError("mirrors: must be a list")
    for i, m in enumerate(mirrors_raw):
        where = f"mirrors[{i}]."
        n_w = _unit_normal(_require(m, "n", where), f"{where}n")
        d_w = float(_finite_array(_require(m, "d", where), (), f"{where}d"))
        n_c, d_c = transform_plane(n_w, d_w, R, t)
        corners = m.get("corners") if isinstance(m, Mapping) else None
        if corners is not None:
            corners = _finite_array(corners, (4, 3), f"{where}corners") @ R.T + t
        mirrors.append(MirrorPlane(name=_require(m, "name", where), n=n_c, d_mm=d_c,
                                   corners_mm=corners))
    plane = _require(_require(data, "laser"), "plane", "laser.")
    n_l = _unit_normal(_require(plane, "n", "laser.plane."), "laser.plane.n")
    d_l = float(_finite_array(_require(plane, "d", "laser.plane."), (), "laser.plane.d"))
    T_cam_world = np.eye(4)
    T_cam_world[:3, :3], T_cam_world[:3, 3] = R, t
    # The world laser plane is z = 0 (DESIGN.md), so the measurement frame is the world frame.
    # A perturbed sheet (tilted or shifted) still gets a frame in its own plane: origin where
    # the world Z axis (the nominal object axis) pierces it, θ = 0 along world +X projected.
    if abs(n_l[2]) < 0.5:
        raise ValueError(f"laser.plane: the sheet must be roughly perpendicular to the world Z "
                         f"axis (the object axis), got n={n_l.tolist()}")
    T_world_meas = make_T_cam_meas((n_l, d_l), (0.0, 0.0, d_l / n_l[2]), (1.0, 0.0, 0.0))
    rig = data.get("rig")  # the frame's rig (frames written before it was recorded: none)
    optics = ({k: rig[k] for k in ("rig", "rig_toml") if isinstance(rig.get(k), str)}
              if isinstance(rig, Mapping) else {})
    return Calibration(image_size=(int(size[0]), int(size[1])), K=K, dist=dist,
                       mirrors=tuple(mirrors), laser_plane=transform_plane(n_l, d_l, R, t),
                       T_cam_meas=T_cam_world @ T_world_meas, optics=optics)


def load_calibration(path) -> Calibration:
    """Read a calibration file, or a rendered frame's ``frame.json`` (world truth).

    Raises
    ------
    ValueError
        Unreadable file, invalid JSON, or a missing/invalid field (named in the message).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f"calibration: cannot read {path} ({exc.strerror})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"calibration: {path} is not valid JSON (line {exc.lineno}: {exc.msg})") \
            from None
    return calibration_from_dict(data)


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"uncertainty: {type(value).__name__} is not JSON serialisable")


def save_calibration(path, cal: Calibration) -> None:
    """Write ``cal`` as JSON atomically (temporary file in the same folder, then rename).

    The text is built before anything is written, so a value that cannot be serialised (in
    ``uncertainty``) raises ``TypeError`` and leaves any existing file untouched.
    """
    if not isinstance(cal, Calibration):
        raise ValueError(f"cal: must be a Calibration, got {type(cal).__name__}")
    path = Path(path)
    text = json.dumps(calibration_to_dict(cal), indent=2, default=_jsonable)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise

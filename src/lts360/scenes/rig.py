"""The rig: camera, laser sheet, two planar mirrors and a Z stage, in world millimetres.

World frame (DESIGN.md): the object's nominal axis is +Z, the nominal laser plane is
``z = 0``, the origin is where the axis pierces the laser plane; camera and laser in front
(−Y), the mirror corner behind (+Y).  Every component is a frozen dataclass that checks
its own fields; :func:`build_rig` makes a rig from design parameters (:class:`RigDesign`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lts360.geometry.camera import camera_center, look_at
from lts360.geometry.mirror import mirror_matrix
from lts360.scenes.checks import RigError, _check, _in_range
from lts360.scenes.sensor import SensorModel

__all__ = ["Camera", "LaserSheet", "Mirror", "Stage", "Rig", "RigDesign", "build_rig",
           "RigError"]


def _vec(value, n: int = 3) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(n)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Camera:
    """Pinhole/thin-lens camera with Brown distortion (OpenCV conventions).

    Attributes
    ----------
    width_px, height_px : int
        Image size.
    pixel_pitch_um : float
        Centre-to-centre pixel distance (square pixels).
    focal_length_mm : float
        Lens focal length ``f``; ``fx = fy = f / pitch``.
    f_number : float
        Working aperture ``N``; the entrance pupil diameter is ``f / N``.
    focus_distance_mm : float
        Distance along the optical axis that is in sharp focus.
    distortion : (5,) float
        ``(k1, k2, p1, p2, k3)``.
    R : (3, 3) float
        World-to-camera rotation: ``X_cam = R X_world + t``.
    t_mm : (3,) float
        World-to-camera translation.
    principal_point_offset_px : (2,) float
        Offset of the principal point from the image centre ``((W−1)/2, (H−1)/2)``.
    """

    width_px: int
    height_px: int
    pixel_pitch_um: float
    focal_length_mm: float
    f_number: float
    focus_distance_mm: float
    distortion: np.ndarray
    R: np.ndarray
    t_mm: np.ndarray
    principal_point_offset_px: np.ndarray = field(default_factory=lambda: _vec((0.0, 0.0), 2))

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px"):
            v = getattr(self, name)
            _check(isinstance(v, (int, np.integer)) and 16 <= v <= 16384, f"camera.{name}",
                   f"must be an integer in [16, 16384], got {v!r}")
        _in_range("camera.pixel_pitch_um", self.pixel_pitch_um, 0.5, 50.0)
        _in_range("camera.focal_length_mm", self.focal_length_mm, 1.0, 500.0)
        _in_range("camera.f_number", self.f_number, 0.5, 64.0)
        _in_range("camera.focus_distance_mm", self.focus_distance_mm, self.focal_length_mm,
                  1e6, lo_open=True)
        object.__setattr__(self, "distortion", _vec(self.distortion, 5))
        object.__setattr__(self, "R", np.asarray(self.R, dtype=float).reshape(3, 3))
        object.__setattr__(self, "t_mm", _vec(self.t_mm))
        object.__setattr__(self, "principal_point_offset_px", _vec(self.principal_point_offset_px, 2))
        _check(np.all(np.isfinite(self.distortion)) and np.all(np.abs(self.distortion) < 10),
               "camera.distortion", f"must be 5 finite numbers with |value| < 10, got {self.distortion}")
        _check(np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-9) and np.linalg.det(self.R) > 0,
               "camera.R", "must be a proper rotation matrix")

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix; ``c = ((W−1)/2, (H−1)/2) + offset`` (pixel centres at integers)."""
        f_px = self.focal_length_mm / (self.pixel_pitch_um * 1e-3)
        cx = (self.width_px - 1) / 2.0 + self.principal_point_offset_px[0]
        cy = (self.height_px - 1) / 2.0 + self.principal_point_offset_px[1]
        return np.array([[f_px, 0.0, cx], [0.0, f_px, cy], [0.0, 0.0, 1.0]])

    @property
    def center_mm(self) -> np.ndarray:
        """Projection centre in the world frame."""
        return camera_center(self.R, self.t_mm)

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit viewing direction in the world frame."""
        return self.R[2].copy()

    @property
    def image_size(self) -> tuple[int, int]:
        return int(self.width_px), int(self.height_px)

    @property
    def aperture_diameter_mm(self) -> float:
        return self.focal_length_mm / self.f_number


@dataclass(frozen=True, eq=False)
class LaserSheet:
    """A laser line projector: a fan of light in a plane, Gaussian across its thickness.

    Attributes
    ----------
    origin_mm : (3,) float
        Apex of the fan.
    direction : (3,) float
        Unit central direction of the fan (in the sheet plane).
    normal : (3,) float
        Unit normal of the sheet plane (perpendicular to ``direction``).
    fan_angle_deg : float, (0, 180)
        Full opening angle of the fan.
    fan_profile : str
        ``"flat"`` (Powell lens: uniform in angle) or ``"gaussian"`` (1/e² at the fan edge).
    waist_um : float
        1/e² intensity half-thickness ``w0`` of the sheet at its waist.
    waist_distance_mm : float
        Distance from the origin to the waist along the fan direction.
    rayleigh_range_mm : float
        ``z_R``; must satisfy ``z_R <= π w0² / λ`` (beam quality ``M² = π w0² / (λ z_R) >= 1``).
    wavelength_nm : float
    power_mW : float
        Optical power in the whole fan.
    """

    origin_mm: np.ndarray
    direction: np.ndarray
    normal: np.ndarray
    fan_angle_deg: float
    waist_um: float
    waist_distance_mm: float
    rayleigh_range_mm: float
    wavelength_nm: float
    power_mW: float
    fan_profile: str = "flat"

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin_mm", _vec(self.origin_mm))
        for name in ("direction", "normal"):
            v = np.asarray(getattr(self, name), dtype=float).reshape(3)
            _check(np.all(np.isfinite(v)) and np.linalg.norm(v) > 0, f"laser.{name}",
                   "must be a finite non-zero vector")
            object.__setattr__(self, name, _vec(v / np.linalg.norm(v)))
        _check(abs(float(self.direction @ self.normal)) < 1e-9, "laser.normal",
               "must be perpendicular to laser.direction")
        _in_range("laser.fan_angle_deg", self.fan_angle_deg, 0.0, 170.0, lo_open=True)
        _in_range("laser.waist_um", self.waist_um, 1.0, 5000.0)
        _in_range("laser.waist_distance_mm", self.waist_distance_mm, 0.0, 1e4)
        _in_range("laser.wavelength_nm", self.wavelength_nm, 200.0, 2000.0)
        _in_range("laser.power_mW", self.power_mW, 0.0, 1e4, lo_open=True)
        zr_max = math.pi * (self.waist_um * 1e-3) ** 2 / (self.wavelength_nm * 1e-6)
        _in_range("laser.rayleigh_range_mm", self.rayleigh_range_mm, 0.0, zr_max, lo_open=True,
                  unit=f" (π·w0²/λ for waist_um={self.waist_um:g}, wavelength_nm={self.wavelength_nm:g}; "
                  "a larger value would mean M² < 1)")
        _check(self.fan_profile in ("flat", "gaussian"), "laser.fan_profile",
               f"must be 'flat' or 'gaussian', got {self.fan_profile!r}")

    @property
    def plane(self) -> tuple[np.ndarray, float]:
        """Sheet plane ``(n, d)`` with ``n · X = d``."""
        return self.normal.copy(), float(self.normal @ self.origin_mm)

    @property
    def m_squared(self) -> float:
        """Beam quality factor implied by waist and Rayleigh range."""
        return math.pi * (self.waist_um * 1e-3) ** 2 / (self.wavelength_nm * 1e-6 * self.rayleigh_range_mm)


@dataclass(frozen=True, eq=False)
class Mirror:
    """A rectangular first-surface planar mirror.

    Attributes
    ----------
    name : str
        ``"left"`` or ``"right"`` (seen from the camera).
    center_mm : (3,) float
        Centre of the rectangle.
    normal : (3,) float
        Unit normal pointing to the reflecting side (towards the object).
    u_axis : (3,) float
        Unit in-plane axis of the width (horizontal).
    width_mm, height_mm : float
        Extent along ``u_axis`` and along ``normal × u_axis``.
    reflectance : float, (0, 1]
        Specular reflectance at the laser wavelength.
    """

    name: str
    center_mm: np.ndarray
    normal: np.ndarray
    u_axis: np.ndarray
    width_mm: float
    height_mm: float
    reflectance: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center_mm", _vec(self.center_mm))
        for name in ("normal", "u_axis"):
            v = np.asarray(getattr(self, name), dtype=float).reshape(3)
            _check(np.linalg.norm(v) > 0, f"mirror {self.name}.{name}", "must be non-zero")
            object.__setattr__(self, name, _vec(v / np.linalg.norm(v)))
        _check(abs(float(self.normal @ self.u_axis)) < 1e-9, f"mirror {self.name}.u_axis",
               "must lie in the mirror plane")
        _in_range(f"mirror {self.name}.width_mm", self.width_mm, 1.0, 2000.0)
        _in_range(f"mirror {self.name}.height_mm", self.height_mm, 1.0, 2000.0)
        _in_range(f"mirror {self.name}.reflectance", self.reflectance, 0.0, 1.0, lo_open=True)

    @property
    def v_axis(self) -> np.ndarray:
        return np.cross(self.normal, self.u_axis)

    @property
    def d_mm(self) -> float:
        return float(self.normal @ self.center_mm)

    @property
    def plane(self) -> tuple[np.ndarray, float]:
        return self.normal.copy(), self.d_mm

    @property
    def T(self) -> np.ndarray:
        """Mirror matrix ``T_pi`` (paper Eq. 3) in the world frame."""
        return mirror_matrix(self.normal, self.d_mm)

    @property
    def corners_mm(self) -> np.ndarray:
        """(4, 3) corners, counter-clockwise seen from the reflecting side."""
        u = self.u_axis * self.width_mm / 2.0
        v = self.v_axis * self.height_mm / 2.0
        c = self.center_mm
        return np.array([c - u - v, c + u - v, c + u + v, c - u + v])


@dataclass(frozen=True)
class Stage:
    """Linear Z stage that moves the object along its nominal axis between sections.

    Attributes
    ----------
    pitch_mm : float
        Default step between sections.
    travel_mm : float
        Total travel.
    """

    pitch_mm: float = 0.68
    travel_mm: float = 100.0

    def __post_init__(self) -> None:
        _in_range("stage.pitch_mm", self.pitch_mm, 0.0, 100.0, lo_open=True)
        _in_range("stage.travel_mm", self.travel_mm, 0.0, 2000.0, lo_open=True)


@dataclass(frozen=True, eq=False)
class Rig:
    """The whole measuring head in the world frame."""

    name: str
    camera: Camera
    laser: LaserSheet
    mirrors: tuple[Mirror, ...]
    stage: Stage
    design: "RigDesign | None" = None
    sensor: SensorModel | None = None  # None → the default (the paper's camera)

    def __post_init__(self) -> None:

        if self.sensor is None:
            object.__setattr__(self, "sensor", SensorModel())
        _check(isinstance(self.sensor, SensorModel), "sensor", "must be a SensorModel")
        names = [m.name for m in self.mirrors]
        _check(len(set(names)) == len(names), "mirrors", f"names must be unique, got {names}")
        cam_c = self.camera.center_mm
        for m in self.mirrors:
            _check(float(m.normal @ cam_c) > m.d_mm, f"mirror {m.name}",
                   "the camera must be on the reflecting side of the mirror")
            _check(float(m.normal @ self.laser.origin_mm) > m.d_mm, f"mirror {m.name}",
                   "the laser must be on the reflecting side of the mirror")

    def mirror(self, name: str) -> Mirror:
        for m in self.mirrors:
            if m.name == name:
                return m
        raise KeyError(f"no mirror named {name!r}; have {[m.name for m in self.mirrors]}")


@dataclass(frozen=True)
class RigDesign:
    """Design parameters from which :func:`build_rig` places every component.

    Attributes
    ----------
    alpha_deg : float, [10, 80]
        Triangulation angle between the laser plane and the camera's optical axis.
    beta_deg : float, [60, 150]
        Angle between the two mirrors (paper: 90°).
    camera_distance_mm : float
        Distance from the camera centre to the point where its optical axis meets the laser plane.
    camera_target_y_mm : float
        That point is ``(0, camera_target_y_mm, 0)``; slightly behind the axis so that the
        direct view and the mirror views share the frame.
    laser_distance_mm : float
        Distance from the fan apex to the object axis (laser at ``(0, −L, 0)``, fan towards +Y).
    mirror_corner_distance_mm : float
        Distance from the object axis to the mirrors' common edge (at ``(0, +D, z)``).
    mirror_width_mm, mirror_height_mm : float
        Size of each mirror (width measured from the corner outwards).
    mirror_center_z_mm : float
        Height of the mirrors' centre above the laser plane.
    mirror_reflectance : float, (0, 1]
    max_object_radius_mm : float
        Largest object the rig must hold; the mirrors must clear it.
    """

    alpha_deg: float = 40.0
    beta_deg: float = 90.0
    camera_distance_mm: float = 180.0
    camera_target_y_mm: float = 20.0
    laser_distance_mm: float = 100.0
    mirror_corner_distance_mm: float = 60.0
    mirror_width_mm: float = 105.0
    mirror_height_mm: float = 80.0
    mirror_center_z_mm: float = 20.0
    mirror_reflectance: float = 0.92
    max_object_radius_mm: float = 20.0

    def __post_init__(self) -> None:
        _in_range("design.alpha_deg", self.alpha_deg, 10.0, 80.0)
        _in_range("design.beta_deg", self.beta_deg, 60.0, 150.0)
        _in_range("design.camera_distance_mm", self.camera_distance_mm, 30.0, 5000.0)
        _in_range("design.camera_target_y_mm", self.camera_target_y_mm, -100.0, 100.0)
        _in_range("design.laser_distance_mm", self.laser_distance_mm, 10.0, 5000.0)
        _in_range("design.mirror_corner_distance_mm", self.mirror_corner_distance_mm, 1.0, 2000.0)
        _in_range("design.mirror_width_mm", self.mirror_width_mm, 1.0, 2000.0)
        _in_range("design.mirror_height_mm", self.mirror_height_mm, 1.0, 2000.0)
        _in_range("design.mirror_center_z_mm", self.mirror_center_z_mm, -1000.0, 1000.0)
        _in_range("design.mirror_reflectance", self.mirror_reflectance, 0.0, 1.0, lo_open=True)
        _in_range("design.max_object_radius_mm", self.max_object_radius_mm, 0.5, 500.0)
        clearance = self.mirror_corner_distance_mm * math.sin(math.radians(self.beta_deg) / 2.0)
        _check(clearance > self.max_object_radius_mm, "design.mirror_corner_distance_mm",
               f"mirrors pass {clearance:.3g} mm from the axis, inside max_object_radius_mm="
               f"{self.max_object_radius_mm:g}; must be > "
               f"{self.max_object_radius_mm / math.sin(math.radians(self.beta_deg) / 2.0):.4g} "
               f"for beta_deg={self.beta_deg:g}")
        _check(self.laser_distance_mm > self.max_object_radius_mm, "design.laser_distance_mm",
               f"must exceed max_object_radius_mm={self.max_object_radius_mm:g}, got "
               f"{self.laser_distance_mm:g}")


def _mirrors(design: RigDesign) -> tuple[Mirror, Mirror]:
    half = math.radians(design.beta_deg) / 2.0
    corner = np.array([0.0, design.mirror_corner_distance_mm, design.mirror_center_z_mm])
    out = []
    for name, sx in (("left", -1.0), ("right", 1.0)):
        # In-plane direction from the corner outwards, towards the camera side.
        u = np.array([sx * math.sin(half), -math.cos(half), 0.0])
        normal = np.array([-sx * math.cos(half), -math.sin(half), 0.0])
        center = corner + u * design.mirror_width_mm / 2.0
        out.append(Mirror(name=name, center_mm=center, normal=normal, u_axis=u,
                          width_mm=design.mirror_width_mm, height_mm=design.mirror_height_mm,
                          reflectance=design.mirror_reflectance))
    return out[0], out[1]


def build_rig(design: RigDesign, *, camera: dict | None = None, laser: dict | None = None,
              stage: dict | None = None, sensor: dict | None = None, name: str = "custom") -> Rig:
    """Place camera, laser and mirrors from design parameters.

    Parameters
    ----------
    design : RigDesign
    camera : dict
        Camera fields other than the pose (``width_px``, ``pixel_pitch_um``, ...);
        ``focus_distance_mm`` defaults to the depth of the object axis in the laser plane
        (focus on the object; the mirror views lie farther and are defocused).
    laser : dict
        Laser fields other than origin/direction/normal (``fan_angle_deg``, ``waist_um``, ...).
    stage : dict
        :class:`Stage` fields.
    sensor : dict
        :class:`lts360.scenes.sensor.SensorModel` fields (EMVA 1288 parameters).
    """
    camera = dict(camera or {})
    laser = dict(laser or {})
    a = math.radians(design.alpha_deg)
    target = np.array([0.0, design.camera_target_y_mm, 0.0])
    position = target + design.camera_distance_mm * np.array([0.0, -math.cos(a), math.sin(a)])
    R, t = look_at(position, target, up=(0.0, 0.0, 1.0))
    # Focus on the object: the depth of the nominal axis in the laser plane (the origin).
    camera.setdefault("focus_distance_mm", float(R[2] @ (np.zeros(3) - position)))
    try:
        cam = Camera(R=R, t_mm=t, **camera)
        las = _laser(design, laser)
        stg = Stage(**(stage or {}))
    except TypeError as exc:  # unknown keyword in a table
        raise RigError(str(exc).replace("__init__() ", "")) from None

    sens = SensorModel.from_dict(sensor or {})
    return Rig(name=name, camera=cam, laser=las, mirrors=_mirrors(design), stage=stg, design=design,
               sensor=sens)


def _laser(design: RigDesign, fields: dict) -> LaserSheet:
    """The laser of a design: apex at ``(0, −L, 0)``, fan towards +Y in the plane ``z = 0``."""
    fields = dict(fields)
    fields.setdefault("waist_distance_mm", design.laser_distance_mm)
    return LaserSheet(origin_mm=(0.0, -design.laser_distance_mm, 0.0), direction=(0.0, 1.0, 0.0),
                      normal=(0.0, 0.0, 1.0), **fields)

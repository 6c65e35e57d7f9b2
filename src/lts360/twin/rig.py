"""The twin's rig: the calibration's geometry with the rig file's optics, laser and sensor.

The twin renders in the calibration's measurement frame (its world): the camera is the
calibrated one (``K``, distortion, pose), the mirrors and the laser sheet lie in the calibrated
planes.

The mirrors play two parts.  The camera sees the section through them: the twin's camera side
uses the calibrated mirrors as they are, so that the twin's image of a profile lies where the
measurement's model (the same planes) puts it.  The laser light reaches the section's back
through them: the design premise is that the mirrors are perpendicular to the sheet, so the
reflected sheet stays in the sheet's plane (DESIGN.md); an estimated calibration's mirrors
are 0.03–0.05° out of perpendicular to its estimated plane (errors of the estimates, not of
the rig), and reflecting the twin's sheet in them would light the back ~2δ·(mirror distance)
off the plane and correct the mirror views by tens of µm no real rig shows.  So the laser
side uses each calibrated mirror turned about its line in the calibrated sheet plane until
perpendicular to it (:func:`laser_side_mirrors`): the same line where light meets it, the
reflected sheet in the plane.  What this assumes: the real mirrors are perpendicular to the
real sheet to well within the calibration's errors (a real tilt δ moves the back's light by
2δ·L out of the plane, which neither the measurement nor the twin models).  What a calibration does not estimate comes from the rig file: focal length, f-number
and focus distance (the thin lens's blur), pixel pitch, the sheet's waist and Rayleigh range,
the fan, the power, the mirrors' extents and reflectance, the sensor.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from lts360.recon.model import Calibration
from lts360.scenes.rig import Camera, Mirror, Rig

__all__ = ["CalibratedCamera", "twin_rig", "twin_design", "recorded_rig", "laser_side_mirrors", "MAX_FRAME_MISMATCH_MM",
           "MAX_MIRROR_TILT_DEG"]

#: The rig file's camera centre and the calibrated one (measurement frame) may differ by at most
#: this much: more means the calibration's measurement frame is not the rig file's world frame.
MAX_FRAME_MISMATCH_MM = 25.0
#: Largest tilt of a calibrated mirror out of perpendicular to the calibrated laser plane that
#: the twin accepts.  An estimated calibration's planes carry ~0.03–0.05° (the laser side
#: then uses the mirrors turned perpendicular, :func:`laser_side_mirrors`); a tilt beyond this
#: is not a rig of this design (mirrors parallel to the object axis, the sheet across it).
MAX_MIRROR_TILT_DEG = 0.5
#: A mirror tilted less than this (rad) is taken as perpendicular: the laser side uses it as
#: it is (a true calibration from a frame's ``frame.json``: float round-off only).
PERPENDICULAR_TOL_RAD = 1e-9


@dataclass(frozen=True, eq=False)
class CalibratedCamera(Camera):
    """A :class:`~lts360.scenes.rig.Camera` whose intrinsic matrix is the calibrated ``K``
    (``fx ≠ fy``, skew and principal point as estimated) instead of ``f / pitch``."""

    K_px: np.ndarray | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        K = np.asarray(self.K_px, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0
                and np.allclose(K[2], [0, 0, 1])):
            raise ValueError(f"K_px: must be a finite [[fx, s, cx], [0, fy, cy], [0, 0, 1]], "
                             f"got {K.tolist()}")
        K.setflags(write=False)
        object.__setattr__(self, "K_px", K)

    @property
    def K(self) -> np.ndarray:
        return self.K_px.copy()


def _plane_meas(cal: Calibration, n_cam, d_cam: float) -> tuple[np.ndarray, float]:
    """A camera-frame plane ``n · X_cam = d`` in the measurement frame."""
    R, t = cal.R_cam_meas, cal.t_cam_meas_mm
    n = R.T @ np.asarray(n_cam, float)
    return n, float(d_cam - np.asarray(n_cam, float) @ t)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _mirror(cal: Calibration, design: Mirror, cam_center: np.ndarray) -> Mirror:
    mp = cal.mirror(design.name)
    n, d = _plane_meas(cal, mp.n, mp.d_mm)
    if n @ cam_center < d:  # the reflecting side faces the camera
        n, d = -n, -d
    if mp.corners_mm is not None:
        c = (mp.corners_mm - cal.t_cam_meas_mm) @ cal.R_cam_meas  # camera → measurement
        center = c.mean(axis=0)
        u = c[1] - c[0]
        width, height = float(np.linalg.norm(u)), float(np.linalg.norm(c[3] - c[0]))
    else:  # the rig file's rectangle, moved onto the calibrated plane
        center = design.center_mm - (design.center_mm @ n - d) * n
        u, width, height = design.u_axis, design.width_mm, design.height_mm
    u = _unit(u - (u @ n) * n)
    center = center - (center @ n - d) * n
    return Mirror(name=design.name, center_mm=center, normal=n, u_axis=u, width_mm=width,
                  height_mm=height, reflectance=design.reflectance)


def twin_rig(cal: Calibration, design: Rig) -> Rig:
    """The rig the twin renders: ``cal``'s geometry in its measurement frame, ``design``'s
    optics, laser and sensor (see the module docstring).

    Raises
    ------
    ValueError
        The calibration's mirrors are not the rig file's, its measurement frame is not the
        rig file's world frame (camera centres more than :data:`MAX_FRAME_MISMATCH_MM` apart),
        or a mirror is tilted out of perpendicular to the laser plane by more than
        :data:`MAX_MIRROR_TILT_DEG` (a smaller tilt is fine: :func:`laser_side_mirrors`).
    """
    cam = design.camera
    w, h = cal.image_size
    R, t = cal.R_cam_meas, cal.t_cam_meas_mm
    camera = CalibratedCamera(
        width_px=int(w), height_px=int(h),
        pixel_pitch_um=cam.pixel_pitch_um * cam.width_px / w,
        focal_length_mm=cam.focal_length_mm, f_number=cam.f_number,
        focus_distance_mm=cam.focus_distance_mm, distortion=cal.dist, R=R, t_mm=t,
        K_px=cal.K)
    off = float(np.linalg.norm(camera.center_mm - cam.center_mm))
    if off > MAX_FRAME_MISMATCH_MM:
        raise ValueError(f"twin: the calibrated camera centre is {off:.1f} mm from the rig "
                         f"file's (more than {MAX_FRAME_MISMATCH_MM:g} mm): the calibration's "
                         f"measurement frame is not rig {design.name!r}'s world frame")
    names = set(cal.mirror_names)
    if names != {m.name for m in design.mirrors}:
        raise ValueError(f"twin: the calibration's mirrors {sorted(names)} are not rig "
                         f"{design.name!r}'s {sorted(m.name for m in design.mirrors)}")
    mirrors = tuple(_mirror(cal, m, camera.center_mm) for m in design.mirrors)
    tilts = {m.name: math.degrees(math.asin(min(abs(float(m.normal[2])), 1.0))) for m in mirrors}
    worst = max(tilts, key=tilts.get)
    if tilts[worst] > MAX_MIRROR_TILT_DEG:
        raise ValueError(
            f"twin: the calibration's mirror {worst!r} is {tilts[worst]:.4f}° out of "
            f"perpendicular to its laser plane (at most {MAX_MIRROR_TILT_DEG:g}°: the mirrors "
            f"must stand perpendicular to the sheet); recalibrate the mirrors or the plane")
    las = design.laser
    # The sheet is the calibrated plane z = 0 of the measurement frame; the apex and the fan's
    # direction are the rig file's, moved into it.
    sign = 1.0 if las.normal[2] >= 0 else -1.0
    direction = _unit(np.array([las.direction[0], las.direction[1], 0.0]))
    laser = dataclasses.replace(las, origin_mm=np.array([las.origin_mm[0], las.origin_mm[1], 0.0]),
                                direction=direction, normal=np.array([0.0, 0.0, sign]))
    return Rig(name=f"{design.name}-twin", camera=camera, laser=laser, mirrors=mirrors,
               stage=design.stage, design=None, sensor=design.sensor)


def _perpendicular(m: Mirror, n_l: np.ndarray, d_l: float) -> Mirror:
    """``m`` turned about its line in the sheet plane ``n_l · X = d_l`` until perpendicular to
    the sheet (the same rectangle, centre moved onto the new plane along its normal)."""
    n = m.normal - (m.normal @ n_l) * n_l
    s = float(np.linalg.norm(n))
    n = n / s
    # A point of the old plane's line in the sheet: the foot of the centre's projection.
    c = m.center_mm
    # The line: n_old·X = d_old and n_l·X = d_l; the point of it nearest the centre.
    A = np.vstack([m.normal, n_l])
    b = np.array([m.d_mm, d_l])
    p = c - A.T @ np.linalg.solve(A @ A.T, A @ c - b)
    center = c - ((c - p) @ n) * n
    u = m.u_axis - (m.u_axis @ n) * n
    return Mirror(name=m.name, center_mm=center, normal=n, u_axis=_unit(u),
                  width_mm=m.width_mm, height_mm=m.height_mm, reflectance=m.reflectance)


def laser_side_mirrors(rig: Rig) -> tuple[Mirror, ...] | None:
    """The mirrors the twin's laser light meets: ``rig``'s mirrors, each turned about its line
    in the laser sheet's plane until perpendicular to the sheet (module docstring); ``None``
    when all are perpendicular already (within :data:`PERPENDICULAR_TOL_RAD`): the laser side
    is then the rig's own."""
    n_l, d_l = rig.laser.plane
    n_l = _unit(n_l)
    if all(abs(float(m.normal @ n_l)) <= PERPENDICULAR_TOL_RAD for m in rig.mirrors):
        return None
    return tuple(_perpendicular(m, n_l, float(d_l)) for m in rig.mirrors)


def recorded_rig(cal: Calibration) -> Rig | None:
    """The rig ``cal.optics`` records (``None`` without a record)."""
    import tomllib

    from lts360.scenes.rig_io import rig_from_dict

    text = cal.optics.get("rig_toml")
    if not text:
        return None
    try:
        return rig_from_dict(tomllib.loads(text), default_name=cal.optics.get("rig", "custom"))
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise ValueError(f"the calibration's optics.rig_toml is not a valid rig ({exc})") \
            from None


def twin_design(cal: Calibration, override: str | None = None) -> Rig:
    """The rig file whose optics, laser and sensor the twin of ``cal`` uses.

    ``cal.optics`` records the rig the calibration (or the frame) was made with; ``override``
    (a preset name or a TOML file: ``--twin-rig``) replaces it, e.g. for a lens set to
    another f-number since, and must have the same design geometry (α, β, distances, mirror
    extents) as the recorded one.

    Raises
    ------
    ValueError
        (one line) The override's geometry is not the recorded rig's, or the calibration
        records no optics (an older calibration file) and no override is given.
    """
    from lts360.scenes.rig_io import load_rig

    recorded = recorded_rig(cal)
    if override is None:
        if recorded is None:
            raise ValueError("the calibration records no optics (a calibration file older than "
                             "its optics record, or a frame without its rig): name the rig it "
                             "was made with (--twin-rig PRESET|FILE)")
        return recorded
    design = load_rig(override)
    if recorded is not None and recorded.design is not None and design.design is not None:
        a, b = dataclasses.asdict(recorded.design), dataclasses.asdict(design.design)
        for key in a:
            if not np.allclose(np.asarray(a[key], float), np.asarray(b[key], float),
                               rtol=1e-9, atol=1e-9):
                raise ValueError(f"rig {design.name!r} is not the rig the calibration was made "
                                 f"with ({cal.optics.get('rig', recorded.name)!r}): design."
                                 f"{key} {b[key]} against {a[key]}")
    return design

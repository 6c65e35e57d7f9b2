"""The twin's rig: the calibration's geometry with the rig file's optics, laser and sensor.

The twin renders in the calibration's measurement frame (its world): the camera is the
calibrated one (``K``, distortion, pose), the mirrors and the laser sheet lie in the calibrated
planes.  What a calibration does not estimate comes from the rig file: focal length, f-number
and focus distance (the thin lens's blur), pixel pitch, the sheet's waist and Rayleigh range,
the fan, the power, the mirrors' extents and reflectance, the sensor.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from lts360.recon.calibration.model import Calibration
from lts360.scenes.rig import Camera, Mirror, Rig

__all__ = ["CalibratedCamera", "twin_rig", "MAX_FRAME_MISMATCH_MM", "MAX_MIRROR_TILT_DEG"]

#: The rig file's camera centre and the calibrated one (measurement frame) may differ by at most
#: this much: more means the calibration's measurement frame is not the rig file's world frame.
MAX_FRAME_MISMATCH_MM = 25.0
#: Largest tilt of a calibrated mirror out of perpendicular to the calibrated laser plane that
#: the twin accepts.  The twin reflects the sheet in its mirrors as it renders: a mirror tilted
#: by δ lights the back of the section about 2δ·(mirror distance) off the plane the
#: measurement assumes, and the mirror views then read tens of µm off (measured: +30 / +50 µm
#: for 0.03° / 0.05°, ~1 µm per 0.001°).  A calibration's planes carry errors of that size, so
#: a twin built on them would correct a bias no real rig with perpendicular mirrors shows.
MAX_MIRROR_TILT_DEG = 0.0005


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
        :data:`MAX_MIRROR_TILT_DEG`.
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
            f"perpendicular to its laser plane (at most {MAX_MIRROR_TILT_DEG:g}°): the twin "
            f"would light the back of the section off the plane and correct the mirror views "
            f"by tens of µm no real rig shows; it needs the true rig's calibration (a frame's "
            f"frame.json)")
    las = design.laser
    # The sheet is the calibrated plane z = 0 of the measurement frame; the apex and the fan's
    # direction are the rig file's, moved into it.
    sign = 1.0 if las.normal[2] >= 0 else -1.0
    direction = _unit(np.array([las.direction[0], las.direction[1], 0.0]))
    laser = dataclasses.replace(las, origin_mm=np.array([las.origin_mm[0], las.origin_mm[1], 0.0]),
                                direction=direction, normal=np.array([0.0, 0.0, sign]))
    return Rig(name=f"{design.name}-twin", camera=camera, laser=laser, mirrors=mirrors,
               stage=design.stage, design=None, sensor=design.sensor)

"""Files of a rendered frame: atomic writers for PNG, EXR, PLY and the ``frame.json`` truth."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

__all__ = ["atomic_path", "write_png", "write_exr", "read_exr", "write_json",
           "rig_truth", "rig_record"]


class atomic_path:
    """Context manager yielding a temporary sibling path that is renamed onto ``path`` on success.

    >>> with atomic_path("out/image.png") as tmp:   # doctest: +SKIP
    ...     cv2.imwrite(str(tmp), img)
    """

    def __init__(self, path) -> None:
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.stem}.tmp{self.path.suffix}")

    def __enter__(self) -> Path:
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            os.replace(self.tmp, self.path)
        elif self.tmp.exists():
            self.tmp.unlink()


def write_png(path, image: np.ndarray) -> None:
    """8-bit or 16-bit greyscale PNG (lossless)."""
    import cv2

    img = np.asarray(image)
    if img.dtype not in (np.uint8, np.uint16) or img.ndim != 2:
        raise ValueError(f"image must be a 2-D uint8 or uint16 array, got {img.dtype} {img.shape}")
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise OSError(f"could not write {path}")


def write_exr(path, channels: dict[str, np.ndarray]) -> None:
    """float32 OpenEXR with the given named channels (ZIP compression)."""
    import OpenEXR

    data = {name: np.ascontiguousarray(arr, dtype=np.float32) for name, arr in channels.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, data) as f:
            f.write(str(tmp))


def read_exr(path) -> dict[str, np.ndarray]:
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        return {name: np.array(ch.pixels, dtype=np.float32) for name, ch in f.channels().items()}


def write_json(path, data: dict) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, default=_jsonable))


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value)}")


def rig_record(rig, source: str | None = None) -> dict:
    """What a frame or a calibration records of the rig it was made with (for the twin):
    ``rig`` (the preset name or file given, else the rig's name) and ``rig_toml`` (its TOML:
    design, lens, sheet, sensor; absent for a rig not built from a design)."""
    from lts360.scenes.rig import RigError
    from lts360.scenes.rig_io import rig_to_toml

    out = {"rig": str(source) if source else rig.name}
    try:
        out["rig_toml"] = rig_to_toml(rig)
    except RigError:
        pass
    return out


def rig_truth(rig, K: np.ndarray, image_size: tuple[int, int]) -> dict:
    """The true rig in world millimetres, in the ``frame.json`` layout.

    ``camera.R``/``camera.t`` map world to camera (``X_cam = R X_world + t``); ``K`` and
    ``image_size`` are those of the written image (scaled with ``--scale``); mirror planes
    and the laser plane are ``n · X = d`` in the world frame; ``rig`` is :func:`rig_record`.
    """
    cam = rig.camera
    n_l, d_l = rig.laser.plane
    return {
        "rig": rig_record(rig),
        "camera": {"K": K, "dist": cam.distortion, "R": cam.R, "t": cam.t_mm,
                   "image_size": list(image_size), "f_number": cam.f_number,
                   "focus_distance_mm": cam.focus_distance_mm, "pixel_pitch_um": cam.pixel_pitch_um
                   * cam.width_px / image_size[0], "center_mm": cam.center_mm},
        "mirrors": [{"name": m.name, "n": m.normal, "d": m.d_mm, "corners": m.corners_mm,
                     "reflectance": m.reflectance} for m in rig.mirrors],
        "laser": {"plane": {"n": n_l, "d": d_l}, "origin_mm": rig.laser.origin_mm,
                  "direction": rig.laser.direction, "fan_angle_deg": rig.laser.fan_angle_deg,
                  "wavelength_nm": rig.laser.wavelength_nm, "power_mW": rig.laser.power_mW,
                  "waist_um": rig.laser.waist_um, "rayleigh_range_mm": rig.laser.rayleigh_range_mm},
    }

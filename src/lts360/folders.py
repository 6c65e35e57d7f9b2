"""The frame and scan folder format, read and written in one place.

A *frame folder* holds one image and its truth: ``image.png`` (the sensor's image),
``radiance.exr`` and other render outputs, and ``frame.json`` (the true rig, the object's
spec, the stage position, the render settings; a rendered frame's ``frame.json`` is also a
perfect calibration).  A *scan folder* holds ``scan.json`` (the object, the pitch or the
acquisition, and the list of its sections with their folder names and stage positions) and
one frame folder per section, ``section_0000`` …  Every module that reads or writes these
folders goes through this one; no other module spells the file names.

Depends on nothing of lts360, so the reconstruction (which reads a frame's stage position
and a scan's sections) may import it like every other layer.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = ["FRAME_FILE", "SCAN_FILE", "IMAGE_FILE", "frame_file", "scan_file", "image_file",
           "is_frame", "is_scan", "section_dir_name", "read_frame_meta", "read_scan",
           "section_dirs", "frame_dirs", "frame_metas", "first_frame_meta", "write_json_atomic",
           "write_scan_meta", "read_image"]

FRAME_FILE = "frame.json"
SCAN_FILE = "scan.json"
IMAGE_FILE = "image.png"


def frame_file(folder) -> Path:
    """``folder/frame.json``."""
    return Path(folder) / FRAME_FILE


def scan_file(folder) -> Path:
    """``folder/scan.json``."""
    return Path(folder) / SCAN_FILE


def image_file(folder) -> Path:
    """``folder/image.png``."""
    return Path(folder) / IMAGE_FILE


def is_frame(folder) -> bool:
    """A frame folder: it holds ``frame.json``."""
    return frame_file(folder).is_file()


def is_scan(folder) -> bool:
    """A scan folder: it holds ``scan.json``."""
    return scan_file(folder).is_file()


def section_dir_name(k: int) -> str:
    """The folder of section ``k`` of a scan: ``section_0000`` …"""
    return f"section_{k:04d}"


def read_frame_meta(folder) -> dict:
    """The parsed ``frame.json`` of a frame folder."""
    return json.loads(frame_file(folder).read_text())


def read_scan(folder) -> dict:
    """The parsed ``scan.json`` of a scan folder."""
    return json.loads(scan_file(folder).read_text())


def section_dirs(folder) -> list[Path]:
    """The section folders of a scan folder, in scan order.

    Raises
    ------
    ValueError
        ``scan.json`` has no list of sections with their ``dir``.
    """
    sections = read_scan(folder).get("sections")
    if not isinstance(sections, list) or not all(isinstance(s, dict) and "dir" in s
                                                 for s in sections):
        raise ValueError(f"{scan_file(folder)}: no list of 'sections' with their 'dir'")
    return [Path(folder) / s["dir"] for s in sections]


def frame_dirs(folder, what: str = "--truth") -> list[Path]:
    """The frame folders of a frame folder (itself) or of a scan folder (its sections).

    Raises
    ------
    ValueError
        ``folder`` holds neither ``frame.json`` nor ``scan.json`` (``what`` names the option).
    """
    if is_scan(folder):
        return section_dirs(folder)
    if is_frame(folder):
        return [Path(folder)]
    raise ValueError(f"{what}: {str(folder)!r} holds neither {FRAME_FILE} nor {SCAN_FILE}")


def frame_metas(folder, what: str = "--truth") -> list[dict]:
    """The ``frame.json`` of every frame of a frame or scan folder (:func:`frame_dirs`)."""
    return [read_frame_meta(d) for d in frame_dirs(folder, what)]


def first_frame_meta(folder) -> dict:
    """The ``frame.json`` of a frame folder, or of the first section of a scan folder."""
    return read_frame_meta(frame_dirs(folder)[0])


def write_json_atomic(path, data, *, indent: int | None = None) -> None:
    """``data`` as JSON through a temporary sibling name (never a half-written file)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=indent))
    os.replace(tmp, path)


def write_scan_meta(folder, data: dict) -> None:
    """Write a scan folder's ``scan.json``."""
    write_json_atomic(scan_file(folder), data)


def read_image(path):
    """A greyscale image (numpy array) from a file (8 or 16 bit as stored; colour converted to
    grey).

    Raises
    ------
    ValueError
        Not a readable image.
    """
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path}: not a readable image")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img

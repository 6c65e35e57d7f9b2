"""Measure a scan: images at stage positions → one cloud organised by (θ, section).

Inputs are what a real rig gives: grey images and the stage position of each (read from a
rendered frame's ``frame.json`` ``stage.z_mm`` — the stage encoder's reading — or from a pitch).
Nothing here reads the object or its truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.recon.calibration.model import Calibration
from lts360.recon.triangulation.cloud import VIEW_CODES, Cloud
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import InverseResult, inverse_triangulate, plan_inverse

__all__ = ["Section", "collect_sections", "measure_sections", "result_to_cloud", "read_image"]


@dataclass(frozen=True)
class Section:
    """One image of a scan and the stage position it was taken at."""

    image_path: Path
    z_mm: float


def read_image(path: Path) -> np.ndarray:
    """A greyscale image from a file (8 or 16 bit as stored; colour converted to grey)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path}: not a readable image")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img


def collect_sections(inputs, *, pitch_mm: float | None = None) -> list[Section]:
    """Sections from frame directories, scan directories (``scan.json``) or image files.

    Frame directories give their own stage position; bare images are placed at
    ``k · pitch_mm`` in the order given.
    """
    out: list[Section] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir() and (p / "scan.json").is_file():
            scan = json.loads((p / "scan.json").read_text())
            out += [Section(p / s["dir"] / "image.png", float(s["z_mm"])) for s in scan["sections"]]
        elif p.is_dir() and (p / "image.png").is_file():
            z = 0.0
            if (p / "frame.json").is_file():
                z = float(json.loads((p / "frame.json").read_text()).get("stage", {}).get("z_mm", 0.0))
            out.append(Section(p / "image.png", z))
        elif p.is_file():
            if pitch_mm is None:
                raise ValueError(f"{p}: a bare image needs --pitch-mm to place it on the stage")
            out.append(Section(p, len(out) * float(pitch_mm)))
        else:
            raise ValueError(f"{p}: neither a frame directory, a scan directory nor an image file")
    if not out:
        raise ValueError("no images to measure")
    return out


def result_to_cloud(result: InverseResult, *, z_mm: float, section: int) -> Cloud:
    """Every θ of every view (valid or not, with its quality) as cloud rows."""
    parts = []
    for name, v in result.views.items():
        m = v.window
        n = int(m.sum())
        r = v.r_mm[m]
        th = v.theta_rad[m]
        pts = np.column_stack([r * np.cos(th), r * np.sin(th), np.full(n, float(z_mm))])
        code = VIEW_CODES.get(name, 255)
        intensity = np.nan_to_num(v.intensity[m]).astype(np.float32)
        quality = v.quality[m].astype(np.uint8)
        parts.append(Cloud(pts, th, r, np.full(n, code, np.uint8), quality,
                           np.full(n, section, np.int32), intensity))
    return Cloud.concatenate(parts)


def classic_to_cloud(res: dict, *, z_mm: float, section: int) -> Cloud:
    """Points of :func:`lts360.recon.triangulation.classic.classic_triangulate` as cloud rows."""
    parts = []
    for name, v in res.items():
        n = len(v["r_mm"])
        pts = np.column_stack([v["points_meas_mm"][:, :2], np.full(n, float(z_mm))])
        parts.append(Cloud(pts, v["theta_rad"], v["r_mm"], np.full(n, VIEW_CODES.get(name, 255), np.uint8),
                           np.zeros(n, np.uint8), np.full(n, section, np.int32),
                           v["intensity"].astype(np.float32)))
    return Cloud.concatenate(parts)


def measure_sections(sections: list[Section], cal: Calibration, grid: CylGrid, *,
                     peak: str = "centroid", compensate: bool = False, backend: str = "auto",
                     method: str = "inverse", progress=None) -> Cloud:
    """Inverse triangulation of every section with one plan.

    ``backend``: ``numpy`` (the reference), ``llvm`` or ``cuda`` (the Dr.Jit kernel of the
    centroid detector, :class:`lts360.recon.triangulation.fast.FastInverse`), or ``auto`` (Dr.Jit LLVM for
    the centroid when available, numpy otherwise).
    """
    if method == "classic":
        from lts360.recon.triangulation.classic import classic_triangulate, view_regions

        regions = view_regions(cal, grid)
        items = list(enumerate(sections))
        return Cloud.concatenate([
            classic_to_cloud(classic_triangulate(read_image(s.image_path), cal, grid, regions=regions),
                             z_mm=s.z_mm, section=k)
            for k, s in (progress(items) if progress else items)])
    if method != "inverse":
        raise ValueError(f"method must be 'inverse' or 'classic', got {method!r}")
    if backend not in ("auto", "numpy", "llvm", "cuda"):
        raise ValueError(f"backend must be auto, numpy, llvm or cuda, got {backend!r}")
    fast = None
    if peak == "centroid" and backend != "numpy":
        from lts360.recon.triangulation.fast import FastInverse

        try:
            fast = FastInverse(plan_inverse(cal, grid, precompute=False),
                               backend="llvm" if backend == "auto" else backend)
        except RuntimeError:
            if backend != "auto":
                raise
    elif backend in ("llvm", "cuda"):
        raise ValueError(f"the Dr.Jit backend implements the centroid detector only, not {peak!r}")
    plan = fast.plan if fast is not None else plan_inverse(cal, grid, precompute=True)
    clouds = []
    items = list(enumerate(sections))
    for k, s in (progress(items) if progress else items):
        img = read_image(s.image_path)
        if fast is not None:
            res = fast(img, compensate=compensate)
        else:
            res = inverse_triangulate(img, cal, grid, peak=peak, compensate=compensate, plan=plan)
        clouds.append(result_to_cloud(res, z_mm=s.z_mm, section=k))
    return Cloud.concatenate(clouds)

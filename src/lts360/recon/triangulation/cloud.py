"""Measured point clouds organised by (θ, section), with view labels and quality flags.

Written as binary little-endian PLY with per-vertex attributes, readable by trimesh, Open3D and
any PLY reader: ``x y z`` (measurement frame, mm; ``z`` is the stage position of the
section), ``theta`` (rad), ``radius`` (mm), ``view`` (uchar, see :data:`VIEW_CODES`),
``quality`` (uchar, :class:`lts360.recon.triangulation.peaks.Quality`; points that gave no valid
measurement are NaN and keep the reason here),
``section`` (int), ``intensity`` (float, peak grey value).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["VIEW_CODES", "VIEW_NAMES", "Cloud", "write_cloud", "read_cloud",
           "read_cloud_rejections", "read_cloud_twin", "read_cloud_master"]

VIEW_CODES = {"direct": 0, "left": 1, "right": 2, "left-right": 3, "right-left": 4, "fused": 9}
VIEW_NAMES = {v: k for k, v in VIEW_CODES.items()}

_FIELDS = (("x", "<f8", "double"), ("y", "<f8", "double"), ("z", "<f8", "double"),
           ("theta", "<f8", "double"), ("radius", "<f8", "double"), ("view", "u1", "uchar"),
           ("quality", "u1", "uchar"), ("section", "<i4", "int"), ("intensity", "<f4", "float"))
#: The optional last property: the exposure time of the point's row (s).
_TIME = ("time", "<f8", "double")


@dataclass(frozen=True, eq=False)
class Cloud:
    """A measured point cloud (one row per point).

    Attributes
    ----------
    points_mm : (n, 3) float
        Measurement frame; ``z`` is the section's stage position.
    theta_rad, radius_mm : (n,) float
    view : (n,) uint8
        :data:`VIEW_CODES`.
    quality : (n,) uint8
        :class:`lts360.recon.triangulation.peaks.Quality` of the θ: a valid point (finite) is FOUND (0) or
        SATURATED (2); an invalid one (NaN) keeps the reason it gave no point.
    section : (n,) int32
    intensity : (n,) float32
    time_s : (n,) float, optional
        When the point's image row was exposed (middle of its exposure, s from the scan's
        first trigger), for frames of a moving object (:func:`~lts360.recon.triangulation.
        measure.row_timing`); ``None`` for still frames.  Stored as a ``time`` property.
    """

    points_mm: np.ndarray
    theta_rad: np.ndarray
    radius_mm: np.ndarray
    view: np.ndarray
    quality: np.ndarray
    section: np.ndarray
    intensity: np.ndarray
    time_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.points_mm)
        if np.asarray(self.points_mm).shape != (n, 3):
            raise ValueError(f"points_mm must have shape (n, 3), got {np.asarray(self.points_mm).shape}")
        for name in ("theta_rad", "radius_mm", "view", "quality", "section", "intensity"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} must have {n} entries, got {len(getattr(self, name))}")
        if self.time_s is not None and len(self.time_s) != n:
            raise ValueError(f"time_s must have {n} entries, got {len(self.time_s)}")

    def __len__(self) -> int:
        return len(self.points_mm)

    @property
    def valid(self) -> np.ndarray:
        return np.all(np.isfinite(self.points_mm), axis=1)

    def select(self, mask: np.ndarray) -> "Cloud":
        return Cloud(*(np.asarray(getattr(self, f))[mask] for f in
                       ("points_mm", "theta_rad", "radius_mm", "view", "quality", "section",
                        "intensity")),
                     time_s=None if self.time_s is None else np.asarray(self.time_s)[mask])

    @staticmethod
    def concatenate(clouds: list["Cloud"]) -> "Cloud":
        names = ("points_mm", "theta_rad", "radius_mm", "view", "quality", "section", "intensity")
        if not clouds:
            return Cloud(np.zeros((0, 3)), *(np.zeros(0, dtype=d) for d in
                                             (float, float, np.uint8, np.uint8, np.int32, np.float32)))
        times = None
        if any(c.time_s is not None for c in clouds):  # NaN where a part has no timing
            times = np.concatenate([np.full(len(c), np.nan) if c.time_s is None
                                    else np.asarray(c.time_s, float) for c in clouds])
        return Cloud(*(np.concatenate([getattr(c, n) for c in clouds]) for n in names),
                     time_s=times)


def write_cloud(path, cloud: Cloud, *, comments=()) -> Path:
    """Binary PLY with the attributes above (written to a temporary name, then renamed).

    The header carries the count of each truth-free rejection
    (``comment lts360 rejected NAME COUNT``; the names of
    :data:`lts360.recon.triangulation.reject.REJECTION_CODES`) and any further
    ``comments`` (one ASCII line each)."""
    from lts360.recon.triangulation.reject import rejection_counts

    path = Path(path)
    n = len(cloud)
    fields = _FIELDS + ((_TIME,) if cloud.time_s is not None else ())
    rec = np.empty(n, dtype=[(name, dt) for name, dt, _ in fields])
    rec["x"], rec["y"], rec["z"] = (cloud.points_mm[:, k] for k in range(3))
    rec["theta"], rec["radius"] = cloud.theta_rad, cloud.radius_mm
    rec["view"], rec["quality"] = cloud.view, cloud.quality
    rec["section"], rec["intensity"] = cloud.section, cloud.intensity
    if cloud.time_s is not None:
        rec["time"] = cloud.time_s
    extra = [f"comment lts360 rejected {k} {v}" for k, v in
             rejection_counts(cloud.quality).items()]
    for c in comments:
        if "\n" in str(c) or not str(c).isascii():
            raise ValueError(f"comments: one ASCII line each, got {c!r}")
        extra.append(f"comment {c}")
    header = ["ply", "format binary_little_endian 1.0", "comment lts360 measured cloud, mm",
              *extra, f"element vertex {n}"]
    header += [f"property {ply} {name}" for name, _, ply in fields]
    header.append("end_header")
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(rec.tobytes())
    os.replace(tmp, path)
    return path


def _lts360_comments(path, kind: str) -> list[list[str]]:
    """The words after ``comment lts360 KIND`` of each such line of a cloud's header."""
    with open(path, "rb") as f:
        head = f.read(8192)
    end = head.find(b"end_header")
    lines = head[:end if end >= 0 else None].decode("ascii", "replace").splitlines()
    return [p[3:] for p in (line.split() for line in lines)
            if p[:3] == ["comment", "lts360", kind]]


def read_cloud_rejections(path) -> dict[str, int]:
    """The rejection counts a cloud's header carries (``{}`` for a cloud written without)."""
    return {w[0]: int(w[1]) for w in _lts360_comments(path, "rejected") if len(w) == 2}


def read_cloud_twin(path) -> dict[str, dict[str, float]]:
    """The digital twin's record in a cloud's header, per view (``{}`` without a twin):
    ``bias_um``, ``corrected``, ``uncorrected``, ``u_render_um``, ``u_inputs_um``."""
    out = {}
    for w in _lts360_comments(path, "twin"):
        if len(w) >= 1 and len(w) % 2 == 1:
            try:
                out[w[0]] = {k: float(v) for k, v in zip(w[1::2], w[2::2])}
            except ValueError:
                continue
    return out


def read_cloud_master(path) -> dict[str, float]:
    """The mastering a cloud was compensated with, per view: ``u_radius_um`` (``{}``
    without one)."""
    out = {}
    for w in _lts360_comments(path, "master"):
        if len(w) == 3 and w[1] == "u_radius_um":
            try:
                out[w[0]] = float(w[2])
            except ValueError:
                continue
    return out


def read_cloud(path) -> Cloud:
    """Read a cloud written by :func:`write_cloud`; ``ValueError`` names what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"cloud {str(path)!r}: no such file")
    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise ValueError(f"cloud {path}: not a PLY file")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise ValueError(f"cloud {path}: expected binary_little_endian PLY")
    n = next((int(line.split()[2]) for line in header if line.startswith("element vertex")), None)
    props = [line.split()[2] for line in header if line.startswith("property")]
    fields = _FIELDS + ((_TIME,) if props and props[-1] == _TIME[0] else ())
    if n is None or props != [name for name, _, _ in fields]:
        raise ValueError(f"cloud {path}: vertex properties must be {[f[0] for f in _FIELDS]} "
                         f"(and optionally {_TIME[0]!r}), got {props}")
    dt = np.dtype([(name, d) for name, d, _ in fields])
    rec = np.frombuffer(data, dtype=dt, count=n, offset=end + len(b"end_header\n"))
    pts = np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(float)
    return Cloud(pts, rec["theta"].astype(float), rec["radius"].astype(float),
                 rec["view"].copy(), rec["quality"].copy(), rec["section"].astype(np.int32),
                 rec["intensity"].astype(np.float32),
                 time_s=rec["time"].astype(float) if "time" in rec.dtype.names else None)

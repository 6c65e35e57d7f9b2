"""Which part of a section each view measures: visibility *and* illumination through mirrors.

A point ``X`` of a section (radius ``r``, angle ``θ`` in the laser plane) is measured in a
*view* — the camera seen through an ordered sequence of mirrors, ``()`` for the direct view —
when

1. the light path ``X → mirror(s) → camera`` exists: aimed at the virtual camera
   ``T_{m1} T_{m2} … C`` it meets every mirror inside its real rectangle, on its reflecting
   side, and no segment is blocked by the object (a cylinder of radius ``r``) or by a
   mirror; the surface faces the path within ``max_incidence_deg``; and ``X`` projects
   inside the image with ``margin_px``;
2. some laser path ``laser → mirror(s) → X`` exists in the same sense (method of images with
   the virtual lasers), leaves the real laser inside its fan, and meets the surface within
   ``max_incidence_deg``.

Mirror sequences never repeat a mirror twice in a row (a planar mirror cannot be hit twice in
succession).  At β = 90° the two double reflections ``(left, right)`` and ``(right, left)`` have
the same virtual camera: the corner shows them side by side with a seam.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from lts360.geometry import mirror_path
from lts360.geometry.camera import project_points
from lts360.geometry.mirror_path import PathMirror, rectangle_extent
from lts360.scenes.rig import Mirror, Rig

__all__ = ["mirror_sequences", "view_name", "path_valid", "CoverageResult", "coverage",
           "circular_windows", "MAX_BOUNCES"]

#: The longest mirror sequence followed on a camera or laser path (also the renderer's).
MAX_BOUNCES = 3

def mirror_sequences(mirrors: tuple[Mirror, ...], max_bounces: int) -> list[tuple[int, ...]]:
    """Ordered mirror index sequences of length ``0..max_bounces`` without immediate repeats."""
    out: list[tuple[int, ...]] = [()]
    for k in range(1, max_bounces + 1):
        for seq in itertools.product(range(len(mirrors)), repeat=k):
            if all(a != b for a, b in zip(seq[:-1], seq[1:])):
                out.append(seq)
    return out


def view_name(seq: tuple[int, ...], mirrors: tuple[Mirror, ...]) -> str:
    """``"direct"``, ``"left"``, ``"right"``, ``"left-right"`` (object → left → right → camera)."""
    return "direct" if not seq else "-".join(mirrors[i].name for i in seq)


def path_mirrors(mirrors: tuple[Mirror, ...]) -> list[PathMirror]:
    """The rig's mirrors as the path test sees them (world frame, their rectangles)."""
    out = []
    for m in mirrors:
        n, d = m.plane
        out.append(PathMirror(n=n, d=d, T=m.T, contains=rectangle_extent(
            m.center_mm, m.u_axis, m.v_axis, m.width_mm, m.height_mm)))
    return out


def path_valid(points_mm: np.ndarray, target_mm: np.ndarray, seq: tuple[int, ...],
               mirrors: tuple[Mirror, ...], radius_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trace the light path from surface points to a real target through a mirror sequence
    (:func:`lts360.geometry.mirror_path.path_valid` on the rig's mirrors).

    Parameters
    ----------
    points_mm : (n, 3) float
        Points on the section (world frame).
    target_mm : (3,) float
        Real camera centre or laser apex.
    seq : tuple of int
        Mirror indices in the order met when leaving ``points`` (the first is nearest them).
    mirrors : tuple of Mirror
    radius_mm : float
        Radius of the occluding cylinder (the object).

    Returns
    -------
    valid : (n,) bool
        The path meets each mirror inside its extent, on its reflecting side, unoccluded.
    leave_dir : (n, 3) float
        Unit direction in which the path leaves the points.
    arrive_dir : (n, 3) float
        Unit direction in which the path reaches the target (pointing towards the target).
    """
    return mirror_path.path_valid(points_mm, target_mm, seq, path_mirrors(mirrors), radius_mm)


def circular_windows(theta_rad: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """Contiguous runs of ``mask`` on a uniform periodic θ grid, as (start, end) in degrees.

    Windows that wrap through ±180° are returned with ``end < start``.  Each bound is the
    sample angle of the first / last sample of the run.
    """
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return []
    deg = np.degrees(theta_rad)
    if mask.all():
        return [(float(deg[0]), float(deg[-1]))]
    start_idx = int(np.argmin(mask))  # a False sample: runs never straddle the array start here
    rolled = np.roll(mask, -start_idx)
    idx = (np.arange(len(mask)) + start_idx) % len(mask)
    edges = np.diff(rolled.astype(int))
    starts = np.flatnonzero(edges == 1) + 1
    ends = np.flatnonzero(edges == -1)
    if rolled[-1]:
        ends = np.append(ends, len(mask) - 1)
    return [(float(deg[idx[s]]), float(deg[idx[e]])) for s, e in zip(starts, ends)]


@dataclass(frozen=True)
class CoverageResult:
    """Coverage of one section radius.

    Attributes
    ----------
    radius_mm : float
    theta_rad : (n,) float
        Uniform grid over [−π, π).
    seen : dict[str, (n,) bool]
        Per view: the path to the camera exists and the point is inside the image.
    lit : dict[str, (n,) bool]
        Per laser path (``"direct"``, ``"left"``, ...): the laser reaches the point.
    measured : dict[str, (n,) bool]
        Per view: seen and lit by at least one laser path.
    image_uv : dict[str, (n, 2) float]
        Projection of every point in every view (pixels; NaN behind the camera).
    """

    radius_mm: float
    theta_rad: np.ndarray
    seen: dict
    lit: dict
    measured: dict
    image_uv: dict

    @property
    def step_deg(self) -> float:
        return float(np.degrees(self.theta_rad[1] - self.theta_rad[0]))

    def windows(self, view: str) -> list[tuple[float, float]]:
        return circular_windows(self.theta_rad, self.measured[view])

    @property
    def union(self) -> np.ndarray:
        return np.logical_or.reduce(list(self.measured.values()))

    @property
    def coverage_deg(self) -> float:
        """Total angle measured by at least one view."""
        return float(self.union.sum() * self.step_deg)

    def overlap_deg(self, view_a: str, view_b: str) -> float:
        return float((self.measured[view_a] & self.measured[view_b]).sum() * self.step_deg)

    def measured_deg(self, view: str) -> float:
        return float(self.measured[view].sum() * self.step_deg)

    def views(self) -> list[str]:
        return list(self.measured)

    def image_margin_px(self, image_size: tuple[int, int]) -> float:
        """Smallest distance from any measured point's projection to the image border."""
        w, h = image_size
        margins = []
        for view, mask in self.measured.items():
            if mask.any():
                uv = self.image_uv[view][mask]
                margins.append(np.min(np.concatenate([uv[:, 0] + 0.5, w - 0.5 - uv[:, 0],
                                                      uv[:, 1] + 0.5, h - 0.5 - uv[:, 1]])))
        return float(min(margins)) if margins else float("nan")


def coverage(rig: Rig, radius_mm: float, *, theta_step_deg: float = 0.1, max_bounces: int = 2,
             max_incidence_deg: float = 80.0, margin_px: float = 0.0,
             center_xy_mm=(0.0, 0.0)) -> CoverageResult:
    """Per-view coverage of a circular section of ``radius_mm`` in the laser plane.

    Parameters
    ----------
    rig : Rig
    radius_mm : float, >0
    theta_step_deg : float, (0, 10]
    max_bounces : int, [0, 3]
        Longest mirror sequence considered, for camera and laser paths alike.
    max_incidence_deg : float, (0, 90]
        Largest angle between the surface normal and the camera or laser direction that
        still gives a usable stripe (grazing views and grazing light are discarded).
    margin_px : float, >=0
        Projections closer than this to the image border do not count as seen.
    center_xy_mm : (2,) float
        Centre of the section (an off-axis placement).
    """
    if not radius_mm > 0:
        raise ValueError(f"radius_mm must be > 0, got {radius_mm}")
    if not 0 < theta_step_deg <= 10:
        raise ValueError(f"theta_step_deg must be in (0, 10], got {theta_step_deg}")
    if not 0 <= max_bounces <= MAX_BOUNCES:
        raise ValueError(f"max_bounces must be in [0, {MAX_BOUNCES}], got {max_bounces}")
    if not 0 < max_incidence_deg <= 90:
        raise ValueError(f"max_incidence_deg must be in (0, 90], got {max_incidence_deg}")
    n = int(round(360.0 / theta_step_deg))
    theta = -np.pi + np.arange(n) * (2 * np.pi / n)
    cx, cy = (float(c) for c in center_xy_mm)
    normal = np.stack([np.cos(theta), np.sin(theta), np.zeros(n)], -1)
    pts = normal * radius_mm + np.array([cx, cy, 0.0])
    # Occlusion uses a cylinder about the section's own centre: shift everything by -centre.
    shift = np.array([cx, cy, 0.0])
    mirrors = tuple(_shifted_mirror(m, -shift) for m in rig.mirrors)
    pts0 = pts - shift
    cos_max = np.cos(np.radians(max_incidence_deg))
    cam = rig.camera
    seqs = mirror_sequences(rig.mirrors, max_bounces)

    seen, uv_all = {}, {}
    for seq in seqs:
        name = view_name(seq, rig.mirrors)
        ok, leave, _ = path_valid(pts0, cam.center_mm - shift, seq, mirrors, radius_mm)
        ok &= np.einsum("ij,ij->i", leave, normal) > cos_max
        T = np.eye(4)  # object → m1 → m2 → camera: the camera sees T_m2 · T_m1 · X
        for k in seq:
            T = rig.mirrors[k].T @ T
        uv = project_points(pts, cam.K, cam.distortion, cam.R, cam.t_mm, T_mirror=T)
        inside = (uv[:, 0] >= -0.5 + margin_px) & (uv[:, 0] <= cam.width_px - 0.5 - margin_px) & \
                 (uv[:, 1] >= -0.5 + margin_px) & (uv[:, 1] <= cam.height_px - 0.5 - margin_px)
        seen[name] = ok & inside
        uv_all[name] = uv

    laser = rig.laser
    half_fan = np.radians(laser.fan_angle_deg) / 2.0
    n_l, d_l = laser.plane
    lit = {}
    for seq in seqs:
        name = view_name(seq, rig.mirrors)
        ok, leave, arrive = path_valid(pts0, laser.origin_mm - shift, seq, mirrors, radius_mm)
        ok &= np.einsum("ij,ij->i", leave, normal) > cos_max
        emitted = -arrive  # direction in which the light leaves the real laser
        in_plane = np.abs(emitted @ n_l) < 1e-6
        angle = np.arctan2(np.linalg.norm(np.cross(emitted, laser.direction), axis=1),
                           emitted @ laser.direction)
        lit[name] = ok & in_plane & (angle <= half_fan)
    lit_any = np.logical_or.reduce(list(lit.values()))
    measured = {k: v & lit_any for k, v in seen.items()}
    return CoverageResult(radius_mm=float(radius_mm), theta_rad=theta, seen=seen, lit=lit,
                          measured=measured, image_uv=uv_all)


def _shifted_mirror(m: Mirror, offset: np.ndarray) -> Mirror:
    return Mirror(name=m.name, center_mm=m.center_mm + offset, normal=m.normal, u_axis=m.u_axis,
                  width_mm=m.width_mm, height_mm=m.height_mm, reflectance=m.reflectance)

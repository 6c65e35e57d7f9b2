"""Calibration pose planning: where to hold the chessboard so that every part of the rig is
determined (paper §4.2–4.3).  numpy only.

Three kinds of shot, each checked against the rig before it is accepted (every inner corner
in the image with a margin, not hidden by a mirror, and for mirror shots also visible
through the mirror; a board also seen through the *other* mirror is rejected, since two
mirror images in one picture would make the real/virtual pairing ambiguous):

* ``camera`` — the board alone, spread over the image and over depth, tilted 15–40° about
  random axes (Zhang's method needs varied orientations; Zhang 2000, §5);
* ``mirror`` — the board in the measurement volume, facing the bisector of the camera and
  its mirror image, so that the camera sees it directly and in one mirror (the virtual,
  mirror-reversed board); tilted ±10° so that the poses differ;
* ``laser`` — the board across the laser sheet, lit by it from the printed side, the line
  crossing the squares obliquely; the lines of different poses are not parallel, so their
  points span the plane.  By default (``laser_in_mirror``) a laser board is posed like a
  mirror shot, so that the camera sees it directly *and* in one mirror (the shots alternate
  between the mirrors): its pose is then fixed by both views, a stereo pair with the
  mirror's virtual camera, instead of by the scale of a small board in one view (measured on
  rendered 7×6 × 2 mm boards: depth at the board's centre ±4 µm against ±150 µm).  Without
  it, a laser board faces the bisector of the laser apex and the camera and is seen directly
  only.

Poses come from a seeded generator: the same rig, board and seed give the same plan.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lts360.geometry.camera import project_points
from lts360.scenes.coverage import path_valid
from lts360.scenes.rig import Rig
from lts360.scenes.targets import Chessboard

__all__ = ["BoardShot", "plan_calibration", "shot_visibility", "default_camera_board",
           "laser_crossing_ok"]

SHOT_KINDS = ("camera", "mirror", "laser")


@dataclass(frozen=True, eq=False)
class BoardShot:
    """One planned calibration image.

    Attributes
    ----------
    name : str
        File stem, e.g. ``camera-03``, ``mirror-left-01``, ``laser-02``.
    kind : {"camera", "mirror", "laser"}
    mirror : str or None
        The mirror a ``mirror`` shot is for; for a ``laser`` shot, the mirror in which the
        board is seen as well (``None``: seen directly only).
    board : Chessboard
        The board with its world pose (``T_world_board``).
    mirrors_covered : bool
        The mirrors are not in place for this shot (mounted after the camera calibration, or
        taken off): the camera sees the board only directly, and nothing hides it.
    """

    name: str
    kind: str
    mirror: str | None
    board: Chessboard
    mirrors_covered: bool = False


def _rotation(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1 - np.cos(angle_rad)) * K @ K


def _board_at(board: Chessboard, centre_mm: np.ndarray, normal: np.ndarray,
              spin_rad: float) -> Chessboard:
    """The board with its pattern centred on ``centre_mm``, printed side facing ``normal``,
    its x axis turned by ``spin_rad`` about the normal from the horizontal."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    ref = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, n)
    x /= np.linalg.norm(x)
    x = _rotation(n, spin_rad) @ x
    R = np.column_stack([x, np.cross(n, x), n])
    half = np.array([board.squares_x, board.squares_y, 0.0]) * board.square_mm / 2.0
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = centre_mm - R @ half
    from dataclasses import replace

    return replace(board, T_world_board=T)


def shot_visibility(rig: Rig, board: Chessboard, *, margin_px: float = 20.0) -> dict[str, float]:
    """Share of the board's inner corners that the camera sees, per path.

    Keys: ``direct`` and each mirror name (single reflection) and ``a-b`` (double). A corner
    counts where the path is unoccluded by the mirrors, meets each mirror inside its
    rectangle, reaches the camera from the printed side and projects at least ``margin_px``
    inside the image.
    """
    cam = rig.camera
    C = cam.center_mm
    X = board.corners_world_mm()
    n_board = board.T_world_board[:3, 2]
    w, h = cam.width_px, cam.height_px
    out = {}
    names = [m.name for m in rig.mirrors]
    seqs = [()] + [(i,) for i in range(len(names))] + \
        [(i, j) for i in range(len(names)) for j in range(len(names)) if i != j]
    for seq in seqs:
        valid, leave, _ = path_valid(X, C, seq, rig.mirrors, radius_mm=0.0)
        valid &= leave @ n_board > 0.05  # printed side towards the (virtual) camera
        T = np.eye(4)
        for k in seq:
            T = rig.mirrors[k].T @ T
        uv = project_points(X, cam.K, cam.distortion, cam.R, cam.t_mm, T_mirror=T if seq else None)
        inside = (uv[:, 0] >= margin_px) & (uv[:, 0] <= w - 1 - margin_px) & \
                 (uv[:, 1] >= margin_px) & (uv[:, 1] <= h - 1 - margin_px)
        key = "direct" if not seq else "-".join(names[k] for k in seq)
        out[key] = float(np.mean(valid & inside))
    return out


def _accept(vis: dict[str, float], want: str | None) -> bool:
    if vis["direct"] < 1.0:
        return False
    others = [v for k, v in vis.items() if k not in ("direct", want)]
    if want is not None and vis[want] < 1.0:
        return False
    return max(others, default=0.0) < 0.5  # no second complete board in the picture


def _camera_shot(rig, board, rng, tilt_deg=(30.0, 50.0), depth_range=(0.85, 1.1)):
    cam = rig.camera
    Rinv = cam.R.T
    u = rng.uniform(0.15, 0.85) * cam.width_px
    v = rng.uniform(0.15, 0.85) * cam.height_px
    depth = rng.uniform(*depth_range) * cam.focus_distance_mm
    ray = np.linalg.solve(cam.K, [u, v, 1.0])
    centre = cam.center_mm + Rinv @ (ray * depth)
    towards = cam.center_mm - centre
    towards /= np.linalg.norm(towards)
    axis = np.cross(towards, rng.normal(size=3))
    normal = _rotation(axis, np.radians(rng.uniform(*tilt_deg))) @ towards
    return _board_at(board, centre, normal, rng.uniform(-np.pi, np.pi))


def _mirror_shot(rig, board, mirror, rng, volume_mm, z_mm=None):
    C = rig.camera.center_mm
    Cv = (mirror.T @ np.append(C, 1.0))[:3]
    r = volume_mm * np.sqrt(rng.uniform(0, 1))
    phi = rng.uniform(-np.pi, np.pi)
    z = rng.uniform(-0.4, 0.4) * volume_mm if z_mm is None else rng.uniform(-z_mm, z_mm)
    centre = np.array([r * np.cos(phi), r * np.sin(phi), z])
    n = (C - centre) / np.linalg.norm(C - centre) + (Cv - centre) / np.linalg.norm(Cv - centre)
    n /= np.linalg.norm(n)
    n = _rotation(np.cross(n, rng.normal(size=3)), np.radians(rng.uniform(0.0, 10.0))) @ n
    return _board_at(board, centre, n, rng.uniform(-np.pi, np.pi))


def _laser_shot(rig, board, rng, volume_mm):
    C = rig.camera.center_mm
    L = np.asarray(rig.laser.origin_mm, dtype=float)
    centre = np.array([rng.uniform(-1, 1) * volume_mm, rng.uniform(-1, 0.5) * volume_mm,
                       rng.uniform(-0.1, 0.1) * board.square_mm])
    n = (C - centre) / np.linalg.norm(C - centre) + (L - centre) / np.linalg.norm(L - centre)
    n /= np.linalg.norm(n)
    n = _rotation(np.cross(n, rng.normal(size=3)), np.radians(rng.uniform(5.0, 25.0))) @ n
    # Spin so that the sheet crosses the squares at 20–70° (never along a row of corners).
    return _board_at(board, centre, n, np.radians(rng.choice([-1, 1]) * rng.uniform(20.0, 70.0)))


def laser_crossing_ok(rig: Rig, board: Chessboard, *, min_cos: float = 0.2,
                      min_angle_deg: float = 15.0, inner: float = 0.6) -> bool:
    """The laser sheet crosses ``board`` usefully: it lights the printed side (cosine of
    incidence at least ``min_cos``), meets the inner corners within the middle ``inner``
    share of their extent across the line, and runs at least ``min_angle_deg`` off the
    board's rows and columns (a line along a row of corners lies on black/white edges)."""
    T = board.T_world_board
    L = np.asarray(rig.laser.origin_mm, dtype=float)
    p, n_sheet = L, np.asarray(rig.laser.normal, dtype=float)
    n_b = T[:3, 2]
    X = board.corners_world_mm()
    centre = X.mean(axis=0)
    to_board = centre - L
    to_board -= (to_board @ n_sheet) * n_sheet
    to_board /= np.linalg.norm(to_board)
    if -(n_b @ to_board) < min_cos:
        return False
    h = (X - p) @ n_sheet  # signed distance of the corners from the sheet
    lo, hi = h.min(), h.max()
    mid, half = (lo + hi) / 2.0, inner * (hi - lo) / 2.0
    if not (mid - half <= 0.0 <= mid + half):
        return False
    line = np.cross(n_b, n_sheet)
    line /= np.linalg.norm(line)
    ang = np.degrees(np.arccos(np.clip(np.abs([line @ T[:3, 0], line @ T[:3, 1]]), 0, 1)))
    return bool(ang.min() >= min_angle_deg)


def default_camera_board() -> Chessboard:
    """The camera-calibration board: 9×7 squares of 8 mm (72 × 56 mm).

    The paper calibrates the camera first and uses the small 7×6 × 2 mm board only for the
    mirrors and the laser "due to the restricted space" (§4.2).  Measured: Zhang's method
    with the 2 mm board (≈ 120 px across in the image) misses fx by 2 %; a board that
    covers a good part of the image is what Zhang's method needs.
    """
    return Chessboard(squares_x=9, squares_y=7, square_mm=8.0, margin_mm=4.0)


def plan_calibration(rig: Rig, board: Chessboard | None = None, *,
                     camera_board: Chessboard | None = None, n_camera: int = 12,
                     n_mirror: int = 4, n_laser: int = 4, seed: int = 0,
                     volume_mm: float = 10.0, max_tries: int = 2000,
                     cover_mirrors_for_camera: bool = True,
                     laser_in_mirror: bool = True) -> list[BoardShot]:
    """Board poses for a full calibration of ``rig``.

    Parameters
    ----------
    board : Chessboard, optional
        The mirror and laser target (default: the paper's 7×6 squares of 2 mm).  Its pose
        is ignored.
    camera_board : Chessboard, optional
        The camera-calibration target (default :func:`default_camera_board`).
    n_camera : int, >= 4
        Shots for Zhang's camera calibration.
    n_mirror : int, >= 1
        Shots per mirror (board seen directly and in that mirror).
    n_laser : int, >= 2
        Shots of the board across the laser sheet (each is rendered with the laser on and off).
    volume_mm : float
        Radius of the measurement volume the mirror and laser shots are placed in.
    cover_mirrors_for_camera : bool
        Take the camera shots without the mirrors (before they are mounted, or with them
        taken off), as a lab calibrating the camera first would.  With the mirrors in place, every pose that shows
        a second complete board in a mirror is refused, and what is left is tilted one way
        only (measured, paper rig: 38 of 40 poses tilted +20…+46° about the image x axis);
        Zhang's method then fixes cy to σ ≈ 1 px and fx to 0.06 % at 0.05 px corner noise
        (20 shots), against 0.2–0.3 px and 0.03 % without the mirrors.
    laser_in_mirror : bool
        Pose each laser board so that it is seen directly and in one mirror (alternating
        left, right, …), lit by the sheet from its printed side; its pose then comes from both
        views.  ``False``: laser boards seen directly only.

    Raises
    ------
    ValueError
        Too few shots requested, or no valid pose found in ``max_tries`` draws (the board
        does not fit the rig's views).
    """
    board = board or Chessboard()
    camera_board = camera_board or default_camera_board()
    if n_camera < 4 or n_mirror < 1 or n_laser < 2:
        raise ValueError(f"plan_calibration: need n_camera >= 4, n_mirror >= 1, n_laser >= 2; "
                         f"got {n_camera}, {n_mirror}, {n_laser}")
    rng = np.random.default_rng(seed)
    shots: list[BoardShot] = []

    def draw(n, make, kind, mirror=None, target=board, view_rig=rig, check=None, first=0,
             stem=None):
        got, tries = 0, 0
        while got < n:
            tries += 1
            if tries > max_tries:
                raise ValueError(f"plan_calibration: found only {got} of {n} valid {kind} poses"
                                 f"{'' if mirror is None else ' for the ' + mirror + ' mirror'} "
                                 f"in {max_tries} draws (board {target.size_mm} mm)")
            b = make()
            if not _accept(shot_visibility(view_rig, b), mirror):
                continue
            if check is not None and not check(b):
                continue
            name = stem or (kind if mirror is None else f"{kind}-{mirror}")
            shots.append(BoardShot(name=f"{name}-{first + got:02d}", kind=kind, mirror=mirror,
                                   board=b, mirrors_covered=not view_rig.mirrors))
            got += 1

    camera_rig = replace(rig, mirrors=()) if cover_mirrors_for_camera else rig
    draw(n_camera, lambda: _camera_shot(camera_rig, camera_board, rng), "camera",
         target=camera_board, view_rig=camera_rig)
    for m in rig.mirrors:
        draw(n_mirror, lambda m=m: _mirror_shot(rig, board, m, rng, volume_mm), "mirror", m.name)
    if laser_in_mirror and rig.mirrors:
        # One at a time, alternating between the mirrors; the sheet must cross the board
        # near its middle, within ±0.3 squares of its centre height.
        for k in range(n_laser):
            m = rig.mirrors[k % len(rig.mirrors)]
            draw(1, lambda m=m: _mirror_shot(rig, board, m, rng, volume_mm,
                                             z_mm=0.3 * board.square_mm),
                 "laser", m.name, check=lambda b: laser_crossing_ok(rig, b), first=k,
                 stem="laser")
    else:
        draw(n_laser, lambda: _laser_shot(rig, board, rng, volume_mm), "laser",
             check=lambda b: laser_crossing_ok(rig, b, min_cos=0.0, inner=1.0, min_angle_deg=0.0))
    return shots

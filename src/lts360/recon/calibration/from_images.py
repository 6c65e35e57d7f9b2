"""The whole rig calibration from a folder of chessboard images (paper §4.2–4.3).

Input: a folder with the images and ``manifest.json``::

    {"board": {"pattern_size": [6, 5], "square_mm": 2.0},
     "camera_board": {"pattern_size": [8, 6], "square_mm": 8.0},
     "design": {"mirror_corner_distance_mm": 60.0, "mirror_width_mm": 105.0,
                "mirror_height_mm": 80.0, "mirror_center_z_mm": 20.0},
     "shots": [{"name": "camera-00", "kind": "camera", "image": "camera-00.png"},
               {"name": "mirror-left-00", "kind": "mirror", "mirror": "left",
                "image": "mirror-left-00.png"},
               {"name": "laser-00", "kind": "laser", "mirror": "left",
                "image_board": "laser-00-board.png",
                "image_on": "laser-00-on.png", "image_off": "laser-00-off.png"}]}

``board`` is the small target of the mirror and laser shots; ``camera_board`` (optional,
default ``board``) the one of the ``camera`` shots.

Steps: (1) Zhang's camera calibration on the ``camera`` shots; (2) per mirror, the real and the
virtual board in each ``mirror`` shot → the paper's midpoint plane and a joint least-squares
plane (the one kept); (3) the laser plane from the line on the board — a laser shot that
names a ``mirror`` shows its board in that mirror too (``image_board``), and its pose is
then taken from both views with the calibrated mirror; (4) the measurement
frame: z along the laser normal, origin where the nominal object axis meets the sheet — the
axis is parallel to the mirrors' common edge, ``mirror_corner_distance_mm`` from it on the
bisector of the mirrors (the rig's design; a lab measures it once) — and θ = 0 along the
mirrors' left-to-right direction.  Uncertainties: OpenCV's intrinsic standard deviations,
and for every plane the larger of its least-squares covariance and a jackknife over the
poses (pose errors are shared by all points of a pose, which least squares does not see).

Nothing here reads ground truth.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.recon.calibration.board import BoardGeometry
from lts360.recon.calibration.camera import CameraCalibration, calibrate_camera
from lts360.recon.calibration.laser_plane import (
    LaserLine,
    LaserPlaneEstimate,
    board_pose,
    board_pose_in_mirror,
    fit_laser_plane,
    laser_line_points,
)
from lts360.recon.calibration.mirrors import (
    MirrorEstimate,
    MirrorObservation,
    detect_real_and_virtual,
    mirror_from_midpoints,
    refine_mirror,
    robust_refine_mirror,
)
from lts360.recon.calibration.uncertainty import (
    CAMERA_STD_NAMES,
    jackknife_covariance,
    plane_offset_abd,
)
from lts360.recon.images import read_image as _read
from lts360.recon.model import Calibration, MirrorPlane, make_T_cam_meas

__all__ = ["CalibrationImages", "read_calibration_images", "calibrate_rig",
           "measurement_frame_from_mirrors", "RigCalibrationResult", "select_laser_lines"]


@dataclass(frozen=True)
class CalibrationImages:
    """A manifest read from disk (paths resolved) — see the module docstring."""

    root: Path
    board: BoardGeometry
    camera_board: BoardGeometry
    design: dict
    shots: tuple[dict, ...]


@dataclass(frozen=True, eq=False)
class RigCalibrationResult:
    """The calibration and everything the report needs."""

    calibration: Calibration
    camera: CameraCalibration
    camera_images: tuple[str, ...]
    mirror_observations: dict
    mirror_midpoint: dict
    mirror_lsq: dict
    laser_lines: dict
    laser: LaserPlaneEstimate
    skipped: dict


def read_calibration_images(folder) -> CalibrationImages:
    """Read ``folder/manifest.json``.

    Raises
    ------
    ValueError
        Missing manifest or field, unknown shot kind, missing image file.
    """
    root = Path(folder)
    path = root / "manifest.json"
    if not path.is_file():
        raise ValueError(f"--images: {str(root)!r} has no manifest.json (board geometry and shots)")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"--images: manifest.json is not valid JSON (line {exc.lineno}: "
                         f"{exc.msg})") from None
    try:
        b = data["board"]
        board = BoardGeometry(tuple(int(v) for v in b["pattern_size"]), float(b["square_mm"]))
        cb = data.get("camera_board") or b
        camera_board = BoardGeometry(tuple(int(v) for v in cb["pattern_size"]),
                                     float(cb["square_mm"]))
        shots = tuple(data["shots"])
    except (KeyError, TypeError) as exc:
        raise ValueError(f"manifest.json: missing or invalid field {exc}") from None
    for s in shots:
        kind = s.get("kind")
        keys = {"camera": ("image",), "mirror": ("image", "mirror"),
                "laser": ("image_board", "image_on", "image_off")}.get(kind)
        if keys is None:
            raise ValueError(f"manifest.json: shot {s.get('name')!r} has kind {kind!r}; "
                             "expected camera, mirror or laser")
        for k in keys:
            if k not in s:
                raise ValueError(f"manifest.json: shot {s.get('name')!r} lacks {k!r}")
            if k.startswith("image") and not (root / s[k]).is_file():
                raise ValueError(f"manifest.json: image {s[k]!r} of shot {s.get('name')!r} "
                                 "is missing")
    return CalibrationImages(root=root, board=board, camera_board=camera_board, design=dict(data.get("design") or {}),
                             shots=shots)


def measurement_frame_from_mirrors(mirrors: dict[str, MirrorPlane], laser_plane,
                                   corner_distance_mm: float) -> np.ndarray:
    """``T_cam_meas`` from two mirror planes, the laser plane and the axis-to-corner distance.

    Origin: the mirrors' common edge meets the laser plane at ``P``; the axis lies at
    ``corner_distance_mm`` from ``P`` along the mirrors' bisector (towards the camera side),
    within the laser plane.  z: the laser normal, on the camera's side.  y: from the axis
    towards the mirror corner; x = y × z (from the ``left`` towards the ``right`` mirror).
    """
    if set(mirrors) != {"left", "right"}:
        raise ValueError(f"the measurement frame needs a 'left' and a 'right' mirror, got "
                         f"{sorted(mirrors)}")
    n_l, d_l = mirrors["left"].plane
    n_r, d_r = mirrors["right"].plane
    n_z, d_z = np.asarray(laser_plane[0], float), float(laser_plane[1])
    if d_z > 0:
        n_z, d_z = -n_z, -d_z
    A = np.vstack([n_l, n_r, n_z])
    P = np.linalg.solve(A, [d_l, d_r, d_z])
    b = n_l + n_r  # both normals face the camera side: their sum points from the edge outwards
    b -= (b @ n_z) * n_z
    b /= np.linalg.norm(b)
    origin = P + corner_distance_mm * b
    z = n_z  # d_z < 0: the camera (the origin) is on the +n_z side
    y = -b
    x = np.cross(y, z)
    return make_T_cam_meas((z, d_z), origin, x)


def _mirror_corners(mirror: MirrorPlane, other: MirrorPlane, T_cam_meas: np.ndarray,
                    design: dict) -> np.ndarray | None:
    """The mirror's rectangle from the design sizes, on the calibrated plane."""
    try:
        w = float(design["mirror_width_mm"])
        h = float(design["mirror_height_mm"])
        zc = float(design["mirror_center_z_mm"])
    except (KeyError, TypeError, ValueError):
        return None
    R, t = T_cam_meas[:3, :3], T_cam_meas[:3, 3]
    z = R[:, 2]
    edge = np.cross(mirror.n, other.n)
    edge /= np.linalg.norm(edge)
    if edge @ z < 0:
        edge = -edge
    # A point of the common edge at measurement height zc.
    A = np.vstack([mirror.n, other.n, z])
    P = np.linalg.solve(A, [mirror.d_mm, other.d_mm, z @ t + zc])
    u = np.cross(edge, mirror.n)  # in the mirror plane, across the edge
    origin = t
    if u @ (origin - P) < 0:
        u = -u
    c = [P + a * u + e * edge for a, e in ((0, -h / 2), (w, -h / 2), (w, h / 2), (0, h / 2))]
    c = np.array(c)
    return c - (c @ mirror.n - mirror.d_mm)[:, None] * mirror.n


def _plane_unc(n, d, lsq_cov, groups_abd) -> dict:
    out = {"cov_abd_lsq": np.asarray(lsq_cov).tolist()}
    cov = np.asarray(lsq_cov, dtype=float)
    if len(groups_abd) >= 3:
        jk = jackknife_covariance(groups_abd)
        out["cov_abd_jackknife"] = jk.tolist()
        # Keep the larger: compare the total variances of the normal and the offset.
        if np.trace(jk[:2, :2]) + jk[2, 2] > np.trace(cov[:2, :2]) + cov[2, 2]:
            cov = jk
    out["cov_abd"] = cov.tolist()
    out["std_angle_deg"] = float(np.degrees(np.sqrt(np.trace(cov[:2, :2]))))
    out["std_offset_mm"] = float(np.sqrt(cov[2, 2]))
    return out


def select_laser_lines(lines: dict[str, LaserLine], skipped: dict[str, str]
                       ) -> dict[str, LaserLine]:
    """The laser lines the plane is fitted to: where two or more boards were posed from both
    their direct and their mirror view, the boards posed from one view are left out (their
    reason added to ``skipped``); otherwise all of them.

    One view fixes a small board's depth ~40× worse than a view and a mirror (measured on the
    paper board: ±150 µm against ±4 µm, :func:`board_pose_in_mirror`), and one such pose
    among stereo poses tilts the plane: a rejected mirror pair at f/8, posed from its direct
    view, put the plane 0.9° off.
    """
    stereo = {n for n, ln in lines.items() if len(ln.pose_views) > 1}
    if len(stereo) < 2:
        return dict(lines)
    for n in lines:
        if n not in stereo:
            skipped[n] = "; ".join(filter(None, (skipped.get(n), "laser plane: posed from one "
                                                 "view only, left out beside the boards posed "
                                                 "from two")))
    return {n: ln for n, ln in lines.items() if n in stereo}


# Rounds of the camera calibration on the boards' image model (see calibrate_rig).
CAMERA_MODEL_ROUNDS = 0

#: Threads for the per-shot steps of :func:`calibrate_rig` (the mirror shots' boards, the
#: laser lines): at most two, the cores of the machines the demo is timed on.
FIT_THREADS = min(2, os.cpu_count() or 1)


def calibrate_rig(images: CalibrationImages, *, tangential: bool = False,
                  progress=None, use_laser_boards_for_mirrors: bool = True,
                  camera_model_rounds: int = CAMERA_MODEL_ROUNDS,
                  camera_corners: dict | None = None) -> RigCalibrationResult:
    """Calibrate camera, mirrors and laser plane from the manifest's images.

    ``tangential``: estimate the tangential distortion p1, p2 too.  Off by default — k1, k2
    only, as is usual for a fixed-focal machine-vision lens: p1, p2 trade off against the
    principal point (measured on rendered images of a lens without distortion, 24 poses:
    cx/cy errors 0.41/0.58 px with them, 0.03/0.37 px without).

    ``use_laser_boards_for_mirrors``: a laser shot whose board is seen in a mirror too adds
    that real/virtual pair to the mirror's fit (its pose is taken from both views in any
    case).

    ``camera_model_rounds``: rounds of Zhang's method on the camera boards' corners from
    their image model (``board_model_rounds`` of
    :func:`lts360.recon.calibration.camera.calibrate_camera`); 0: on the detected corners.

    ``camera_corners``: ``{shot name: detect_corners(image, camera_board)}`` for camera shots
    whose corners were found beforehand (while the images were rendered); the others are
    detected here.

    Raises
    ------
    ValueError
        Too few usable images for a component (the message says which and why).
    """
    say = progress or (lambda msg: None)
    board = images.board
    cam, names = _calibrate_camera(images, tangential, camera_model_rounds, say,
                                   camera_corners or {})
    K, dist = cam.K, cam.dist
    used_names = tuple(n for n, u in zip(names, cam.used) if u)
    skipped: dict[str, str] = {n: "board not found or reprojection outlier"
                               for n, u in zip(names, cam.used) if not u}
    obs, obs_names, laser_obs, board_images = _mirror_observations(
        images, K, dist, use_laser_boards_for_mirrors, skipped)
    mids, lsqs, planes, rejected = _fit_mirrors(obs, obs_names, laser_obs, board, K, dist,
                                                skipped, say)
    lines = _laser_lines(images, K, dist, planes, laser_obs, board_images, rejected, skipped)
    lines = select_laser_lines(lines, skipped)
    say(f"laser plane: {len(lines)} poses")
    laser = fit_laser_plane(list(lines.values()))
    laser_groups = _leave_one_out_offsets(list(lines.values()), fit_laser_plane, laser)
    mirror_planes, T = _place_frame(planes, laser, images.design)
    unc = {
        "camera": _camera_uncertainty(cam),
        "mirrors": {name: _plane_unc(lsq.normal, lsq.d_mm, _lsq_abd_cov(lsq), g)
                    for name, (lsq, g) in planes.items()},
        "laser_plane": _plane_unc(laser.normal, laser.d_mm, laser.covariance, laser_groups),
        "parameterisation": "planes: n' = normalise(n + a e1 + b e2), d' = d + delta; "
                            "lts360.recon.calibration.uncertainty.tangent_basis(n) gives e1, e2",
    }
    cal = Calibration(image_size=cam.image_size, K=K, dist=dist,
                      mirrors=tuple(mirror_planes[k] for k in sorted(mirror_planes)),
                      laser_plane=(laser.normal, laser.d_mm), T_cam_meas=T, uncertainty=unc)
    return RigCalibrationResult(calibration=cal, camera=cam, camera_images=used_names,
                                mirror_observations={k: (obs_names[k], v) for k, v in obs.items()},
                                mirror_midpoint=mids, mirror_lsq=lsqs, laser_lines=lines,
                                laser=laser, skipped=skipped)


def _calibrate_camera(images: CalibrationImages, tangential: bool, camera_model_rounds: int,
                      say, known: dict) -> tuple[CameraCalibration, list[str]]:
    """Step 1: Zhang's method on the ``camera`` shots (their corners from ``known`` where it
    has them); returns it and the shots' names."""
    from lts360.recon.calibration.camera import detect_corners

    direct, names = [], []
    for s in images.shots:
        if s["kind"] == "camera":
            direct.append(_read(images.root / s["image"]))
            names.append(s["name"])
    say(f"camera: Zhang's method on {len(direct)} images")
    corners = [known[n] if n in known else detect_corners(im, images.camera_board)
               for n, im in zip(names, direct)]
    cam = calibrate_camera(direct, images.camera_board, zero_tangent=not tangential,
                           board_model_rounds=camera_model_rounds, corners=corners,
                           progress=lambda i, n: say(f"camera: board model {i}/{n}")
                           if i == n else None)
    return cam, names


def _mirror_observations(images: CalibrationImages, K, dist, use_laser_boards: bool,
                         skipped: dict[str, str]):
    """The real and the virtual board in the ``mirror`` shots, and in the ``laser`` shots whose
    board is seen in a mirror too.

    Returns ``(obs, obs_names, laser_obs, board_images)``: per mirror its observations and
    their shots' names (laser shots' only with ``use_laser_boards``); per laser shot its
    observation; the laser shots' board images read (to be read once).  Mirror shots without
    both boards are added to ``skipped``.  ``ValueError`` if no mirror has an observation.
    """
    board = images.board
    obs: dict[str, list[MirrorObservation]] = {}
    obs_names: dict[str, list[str]] = {}
    laser_obs: dict[str, MirrorObservation] = {}
    board_images: dict[str, np.ndarray] = {}  # laser shots' board images, read once
    # Mirror shots, and laser shots whose board is seen in a mirror too: both show a real and
    # a virtual board.
    shots = [s for s in images.shots
             if s["kind"] == "mirror" or (s["kind"] == "laser" and s.get("mirror"))]

    def detect(s):
        image = _read(images.root / s["image_board" if s["kind"] == "laser" else "image"])
        return image, detect_real_and_virtual(image, board, K, dist)

    for s, (image, ob) in zip(shots, _map(detect, shots)):
        if s["kind"] == "laser":
            board_images[s["name"]] = image
            if ob is not None:
                laser_obs[s["name"]] = ob
        elif ob is None:
            skipped[s["name"]] = "real and virtual board not both found"
        if ob is None or (s["kind"] == "laser" and not use_laser_boards):
            continue
        obs.setdefault(s["mirror"], []).append(ob)
        obs_names.setdefault(s["mirror"], []).append(s["name"])
    if not obs:
        raise ValueError("mirror calibration: no image shows a board directly and in a mirror")
    return obs, obs_names, laser_obs, board_images


def _map(fn, items: list) -> list:
    """``[fn(x) for x in items]``, run on :data:`FIT_THREADS` threads (the shots are
    independent, each result depends on its own shot only: the same results in the same
    order; the first exception is raised).  OpenCV's detectors, SciPy's filters and NumPy's
    arithmetic on large arrays release Python's lock, so after the rendering a second core
    shares these steps.  Measured with ``benchmarks/bench_calibration.py --seed 1`` on the
    2-core machine while other work shared it (2026-12-05): the mirror shots' boards 6.7 s of
    CPU in 4.2 s, the laser lines 3.7 s in 1.9 s (on one thread: 6.0 s in 6.1 s, 5.1 s in
    5.7 s); the wall times under such load are only indicative."""
    if FIT_THREADS <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=FIT_THREADS) as pool:
        return list(pool.map(fn, items))


def _fit_mirrors(obs, obs_names, laser_obs, board, K, dist, skipped: dict[str, str], say):
    """Step 2: each mirror's plane, the paper's midpoint one and the robust joint
    least-squares one (kept), with its leave-one-out offsets.

    The pairs the robust fit throws out are removed from ``obs`` and ``obs_names`` (in place)
    and added to ``skipped``.  Returns ``(mids, lsqs, planes, rejected)``: per mirror the
    midpoint and the least-squares estimates, and ``(lsq, leave-one-out offsets)``; the names
    of the shots thrown out.
    """
    mids, lsqs, planes = {}, {}, {}
    rejected: set[str] = set()  # real/virtual pairs the mirror fit threw out
    for name in list(obs):
        lsq, keep = robust_refine_mirror(obs[name], board, K, dist)
        for nm, k in zip(obs_names[name], keep):
            if not k:
                rejected.add(nm)
                skipped[nm] = ("mirror fit: large reprojection error, discarded"
                               if nm not in laser_obs else "mirror fit: large reprojection "
                               "error, not used for the mirror; its laser line posed from "
                               "the direct view alone")
        obs[name] = [o for o, k in zip(obs[name], keep) if k]
        obs_names[name] = [n for n, k in zip(obs_names[name], keep) if k]
        ob_list = obs[name]
        say(f"mirror {name}: {len(ob_list)} images kept")
        mid = mirror_from_midpoints(ob_list, board, K, dist)
        groups = _leave_one_out_offsets(
            ob_list, lambda sub: refine_mirror(sub, board, K, dist, initial=lsq), lsq)
        mids[name], lsqs[name] = mid, lsq
        planes[name] = (lsq, groups)
    return mids, lsqs, planes, rejected


def _leave_one_out_offsets(items: list, refit, full) -> list:
    """The jackknife of a plane: with three items or more, per item left out the refitted
    plane's offset from ``full`` (:func:`plane_offset_abd`); none with fewer."""
    groups = []
    if len(items) >= 3:
        for i in range(len(items)):
            e = refit(items[:i] + items[i + 1:])
            groups.append(plane_offset_abd(full.normal, full.d_mm, e.normal, e.d_mm))
    return groups


def _laser_lines(images: CalibrationImages, K, dist, planes, laser_obs, board_images,
                 rejected: set[str], skipped: dict[str, str]) -> dict[str, LaserLine]:
    """Step 3: the laser line on the board of every ``laser`` shot, the board posed from the
    direct view and its calibrated mirror where it can be (:func:`_laser_board_pose`).

    Shots whose line is not found are added to ``skipped``; ``board_images`` is emptied.
    """
    shots = [s for s in images.shots if s["kind"] == "laser"]
    given = {s["name"]: board_images.pop(s["name"], None) for s in shots}
    board_images.clear()

    def line(s):
        image_board = given[s["name"]]
        if image_board is None:
            image_board = _read(images.root / s["image_board"])
        pose, views = _laser_board_pose(s, images.board, K, dist, planes, laser_obs, rejected)
        try:
            return laser_line_points(_read(images.root / s["image_on"]),
                                     _read(images.root / s["image_off"]),
                                     image_board, images.board, K, dist,
                                     pose=pose, pose_views=views)
        except ValueError as exc:
            return exc

    lines: dict[str, LaserLine] = {}
    for s, got in zip(shots, _map(line, shots)):
        if isinstance(got, ValueError):
            skipped[s["name"]] = "; ".join(filter(None, (skipped.get(s["name"]), str(got))))
        else:
            lines[s["name"]] = got
    return lines


def _laser_board_pose(shot: dict, board: BoardGeometry, K, dist, planes, laser_obs,
                      rejected: set[str]):
    """A laser shot's board pose and the views it is taken from: ``(None, ("direct",))``
    for :func:`laser_line_points` to pose the board itself when nothing better is known."""
    name = shot.get("mirror")
    ob = laser_obs.get(shot["name"])
    if name in planes and ob is not None and shot["name"] not in rejected:
        # Seen in a calibrated mirror too (and not a wrongly matched pair): the pose from
        # both views (stereo with the mirror's virtual camera).
        lsq = planes[name][0]
        return board_pose_in_mirror(ob.real_px, ob.virtual_px, board, K, dist,
                                    lsq.normal, lsq.d_mm), ("direct", name)
    if ob is not None:
        # From the direct view alone, from the board the mirror detection found to be the
        # real one: a plain detection may return the virtual board, which the laser (the
        # mirrors covered) does not light.
        return board_pose(ob.real_px, board, K, dist), ("direct",)
    return None, ("direct",)


def _place_frame(planes, laser: LaserPlaneEstimate, design: dict):
    """Step 4: the measurement frame ``T`` and the mirror planes (with their design
    rectangles where there is a left and a right mirror); returns ``(mirror_planes, T)``."""
    mirror_planes = {name: MirrorPlane(name=name, n=lsq.normal, d_mm=lsq.d_mm)
                     for name, (lsq, _) in planes.items()}
    dist_mm = design.get("mirror_corner_distance_mm")
    if dist_mm is None:
        raise ValueError("manifest.json: design.mirror_corner_distance_mm is needed to place "
                         "the measurement frame (the nominal axis relative to the mirrors)")
    T = measurement_frame_from_mirrors(mirror_planes, (laser.normal, laser.d_mm), float(dist_mm))
    if {"left", "right"} <= set(mirror_planes):
        l, r = mirror_planes["left"], mirror_planes["right"]
        mirror_planes = {
            "left": MirrorPlane("left", l.n, l.d_mm, _mirror_corners(l, r, T, design)),
            "right": MirrorPlane("right", r.n, r.d_mm, _mirror_corners(r, l, T, design)),
        }
    return mirror_planes, T


def _camera_uncertainty(cam: CameraCalibration) -> dict:
    """The intrinsics' standard deviations: OpenCV's, or the jackknife over boards where
    there is one (boards, not corners, are the independent units)."""
    std_cv = dict(zip(CAMERA_STD_NAMES, (float(v) for v in cam.std_intrinsics[:9])))
    camera_unc = {"std": std_cv, "std_method": "opencv", "std_opencv": std_cv,
                  "rms_px": cam.rms_px, "n_images": int(cam.used.sum())}
    if cam.cov_jackknife is not None:  # boards, not corners, are the independent units
        camera_unc.update(std=dict(zip(CAMERA_STD_NAMES, (float(v) for v in cam.std_jackknife))),
                          std_method="jackknife over boards", cov=cam.cov_jackknife.tolist(),
                          cov_names=list(CAMERA_STD_NAMES))
    return camera_unc

def _lsq_abd_cov(est: MirrorEstimate) -> np.ndarray:
    """The (θ, φ, d) covariance of :func:`refine_mirror` in the (a, b, δ) parameterisation."""
    if est.covariance is None:
        return np.full((3, 3), np.nan)
    from lts360.recon.calibration.uncertainty import tangent_basis

    n = est.normal
    th, ph = np.arccos(np.clip(n[2], -1, 1)), np.arctan2(n[1], n[0])
    dn_dth = np.array([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), -np.sin(th)])
    dn_dph = np.array([-np.sin(th) * np.sin(ph), np.sin(th) * np.cos(ph), 0.0])
    e1, e2 = tangent_basis(n)
    # refine_mirror may have flipped (n, d); the flip changes signs only, not variances.
    J = np.array([[dn_dth @ e1, dn_dph @ e1, 0.0], [dn_dth @ e2, dn_dph @ e2, 0.0], [0, 0, 1.0]])
    return J @ est.covariance @ J.T

"""``lts360 calibrate``: plan the board poses, render them, calibrate, report, and — for
rendered images — compare the result with the true rig.

Output folder::

    images/            the calibration images and manifest.json (rendered, or --images)
    truth.json         the true rig and board poses (rendered images only; never read by
                       the calibration itself)
    calibration.json   the result (OpenCV names for K and the distortion), with uncertainties
    report.json        reprojection RMS, plane residuals, standard deviations, images used
                       and skipped, and the accuracy against the truth where there is one
    fig8.png           as paper Fig. 8: real and virtual corners in one image; the 3-D
                       symmetry lines and the fitted mirror plane
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lts360.recon.calibration.from_images import (
    RigCalibrationResult,
    calibrate_rig,
    read_calibration_images,
)
from lts360.recon.model import Calibration, calibration_from_frame_truth, save_calibration

__all__ = ["run_calibrate", "render_calibration", "RenderedShots", "RenderStopped",
           "calibration_accuracy", "calibration_report", "plot_fig8", "format_report"]


def _angle_deg(a, b) -> float:
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    return float(np.degrees(np.arccos(np.clip(abs(a @ b), -1.0, 1.0))))


def calibration_accuracy(cal: Calibration, truth: dict, result: RigCalibrationResult | None = None
                         ) -> dict:
    """Errors of ``cal`` against the true rig (``frame.json``-style truth dict)."""
    t = calibration_from_frame_truth(truth)
    K, Kt = cal.K, t.K
    out = {"camera": {"fx_rel_percent": 100 * (K[0, 0] / Kt[0, 0] - 1),
                      "fy_rel_percent": 100 * (K[1, 1] / Kt[1, 1] - 1),
                      "cx_px": float(K[0, 2] - Kt[0, 2]), "cy_px": float(K[1, 2] - Kt[1, 2]),
                      "dist": (cal.dist - t.dist).tolist()}}

    def plane_err(n, d, nt, dt, at):
        """Angle, offset along the normal at the camera (``d``), and the distance of the true
        plane's point ``at`` (where the plane is used) from the estimated plane."""
        n = np.asarray(n, float)
        if np.dot(n, nt) < 0:
            n, d = -n, -d
        return {"normal_deg": _angle_deg(n, nt), "offset_um": 1e3 * (float(d) - float(dt)),
                "offset_at_use_um": 1e3 * (float(d) - float(n @ at))}

    out["mirrors"] = {}
    for m in cal.mirrors:
        mt = t.mirror(m.name)
        centre = mt.corners_mm.mean(axis=0) if mt.corners_mm is not None else mt.d_mm * mt.n
        row = {"lsq": plane_err(m.n, m.d_mm, mt.n, mt.d_mm, centre)}
        if result is not None and m.name in result.mirror_midpoint:
            e = result.mirror_midpoint[m.name]
            row["midpoint"] = plane_err(e.normal, e.d_mm, mt.n, mt.d_mm, centre)
        out["mirrors"][m.name] = row
    out["laser_plane"] = plane_err(*cal.laser_plane, *t.laser_plane, t.T_cam_meas[:3, 3])
    T, Tt = cal.T_cam_meas, t.T_cam_meas
    out["measurement_frame"] = {
        "origin_um": (1e3 * Tt[:3, :3].T @ (T[:3, 3] - Tt[:3, 3])).tolist(),
        "x_axis_deg": _angle_deg(T[:3, 0], Tt[:3, 0]), "z_axis_deg": _angle_deg(T[:3, 2], Tt[:3, 2])}
    return out


def calibration_report(result: RigCalibrationResult) -> dict:
    """What the calibration says about itself (no truth)."""
    cam = result.camera
    unc = result.calibration.uncertainty
    rep = {"camera": {"rms_px": cam.rms_px, "images_used": list(result.camera_images),
                      "per_image_rms_px": [float(v) for v in cam.per_image_rms_px],
                      "std": unc["camera"]["std"],
                      "std_method": unc["camera"].get("std_method", "opencv"),
                      "std_opencv": unc["camera"].get("std_opencv", unc["camera"]["std"])},
           "mirrors": {}, "skipped": result.skipped}
    for name, (names, _) in result.mirror_observations.items():
        lsq, mid = result.mirror_lsq[name], result.mirror_midpoint[name]
        rep["mirrors"][name] = {
            "images": names, "lsq_rms_px": lsq.rms,
            "midpoint_plane_rms_mm": mid.rms, "midpoint_vs_lsq_deg": _angle_deg(mid.normal, lsq.normal),
            "midpoint_vs_lsq_offset_um": 1e3 * (mid.d_mm - lsq.d_mm),
            "std_angle_deg": unc["mirrors"][name]["std_angle_deg"],
            "std_offset_mm": unc["mirrors"][name]["std_offset_mm"]}
    las = result.laser
    rep["laser_plane"] = {"poses": list(result.laser_lines),
                          "points_per_pose": [len(v.uv) for v in result.laser_lines.values()],
                          "pose_views": [list(v.pose_views)
                                         for v in result.laser_lines.values()],
                          "rms_mm": las.rms_mm,
                          "std_angle_deg": unc["laser_plane"]["std_angle_deg"],
                          "std_offset_mm": unc["laser_plane"]["std_offset_mm"]}
    return rep


def plot_fig8(result: RigCalibrationResult, images_dir: Path, path: Path) -> None:
    """Paper Fig. 8: left, real (red) and virtual (blue) corners in one mirror image; right, the
    3-D symmetry lines between corresponding corners and the fitted mirror planes."""
    import matplotlib

    matplotlib.use("Agg")
    import cv2
    import matplotlib.pyplot as plt

    from lts360.recon.calibration.mirrors import _pose, _transform

    imgs = read_calibration_images(images_dir)
    board = imgs.board
    K, dist = result.calibration.K, result.calibration.dist
    fig = plt.figure(figsize=(13, 5.5))
    ax0 = fig.add_subplot(1, 2, 1)
    ax1 = fig.add_subplot(1, 2, 2, projection="3d")
    first = True
    colours = {"left": "tab:green", "right": "tab:blue"}
    for name, (names, obs) in result.mirror_observations.items():
        if first:
            shot = next(s for s in imgs.shots if s["name"] == names[0])
            img = cv2.imread(str(imgs.root / (shot.get("image") or shot["image_board"])),
                             cv2.IMREAD_UNCHANGED)
            ax0.imshow(img, cmap="gray")
            ax0.plot(*obs[0].real_px.T, "r+", ms=5, label="real board")
            ax0.plot(*obs[0].virtual_px.T, "c+", ms=5, label="virtual board")
            allp = np.vstack([obs[0].real_px, obs[0].virtual_px])
            lo, hi = allp.min(0) - 60, allp.max(0) + 60
            ax0.set_xlim(lo[0], hi[0])
            ax0.set_ylim(hi[1], lo[1])
            ax0.set_title(f"{names[0]}: corners of the real and the virtual board")
            ax0.legend(loc="lower right")
            first = False
        obj = board.object_points().astype(float)
        mirror = result.calibration.mirror(name)
        for ob in obs:
            Xr = _transform(obj, *_pose(obj, ob.real_px, K, dist))
            Xv = Xr - 2.0 * ((Xr @ mirror.n) - mirror.d_mm)[:, None] * mirror.n
            # Every real-virtual segment in one line, NaN between them (one artist, not one
            # per corner: the figure took 2 s).
            seg = np.stack([Xr, Xv, np.full_like(Xr, np.nan)], axis=1).reshape(-1, 3)
            ax1.plot(*seg.T, color=colours.get(name, "k"), lw=0.4)
            ax1.scatter(*Xr.T, s=2, c="r")
            ax1.scatter(*((Xr + Xv) / 2).T, s=2, c="k")
    ax1.set_title("3-D symmetry lines (camera frame, mm); midpoints on the mirror planes")
    ax1.set_xlabel("x")
    ax1.set_ylabel("y")
    ax1.set_zlabel("z")
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


@dataclass(frozen=True)
class RenderedShots:
    """What :func:`render_calibration` leaves for :func:`run_calibrate`: the folder of images,
    the truth (never read by the calibration) and the camera shots' corners found while
    rendering."""

    images_dir: Path
    truth: dict
    early: "_EarlyCorners"


class RenderStopped(Exception):
    """:func:`render_calibration` was told to stop (its ``stop`` event was set)."""


def render_calibration(out_dir, *, rig_name: str = "paper", noise: str = "none", seed: int = 0,
                       spp: int = 64, n_camera: int = 30, n_mirror: int = 6, n_laser: int = 6,
                       board=None, camera_board=None, thin_lens: bool = True,
                       f_number: float | None = None, laser_in_mirror: bool = True,
                       target_spp: int | None = None, say=print, bar: bool = True,
                       stop=None, lock=None) -> RenderedShots:
    """Plan the board poses and render them into ``out_dir/images`` (the first half of
    :func:`run_calibrate`, whose parameters these are), detecting the camera shots' corners
    while the next shots render.  ``bar``: a progress bar on stderr; ``stop``: a
    :class:`threading.Event` checked after each shot (set: :class:`RenderStopped`, the
    partial folder left behind), and ``lock`` held while each shot renders
    (:func:`~lts360.simulator.calib_render.render_calibration_images`), for a caller that
    renders in the background."""
    from lts360.scenes.calib_plan import plan_calibration
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.calib_render import render_calibration_images
    from lts360.simulator.io import write_json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rig = load_rig(rig_name)
    if f_number is not None:
        from dataclasses import replace

        rig = replace(rig, camera=replace(rig.camera, f_number=float(f_number)))
    shots = plan_calibration(rig, board, camera_board=camera_board, n_camera=n_camera,
                             n_mirror=n_mirror, n_laser=n_laser, seed=seed,
                             laser_in_mirror=laser_in_mirror)
    say(f"planned {len(shots)} board poses: {n_camera} camera, {n_mirror} per mirror, "
        f"{n_laser} laser (each laser pose: board, laser on, laser off)")
    tmp = out / ".images.partial"
    shutil.rmtree(tmp, ignore_errors=True)
    progress = _bar(len(shots), "rendering") if bar else _NullBar()
    early = _EarlyCorners(shots)

    def rendered_one(name):
        progress.update(1)
        early.add(name, tmp)
        if stop is not None and stop.is_set():
            raise RenderStopped(f"calibration rendering stopped after {name}")

    try:
        rendered = render_calibration_images(rig, shots, tmp, noise=noise, seed=seed, spp=spp,
                                             thin_lens=thin_lens, target_spp=target_spp,
                                             progress=rendered_one, lock=lock)
    except BaseException:
        early.cancel()
        raise
    finally:
        progress.close()
    shutil.rmtree(out / "images", ignore_errors=True)
    tmp.replace(out / "images")
    write_json(out / "truth.json", rendered["truth"])
    return RenderedShots(out / "images", rendered["truth"], early)


def run_calibrate(out_dir, *, rig_name: str = "paper", noise: str = "none", seed: int = 0,
                  images_dir=None, spp: int = 64, n_camera: int = 30, n_mirror: int = 6,
                  n_laser: int = 6, board=None, camera_board=None, tangential: bool = False,
                  thin_lens: bool = True, f_number: float | None = None,
                  laser_in_mirror: bool = True, target_spp: int | None = None,
                  camera_model_rounds: int | None = None, rendered: RenderedShots | None = None,
                  say=print) -> dict:
    """Plan + render (unless ``images_dir``) + calibrate + report.  Returns the report.

    ``f_number``: the aperture the calibration images are taken at (default: the rig's, the
    one the measurements use).  Stopping down for calibration sharpens the small boards,
    which at the rig's focus (set between the direct and the mirror paths) are blurred by
    4–5 px at f/2.8; with the ideal thin lens simulated here the aperture changes nothing
    else (a real lens may shift its principal point slightly with the aperture).

    ``laser_in_mirror``: laser boards posed so that they are seen in a mirror too (their
    pose from both views); ``False``: seen directly only (pose from PnP).

    ``target_spp``: samples per pixel of the mirror and laser shots (default ``spp``); see
    :func:`lts360.simulator.calib_render.render_calibration_images`.

    ``camera_model_rounds``: see :func:`lts360.recon.calibration.from_images.calibrate_rig` (default there).

    ``rendered``: the images already rendered into ``out_dir`` by :func:`render_calibration`
    with these parameters (e.g. in the background while other work ran); only the
    calibration is done here.
    """
    from lts360.recon.calibration.from_images import CAMERA_MODEL_ROUNDS

    if camera_model_rounds is None:
        camera_model_rounds = CAMERA_MODEL_ROUNDS
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if rendered is None and images_dir is None:
        rendered = render_calibration(out, rig_name=rig_name, noise=noise, seed=seed, spp=spp,
                                      n_camera=n_camera, n_mirror=n_mirror, n_laser=n_laser,
                                      board=board, camera_board=camera_board,
                                      thin_lens=thin_lens, f_number=f_number,
                                      laser_in_mirror=laser_in_mirror, target_spp=target_spp,
                                      say=say)
    truth = early = None
    if rendered is not None:
        images_dir, truth, early = rendered.images_dir, rendered.truth, rendered.early
    images = read_calibration_images(images_dir)
    known = early.result(images.camera_board) if early is not None else {}
    result = calibrate_rig(images, tangential=tangential, progress=say,
                           camera_model_rounds=camera_model_rounds, camera_corners=known)
    from dataclasses import replace as _replace

    from lts360.scenes.rig_io import load_rig as _load_rig
    from lts360.simulator.io import rig_record

    # The optics the rig is measured with (its own f-number, not the calibration shots'),
    # for the line-centre bias twin.
    cal = _replace(result.calibration, optics=rig_record(_load_rig(rig_name), rig_name))
    result = _replace(result, calibration=cal)
    save_calibration(out / "calibration.json", cal)
    report = calibration_report(result)
    if truth is not None:
        report["accuracy"] = calibration_accuracy(result.calibration, truth, result)
    report["settings"] = {"rig": rig_name, "noise": noise, "seed": seed, "spp": spp,
                          "target_spp": target_spp or spp,
                          "images": str(images_dir), "tangential": tangential,
                          "thin_lens": thin_lens, "f_number": f_number,
                          "laser_in_mirror": laser_in_mirror,
                          "camera_model_rounds": camera_model_rounds}
    text = json.dumps(report, indent=2, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
    (out / "report.json").write_text(text)
    try:
        plot_fig8(result, Path(images_dir), out / "fig8.png")
    except Exception as exc:  # a figure must not lose a calibration
        say(f"fig8.png not written: {exc}")
    return report


class _EarlyCorners:
    """The camera shots' corners, found while the next shots render (one thread): the
    renderer leaves a core idle between its kernels, and the corner detection
    (:func:`lts360.recon.calibration.camera.detect_corners`, the same call on the same
    image as :func:`calibrate_rig` makes) fills it.  :meth:`result` hands them over only for
    the board the manifest names."""

    def __init__(self, shots):
        from lts360.recon.calibration.board import BoardGeometry

        cam = [s for s in shots if s.kind == "camera"]
        self.names = {s.name for s in cam}
        self.board = (BoardGeometry(tuple(int(v) for v in cam[0].board.pattern_size),
                                    float(cam[0].board.square_mm)) if cam else None)
        self.pool = None
        self.futures = {}

    def add(self, name: str, folder: Path) -> None:
        """Shot ``name`` was written to ``folder``: detect its corners if it is a camera shot."""
        if name not in self.names:
            return
        from concurrent.futures import ThreadPoolExecutor

        from lts360.recon.calibration.camera import detect_corners
        from lts360.recon.images import read_image

        if self.pool is None:
            self.pool = ThreadPoolExecutor(max_workers=1)
        self.futures[name] = self.pool.submit(detect_corners, read_image(folder / f"{name}.png"),
                                              self.board)

    def result(self, board) -> dict:
        """``{name: corners}`` (``None``: board not found); empty if ``board`` is another."""
        if self.pool is None:
            return {}
        out = {n: f.result() for n, f in self.futures.items()}
        self.pool.shutdown()
        return out if board == self.board else {}

    def cancel(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=False, cancel_futures=True)


class _NullBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _bar(total: int, desc: str):
    try:
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, unit="image")
    except ImportError:  # pragma: no cover
        return _NullBar()


def format_report(report: dict) -> str:
    """The terminal summary of a calibration report."""
    lines = []
    c = report["camera"]
    lines.append(f"camera: {len(c['images_used'])} images, reprojection RMS {c['rms_px']:.4f} px, "
                 f"σ(fx) {c['std']['fx']:.3f} px, σ(cx, cy) {c['std']['cx']:.3f}, "
                 f"{c['std']['cy']:.3f} px ({c.get('std_method', 'opencv')}; OpenCV's σ(cx) "
                 f"{c.get('std_opencv', c['std'])['cx']:.3f} px)")
    for name, m in report["mirrors"].items():
        lines.append(f"mirror {name}: {len(m['images'])} images, LSQ RMS {m['lsq_rms_px']:.4f} px, "
                     f"σ(normal) {m['std_angle_deg']:.4f}°, σ(offset) {1e3 * m['std_offset_mm']:.1f} µm;"
                     f" midpoint plane {m['midpoint_vs_lsq_deg']:.4f}° / "
                     f"{m['midpoint_vs_lsq_offset_um']:+.1f} µm from LSQ")
    la = report["laser_plane"]
    in_mirror = sum(len(v) > 1 for v in la.get("pose_views", []))
    lines.append(f"laser plane: {len(la['poses'])} poses ({in_mirror} posed from the direct and "
                 f"a mirror view), {sum(la['points_per_pose'])} points, "
                 f"RMS {1e3 * la['rms_mm']:.1f} µm, σ(normal) {la['std_angle_deg']:.4f}°, "
                 f"σ(offset) {1e3 * la['std_offset_mm']:.1f} µm")
    if report.get("skipped"):
        lines.append(f"skipped: {report['skipped']}")
    acc = report.get("accuracy")
    if acc:
        a = acc["camera"]
        lines.append(f"vs truth: fx {a['fx_rel_percent']:+.4f} %, fy {a['fy_rel_percent']:+.4f} %, "
                     f"cx {a['cx_px']:+.3f} px, cy {a['cy_px']:+.3f} px")
        lines.append("  planes: normal angle; offset d (at the camera); offset at the mirror "
                     "centre / the axis")
        for name, row in acc["mirrors"].items():
            s = (f"  mirror {name}: LSQ {row['lsq']['normal_deg']:.4f}° "
                 f"{row['lsq']['offset_um']:+.1f} µm / {row['lsq']['offset_at_use_um']:+.1f} µm")
            if "midpoint" in row:
                s += (f"; midpoint (paper) {row['midpoint']['normal_deg']:.4f}° "
                      f"{row['midpoint']['offset_um']:+.1f} / "
                      f"{row['midpoint']['offset_at_use_um']:+.1f} µm")
            lines.append(s)
        lp = acc["laser_plane"]
        lines.append(f"  laser plane: {lp['normal_deg']:.4f}° {lp['offset_um']:+.1f} µm / "
                     f"{lp['offset_at_use_um']:+.1f} µm")
        mf = acc["measurement_frame"]
        lines.append("  measurement frame origin (µm): "
                     + ", ".join(f"{v:+.1f}" for v in mf["origin_um"])
                     + f"; x axis {mf['x_axis_deg']:.4f}°")
    return "\n".join(lines)



"""The rig calibration's covariance predicted from the planned board poses (Fisher information).

The calibration from images (:mod:`lts360.recon.calibration.from_images`) runs in three
stages, and so does this model, each linearised at the true rig and the planned poses
(:func:`lts360.scenes.calib_plan.plan_calibration`), with independent image noise:

1. **camera** — Zhang's method on the ``camera`` shots: ``fx fy cx cy k1 k2`` free (``k3``
   fixed, tangential zero), one board pose per shot.  The poses are nuisance parameters:
   the intrinsics' information is the Schur complement
   ``Σ_i (A_i − B_i C_i⁻¹ B_iᵀ)`` of the Gauss–Newton normal matrix, with corner noise
   ``σ_c`` px (iid per coordinate).
2. **mirrors** — per mirror, the plane ``(a, b, δ)`` and one pose per shot from every real
   corner ``P X`` and virtual corner ``P T_π X`` of its ``mirror`` shots (and of the
   ``laser`` shots seen in it), K fixed; again a Schur complement over the poses.
3. **laser plane** — per ``laser`` shot, the board pose from its real and virtual corners
   (the mirror fixed) gives the board plane; the laser line's image points are
   back-projected onto it; an unweighted plane fit through every pose's points.  That fit
   is linear in the points' errors along the laser normal, ``e = n_L · δp``, so its
   covariance is the sandwich ``M⁻¹ Q M⁻¹`` (``M = Σ G Gᵀ``, ``G = (e1·p, e2·p, −1)``)
   with two independent sources in ``Q``: the pose error (shared by a pose's points,
   ``σ_c²``) and the line-centre error across the line (``σ_l`` px, independent per
   point).  Optionally the mirror planes' own covariance, shared by every pose seen in
   that mirror, is carried into the poses too.

Planes are ``n · X = d`` in the camera frame with ``d < 0`` (the calibration's orientation)
and are perturbed as ``n' = normalise(n + a e1 + b e2)``, ``d' = d + δ`` with the
calibration's tangent basis.  Board poses are perturbed in the camera frame,
``X' = X + ω × X + t``.

Where the model stops: corner errors are independent (a board whose corners share an error
— defocus, a detector's bias — spreads its fit more: the calibration's jackknife sees that,
this model does not); each stage conditions on the previous one's result (K fixed in the
mirror fit, as the calibration does; the intrinsics' error is not carried into the planes);
the laser boards' corners enter both their mirror's fit and their own pose, a correlation
left out; ``p1 p2 k3`` of the rig are taken as zero in the projection.

The information blocks are in :mod:`lts360.design.calib_fisher`; they work on matrices as
Python lists of lists of arrays (one matrix per element of the arrays: a corner, a line point
or a shot, :mod:`lts360.design.smallmat`), with ``+ − * /`` and the few functions of an
``ops`` object (:data:`lts360.design.backend.NUMPY_OPS`, or
:func:`lts360.design.backend.drjit_ops` for ``drjit.llvm.ad.Float64``), so that the same code
runs in a Dr.Jit program for gradients.  This module is the numpy front end
(:func:`predict_calibration_covariance` builds the inputs from a rig and a plan) and the
plan the design model re-predicts for every design (:class:`CalibrationPlan`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lts360.design.backend import NUMPY_OPS
from lts360.design.calib_fisher import (
    board_pose_information,
    camera_information,
    laser_plane_parts,
    mirror_information,
)
from lts360.design.shares import CAMERA_NAMES, tangent_basis_np
from lts360.design.smallmat import spd_inverse

__all__ = ["LaserLineSamples", "laser_line_samples", "CalibrationPrediction",
           "predict_calibration_covariance", "INTRINSIC_NAMES", "plan_covariance",
           "PLAN_SIGMA_CORNER_PX", "PLAN_SIGMA_TARGET_PX", "PLAN_SIGMA_LINE_PX", "CalibrationPlan"]

#: The intrinsics the camera stage estimates, in the order of its covariance.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2")


# --------------------------------------------------------------------------- numpy front end

@dataclass(frozen=True)
class LaserLineSamples:
    """The laser line on each laser board, sampled for the plane fit (numpy, camera frame).

    ``p_mm`` (m, k, 3) sample points, ``w`` (m, k) points of the real line each stands for
    (one detected centre per pixel along the line's major image axis), ``n_points`` (m,).
    """

    p_mm: np.ndarray
    w: np.ndarray
    n_points: np.ndarray


def _clip_line(foot, direction, lo, hi):
    """Parameter range of ``foot + s direction`` inside the box ``lo ≤ q ≤ hi`` (2-D)."""
    s0, s1 = -np.inf, np.inf
    for k in range(2):
        if abs(direction[k]) < 1e-12:
            if not lo[k] <= foot[k] <= hi[k]:
                return None
            continue
        a, b = (lo[k] - foot[k]) / direction[k], (hi[k] - foot[k]) / direction[k]
        s0, s1 = max(s0, min(a, b)), min(s1, max(a, b))
    return (s0, s1) if s1 > s0 else None


def laser_line_samples(R_board, t_board_mm, pattern_size, square_mm, n_laser, d_laser_mm, K,
                       *, n_line: int = 32, inset_squares: float = 0.25
                       ) -> tuple[np.ndarray, float] | None:
    """The laser line on one board (camera frame): ``n_line`` sample points and their weight.

    The line is the laser plane ∩ the board plane, clipped to the printed squares shrunk by
    ``inset_squares`` (as :func:`lts360.recon.calibration.laser_plane.laser_line_points`
    keeps its centres); the samples are the midpoints of ``n_line`` equal pieces, each
    weighted by the detected centres it stands for (pixels along the line's major image
    axis / ``n_line``).  ``None`` where the plane misses the board.
    """
    R, t = np.asarray(R_board, float), np.asarray(t_board_mm, float)
    nx, ny = pattern_size
    m = R.T @ np.asarray(n_laser, float)  # the plane in board coordinates: m · q = c
    c = float(d_laser_mm - np.asarray(n_laser, float) @ t)
    m2 = m[:2]
    if np.linalg.norm(m2) < 1e-9:
        return None
    foot = m2 * c / (m2 @ m2)
    direction = np.array([-m2[1], m2[0]]) / np.linalg.norm(m2)
    lo = np.array([(inset_squares - 1.0) * square_mm] * 2)
    hi = np.array([(nx - inset_squares) * square_mm, (ny - inset_squares) * square_mm])
    rng = _clip_line(foot, direction, lo, hi)
    if rng is None:
        return None
    s = rng[0] + (np.arange(n_line) + 0.5) / n_line * (rng[1] - rng[0])
    q = foot + np.outer(s, direction)
    p = np.column_stack([q, np.zeros(n_line)]) @ R.T + t
    ends = np.column_stack([foot + np.outer(rng, direction), np.zeros(2)]) @ R.T + t
    uv = ends[:, :2] / ends[:, 2:3] * np.diag(K)[:2]
    n_px = float(np.max(np.abs(uv[1] - uv[0])))
    return p, n_px / n_line


def _plane_cam(n_world, d_world, R, t):
    """A world plane in the camera frame, oriented with ``d < 0`` (camera on the + side)."""
    n = R @ np.asarray(n_world, float)
    d = float(d_world + n @ t)
    return (-n, -d) if d > 0 else (n, d)


def _cols(P):
    """(k, 3) → list of 3 arrays."""
    P = np.asarray(P, float)
    return [P[:, 0].copy(), P[:, 1].copy(), P[:, 2].copy()]


def _rep(v, k):
    """A per-shot (m, 3) or (m,) array repeated ``k`` times per shot, as columns."""
    v = np.repeat(np.asarray(v, float), k, axis=0)
    return _cols(v) if v.ndim == 2 else v


def _np(A) -> np.ndarray:
    return np.array([[np.asarray(v, float).reshape(-1)[0] for v in row] for row in A])


@dataclass(frozen=True)
class CalibrationPrediction:
    """The predicted covariance of a rig calibration (see the module docstring).

    Attributes
    ----------
    camera_cov : (6, 6) float
        Of ``fx fy cx cy k1 k2`` (px², px², px², px², 1, 1).
    mirror_cov : dict of name → (3, 3) float
        ``(a, b, δ)`` (rad, rad, mm) of each mirror, camera frame, ``d < 0``.
    laser_cov : (3, 3) float
        ``(a, b, δ)`` of the laser plane: the sum of ``laser_parts``.
    laser_parts : dict of name → (3, 3) float
        ``line`` (σ_l), ``pose`` (σ_c through the board poses), ``mirror`` (the mirrors'
        covariance through the poses; zero unless asked for).
    laser_residual_rms_mm : float
        The laser-plane fit's expected residual RMS (all sources), of the points as the
        calibration fits them (each pose's moved onto its straight line): comparable with
        ``LaserPlaneEstimate.rms_mm``.
    laser_points : (m,) float
        Line points per laser pose (centres along the line's major image axis).
    planes_cam : dict of name → ((3,) float, float)
        The planes (``laser`` and the mirrors) the covariances refer to.
    sigma_corner_px, sigma_target_px, sigma_line_px : float
        The noise levels used (camera board corners, mirror/laser board corners, line).
    """

    camera_cov: np.ndarray
    mirror_cov: dict
    laser_cov: np.ndarray
    laser_parts: dict
    laser_residual_rms_mm: float
    laser_points: np.ndarray
    planes_cam: dict
    sigma_corner_px: float
    sigma_target_px: float
    sigma_line_px: float
    notes: dict = field(default_factory=dict)

    @property
    def camera_std(self) -> dict:
        """Standard deviations of the intrinsics, by name (p1 p2 k3: 0, fixed)."""
        out = dict.fromkeys(CAMERA_NAMES, 0.0)
        out.update(zip(INTRINSIC_NAMES, np.sqrt(np.diag(self.camera_cov)).tolist()))
        return out

    def sigma_line_for_residual_rms(self, residual_rms_mm: float) -> float:
        """The line noise ``σ_l`` (px) at which the laser fit's expected residual RMS (points
        on their per-pose lines, as the calibration fits them) is ``residual_rms_mm``, the
        other sources as predicted; 0 where those alone explain it."""
        u = self.notes["laser_ms_per_unit"]
        rest = self.laser_residual_rms_mm ** 2 - u["line_fitted_mm2_per_px2"] * \
            self.sigma_line_px ** 2
        return float(np.sqrt(max(residual_rms_mm ** 2 - rest, 0.0) /
                             u["line_fitted_mm2_per_px2"]))

    def to_uncertainty(self) -> dict:
        """The layout of ``Calibration.uncertainty`` (camera std + cov over the nine names,
        ``mirrors.<name>.cov_abd``, ``laser_plane.cov_abd``), so that a prediction can be
        compared with a calibration file and drawn from like one."""
        cov9 = np.zeros((9, 9))
        cov9[:6, :6] = self.camera_cov

        def plane(c):
            c = np.asarray(c, float)
            return {"cov_abd": c.tolist(),
                    "std_angle_deg": float(np.degrees(np.sqrt(np.trace(c[:2, :2])))),
                    "std_offset_mm": float(np.sqrt(c[2, 2]))}

        return {"camera": {"std": self.camera_std, "std_method": "fisher (predicted)",
                           "cov": cov9.tolist(), "cov_names": list(CAMERA_NAMES),
                           "rms_px": self.sigma_corner_px},
                "mirrors": {k: plane(v) for k, v in self.mirror_cov.items()},
                "laser_plane": plane(self.laser_cov),
                "parameterisation": "planes: n' = normalise(n + a e1 + b e2), d' = d + delta; "
                                    "lts360.recon.calibration.uncertainty.tangent_basis(n) "
                                    "gives e1, e2"}


def _laser_lines(laser_shots, R, t, K, nL, dL, n_line: int):
    """The laser line on every laser board (camera frame), sampled for the plane fit: the
    model's ``line`` dict (points, weights, each board's plane and axes, repeated per sample)
    and the detected centres each board stands for.

    Raises
    ------
    ValueError
        The laser sheet misses a board.
    """
    P, W, NB, DB, B1, B2, counts = [], [], [], [], [], [], []
    for s in laser_shots:
        T = s.board.T_world_board
        Rb, tb = R @ T[:3, :3], R @ T[:3, 3] + t
        got = laser_line_samples(Rb, tb, s.board.pattern_size, s.board.square_mm, nL, dL, K,
                                 n_line=n_line)
        if got is None:
            raise ValueError(f"predict_calibration_covariance: the laser sheet misses the "
                             f"board of {s.name}")
        P.append(got[0])
        W.append(np.full(n_line, got[1]))
        counts.append(got[1] * n_line)
        NB.append(Rb[:, 2])
        DB.append(float(Rb[:, 2] @ tb))
        B1.append(Rb[:, 0])
        B2.append(Rb[:, 1])
    line = {"p": _cols(np.concatenate(P)), "w": np.concatenate(W),
            "n_board": _rep(NB, n_line), "d_board": _rep(DB, n_line),
            "b1": _rep(B1, n_line), "b2": _rep(B2, n_line)}
    return line, counts


def predict_calibration_covariance(rig, shots, *, sigma_corner_px: float,
                                   sigma_line_px: float, sigma_target_px: float | None = None,
                                   laser_boards_in_mirror_fit: bool = True,
                                   mirror_into_laser: bool = False,
                                   mirror_cov_for_laser: dict | None = None, n_line: int = 32,
                                   ops=NUMPY_OPS) -> CalibrationPrediction:
    """Predict the calibration's covariance for ``rig`` and a plan (numpy front end).

    Parameters
    ----------
    rig : lts360.scenes.rig.Rig
        The true rig (camera K and k1, k2, pose; mirrors; laser sheet).
    shots : list of BoardShot
        :func:`lts360.scenes.calib_plan.plan_calibration`'s plan.
    sigma_corner_px : float, > 0
        Corner noise of the camera board (px, per coordinate).
    sigma_line_px : float, >= 0
        Line-centre noise across the line, per detected centre (px).
    sigma_target_px : float, > 0, optional
        Corner noise of the mirror/laser board (default ``sigma_corner_px``).
    laser_boards_in_mirror_fit : bool
        Laser shots seen in a mirror join that mirror's fit (the calibration's default).
    mirror_into_laser : bool
        Carry the mirror covariance into the laser boards' poses (shared by the boards seen
        in one mirror): the predicted one, or ``mirror_cov_for_laser``.
    mirror_cov_for_laser : dict of name → (3, 3), optional
        Mirror covariances to carry instead of the predicted ones (e.g. a calibration's
        jackknife), in this module's orientation (``d < 0``).
    n_line : int
        Samples per laser line.

    Raises
    ------
    ValueError
        A stage without shots, a noise level out of range, or a laser board the sheet
        does not cross.
    """
    if not sigma_corner_px > 0 or not sigma_line_px >= 0:
        raise ValueError(f"sigma_corner_px must be > 0 and sigma_line_px >= 0, got "
                         f"{sigma_corner_px}, {sigma_line_px}")
    s_t = sigma_corner_px if sigma_target_px is None else float(sigma_target_px)
    cam = rig.camera
    R, t = np.asarray(cam.R, float), np.asarray(cam.t_mm, float)
    K = np.asarray(cam.K, float)
    dist = np.asarray(cam.distortion, float)
    intr = (K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist[0], dist[1])

    def corners_cam(sel):
        pts = [s.board.corners_world_mm() @ R.T + t for s in sel]
        return _cols(np.concatenate(pts)), len(pts[0])

    cam_shots = [s for s in shots if s.kind == "camera"]
    if len(cam_shots) < 3:
        raise ValueError(f"predict_calibration_covariance: {len(cam_shots)} camera shots, "
                         "need at least 3")
    Xc, nc = corners_cam(cam_shots)
    camera_cov = np.linalg.inv(_np(camera_information(ops, Xc, intr, nc))) * sigma_corner_px ** 2

    planes = {m.name: _plane_cam(*m.plane, R, t) for m in rig.mirrors}
    planes["laser"] = _plane_cam(*rig.laser.plane, R, t)
    basis = {k: tangent_basis_np(n) for k, (n, _) in planes.items()}
    mirror_cov = {}
    for name in (m.name for m in rig.mirrors):
        sel = [s for s in shots if s.mirror == name and
               (s.kind == "mirror" or (s.kind == "laser" and laser_boards_in_mirror_fit))]
        if not sel:
            raise ValueError(f"predict_calibration_covariance: no shot for mirror {name!r}")
        Xm, nm = corners_cam(sel)
        (n, d), (e1, e2) = planes[name], basis[name]
        info = _np(mirror_information(ops, Xm, intr, list(n), d, list(e1), list(e2), nm))
        mirror_cov[name] = np.linalg.inv(info) * s_t ** 2

    laser_shots = [s for s in shots if s.kind == "laser"]
    if len(laser_shots) < 2:
        raise ValueError("predict_calibration_covariance: need at least 2 laser shots")
    if any(s.mirror not in planes for s in laser_shots):
        raise ValueError("predict_calibration_covariance: every laser shot must be seen in a "
                         "mirror (plan_calibration(laser_in_mirror=True)); direct-only poses "
                         "are not modelled")
    nL, dL = planes["laser"]
    eL1, eL2 = basis["laser"]
    Xl, nl = corners_cam(laser_shots)
    mir_n = np.array([planes[s.mirror][0] for s in laser_shots])
    mir_d = np.array([planes[s.mirror][1] for s in laser_shots])
    mir_e1 = np.array([basis[s.mirror][0] for s in laser_shots])
    mir_e2 = np.array([basis[s.mirror][1] for s in laser_shots])
    C, B, _ = board_pose_information(ops, Xl, intr, _rep(mir_n, nl), _rep(mir_d, nl),
                                     _rep(mir_e1, nl), _rep(mir_e2, nl), nl)
    line, counts = _laser_lines(laser_shots, R, t, K, nL, dL, n_line)
    terms = None
    if mirror_into_laser:
        terms = [((np.array([s.mirror == k for s in laser_shots], float)),
                  [[float(v) for v in row] for row in (mirror_cov_for_laser or mirror_cov)[k]])
                 for k in mirror_cov]
    parts = laser_plane_parts(ops, line, C, B, list(nL), dL, list(eL1), list(eL2), intr,
                              n_line, mirror_terms=terms)
    lp = {"line": _np(parts["cov_line"]) * sigma_line_px ** 2,
          "pose": _np(parts["cov_pose"]) * s_t ** 2,
          "mirror": _np(parts["cov_mirror"]) if terms else np.zeros((3, 3))}
    ms = (float(parts["ms_line_fitted"][0]) * sigma_line_px ** 2
          + float(parts["ms_pose"][0]) * s_t ** 2
          + (float(parts["ms_mirror"][0]) if terms else 0.0))
    return CalibrationPrediction(
        camera_cov=camera_cov, mirror_cov=mirror_cov, laser_cov=sum(lp.values()),
        laser_parts=lp, laser_residual_rms_mm=float(np.sqrt(max(ms, 0.0))),
        laser_points=np.array(counts), planes_cam={k: (np.asarray(n), float(d))
                                                   for k, (n, d) in planes.items()},
        sigma_corner_px=float(sigma_corner_px), sigma_target_px=s_t,
        sigma_line_px=float(sigma_line_px),
        notes={"laser_ms_per_unit": {"line_mm2_per_px2": float(parts["ms_line"][0]),
                                     "line_fitted_mm2_per_px2":
                                         float(parts["ms_line_fitted"][0]),
                                     "pose_mm2_per_px2": float(parts["ms_pose"][0])}})


# --------------------------------------------------------------------------- the plan's covariance

#: Noise levels of the rendered calibration (the demo's ``lts360 calibrate``, paper rig, 64 spp,
#: measured 2026-12-03): the camera board's corners, σ per coordinate = OpenCV's per-corner
#: RMS 0.045 px / √2; the small mirror/laser board's corners (its mirror fits' per-coordinate
#: RMS); the line centres, per detected centre, the σ at which this model's laser-fit residual
#: (each pose's points moved onto their straight line, as the calibration fits them) equals
#: the demo's 5.56 µm.
PLAN_SIGMA_CORNER_PX = 0.0317
PLAN_SIGMA_TARGET_PX = 0.0089
PLAN_SIGMA_LINE_PX = 0.54


def plan_covariance(rig, *, n_camera: int = 30, n_mirror: int = 6, n_laser: int = 6,
                    seed: int = 0, sigma_corner_px: float = PLAN_SIGMA_CORNER_PX,
                    sigma_target_px: float = PLAN_SIGMA_TARGET_PX,
                    sigma_line_px: float = PLAN_SIGMA_LINE_PX):
    """The covariance ``lts360 calibrate``'s plan for ``rig`` is predicted to give, as a
    :class:`lts360.design.shares.CalibrationCovariance` the design model propagates.

    The plan is :func:`lts360.scenes.calib_plan.plan_calibration` with ``lts360 calibrate``'s
    defaults (30 camera shots, 6 per mirror, 6 laser shots, seed 0, the default boards); the
    mirrors' covariance is carried into the laser boards' poses.  The prediction assumes
    independent corner errors: the calibration's jackknife, which sees errors shared by a
    board, is 1–7× larger on the demo (STUDIES.md).

    Raises
    ------
    ValueError
        The plan cannot be made for this rig, or a stage has too few shots.
    """
    from lts360.design.shares import CalibrationCovariance
    from lts360.scenes.calib_plan import plan_calibration

    shots = plan_calibration(rig, n_camera=n_camera, n_mirror=n_mirror, n_laser=n_laser,
                             seed=seed)
    pred = predict_calibration_covariance(rig, shots, sigma_corner_px=sigma_corner_px,
                                          sigma_target_px=sigma_target_px,
                                          sigma_line_px=sigma_line_px, mirror_into_laser=True)
    planes = {k: n for k, (n, _) in pred.planes_cam.items()}
    return CalibrationCovariance.from_uncertainty(
        pred.to_uncertainty(), planes,
        source=f"plan of {rig.name} ({n_camera} camera, {n_mirror} per mirror, {n_laser} "
               f"laser shots; σ corner {sigma_corner_px:g}/{sigma_target_px:g} px, line "
               f"{sigma_line_px:g} px)")


# --------------------------------------------------------------------------- in the design model

@dataclass(frozen=True, eq=False)
class CalibrationPlan:
    """A calibration plan the design model re-predicts for every design (with gradients).

    The plan is made once, for the base rig (:func:`plan_calibration` with ``lts360
    calibrate``'s defaults).  As the design changes, the camera boards keep their image:
    relative to the camera, each board keeps its orientation and the lateral position of its
    centre, and the centre's depth scales with the focal length (the same pixels, the same
    size in the image, the same tilts); the mirror and laser
    boards stay where they were *in the world* (in the measurement volume); every
    covariance (intrinsics, mirrors, laser plane, with the mirrors' carried into the laser
    boards' poses) is recomputed from the design's camera, mirrors and laser.  The laser
    line's sample points on each board stay in the world (the sheet is the plane z = 0 of
    every design) with the base rig's weights.  Compared by identity (one recording of the
    model per plan).
    """

    names: tuple
    mirror_names: tuple
    cam_X: np.ndarray        # (S_c n_c, 3) camera frame, base rig
    n_cam_corners: int
    cam_centre_z: np.ndarray  # (S_c n_c,) depth of each corner's board centre, base rig
    f_px_base: float
    mirror_X: tuple          # per mirror (S_m n, 3) world
    mirror_corners: tuple    # per mirror: corners per shot
    laser_X: np.ndarray      # (S_l n_l, 3) world
    n_laser_corners: int
    laser_mirror: np.ndarray  # (S_l,) index into mirror_names
    line_p: np.ndarray       # (S_l n_line, 3) world
    line_w: np.ndarray       # (S_l n_line,)
    line_nb: np.ndarray      # (S_l, 3) board normal, world
    line_db: np.ndarray      # (S_l,) board offset, world
    line_b1: np.ndarray      # (S_l, 3)
    line_b2: np.ndarray      # (S_l, 3)
    n_line: int
    sigma_corner_px: float
    sigma_target_px: float
    sigma_line_px: float
    source: str = ""

    @classmethod
    def from_rig(cls, rig, *, n_camera: int = 30, n_mirror: int = 6, n_laser: int = 6,
                 seed: int = 0, sigma_corner_px: float = PLAN_SIGMA_CORNER_PX,
                 sigma_target_px: float = PLAN_SIGMA_TARGET_PX,
                 sigma_line_px: float = PLAN_SIGMA_LINE_PX, n_line: int = 32
                 ) -> "CalibrationPlan":
        """The plan of ``rig`` (raises ValueError as :func:`predict_calibration_covariance`)."""
        from lts360.scenes.calib_plan import plan_calibration

        shots = plan_calibration(rig, n_camera=n_camera, n_mirror=n_mirror, n_laser=n_laser,
                                 seed=seed)
        cam = rig.camera
        R, t = np.asarray(cam.R, float), np.asarray(cam.t_mm, float)
        K = np.asarray(cam.K, float)
        mnames = tuple(m.name for m in rig.mirrors)
        cam_shots = [s for s in shots if s.kind == "camera"]
        if len(cam_shots) < 3:
            raise ValueError(f"calibration plan: {len(cam_shots)} camera shots, need 3")
        cam_X = np.concatenate([s.board.corners_world_mm() @ R.T + t for s in cam_shots])
        n_c = len(cam_shots[0].board.corners_world_mm())
        centre_z = np.repeat(cam_X[:, 2].reshape(-1, n_c).mean(axis=1), n_c)
        mX, mC = [], []
        for name in mnames:
            sel = [s for s in shots if s.mirror == name and s.kind in ("mirror", "laser")]
            if not sel:
                raise ValueError(f"calibration plan: no shot for mirror {name!r}")
            mX.append(np.concatenate([s.board.corners_world_mm() for s in sel]))
            mC.append(len(sel[0].board.corners_world_mm()))
        lshots = [s for s in shots if s.kind == "laser"]
        if len(lshots) < 2 or any(s.mirror not in mnames for s in lshots):
            raise ValueError("calibration plan: needs ≥ 2 laser shots, each seen in a mirror")
        nL, dL = _plane_cam(*rig.laser.plane, R, t)
        P, W, NB, DB, B1, B2 = [], [], [], [], [], []
        for s in lshots:
            T = s.board.T_world_board
            Rb, tb = R @ T[:3, :3], R @ T[:3, 3] + t
            got = laser_line_samples(Rb, tb, s.board.pattern_size, s.board.square_mm, nL, dL,
                                     K, n_line=n_line)
            if got is None:
                raise ValueError(f"calibration plan: the laser sheet misses {s.name}")
            P.append((got[0] - t) @ R)  # back to the world
            W.append(np.full(n_line, got[1]))
            NB.append(T[:3, 2])
            DB.append(float(T[:3, 2] @ T[:3, 3]))
            B1.append(T[:3, 0])
            B2.append(T[:3, 1])
        names = tuple([f"camera.{n}" for n in CAMERA_NAMES]
                      + [f"{m}.{p}" for m in sorted(mnames) for p in ("a", "b", "delta")]
                      + [f"laser.{p}" for p in ("a", "b", "delta")])
        return cls(names=names, mirror_names=mnames, cam_X=cam_X,
                   n_cam_corners=n_c, cam_centre_z=centre_z, f_px_base=float(K[0, 0]),
                   mirror_X=tuple(mX), mirror_corners=tuple(mC),
                   laser_X=np.concatenate([s.board.corners_world_mm() for s in lshots]),
                   n_laser_corners=len(lshots[0].board.corners_world_mm()),
                   laser_mirror=np.array([mnames.index(s.mirror) for s in lshots]),
                   line_p=np.concatenate(P), line_w=np.concatenate(W), line_nb=np.array(NB),
                   line_db=np.array(DB), line_b1=np.array(B1), line_b2=np.array(B2),
                   n_line=n_line, sigma_corner_px=float(sigma_corner_px),
                   sigma_target_px=float(sigma_target_px), sigma_line_px=float(sigma_line_px),
                   source=f"plan of {rig.name} per design ({n_camera} camera, {n_mirror} per "
                          f"mirror, {n_laser} laser shots; σ corner {sigma_corner_px:g}/"
                          f"{sigma_target_px:g} px, line {sigma_line_px:g} px)")

    def arrays(self, F, U, designs: int) -> dict:
        """The plan's constants as Dr.Jit arrays for ``designs`` designs (tiled), with the
        design index of every element (made outside the model's recorded function)."""
        def cols(a, key, out):
            a = np.tile(np.asarray(a, float), (designs, 1)) if np.ndim(a) == 2 else \
                np.tile(np.asarray(a, float), designs)
            if a.ndim == 2:
                for j in range(a.shape[1]):
                    out[f"{key}{j}"] = F(a[:, j].copy())
            else:
                out[key] = F(a)
            return out

        def di(n):
            return U(np.repeat(np.arange(designs), n))

        out: dict = {}
        cols(self.cam_X, "camX", out)
        cols(self.cam_centre_z, "camZ", out)
        out["camdi"] = di(len(self.cam_X))
        for k, X in enumerate(self.mirror_X):
            cols(X, f"m{k}X", out)
            out[f"m{k}di"] = di(len(X))
        cols(self.laser_X, "lX", out)
        out["ldi"] = di(len(self.laser_X))
        nl = self.n_laser_corners
        for k in range(len(self.mirror_names)):
            sel = (self.laser_mirror == k).astype(float)
            cols(np.repeat(sel, nl), f"lmask{k}_c", out)
            cols(sel, f"lmask{k}_s", out)
        cols(self.line_p, "pX", out)
        cols(self.line_w, "pw", out)
        out["pdi"] = di(len(self.line_p))
        for key, a in (("nb", self.line_nb), ("b1", self.line_b1), ("b2", self.line_b2)):
            cols(np.repeat(a, self.n_line, axis=0), key, out)
        cols(np.repeat(self.line_db, self.n_line), "db", out)
        out["sdi"] = di(len(self.laser_mirror))  # per laser shot
        out["one"] = di(1)  # per design
        return out

    def covariance(self, ops, A: dict, view, designs: int) -> list:
        """The predicted covariance over :attr:`names` (lists of rows of per-design arrays;
        ``None`` where it is zero by construction).

        ``view(di)`` returns the design's camera and planes gathered at the design indices
        ``di``: ``to_cam(X)``, ``rot(v)``, ``pos`` (3 arrays each), ``intr`` (fx, fy, cx,
        cy, k1, k2) and ``mirrors`` (list of (n_world, d_world)).
        """
        sc, st, sl = self.sigma_corner_px, self.sigma_target_px, self.sigma_line_px

        def x3(key):
            return [A[f"{key}{j}"] for j in range(3)]

        def dot(a, b):
            return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

        def plane_cam(v, n_w, d_w):
            n = v["rot"](n_w)
            d = d_w - dot(n_w, v["pos"])
            # tangent_basis: e1 = normalise(n × x̂), e2 = n × e1 (|n_x| < 0.9 here)
            e1 = [0.0 * n[0], n[2], -n[1]]
            norm = ops.sqrt(e1[1] * e1[1] + e1[2] * e1[2])
            e1 = [e1[0], e1[1] / norm, e1[2] / norm]
            e2 = [n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2],
                  n[0] * e1[1] - n[1] * e1[0]]
            return n, d, e1, e2

        def scaled(M, s2):
            return [[v * s2 for v in row] for row in M]

        n_cam_shots = len(self.cam_X) // self.n_cam_corners
        v = view(A["camdi"])
        Xc = x3("camX")
        # each board's centre moves in depth by f / f_base (the board keeps its image)
        Xc[2] = Xc[2] + A["camZ"] * (v["intr"][0] * (1.0 / self.f_px_base) - 1.0)
        cam_info = camera_information(ops, Xc, v["intr"], self.n_cam_corners,
                                      shots=n_cam_shots)
        cov_cam = scaled(spd_inverse(ops, cam_info), sc * sc)
        cov_m = []
        for k in range(len(self.mirror_names)):
            v = view(A[f"m{k}di"])
            n, d, e1, e2 = plane_cam(v, *v["mirrors"][k])
            nc = self.mirror_corners[k]
            info = mirror_information(ops, v["to_cam"](x3(f"m{k}X")), v["intr"], n, d, e1, e2,
                                      nc, shots=len(self.mirror_X[k]) // nc)
            cov_m.append(scaled(spd_inverse(ops, info), st * st))
        # laser boards: each seen directly and in its mirror
        v = view(A["ldi"])
        planes = [plane_cam(v, *m) for m in v["mirrors"]]
        masks = [A[f"lmask{k}_c"] for k in range(len(planes))]

        def pick(i):
            out = None
            for mk, pl in zip(masks, planes):
                val = pl[i]
                term = [c * mk for c in val] if isinstance(val, list) else val * mk
                out = term if out is None else (
                    [a + b for a, b in zip(out, term)] if isinstance(term, list) else out + term)
            return out

        C, B, _ = board_pose_information(ops, v["to_cam"](x3("lX")), v["intr"], pick(0),
                                         pick(1), pick(2), pick(3), self.n_laser_corners)
        v = view(A["pdi"])
        nL, dL, eL1, eL2 = plane_cam(v, [0.0, 0.0, 1.0], 0.0)
        nb_w = x3("nb")
        line = {"p": v["to_cam"](x3("pX")), "w": A["pw"], "n_board": v["rot"](nb_w),
                "d_board": A["db"] - dot(nb_w, v["pos"]), "b1": v["rot"](x3("b1")),
                "b2": v["rot"](x3("b2"))}
        terms = []
        for k in range(len(self.mirror_names)):
            per_shot = [[ops.gather(c, A["sdi"]) for c in row] for row in cov_m[k]]
            terms.append((A[f"lmask{k}_s"], cov_m[k], per_shot))
        parts = laser_plane_parts(ops, line, C, B, nL, dL, eL1, eL2, v["intr"], self.n_line,
                                  mirror_terms=terms, designs=designs)
        cov_l = [[parts["cov_line"][i][j] * (sl * sl) + parts["cov_pose"][i][j] * (st * st)
                  + parts["cov_mirror"][i][j] for j in range(3)] for i in range(3)]
        # assemble over names
        K = len(self.names)
        out = [[None] * K for _ in range(K)]
        for i in range(6):
            for j in range(6):
                out[i][j] = cov_cam[i][j]
        order = sorted(range(len(self.mirror_names)), key=lambda k: self.mirror_names[k])
        o = 9
        for k in order:
            for i in range(3):
                for j in range(3):
                    out[o + i][o + j] = cov_m[k][i][j]
            o += 3
        for i in range(3):
            for j in range(3):
                out[o + i][o + j] = cov_l[i][j]
        return out

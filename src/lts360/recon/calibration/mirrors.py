"""Mirror calibration from a chessboard seen directly and through a mirror (paper §4.2).

In one image the board appears twice: the real board and its mirror image, which is
mirror-reversed.  A reversed board is an ordinary board with mirrored board coordinates
(x → −x), so OpenCV's PnP gives the virtual corners in 3-D once the detected virtual corners
are put in the order of the physical corners they image; that order (one of the four
symmetries of the grid) is the one whose real–virtual segments are all parallel (they are
all along the mirror normal).  Then:

* ``midpoint`` (the paper): the midpoints of corresponding real and virtual corners lie on
  the mirror; a plane is fitted to them (normal oriented towards the camera);
* ``least squares``: mirror plane and board poses refined together by minimising the
  reprojection error of every real corner (``P X``) and every virtual corner (``P T_π X``)
  over all images (Levenberg–Marquardt), which also gives the residuals and a covariance.

Everything is in the camera frame: ``n · X = d``; no ground truth is read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from lts360.geometry.camera import project_camera_points
from lts360.recon.calibration.board import BoardGeometry
from lts360.recon.calibration.camera import _to_u8, corner_outlier_limit

__all__ = ["MirrorObservation", "MirrorEstimate", "detect_real_and_virtual", "mirror_from_midpoints",
           "refine_mirror", "robust_refine_mirror", "per_image_rms"]


@dataclass(frozen=True)
class MirrorObservation:
    """One image: real corners and virtual corners, both in the physical corners' order."""

    real_px: np.ndarray
    virtual_px: np.ndarray


@dataclass(frozen=True)
class MirrorEstimate:
    """A mirror plane ``n · X = d`` in the camera frame and how well it explains the data."""

    normal: np.ndarray
    d_mm: float
    residuals: np.ndarray
    covariance: np.ndarray | None = None
    corner_kept: np.ndarray | None = None

    @property
    def rms(self) -> float:
        """RMS residual (per coordinate) over the corners the fit kept."""
        r = np.asarray(self.residuals)
        if self.corner_kept is not None and r.size == 2 * np.size(self.corner_kept):
            r = r.reshape(-1, 2)[np.asarray(self.corner_kept, bool)]
        return float(np.sqrt(np.mean(np.square(r))))


def _pose(obj, img, K, dist):
    import cv2

    ok, rvec, tvec = cv2.solvePnP(obj.astype(np.float64), img.astype(np.float64), K, dist,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise ValueError("solvePnP failed on a detected board")
    return rvec.ravel(), tvec.ravel()


def _transform(obj, rvec, tvec):
    import cv2

    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    return obj @ R.T + np.asarray(tvec, dtype=float)


def detect_real_and_virtual(image, board: BoardGeometry, K, dist, *,
                            mask_dilate_px: int = 41,
                            photometric: bool = True) -> MirrorObservation | None:
    """Find the real and the virtual board in one image and put the virtual corners in the
    physical corners' order.  ``None`` when either board is not found.

    The first detection is not assumed to be the real board: the real one is the detection
    whose pose (PnP with the board's own coordinates) shows the printed side to the camera —
    OpenCV orders the corners of a mirror-reversed board so that such a pose sees it from
    behind.

    ``photometric``: refine both boards' corners by fitting each board's image model to the
    image (:mod:`lts360.recon.calibration.board_model`).  Measured on rendered mirror shots of the paper
    board (64 spp, 4–5 px of defocus): corner RMS against the true projections 0.008–0.018 px
    (virtual) and 0.010–0.032 px (real), against 0.09–0.15 and 0.12–0.35 px from the
    detectors.
    """
    import cv2

    from lts360.recon.calibration.camera import _refine_saddle, detect_corners

    im8 = _to_u8(image)
    # Saddle-point corners for both boards (``detect_corners(refine=True)``): SB pulls the
    # outer ring of a board seen in a mirror outwards by 0.04–0.07 px.
    first = detect_corners(im8, board, refine=True)
    if first is None:
        return None
    mask = np.zeros_like(im8)
    hull = cv2.convexHull(first.astype(np.float32)).astype(np.int32)
    cv2.fillConvexPoly(mask, hull, 255)
    mask = cv2.dilate(mask, np.ones((mask_dilate_px, mask_dilate_px), np.uint8))
    im2 = im8.copy()
    im2[mask > 0] = int(np.median(im8))
    second = detect_corners(im2, board, symmetrize=False)
    if second is None:
        return None
    second = _refine_saddle(im8, second, board)  # on the image itself, not the masked one
    obj = board.object_points().astype(np.float64)
    obj_m = obj * np.array([-1.0, 1.0, 1.0])
    nx, ny = board.pattern_size
    grid = np.arange(nx * ny).reshape(ny, nx)
    perms = [grid, grid[:, ::-1], grid[::-1, :], grid[::-1, ::-1]]

    def score(real, virt):
        Xr = _transform(obj, *_pose(obj, real, K, dist))
        best = (np.inf, None)
        for p in perms:
            v = virt[p.ravel()]
            Xv = _transform(obj_m, *_pose(obj_m, v, K, dist))
            u = Xr - Xv
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            m = u.mean(axis=0)
            m /= np.linalg.norm(m)
            dev = float(np.max(np.arccos(np.clip(u @ m, -1.0, 1.0))))
            if dev < best[0]:
                best = (dev, v)
        return best

    # Which detection is the real board: the camera lies on the real board's side of the
    # mirror. With u = X_real − X_virtual (along the mirror normal, towards the real side) and
    # M a midpoint on the mirror, the camera centre (the origin) needs u · (0 − M) > 0; a
    # swapped labelling flips u and fails the test.
    dev, virt = score(first, second)
    Xr = _transform(obj, *_pose(obj, first, K, dist))
    Xv = _transform(obj_m, *_pose(obj_m, virt, K, dist))
    u = (Xr - Xv).mean(axis=0)
    M = ((Xr + Xv) / 2.0).mean(axis=0)
    if float(u @ -M) > 0:
        real = first
    else:
        real, virt = second, score(second, first)[1]
    if photometric:
        real = _photometric_corners(image, real, obj, board, K, dist, mirrored=False)
        virt = _photometric_corners(image, virt, obj_m, board, K, dist, mirrored=True)
    return MirrorObservation(real_px=real, virtual_px=virt)


def _photometric_corners(image, corners, obj, board, K, dist, *, mirrored: bool):
    """The corners re-projected from the board's pose fitted to the image by its image model
    (:func:`lts360.recon.calibration.board_model.refine_board_pose`); the detected corners where that
    fit fails.  ``obj``: the object points the corners were ordered for (x negated for a
    board seen in a mirror)."""
    import cv2

    from lts360.recon.calibration.board_model import refine_board_pose

    rvec, tvec = _pose(obj, corners, K, dist)
    R0, _ = cv2.Rodrigues(rvec)
    if mirrored:
        R0 = R0 @ np.diag([-1.0, 1.0, 1.0])  # improper: the physical board's coordinates
    try:
        fit = refine_board_pose(np.asarray(image, dtype=float), board, R0, tvec, K, dist)
    except ValueError:
        return corners
    return fit.corners_px(board, K, dist)


def _midpoint_plane(ob: MirrorObservation, board: BoardGeometry, K, dist):
    obj = board.object_points().astype(np.float64)
    obj_m = obj * np.array([-1.0, 1.0, 1.0])
    Xr = _transform(obj, *_pose(obj, ob.real_px, K, dist))
    Xv = _transform(obj_m, *_pose(obj_m, ob.virtual_px, K, dist))
    mids = (Xr + Xv) / 2.0
    u = Xr - Xv
    n = (u / np.linalg.norm(u, axis=1, keepdims=True)).mean(axis=0)
    n /= np.linalg.norm(n)
    d = float(mids.mean(axis=0) @ n)
    if d > 0:  # the camera (origin) is on the reflecting side: n · 0 > d
        n, d = -n, -d
    return n, d, mids @ n - d


def mirror_from_midpoints(observations, board: BoardGeometry, K, dist) -> MirrorEstimate:
    """The paper's estimate: per image, the plane through the midpoints of corresponding real
    and virtual corners (normal along the real–virtual segments); over several images, the
    mean of the per-image planes.

    One plane fitted to the midpoints of all images together is ill-conditioned: each board's
    PnP depth error (tens of µm for a 14 mm board at 165 mm) shifts its midpoints along the
    normal, and over the small span of the boards that tilts the fitted plane by tenths of a
    degree (measured: 0.5° with four boards, against ≤ 0.04° per board).
    """
    if not observations:
        raise ValueError("mirror_from_midpoints: no observations")
    planes = [_midpoint_plane(ob, board, K, dist) for ob in observations]
    n = np.mean([p[0] for p in planes], axis=0)
    n /= np.linalg.norm(n)
    d = float(np.mean([p[1] for p in planes]))
    return MirrorEstimate(normal=n, d_mm=d, residuals=np.concatenate([p[2] for p in planes]))


def per_image_rms(estimate: MirrorEstimate, n_images: int) -> np.ndarray:
    """RMS reprojection error (px) of each image of a :func:`refine_mirror` fit, over the
    corners the fit kept."""
    r2 = np.sum(np.asarray(estimate.residuals).reshape(-1, 2) ** 2, axis=1)
    keep = (np.ones(len(r2), bool) if estimate.corner_kept is None
            else np.asarray(estimate.corner_kept, bool))
    r2, keep = r2.reshape(n_images, -1), keep.reshape(n_images, -1)
    return np.sqrt(np.sum(r2 * keep, axis=1) / np.maximum(1, keep.sum(axis=1)) / 2.0)


def robust_refine_mirror(observations, board: BoardGeometry, K, dist, *,
                         max_image_rms_px: float = 0.15, outlier_factor: float = 2.5,
                         min_images: int = 2) -> tuple[MirrorEstimate, np.ndarray]:
    """:func:`refine_mirror`, then images whose RMS exceeds ``max_image_rms_px`` or
    ``outlier_factor`` × the median are discarded and the fit repeated (paper §4.2: "images
    with large reprojection errors are discarded").  Returns the estimate and the mask of
    the images kept.

    Measured on rendered images (64 spp): most images fit to 0.035–0.06 px; obliquely seen
    boards reach 0.1–0.3 px and moved the plane by up to 1 mm on their own.  An image that
    loses a quarter of its corners to the outlier rule is discarded too: its RMS over the
    corners left would not show it (a wrongly matched virtual board loses all of them).
    """
    keep = np.ones(len(observations), bool)
    est = None
    for _ in range(3):
        obs = [o for o, k in zip(observations, keep) if k]
        if len(obs) < min_images:
            raise ValueError(f"mirror calibration: {len(obs)} image(s) left after discarding "
                             f"outliers, need {min_images}")
        est = refine_mirror(obs, board, K, dist)
        rms = per_image_rms(est, len(obs))
        kept = np.asarray(est.corner_kept, bool).reshape(len(obs), -1).mean(axis=1)
        bad = (rms > max_image_rms_px) | (rms > outlier_factor * np.median(rms))
        bad |= kept < 0.75  # a quarter of its corners wrong: the image is (a wrong match)
        if not bad.any():
            break
        idx = np.flatnonzero(keep)
        keep[idx[bad]] = False
    return est, keep


def _mirror_points(X, n, d):
    return X - 2.0 * ((X @ n) - d)[:, None] * n


def refine_mirror(observations, board: BoardGeometry, K, dist,
                  initial: MirrorEstimate | None = None, *,
                  corner_outlier_px: float | None = 0.25) -> MirrorEstimate:
    """Least-squares mirror plane and board poses from every real and virtual corner.

    Residuals are reprojection errors in pixels; the covariance of ``(θ, φ, d)`` (the normal's
    spherical angles and the offset) is ``σ² (JᵀJ)⁻¹`` restricted to the mirror parameters.

    ``corner_outlier_px``: after a first fit, corners whose reprojection error exceeds both
    this and 4 robust standard deviations are left out and the fit is repeated (``None``:
    keep every corner).  OpenCV's SB detector pulls whole columns of corners by 0.6–0.9 px
    where the board's edge and a bright background fall within its reach (the paper's target
    has half a square of margin; measured on rendered mirror shots, 5 of 12 images); those
    columns otherwise move the plane by tens of micrometres.  The returned residuals keep
    their full length, with the left-out corners' residuals included (so that per-image RMS
    still shows them).
    """
    if not observations:
        raise ValueError("refine_mirror: no observations")
    obj = board.object_points().astype(np.float64)
    init = initial or mirror_from_midpoints(observations, board, K, dist)
    n0 = init.normal / np.linalg.norm(init.normal)
    theta0, phi0 = np.arccos(np.clip(n0[2], -1, 1)), np.arctan2(n0[1], n0[0])
    poses = [np.concatenate(_pose(obj, ob.real_px, K, dist)) for ob in observations]
    x0 = np.concatenate([[theta0, phi0, init.d_mm]] + poses)

    def unpack(x):
        th, ph, d = x[:3]
        n = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
        return n, d, x[3:].reshape(-1, 6)

    real_px = np.stack([ob.real_px for ob in observations])  # (m, N, 2)
    virtual_px = np.stack([ob.virtual_px for ob in observations])
    m_obs, n_pts = real_px.shape[:2]

    def residuals(x):
        n, d, ps = unpack(x)
        X = np.stack([_transform(obj, p[:3], p[3:]) for p in ps]).reshape(-1, 3)
        real = project_camera_points(X, K, dist).reshape(m_obs, n_pts, 2) - real_px
        virt = (project_camera_points(_mirror_points(X, n, d), K, dist).reshape(m_obs, n_pts, 2)
                - virtual_px)
        return np.stack([real, virt], axis=1).ravel()  # per image: its real, then virtual

    # Forward differences with the columns grouped by the rows they touch: a board's pose
    # moves only that board's residuals, so one evaluation perturbs the same pose parameter
    # of every board (3 + 6 evaluations per Jacobian instead of 3 + 6 m).
    rows_per_obs = 4 * n_pts
    groups = [[j] for j in range(3)] + [[3 + 6 * i + k for i in range(m_obs)] for k in range(6)]

    def jacobian(x, f0, w2):
        J = np.zeros((f0.size, x.size))
        for cols in groups:
            h = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x[cols]))
            xp = x.copy()
            xp[cols] += h
            df = (residuals(xp) * w2 - f0)
            if len(cols) == 1 and cols[0] < 3:
                J[:, cols[0]] = df / h[0]
            else:
                for i, (j, hj) in enumerate(zip(cols, h)):
                    r = slice(i * rows_per_obs, (i + 1) * rows_per_obs)
                    J[r, j] = df[r] / hj
        return J

    weight = np.ones(2 * len(observations) * len(obj))  # per corner: real, virtual per image
    sol = None
    for _ in range(6):  # until the corners left out no longer change
        w2 = np.repeat(weight, 2)
        sol = least_squares(lambda x, w2=w2: residuals(x) * w2, x0 if sol is None else sol.x,
                            jac=lambda x, w2=w2: jacobian(x, residuals(x) * w2, w2),
                            method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        err = np.linalg.norm(residuals(sol.x).reshape(-1, 2), axis=1)
        if corner_outlier_px is None:
            break
        limit = corner_outlier_limit(err, corner_outlier_px)
        new = (err <= limit).astype(float)
        if np.array_equal(new, weight):
            break
        weight = new
    n, d, _ = unpack(sol.x)
    res = residuals(sol.x)
    kept = np.repeat(weight, 2) > 0
    dof = max(1, int(kept.sum()) - sol.x.size)
    cov = None
    try:
        JtJ = sol.jac.T @ sol.jac
        cov = np.linalg.inv(JtJ)[:3, :3] * float(res[kept] @ res[kept]) / dof
    except np.linalg.LinAlgError:
        pass
    if d > 0:
        n, d = -n, -d
    return MirrorEstimate(normal=n, d_mm=float(d), residuals=res, covariance=cov,
                          corner_kept=weight > 0)

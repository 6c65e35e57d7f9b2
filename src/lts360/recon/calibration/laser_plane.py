"""Laser-plane calibration from the laser line on a chessboard (paper §4.3; Li, Kästner and
Reithmeier 2018).

For each pose: the board's pose from its corners gives the board plane — from the direct
view alone (PnP with the calibrated camera), or, where the board is seen in a calibrated
mirror too, from both views at once (:func:`board_pose_in_mirror`: the mirror's virtual
camera makes a stereo pair with the camera, so the board's depth no longer hangs on the
scale of a small board in one view); the line centres in the laser-on minus laser-off image (Steger's 2-D detector,
sub-pixel, perpendicular to the line) inside the board's chequered area are turned into
camera rays, and the rays meet the board plane.  A plane fitted to the points of every pose
is the laser sheet.  Points of one pose lie on a line, so at least two poses whose lines are
not parallel are needed: collinear points fail with an error (``fit_plane``).

The line on a plane is straight (after undistortion): a robust straight-line fit per pose
through the detected centres starts a fit of the band's image model on the printed board
(:mod:`lts360.recon.calibration.laser_line_model`), which takes out the pull of the black squares on the
detected centres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.geometry.camera import backproject_pixels, project_camera_points
from lts360.geometry.fit import fit_plane
from lts360.recon.calibration.board import BoardGeometry
from lts360.recon.calibration.camera import detect_corners
from lts360.recon.lines import steger_centres

__all__ = ["LaserLine", "LaserPlaneEstimate", "board_pose", "board_pose_in_mirror",
           "laser_line_points", "fit_laser_plane"]


@dataclass(frozen=True)
class LaserLine:
    """Laser-line points of one pose: image centres (n, 2) px and 3-D points (n, 3) camera mm."""

    uv: np.ndarray
    points_mm: np.ndarray
    board_normal: np.ndarray
    board_d_mm: float
    pose_views: tuple[str, ...] = ("direct",)


@dataclass(frozen=True)
class LaserPlaneEstimate:
    """The laser sheet ``n · X = d`` (camera frame, ``d < 0``: the camera on the + side)."""

    normal: np.ndarray
    d_mm: float
    residuals_mm: np.ndarray
    covariance: np.ndarray
    n_poses: int

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residuals_mm))))


def board_pose(corners_px: np.ndarray, board: BoardGeometry, K, dist, *,
               corner_outlier_px: float | None = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` board → camera from the detected corners (OpenCV's iterative PnP).

    ``corner_outlier_px``: while the worst corner's reprojection error exceeds it, that corner
    is left out and the pose solved again (at most a quarter of the corners; ``None``: keep
    all).  OpenCV's SB detector shifts whole columns of a small board's corners by 0.6–0.9 px
    next to its narrow margin (measured on rendered laser shots: 2 of 6 images); kept, such a
    column tilts the board plane, and with it every laser point of the pose, by tenths of a
    degree.  One board's fit spreads a shifted column's error over its neighbours, so a
    robust scale of the residuals is no guide here: the worst corner goes first, one at a
    time (measured corner noise on renders: 0.04–0.1 px RMS).
    """
    import cv2

    obj = board.object_points().astype(np.float64)
    img = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    K, dist = np.asarray(K, float), np.asarray(dist, float)
    keep = np.ones(len(obj), bool)
    while True:
        ok, rvec, tvec = cv2.solvePnP(obj[keep], img[keep], K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            raise ValueError("solvePnP failed on a detected board")
        if corner_outlier_px is None or (~keep).sum() >= len(obj) // 4:
            break
        err = np.linalg.norm(cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2) - img,
                             axis=1)
        err[~keep] = -1.0
        worst = int(np.argmax(err))
        if err[worst] <= corner_outlier_px:
            break
        keep[worst] = False
    R, _ = cv2.Rodrigues(rvec)
    return R, tvec.ravel()


def board_pose_in_mirror(real_px: np.ndarray, virtual_px: np.ndarray, board: BoardGeometry, K,
                         dist, mirror_normal, mirror_d_mm: float, *,
                         corner_outlier_px: float | None = 0.25
                         ) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` board → camera from the board seen directly and in a mirror of known plane
    ``n · X = d`` (camera frame): the pose that reprojects both the real corners and their
    mirror images (the virtual corners, in the physical corners' order as
    :func:`lts360.recon.calibration.mirrors.detect_real_and_virtual` gives them) best, by
    Levenberg–Marquardt from the direct view's PnP pose.

    One view fixes a board's depth only through its scale in the image: a 7×6 × 2 mm board
    spans ~130 px, so 0.1 px of corner noise moves it by ~100 µm.  The virtual camera sees
    the board from the mirror's side, ~90° away, and there the depth is a lateral position
    (measured on rendered mirror shots of that board with the true mirror: depth at the
    board's centre within ±4 µm, against ±150 µm from PnP).  The mirror's own error enters
    instead: an offset error δ moves the virtual camera by 2δ.

    ``corner_outlier_px``: after a first fit, corners (real or virtual) whose reprojection
    error exceeds both this and 4 robust standard deviations are left out and the pose
    solved again, as in the mirror fit.
    """
    import cv2
    from scipy.optimize import least_squares

    from lts360.geometry.mirror import reflect_points
    from lts360.recon.calibration.camera import corner_outlier_limit

    obj = board.object_points().astype(np.float64)
    real = np.asarray(real_px, dtype=np.float64).reshape(-1, 2)
    virt = np.asarray(virtual_px, dtype=np.float64).reshape(-1, 2)
    K, dist = np.asarray(K, float), np.asarray(dist, float)
    n = np.asarray(mirror_normal, dtype=float)
    R0, t0 = board_pose(real, board, K, dist)
    x0 = np.concatenate([cv2.Rodrigues(R0)[0].ravel(), t0])

    def residuals(x):
        X = obj @ cv2.Rodrigues(x[:3])[0].T + x[3:]
        return np.concatenate([project_camera_points(X, K, dist) - real,
                               project_camera_points(reflect_points(X, n, mirror_d_mm), K,
                                                     dist) - virt])

    keep = np.ones(2 * len(obj), bool)
    x = x0
    for _ in range(2):
        sol = least_squares(lambda p: (residuals(p) * keep[:, None]).ravel(), x, method="lm",
                            xtol=1e-14, ftol=1e-14)
        x = sol.x
        if corner_outlier_px is None:
            break
        err = np.linalg.norm(residuals(x), axis=1)
        new = err <= corner_outlier_limit(err, corner_outlier_px)
        if np.array_equal(new, keep):
            break
        keep = new
    return cv2.Rodrigues(x[:3])[0], x[3:].copy()


def _robust_line(xy: np.ndarray, *, k: float = 3.0, iterations: int = 10):
    """Total-least-squares line through 2-D points with iterative k·σ clipping (σ from the
    median absolute deviation).  Returns ``(point, direction, inlier mask)``."""
    keep = np.ones(len(xy), bool)
    for _ in range(iterations):
        c = xy[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(xy[keep] - c, full_matrices=False)
        d = vt[0]
        dist = (xy - c) @ np.array([-d[1], d[0]])
        sigma = 1.4826 * np.median(np.abs(dist[keep])) + 1e-12
        new = np.abs(dist) <= k * sigma
        if new.sum() < 2 or np.array_equal(new, keep):
            break
        keep = new
    return c, d, keep


def laser_line_points(image_on, image_off, image_board, board: BoardGeometry, K, dist, *,
                      sigma_px: float = 1.5, inset_squares: float = 0.25,
                      min_points: int = 20, pose=None,
                      pose_views: tuple[str, ...] = ("direct",),
                      line_model: bool = True) -> LaserLine:
    """Laser-line points on the board of one pose.

    The line centres (Steger) of the laser-on minus laser-off image inside the board's
    squares are undistorted; a straight line is fitted to them in normalised image
    coordinates with outlier clipping (the line on a plane is straight once the lens
    distortion is removed), and every inlier centre, moved onto that line, is back-projected
    onto the board plane.  Where a black/white edge runs under the line its centre is pulled
    towards the white side; these errors alternate in sign along the line and the line fit
    averages them out (measured: 0.1–0.4 mm errors of single centres on a 2 mm board).

    Parameters
    ----------
    image_on, image_off : (h, w) array
        Laser on / off at the same exposure.
    image_board : (h, w) array or None
        The board exposed for its corners (not read when ``pose`` is given).
    pose : (R, t), optional
        The board's pose (board → camera), e.g. from :func:`board_pose_in_mirror`; by
        default it comes from ``image_board``'s corners (:func:`board_pose`).
    pose_views : tuple of str
        What the pose was fixed by, kept with the result (``("direct", "left")``, …).
    inset_squares : float
        Keep centres at least this many squares inside the printed squares' outline.
    line_model : bool
        Refine the detected line by fitting the image model of the band on the printed board
        (:func:`lts360.recon.calibration.laser_line_model.fit_line_on_board`: the albedo under the band
        and the blur taken into account), and return points along that line.  ``False``: the
        detected centres, moved onto their straight-line fit.  Measured on rendered paper-board
        laser shots with the true pose: the line at the board's centre within −10.5…+2.6 µm
        of the truth with the model, −105…+9 µm without.

    Raises
    ------
    ValueError
        Board not found, or fewer than ``min_points`` line centres on it.
    """
    import cv2

    if pose is None:
        corners = detect_corners(image_board, board)
        if corners is None:
            raise ValueError("laser calibration: the board is not found in the board image")
        R, t = board_pose(corners, board, K, dist)
        pose_views = ("direct",)
    else:
        R, t = (np.asarray(v, dtype=float) for v in pose)
    n_b = R[:, 2]
    d_b = float(n_b @ t)
    diff = np.asarray(image_on, dtype=float) - np.asarray(image_off, dtype=float)
    # Board area: the printed squares (inner corners ± one square), shrunk by `inset_squares`.
    nx, ny = board.pattern_size
    s = board.square_mm
    lo, hx, hy = (inset_squares - 1.0) * s, (nx - inset_squares) * s, (ny - inset_squares) * s
    quad = np.array([[lo, lo, 0.0], [hx, lo, 0.0], [hx, hy, 0.0], [lo, hy, 0.0]])
    hull = project_camera_points(quad @ R.T + t, K, dist)
    mask = np.zeros(diff.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(hull).astype(np.int32), 1)
    mask = mask.astype(bool)
    if not mask.any():
        raise ValueError("laser calibration: the board area is outside the image")
    peak = float(diff[mask].max())
    if peak <= 0:
        raise ValueError("laser calibration: no laser light on the board")
    c = steger_centres(diff, sigma_px=sigma_px, mask=mask, threshold=0.05 * peak)
    if len(c.uv) < min_points:
        raise ValueError(f"laser calibration: {len(c.uv)} laser-line centres on the board, "
                         f"need {min_points}")
    rays = backproject_pixels(c.uv, K, dist)
    xy = rays[:, :2] / rays[:, 2:3]
    p0, direction, inl = _robust_line(xy)
    if inl.sum() < min_points:
        raise ValueError(f"laser calibration: {int(inl.sum())} centres on one straight line, "
                         f"need {min_points}")
    xy_on = p0 + np.outer((xy[inl] - p0) @ direction, direction)
    rays = np.column_stack([xy_on, np.ones(len(xy_on))])
    scale = d_b / (rays @ n_b)
    points = rays * scale[:, None]
    uv = c.uv[inl]
    if line_model:
        from lts360.recon.calibration.laser_line_model import fit_line_on_board

        # The detected line in board coordinates starts the fit of the image model.
        xb = ((points - t) @ R)[:, :2]
        cen = xb.mean(axis=0)
        along = np.linalg.svd(xb - cen, full_matrices=False)[2][0]
        normal = np.array([-along[1], along[0]])
        fit = fit_line_on_board(diff, image_board, board, R, t, K, dist, initial_normal=normal,
                                initial_offset_mm=float(normal @ cen),
                                inset_squares=inset_squares)
        # Points along the fitted line over the span of the detected centres.
        n2 = fit.normal
        a = np.array([-n2[1], n2[0]])
        span = (xb - cen) @ a
        k = np.linspace(span.min(), span.max(), len(xb))
        foot = cen - (cen @ n2 - fit.offset_mm) * n2
        pb = foot + np.outer(k, a)
        points = np.column_stack([pb, np.zeros(len(pb))]) @ R.T + t
        uv = project_camera_points(points, K, dist)
    return LaserLine(uv=uv, points_mm=points, board_normal=n_b, board_d_mm=d_b,
                     pose_views=tuple(pose_views))


def fit_laser_plane(lines: list[LaserLine], *, min_poses: int = 2) -> LaserPlaneEstimate:
    """Total-least-squares plane through the laser points of every pose.

    The covariance (3×3) is of ``(a, b, d)`` with the normal perturbed as
    ``n' = normalise(n + a e1 + b e2)`` (``e1, e2`` the tangent basis of
    :func:`lts360.recon.calibration.from_images.tangent_basis`), from the residual variance and the points'
    spread — the input of the Monte Carlo study.

    Raises
    ------
    ValueError
        Fewer than ``min_poses`` poses, or all points on one line (the plane is not determined,
        as paper §4.3 warns).
    """
    from lts360.recon.calibration.uncertainty import plane_covariance

    if len(lines) < min_poses:
        raise ValueError(f"laser calibration: {len(lines)} pose(s) with a laser line, need at "
                         f"least {min_poses} (one pose gives collinear points)")
    pts = np.concatenate([ln.points_mm for ln in lines])
    fit = fit_plane(pts, min_spread_ratio=1e-3)
    n, d = fit.normal, fit.offset_mm
    if d > 0:
        n, d = -n, -d
    res = pts @ n - d
    return LaserPlaneEstimate(normal=n, d_mm=float(d), residuals_mm=res,
                              covariance=plane_covariance(pts, n, d), n_poses=len(lines))

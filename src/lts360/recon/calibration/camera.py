"""Camera calibration from chessboard images: Zhang's method with OpenCV (paper §4.2).

Corners are found with OpenCV's sector-based detector (``findChessboardCornersSB`` with
``CALIB_CB_ACCURACY``: sub-pixel by design); ``calibrateCameraExtended`` estimates K, the
distortion (k1, k2, p1, p2, k3) and every board pose with their standard deviations; images
whose RMS reprojection error exceeds ``max_image_rms_px`` (or ``outlier_factor`` × the median)
are discarded and the calibration is repeated, as the paper does.  No ground truth is read.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from lts360.recon.calibration.board import BoardGeometry
from lts360.recon.calibration.board_model import refine_corners_locally

__all__ = ["BoardGeometry", "CameraCalibration", "detect_corners", "calibrate_camera",
           "corner_outlier_limit", "intrinsics_jackknife", "INTRINSIC_NAMES"]


@dataclass(frozen=True, eq=False)
class CameraCalibration:
    """Result of :func:`calibrate_camera`.

    Attributes
    ----------
    K : (3, 3) float
    dist : (5,) float
        ``(k1, k2, p1, p2, k3)``.
    image_size : (int, int)
        ``(width, height)``.
    rms_px : float
        Overall RMS reprojection error of the kept images.
    per_image_rms_px : (m,) float
        Of the kept images.
    used : (n,) bool
        Which input images were detected and kept.
    std_intrinsics : (18,) float
        OpenCV's standard deviations (fx, fy, cx, cy, k1, k2, p1, p2, k3, …).  They assume
        independent corner errors; corners of one board share much of theirs (its
        homography), so these understate the real spread (see ``cov_jackknife``).
    cov_jackknife : (9, 9) float or None
        Delete-one-board jackknife covariance of ``(fx, fy, cx, cy, k1, k2, p1, p2, k3)``
        (:func:`intrinsics_jackknife`): the spread of the intrinsics when the boards, not
        the corners, are the independent units.  ``None`` with fewer than 3 boards; zero
        rows and columns for fixed parameters.
    rvecs, tvecs : list of (3,) float
        Board poses of the kept images (board → camera).
    corners : list of (n, 2) float
        Corners of the kept images: detected, or from the image model after
        ``board_model_rounds`` (NaN where its fit failed).
    corner_kept : list of (n,) bool
        Which of them the calibration used (the others were outliers).
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    rms_px: float
    per_image_rms_px: np.ndarray
    used: np.ndarray
    std_intrinsics: np.ndarray
    rvecs: list = field(default_factory=list)
    tvecs: list = field(default_factory=list)
    corners: list = field(default_factory=list)
    corner_kept: list = field(default_factory=list)
    cov_jackknife: np.ndarray | None = None

    @property
    def std_jackknife(self) -> np.ndarray | None:
        """(9,) square roots of the diagonal of ``cov_jackknife`` (or ``None``)."""
        return None if self.cov_jackknife is None else np.sqrt(np.diag(self.cov_jackknife))


#: Order of the intrinsics in ``std_intrinsics[:9]`` and ``cov_jackknife``.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _intrinsic_vector(K: np.ndarray, dist) -> np.ndarray:
    d = np.zeros(5)
    flat = np.ravel(dist)[:5]
    d[:len(flat)] = flat
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d])


def intrinsics_jackknife(object_points, image_points, image_size, K, dist, *, flags: int = 0,
                         criteria=None) -> np.ndarray:
    """Delete-one-board jackknife covariance of the intrinsics ``INTRINSIC_NAMES``.

    Zhang's calibration is repeated with each board left out in turn, started from ``K,
    dist`` (the all-board solution, ``CALIB_USE_INTRINSIC_GUESS``) with the same ``flags``;
    the covariance is ``(m − 1)/m · Σ (θ_i − θ̄)(θ_i − θ̄)ᵀ`` over the ``m`` estimates.  Unlike
    OpenCV's ``stdDeviationsIntrinsics`` it does not assume that a board's corners err
    independently: an error shared by a board (a wrong homography) moves the leave-one-out
    estimates as much as it moves the calibration.

    Parameters
    ----------
    object_points, image_points : sequences of (n_i, 3) / (n_i, 2) float, one per board
    image_size : (int, int)
        ``(width, height)``.
    K, dist : the calibration from all boards

    Raises
    ------
    ValueError
        Fewer than 3 boards.
    """
    import cv2

    from lts360.recon.calibration.uncertainty import jackknife_covariance

    m = len(object_points)
    if m < 3 or len(image_points) != m:
        raise ValueError(f"intrinsics_jackknife: need at least 3 boards with image points, "
                         f"got {m} and {len(image_points)}")
    if criteria is None:
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    est = []
    for i in range(m):
        objs = [np.asarray(o, np.float32) for j, o in enumerate(object_points) if j != i]
        pts = [np.asarray(p, np.float32) for j, p in enumerate(image_points) if j != i]
        _, K_i, d_i, _, _ = cv2.calibrateCamera(
            objs, pts, tuple(int(v) for v in image_size), np.array(K, float).copy(),
            np.array(dist, float).reshape(-1, 1).copy(),
            flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS, criteria=criteria)
        est.append(_intrinsic_vector(K_i, d_i))
    return jackknife_covariance(np.array(est))


def corner_outlier_limit(errors_px: np.ndarray, floor_px: float) -> float:
    """Reprojection error (px) above which a corner is an outlier: ``floor_px`` or 4 robust
    standard deviations of ``errors_px`` (the distances of many corners from their fit,
    σ ≈ 1.4826 × median), whichever is larger.  Used where many boards share one fit (Zhang,
    the mirror planes); a single board's fit needs the worst-first rule of
    :func:`lts360.recon.calibration.laser_plane.board_pose`."""
    return max(float(floor_px), 4.0 * 1.4826 * float(np.median(errors_px)))


def _to_u8(image) -> np.ndarray:
    img = np.asarray(image)
    if img.dtype == np.uint8:
        return img
    img = img.astype(float)
    hi = np.percentile(img, 99.9)
    return np.clip(img / (hi if hi > 0 else 1.0) * 255.0, 0, 255).astype(np.uint8)


def _sb_corners(im8: np.ndarray, board: BoardGeometry) -> np.ndarray | None:
    import cv2

    ok, corners = cv2.findChessboardCornersSB(im8, tuple(board.pattern_size),
                                              flags=cv2.CALIB_CB_ACCURACY)
    return corners.reshape(-1, 2).astype(np.float64) if ok else None


def _board_crop(im8: np.ndarray, board: BoardGeometry, *, margin_squares: float = 1.5,
                margin_px: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The part of ``im8`` around the board, and its origin ``(x0, y0)`` in px.

    SB without ``CALIB_CB_ACCURACY`` on the image at half size locates the board (a tenth of
    the accurate detector's time); the crop adds ``margin_squares`` corner spacings and
    ``margin_px`` around the corners found.  The accurate detector then runs on a fraction of
    the pixels: measured on the 30 camera boards of the demo (1280 × 1024, 64 spp, realistic
    noise), symmetrized corners against their true projections 0.0463 px RMS on the crop as
    on the whole image, the mean offset within 0.0005 px, in a third of the time.  Where the
    coarse pass finds no board, the whole image is returned."""
    import cv2

    h, w = im8.shape[:2]
    small = cv2.resize(im8, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    ok, coarse = cv2.findChessboardCornersSB(small, tuple(board.pattern_size), flags=0)
    if not ok:
        return im8, np.zeros(2)
    c = coarse.reshape(-1, 2).astype(np.float64) * 2.0 + 0.5  # half-size px -> px
    nx, ny = board.pattern_size
    g = c.reshape(ny, nx, 2)
    spacing = max(np.linalg.norm(np.diff(g, axis=1), axis=2).max(),
                  np.linalg.norm(np.diff(g, axis=0), axis=2).max())
    m = margin_squares * spacing + margin_px
    x0, y0 = (max(int(np.floor(v - m)), 0) for v in c.min(axis=0))
    x1 = min(int(np.ceil(c[:, 0].max() + m)) + 1, w)
    y1 = min(int(np.ceil(c[:, 1].max() + m)) + 1, h)
    return np.ascontiguousarray(im8[y0:y1, x0:x1]), np.array([x0, y0], float)


def _refine_saddle(im8: np.ndarray, corners: np.ndarray, board: BoardGeometry, *,
                   window_fraction: float = 0.4, max_move_px: float = 1.0) -> np.ndarray:
    """``cornerSubPix`` on every corner, with a window of ``window_fraction`` of the shortest
    corner spacing (2–10 px half-size); a corner it moves by more than ``max_move_px`` keeps
    its SB position (the window slipped off the junction)."""
    import cv2

    nx, ny = board.pattern_size
    g = corners.reshape(ny, nx, 2)
    spacing = min(np.linalg.norm(np.diff(g, axis=1), axis=2).min(),
                  np.linalg.norm(np.diff(g, axis=0), axis=2).min())
    w = int(np.clip(np.floor(window_fraction * spacing), 2, 10))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    sub = cv2.cornerSubPix(im8, corners.astype(np.float32).reshape(-1, 1, 2).copy(), (w, w),
                           (-1, -1), crit).reshape(-1, 2).astype(np.float64)
    moved = np.linalg.norm(sub - corners, axis=1) > max_move_px
    return np.where(moved[:, None], corners, sub)


def detect_corners(image, board: BoardGeometry, *, symmetrize: bool = True,
                   refine: bool = False, flips: int = 2) -> np.ndarray | None:
    """(n, 2) sub-pixel inner corners in OpenCV order, or ``None`` where the board is not found.

    OpenCV's SB detector (``findChessboardCornersSB`` with ``CALIB_CB_ACCURACY``) finds and
    orders the corners.  Two corrections of its biases, measured on rendered boards:

    ``symmetrize`` (default)
        Also detect in the image turned by 180° (``flips=2``, the default), or also flipped
        left–right and up–down (``flips=4``), map those corners back and average them.  SB
        is not symmetric: the corners found in a flipped image and mapped back differ by up
        to 0.08 px on average over a board.  Averaging cancels the part of the offset that
        changes sign with the flips.  Four flips, measured on 30 camera poses: fx +0.005 →
        +0.001 %, cx +0.14 → +0.01 px.  The half turn alone cancels as much on the demo's 30
        camera boards (the mean offset from the true projections −0.0003, −0.0003 px against
        −0.0004, −0.0004 px with four flips and −0.0078, −0.0020 px without; the per-board
        mean offsets 0.0059 against 0.0058 px RMS; the corners' RMS error 0.043 against
        0.042 px) in half the detector's time; ``flips=4`` keeps the mirror-symmetric average.
    ``refine``
        Move every corner to the saddle point of a small window (:func:`_refine_saddle`,
        OpenCV's ``cornerSubPix``).  The saddle point does not depend on the start, so
        ``symmetrize`` is moot then.  It is noisier than SB at 64 spp (0.08–0.15 against
        0.05 px RMS) but free of SB's pull near the board's edge: on boards seen in a mirror,
        SB shifts the outer ring of corners outwards by 0.04–0.07 px on average (the real
        boards: 0.00), which moved the mirror planes by tens of µm.  The mirror shots use it.
    """
    full = _to_u8(image)
    im8, origin = _board_crop(full, board)
    corners = _detect_in(im8, board, symmetrize=symmetrize and not refine, flips=flips)
    if corners is None and im8 is not full:  # the crop lost it: the whole image
        im8, origin = full, np.zeros(2)
        corners = _detect_in(im8, board, symmetrize=symmetrize and not refine, flips=flips)
    if corners is None:
        return None
    if refine:
        return _refine_saddle(full, corners + origin, board)
    return corners + origin


def _detect_in(im8: np.ndarray, board: BoardGeometry, *, symmetrize: bool,
               flips: int = 2) -> np.ndarray | None:
    """SB's corners in ``im8``; ``symmetrize``: averaged over the image and its half turn
    (``flips=2``), or also its left–right and up–down flips (``flips=4``; see
    :func:`detect_corners`)."""
    from scipy.spatial import cKDTree

    if not symmetrize:
        return _sb_corners(im8, board)
    if flips not in (2, 4):
        raise ValueError(f"flips must be 2 or 4, got {flips!r}")
    h, w = im8.shape[:2]
    turned = (im8[::-1, ::-1], lambda c: np.column_stack([w - 1 - c[:, 0], h - 1 - c[:, 1]]))
    mirrored = [(im8[:, ::-1], lambda c: np.column_stack([w - 1 - c[:, 0], c[:, 1]])),
                (im8[::-1, :], lambda c: np.column_stack([c[:, 0], h - 1 - c[:, 1]]))]
    others = [turned] + (mirrored if flips == 4 else [])
    views = [im8] + [np.ascontiguousarray(f) for f, _ in others]
    # The detections are independent; OpenCV releases the GIL, so two threads overlap them.
    with ThreadPoolExecutor(max_workers=2) as pool:
        detected = list(pool.map(lambda im: _sb_corners(im, board), views))
    corners = detected[0]
    if corners is None:
        return None
    found = [corners]
    for c, (_, back) in zip(detected[1:], others):
        if c is None:
            continue
        c = back(c)
        dist, idx = cKDTree(c).query(corners)
        if len(set(idx.tolist())) == len(corners) and dist.max() < 1.5:  # the same corners
            found.append(c[idx])
    return np.mean(found, axis=0)


def calibrate_camera(images, board: BoardGeometry, *, max_image_rms_px: float = 0.5,
                     outlier_factor: float = 3.0, fix_k3: bool = True,
                     zero_tangent: bool = False, min_images: int = 4,
                     corner_outlier_px: float = 0.25, board_model_rounds: int = 0,
                     model_outlier_px: float = 0.05, jackknife: bool = True,
                     progress=None, corners=None) -> CameraCalibration:
    """Zhang calibration of the camera from images of a chessboard.

    ``fix_k3`` keeps k3 = 0 and ``zero_tangent`` keeps p1 = p2 = 0 (OpenCV's
    ``CALIB_FIX_K3``, ``CALIB_ZERO_TANGENT_DIST``): fewer parameters for a lens that does not
    need them — the tangential terms trade off against the principal point.

    Corners whose reprojection error exceeds both ``corner_outlier_px`` and 4 robust
    standard deviations are left out and the calibration repeated; an image that loses a
    quarter of its corners is dropped.  Measured on rendered images (40 poses of the 9 × 7 ×
    8 mm board, 64 spp): OpenCV's SB detector placed a few corners of 4 of 40 images 0.9 to
    5 px off their true projections; left out, fx moved by 0.07 % and cy by 0.6 px (of
    20 of those poses, taken with the mirrors in place).

    ``board_model_rounds`` > 0: then place every corner of the kept boards by the image
    model of the four squares around it
    (:func:`lts360.recon.calibration.board_model.refine_corners_locally`: the corners follow the image
    whatever the current camera model) and calibrate again on those corners, that many
    times, leaving out corners as above with ``model_outlier_px`` for ``corner_outlier_px``
    (the model's corners are ~5 times more precise).  Slow (LM per corner) but every pixel
    of the squares counts, not only those next to the corner.  See STUDIES.md for what it
    changes.  ``progress(i, n)`` is called after each board.

    ``jackknife`` (default): also the delete-one-board covariance of the intrinsics
    (:func:`intrinsics_jackknife`, one more Zhang solution per kept board).

    ``corners``: per image, what ``detect_corners(image, board)`` returns for it (found
    beforehand, e.g. while the images were being taken); ``None``: detected here.

    Raises
    ------
    ValueError
        Fewer than ``min_images`` usable images, or inconsistent image sizes.
    """
    import cv2

    images = list(images)
    if not images:
        raise ValueError("calibrate_camera: no images")
    shapes = {np.asarray(im).shape for im in images}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"calibrate_camera: images must be 2-D and of one size, got {sorted(shapes)}")
    h, w = next(iter(shapes))
    if corners is None:
        found = [detect_corners(im, board) for im in images]
    elif len(corners) != len(images):
        raise ValueError(f"calibrate_camera: {len(corners)} corner sets for {len(images)} images")
    else:
        found = [None if c is None else np.asarray(c, dtype=np.float64) for c in corners]
    used = np.array([c is not None for c in found])
    obj = board.object_points()
    keep = [None if c is None else np.ones(len(c), bool) for c in found]
    flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (cv2.CALIB_ZERO_TANGENT_DIST if zero_tangent else 0)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    K = dist = rvecs = tvecs = None  # set by round 0's calibration, read by the later rounds
    for model_round in range(board_model_rounds + 1):
        if model_round > 0:  # the corners from the image model, from the last calibration
            idx = np.flatnonzero(used)
            model = _board_model_corners([images[i] for i in idx], board, K, dist.ravel()[:5],
                                         rvecs, tvecs, progress)
            for i, m in zip(idx, model):
                found[i] = m
                keep[i] = np.isfinite(m).all(axis=1)  # a patch the model could not fit
        floor = corner_outlier_px if model_round == 0 else model_outlier_px
        for _ in range(5):  # calibrate, drop outlier corners and images, calibrate again
            idx = np.flatnonzero(used)
            if len(idx) < min_images:
                raise ValueError(f"calibrate_camera: only {len(idx)} usable images, "
                                 f"need {min_images}")
            objs = [obj[keep[i]] for i in idx]
            pts = [found[i][keep[i]].astype(np.float32) for i in idx]
            rms, K, dist, rvecs, tvecs, std_i, _, per_view = cv2.calibrateCameraExtended(
                objs, pts, (w, h), None, None, flags=flags, criteria=crit)
            per_view = per_view.ravel()
            # Every corner against this calibration (the left-out ones too; NaN: not found).
            err = [np.linalg.norm(cv2.projectPoints(obj, r, t, K, dist)[0].reshape(-1, 2)
                                  - found[i], axis=1) for i, r, t in zip(idx, rvecs, tvecs)]
            all_err = np.concatenate(err)
            limit = corner_outlier_limit(all_err[np.isfinite(all_err)], floor)
            new_keep = {i: np.nan_to_num(e, nan=np.inf) <= limit for i, e in zip(idx, err)}
            bad = ((per_view > max_image_rms_px)
                   | (per_view > outlier_factor * np.median(per_view)))
            bad |= np.array([new_keep[i].mean() < 0.75 for i in idx])  # a quarter of it wrong
            changed = any(not np.array_equal(new_keep[i], keep[i]) for i in idx)
            if not bad.any() and not changed:
                break
            for i in idx:
                keep[i] = new_keep[i]
            used[idx[bad]] = False
    corners = [found[i] for i in idx]
    kept = [keep[i].copy() for i in idx]
    cov_jk = (intrinsics_jackknife(objs, pts, (w, h), K, dist, flags=flags, criteria=crit)
              if jackknife and len(idx) >= 3 else None)
    return CameraCalibration(K=K, dist=dist.ravel()[:5], image_size=(w, h), rms_px=float(rms),
                             per_image_rms_px=per_view, used=used, std_intrinsics=std_i.ravel(),
                             rvecs=[r.ravel() for r in rvecs], tvecs=[t.ravel() for t in tvecs],
                             corners=corners, corner_kept=kept, cov_jackknife=cov_jk)


def _board_model_corners(images, board, K, dist, rvecs, tvecs, progress=None) -> list:
    """Every board's corners from the image model of the squares around each (NaN where
    the fit failed), from the board's current pose; the boards fitted in parallel threads
    (numpy and scipy release the GIL)."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    import cv2

    def one(args):
        image, r, t = args
        return refine_corners_locally(image, board, cv2.Rodrigues(np.ravel(r))[0], np.ravel(t),
                                      K, dist)[0]

    out = []
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        for i, c in enumerate(pool.map(one, zip(images, rvecs, tvecs))):
            out.append(c)
            if progress is not None:
                progress(i + 1, len(images))
    return out

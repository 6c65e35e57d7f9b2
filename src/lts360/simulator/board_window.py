"""Image windows where a calibration board changes the picture: seen directly and through
every mirror sequence the renderer follows, blurred by the thin lens.  numpy only.

The simulator knows the true rig and board pose, so it can render the board's windows at the
full sample count and the rest of the frame (ambient environment, mirrors) once.  Outside the
windows returned here the board changes nothing: the integrator's only non-delta surface is
the board (no interreflections), so the board shows up only where a camera ray — through the
pupil and up to ``max_bounces`` planar mirrors — meets it.

Geometry, exact for the renderer's camera (:mod:`lts360.simulator.camera_plugin`): a path
through the mirrors ``(s_0, …, s_{n−1})`` (``s_{n−1}`` nearest the camera) sees the virtual
board ``M_{s_{n−1}} ⋯ M_{s_0} X``; it is convex, so its ideal (undistorted) normalised image
``Q`` is a convex polygon.  A thin-lens ray from pupil point ``a`` through the film point of
normalised ideal coordinates ``x`` meets depth ``z`` at ``X/z = x − a (1/z − 1/s_f)``: a point
at depth ``z`` is spread over a disk of radius ``ρ = r_pupil |1/z − 1/s_f|`` in normalised
units, so the board touches the film where ``Q ⊕ disk(ρ)`` does.  Its pixel bounding box is
found on its boundary: the samples of ``∂Q`` that project inside the film and the film's own
border where it lies in ``Q ⊕ ρ``; the box is then padded by ``ρ`` in pixels (times the
distortion's largest stretch), the sample spacing, one pixel for the pixel footprint and box
filter, and a safety margin.  The box of each mirror view is intersected with the boxes of the
(virtual) mirror rectangles the path goes through, padded the same way.
"""

from __future__ import annotations

import numpy as np

from lts360.geometry.camera import distort_normalized, scale_intrinsics, undistort_normalized

__all__ = ["board_windows", "board_pixels", "board_edge_pixels", "board_lines_mm",
           "mirror_edge_pixels", "edge_mask", "segments_mask", "clip_segments_near", "view_box",
           "merge_boxes", "mirror_paths", "clip_near", "blur_radius_norm", "FILTER_MARGIN_PX", "SAFETY_MARGIN_PX"]

#: Pixel footprint plus Mitsuba's ``box`` filter (radius 0.5 px): a sample lands in its own
#: pixel, at most half a pixel from the pixel centre.
FILTER_MARGIN_PX = 1.0
#: Extra pixels around every window.
SAFETY_MARGIN_PX = 4.0
#: Nearest depth rendered (mm): the camera plugin's near clip plane.
NEAR_MM = 1.0
_EDGE_SAMPLES = 256


def mirror_paths(mirrors, max_bounces: int) -> list[tuple[tuple[int, ...], np.ndarray]]:
    """Every mirror sequence the renderer follows and its unfolding transform.

    Parameters
    ----------
    mirrors : sequence of lts360.scenes.rig.Mirror
    max_bounces : int, >= 0

    Returns
    -------
    list of (seq, T)
        ``seq`` from the object towards the camera (as :func:`lts360.scenes.coverage.view_name`),
        ``T`` (4, 4) the product of mirror matrices mapping a world point to its virtual image
        seen along that path (identity for the direct view).
    """
    from lts360.scenes.coverage import mirror_sequences

    out = []
    for seq in mirror_sequences(tuple(mirrors), max_bounces):
        T = np.eye(4)
        for k in seq:
            T = mirrors[k].T @ T
        out.append((tuple(seq), T))
    return out


def clip_near(poly_cam_mm: np.ndarray, z_min_mm: float = NEAR_MM) -> np.ndarray:
    """Clip a planar convex polygon (camera frame, mm) to ``z >= z_min_mm``.

    Parameters
    ----------
    poly_cam_mm : (n, 3) float
        Vertices in order.

    Returns
    -------
    (m, 3) float
        The clipped polygon (``m = 0`` when it lies wholly in front of the near plane).
    """
    P = np.asarray(poly_cam_mm, dtype=float)
    Q = np.roll(P, -1, axis=0)
    a, b = P[:, 2] - z_min_mm, Q[:, 2] - z_min_mm
    keep_a = a >= 0
    cross = (a >= 0) != (b >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, a / (a - b), 0.0)
    hits = P + t[:, None] * (Q - P)
    # Each edge contributes its start vertex (if kept) then its crossing (if any), in order.
    pts = np.stack([P, hits], axis=1).reshape(-1, 3)
    mask = np.stack([keep_a, cross], axis=1).reshape(-1)
    return pts[mask]


def blur_radius_norm(aperture_radius_mm: float, focus_distance_mm: float,
                     depth_mm: np.ndarray) -> np.ndarray:
    """Thin-lens blur radius in ideal normalised image units, ``r |1/z − 1/s_f|``.

    Parameters
    ----------
    aperture_radius_mm : float, >= 0
        Entrance pupil radius (0: pinhole).
    focus_distance_mm : float, > 0
    depth_mm : array, > 0
        Camera-frame depth ``z`` of the (virtual) points.
    """
    z = np.asarray(depth_mm, dtype=float)
    return float(aperture_radius_mm) * np.abs(1.0 / z - 1.0 / float(focus_distance_mm))


def _film_border_px(width: int, height: int) -> np.ndarray:
    """(n, 2) points every half pixel along the film's outer edge (pixel units, OpenCV)."""
    u = np.arange(-0.5, width - 0.5 + 1e-9, 0.5)
    v = np.arange(-0.5, height - 0.5 + 1e-9, 0.5)
    top = np.column_stack([u, np.full_like(u, -0.5)])
    bottom = np.column_stack([u, np.full_like(u, height - 0.5)])
    left = np.column_stack([np.full_like(v, -0.5), v])
    right = np.column_stack([np.full_like(v, width - 0.5), v])
    return np.vstack([top, bottom, left, right])


def _to_norm(px: np.ndarray, K: np.ndarray, dist) -> np.ndarray:
    """Ideal normalised coordinates of pixel positions (n, 2)."""
    yd = (px[:, 1] - K[1, 2]) / K[1, 1]
    xd = (px[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
    return undistort_normalized(np.column_stack([xd, yd]), dist)


def _to_px(xy: np.ndarray, K: np.ndarray, dist) -> np.ndarray:
    """Pixel positions (n, 2) of ideal normalised coordinates."""
    d = distort_normalized(xy, dist)
    return np.column_stack([K[0, 0] * d[:, 0] + K[0, 1] * d[:, 1] + K[0, 2],
                            K[1, 1] * d[:, 1] + K[1, 2]])


def _within(xy: np.ndarray, poly: np.ndarray, rho: float) -> np.ndarray:
    """Points ``xy`` (n, 2) inside the convex polygon ``poly`` (m, 2) dilated by ``rho``."""
    a = poly
    e = np.roll(poly, -1, axis=0) - a
    if np.sum(a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]) < 0:  # make it counter-clockwise
        a = a[::-1]
        e = np.roll(a, -1, axis=0) - a
    rel = xy[:, None, :] - a[None, :, :]
    inside = np.all(e[None, :, 0] * rel[..., 1] - e[None, :, 1] * rel[..., 0] >= 0, axis=1)
    ee = np.maximum(np.sum(e * e, axis=1), 1e-300)
    t = np.clip(np.sum(rel * e[None], axis=2) / ee[None], 0.0, 1.0)
    d2 = np.sum((rel - t[..., None] * e[None]) ** 2, axis=2)
    return inside | (np.min(d2, axis=1) <= rho * rho)


def _stretch(K: np.ndarray, dist, width: int, height: int) -> float:
    """Largest local magnification of ideal normalised → pixel units over the film (px)."""
    u, v = np.meshgrid(np.linspace(-0.5, width - 0.5, 17), np.linspace(-0.5, height - 0.5, 17))
    xy = _to_norm(np.column_stack([u.ravel(), v.ravel()]), K, dist)
    h = 1e-6
    J = np.stack([(_to_px(xy + [h, 0.0], K, dist) - _to_px(xy - [h, 0.0], K, dist)) / (2 * h),
                  (_to_px(xy + [0.0, h], K, dist) - _to_px(xy - [0.0, h], K, dist)) / (2 * h)],
                 axis=-1)
    return float(np.max(np.linalg.norm(J, ord=2, axis=(1, 2))))


def view_box(poly_cam_mm: np.ndarray, K: np.ndarray, dist, width: int, height: int, *,
             aperture_radius_mm: float = 0.0, focus_distance_mm: float = 1.0,
             margin_px: float = SAFETY_MARGIN_PX, stretch: float | None = None,
             outline: bool = False):
    """Pixel box of the film where a planar convex polygon (camera frame) can be seen.

    Parameters
    ----------
    poly_cam_mm : (n, 3) float
        The (virtual) polygon in the OpenCV camera frame, mm.
    K, dist : intrinsics (px) and Brown distortion ``(k1, k2, p1, p2, k3)``
    width, height : int
        Film size, px.
    aperture_radius_mm, focus_distance_mm : float
        Thin lens (``aperture_radius_mm = 0``: pinhole).
    margin_px : float, >= 0
        Safety margin added on every side, px.
    stretch : float, optional
        Largest px per normalised unit over the film (computed when omitted).

    outline : bool
        Also return the pixels the polygon can touch: its image filled and dilated by the
        same padding as the box (``None`` where that image is not a closed curve on the film,
        i.e. part of the polygon lies beyond the film's largest radius: use the box).

    Returns
    -------
    (x0, y0, x1, y1) int or None
        Inclusive pixel bounds clipped to the film, or ``None`` when the polygon cannot
        touch the film.  With ``outline``: ``(box, mask)``, ``mask`` a (height, width) bool
        array or ``None``.
    """
    K = np.asarray(K, dtype=float)
    P = clip_near(poly_cam_mm)
    if len(P) < 3:
        return (None, None) if outline else None
    Q = P[:, :2] / P[:, 2:3]
    rho = float(np.max(blur_radius_norm(aperture_radius_mm, focus_distance_mm, P[:, 2])))
    if stretch is None:
        stretch = _stretch(K, dist, width, height)
    # Boundary samples of Q that land inside the film (distortion is checked to be monotonic
    # only over the film: a sample beyond the film's largest normalised radius is left out).
    t = np.arange(_EDGE_SAMPLES) / _EDGE_SAMPLES
    E = np.roll(Q, -1, axis=0) - Q
    edge = (Q[:, None, :] + t[None, :, None] * E[:, None, :]).reshape(-1, 2)
    border = _film_border_px(width, height)
    border_xy = _to_norm(border, K, dist)
    r_film = float(np.max(np.hypot(border_xy[:, 0], border_xy[:, 1])))
    near = np.hypot(edge[:, 0], edge[:, 1]) <= r_film
    uv = _to_px(edge[near], K, dist)
    spacing = float(np.max(np.linalg.norm(np.diff(uv, axis=0), axis=1), initial=0.0))
    spacing = min(spacing, stretch * float(np.max(np.linalg.norm(E, axis=1))) / _EDGE_SAMPLES)
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= width - 0.5) & (uv[:, 1] >= -0.5) & \
             (uv[:, 1] <= height - 0.5)
    pts = np.vstack([uv[inside], border[_within(border_xy, Q, rho)]])
    if len(pts) == 0:
        return (None, None) if outline else None
    pad = rho * stretch + spacing + FILTER_MARGIN_PX + float(margin_px)
    lo = np.floor(pts.min(axis=0) - pad)
    hi = np.ceil(pts.max(axis=0) + pad)
    x0, y0 = int(max(lo[0], 0)), int(max(lo[1], 0))
    x1, y1 = int(min(hi[0], width - 1)), int(min(hi[1], height - 1))
    if x1 < x0 or y1 < y0:
        return (None, None) if outline else None
    if not outline:
        return x0, y0, x1, y1
    mask = _outline_mask(uv, pad, width, height) if near.all() else None
    return (x0, y0, x1, y1), mask


def _outline_mask(uv: np.ndarray, pad_px: float, width: int, height: int) -> np.ndarray:
    """Pixels whose centre lies inside the closed curve ``uv`` (dense samples of the polygon's
    image, px) or within ``pad_px`` (+ 1 px for the fill's rasterisation) of it."""
    import cv2

    r = int(np.ceil(pad_px)) + 1
    off = r + 1  # draw on a canvas with a border, so that parts beyond the film count too
    canvas = np.zeros((height + 2 * off, width + 2 * off), np.uint8)
    poly = np.rint((uv + off) * 16).astype(np.int32)  # 4 fractional bits
    cv2.fillPoly(canvas, [poly], 1, lineType=cv2.LINE_8, shift=4)
    cv2.polylines(canvas, [poly], True, 1, lineType=cv2.LINE_8, shift=4)
    return _grow(canvas, r, off, width, height)


def _grow(canvas: np.ndarray, r: int, off: int, width: int, height: int) -> np.ndarray:
    """The film's part (offset ``off`` in ``canvas``) of ``canvas`` dilated by a disk of
    radius ``r``, as bool.  Only the drawn pixels' bounding box plus ``r`` is dilated: the
    same result as dilating the whole canvas (nothing else is within ``r`` of a drawn pixel),
    in a fraction of the time for a small polygon."""
    import cv2

    out = np.zeros((height, width), bool)
    x, y, w, h = cv2.boundingRect(canvas)
    if w == 0 or h == 0:
        return out
    x0, y0 = max(x - r, 0), max(y - r, 0)
    x1, y1 = min(x + w + r, canvas.shape[1]), min(y + h + r, canvas.shape[0])
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    grown = cv2.dilate(np.ascontiguousarray(canvas[y0:y1, x0:x1]), disk)
    fx0, fy0 = max(x0 - off, 0), max(y0 - off, 0)
    fx1, fy1 = min(x1 - off, width), min(y1 - off, height)
    if fx1 > fx0 and fy1 > fy0:
        out[fy0:fy1, fx0:fx1] = grown[fy0 + off - y0:fy1 + off - y0,
                                      fx0 + off - x0:fx1 + off - x0] > 0
    return out


def clip_segments_near(segments_cam_mm: np.ndarray, z_min_mm: float = NEAR_MM) -> np.ndarray:
    """Clip line segments (camera frame, mm) to ``z >= z_min_mm``.

    Parameters
    ----------
    segments_cam_mm : (m, 2, 3) float
        End points of each segment.

    Returns
    -------
    (k, 2, 3) float
        The parts in front of the near plane (segments wholly behind it are dropped).
    """
    S = np.asarray(segments_cam_mm, dtype=float).reshape(-1, 2, 3)
    a, b = S[:, 0], S[:, 1]
    za, zb = a[:, 2] - z_min_mm, b[:, 2] - z_min_mm
    keep = (za >= 0) | (zb >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where((za >= 0) != (zb >= 0), za / (za - zb), 0.0)
    hit = a + t[:, None] * (b - a)
    a = np.where((za < 0)[:, None], hit, a)
    b = np.where((zb < 0)[:, None], hit, b)
    return np.stack([a, b], axis=1)[keep]


def segments_mask(segments_cam_mm: np.ndarray, K: np.ndarray, dist, width: int, height: int, *,
                  aperture_radius_mm: float = 0.0, focus_distance_mm: float = 1.0,
                  margin_px: float = SAFETY_MARGIN_PX, stretch: float | None = None,
                  samples_per_segment: int = 4096) -> np.ndarray:
    """(height, width) bool: the pixels that line segments (camera frame, mm) can touch,
    padded as :func:`view_box` pads its box (the lens blur, the sample spacing, the pixel
    footprint and ``margin_px``).

    Segment samples beyond the film's largest normalised radius plus the blur are left out
    (they cannot reach the film; the distortion is monotonic only over it)."""
    import cv2

    K = np.asarray(K, dtype=float)
    out = np.zeros((height, width), bool)
    S = clip_segments_near(segments_cam_mm)
    if len(S) == 0:
        return out
    # The blur |1/z - 1/s_f| is largest at an end point of a segment (1/z is monotonic on it).
    rho = float(np.max(blur_radius_norm(aperture_radius_mm, focus_distance_mm, S[..., 2])))
    if stretch is None:
        stretch = _stretch(K, dist, width, height)
    border_xy = _to_norm(_film_border_px(width, height), K, dist)
    r_keep = float(np.max(np.hypot(border_xy[:, 0], border_xy[:, 1]))) + rho
    Q = S[..., :2] / S[..., 2:3]
    t = np.arange(samples_per_segment + 1) / samples_per_segment
    runs, spacing = [], 0.0
    for a, b in Q:
        e = a[None, :] + t[:, None] * (b - a)[None, :]
        keep = np.hypot(e[:, 0], e[:, 1]) <= r_keep
        # Runs of consecutive kept samples (a segment may leave the film's disk and come back).
        cuts = np.flatnonzero(np.diff(keep.astype(np.int8))) + 1
        for run_xy, run_keep in zip(np.split(e, cuts), np.split(keep, cuts)):
            if run_keep[0]:
                uv = _to_px(run_xy, K, dist)
                if len(uv) > 1:
                    spacing = max(spacing, float(np.max(np.linalg.norm(np.diff(uv, axis=0),
                                                                       axis=1))))
                runs.append(uv)
    if not runs:
        return out
    pad = rho * stretch + spacing + FILTER_MARGIN_PX + float(margin_px)
    r = int(np.ceil(pad)) + 1
    off = r + 1  # a canvas with a border: parts just beyond the film count too
    canvas = np.zeros((height + 2 * off, width + 2 * off), np.uint8)
    big = 4 * (width + height + 2 * off)  # keep cv2's fixed-point coordinates in range
    polys = [np.rint((np.clip(uv, -big, big) + off) * 16).astype(np.int32) for uv in runs]
    cv2.polylines(canvas, polys, False, 1, lineType=cv2.LINE_8, shift=4)
    return _grow(canvas, r, off, width, height)


def edge_mask(poly_cam_mm: np.ndarray, K: np.ndarray, dist, width: int, height: int, *,
              aperture_radius_mm: float = 0.0, focus_distance_mm: float = 1.0,
              margin_px: float = SAFETY_MARGIN_PX, stretch: float | None = None,
              samples_per_edge: int = 4096) -> np.ndarray:
    """(height, width) bool: the pixels that the *edges* of a planar convex polygon (camera
    frame, mm) can touch, padded as :func:`view_box` pads its box: :func:`segments_mask` of
    the edges of the polygon clipped to the near plane."""
    P = clip_near(poly_cam_mm)
    if len(P) < 3:
        return np.zeros((height, width), bool)
    return segments_mask(np.stack([P, np.roll(P, -1, axis=0)], axis=1), K, dist, width, height,
                         aperture_radius_mm=aperture_radius_mm,
                         focus_distance_mm=focus_distance_mm, margin_px=margin_px,
                         stretch=stretch, samples_per_segment=samples_per_edge)


def _intersect(a, b):
    if a is None or b is None:
        return None
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[2], b[2]), min(a[3], b[3])
    return None if x1 < x0 or y1 < y0 else (x0, y0, x1, y1)


def merge_boxes(boxes) -> list[tuple[int, int, int, int]]:
    """Replace overlapping or touching inclusive boxes ``(x0, y0, x1, y1)`` by their bounding
    box until none overlap; the result covers every input box."""
    out = [tuple(int(c) for c in b) for b in boxes if b is not None]
    merged = True
    while merged:
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                a, b = out[i], out[j]
                if a[0] <= b[2] + 1 and b[0] <= a[2] + 1 and a[1] <= b[3] + 1 and b[1] <= a[3] + 1:
                    out[i] = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return sorted(out)


def _film(rig, scale: float, thin_lens: bool):
    """The camera as the film boxes see it: intrinsics at ``scale``, distortion, film size (as
    camera_to_mitsuba), the lens for :func:`view_box`, the distortion's stretch, and the
    camera's pose ``R, t``."""
    cam = rig.camera
    K = scale_intrinsics(cam.K, scale)
    dist = np.asarray(cam.distortion, dtype=float)
    W = max(1, int(round(cam.width_px * scale)))  # as camera_to_mitsuba
    H = max(1, int(round(cam.height_px * scale)))
    lens = {"aperture_radius_mm": float(cam.aperture_diameter_mm) / 2.0 if thin_lens else 0.0,
            "focus_distance_mm": float(cam.focus_distance_mm)}
    R, t = np.asarray(cam.R, dtype=float), np.asarray(cam.t_mm, dtype=float)
    return K, dist, W, H, lens, _stretch(K, dist, W, H), R, t


def _path_views(rig, board, *, thin_lens: bool, max_bounces: int, scale: float,
                margin_px: float, outline: bool):
    """For every mirror path the renderer follows: the film box where the board can be seen
    along it (clipped to the mirrors it goes through) and, with ``outline``, the board's padded
    outline on the film (``None`` where only the box is known).  Also returns the film size."""
    K, dist, W, H, lens, stretch, R, t = _film(rig, scale, thin_lens)

    def view(points_world, T, with_outline):
        X = points_world @ T[:3, :3].T + T[:3, 3]
        return view_box(X @ R.T + t, K, dist, W, H, margin_px=margin_px, stretch=stretch,
                        outline=with_outline, **lens)

    corners = np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], float)
    board_outline = (corners @ board.rectangle_transform().T)[:, :3]
    out = []
    for seq, T in mirror_paths(rig.mirrors, max_bounces):
        b, mask = view(board_outline, T, True) if outline else (view(board_outline, T, False), None)
        # Each mirror of the path, as the camera sees it (through the mirrors after it).
        for pos, k in enumerate(seq):
            T_after = np.eye(4)
            for j in seq[pos + 1:]:
                T_after = rig.mirrors[j].T @ T_after
            b = _intersect(b, view(np.asarray(rig.mirrors[k].corners_mm, dtype=float), T_after,
                                   False))
        out.append((b, mask))
    return out, (W, H)


def board_windows(rig, board, *, thin_lens: bool = True, max_bounces: int = 2, scale: float = 1.0,
                  margin_px: float = SAFETY_MARGIN_PX) -> list[tuple[int, int, int, int]]:
    """Film windows outside which ``board`` changes nothing in a render of ``rig`` + board.

    Parameters
    ----------
    rig : lts360.scenes.rig.Rig
        Its mirrors as rendered (pass a rig without mirrors for a mirrors-covered shot).
    board : lts360.scenes.targets.Chessboard
    thin_lens : bool
        As :func:`lts360.simulator.render.render_radiance`.
    max_bounces : int
        As the renderer's (camera-side mirror reflections followed).
    scale : float, (0, 1]
        Image scale, as the renderer's (film and intrinsics scaled alike).
    margin_px : float
        Safety margin, px of the (scaled) film.

    Returns
    -------
    list of (x, y, width, height) int
        Disjoint windows of the full film, px (the crop convention of
        :func:`lts360.simulator.camera_plugin.camera_to_mitsuba`).
    """
    views, _ = _path_views(rig, board, thin_lens=thin_lens, max_bounces=max_bounces, scale=scale,
                           margin_px=margin_px, outline=False)
    return [(x0, y0, x1 - x0 + 1, y1 - y0 + 1)
            for x0, y0, x1, y1 in merge_boxes(b for b, _ in views)]


def board_pixels(rig, board, *, thin_lens: bool = True, max_bounces: int = 2, scale: float = 1.0,
                 margin_px: float = SAFETY_MARGIN_PX) -> np.ndarray:
    """Pixels outside which ``board`` changes nothing: the tighter set of
    :func:`board_windows` — each view's padded outline of the board (not its bounding box),
    inside that view's box (clipped to the mirrors it is seen through).  Same parameters.

    Returns
    -------
    (n, 2) int
        ``(x, y)`` of each pixel once, row-major.
    """
    views, (W, H) = _path_views(rig, board, thin_lens=thin_lens, max_bounces=max_bounces,
                                scale=scale, margin_px=margin_px, outline=True)
    covered = np.zeros((H, W), bool)
    for b, mask in views:
        if b is None:
            continue
        x0, y0, x1, y1 = b
        covered[y0:y1 + 1, x0:x1 + 1] |= True if mask is None else mask[y0:y1 + 1, x0:x1 + 1]
    y, x = np.nonzero(covered)
    return np.column_stack([x, y])


def _mirror_image(rig, k: int, T: np.ndarray, film, *, edges: bool, margin_px: float):
    """Film mask of mirror ``k`` seen through the mirrors of ``T`` (``edges``: its edges'
    padded pixels; else its padded filled image, its box where the outline is not known); all
    False where it cannot be seen.  ``film`` as :func:`_film` returns it."""
    K, dist, W, H, lens, stretch, R, t = film
    X = np.asarray(rig.mirrors[k].corners_mm, dtype=float)
    X = (X @ T[:3, :3].T + T[:3, 3]) @ R.T + t
    if edges:
        return edge_mask(X, K, dist, W, H, margin_px=margin_px, stretch=stretch, **lens)
    box, mask = view_box(X, K, dist, W, H, margin_px=margin_px, stretch=stretch,
                         outline=True, **lens)
    out = np.zeros((H, W), bool)
    if box is not None:
        x0, y0, x1, y1 = box
        out[y0:y1 + 1, x0:x1 + 1] = True if mask is None else mask[y0:y1 + 1, x0:x1 + 1]
    return out


def _through(rig, seq, film, margin_px: float):
    """The pixels whose rays can go through the mirror sequence ``seq`` (object side first):
    inside each of its mirrors' images, each seen through the mirrors after it; and the
    unfolding transform of the mirrors in front of the object."""
    _, _, W, H, _, _, _, _ = film
    through = np.ones((H, W), bool)
    T_after = np.eye(4)
    for k in reversed(seq):
        through &= _mirror_image(rig, k, T_after, film, edges=False, margin_px=margin_px)
        T_after = T_after @ rig.mirrors[k].T
    return through, T_after


def mirror_edge_pixels(rig, *, thin_lens: bool = True, max_bounces: int = 2, scale: float = 1.0,
                       margin_px: float = SAFETY_MARGIN_PX) -> np.ndarray:
    """Pixels of a picture of ``rig`` without any board (its mirrors under a uniform ambient
    light) whose samples may see different things: outside them every camera ray of a pixel
    follows the same mirror sequence to the same uniform environment, so the pixel's value
    is the same for one sample as for any number.

    The picture changes only across the edges of the mirror rectangles, seen directly and
    through every mirror sequence the renderer follows (a rectangle seen through
    ``max_bounces`` mirrors bounds where a ray would meet one mirror too many): these are the
    pixels within the padding of :func:`view_box` of each such edge (the lens blur, the
    sample spacing, the pixel footprint and ``margin_px``), kept where the rays can go
    through the mirrors in front of it (each of those mirrors' filled, padded images).
    Same parameters as :func:`board_pixels`; no mirrors: no pixels.

    Returns
    -------
    (n, 2) int
        ``(x, y)`` of each pixel once, row-major.
    """
    film = _film(rig, scale, thin_lens)
    covered = np.zeros((film[3], film[2]), bool)
    for seq, _ in mirror_paths(rig.mirrors, max_bounces):
        through, T_after = _through(rig, seq, film, margin_px)
        for k in range(len(rig.mirrors)):
            covered |= _mirror_image(rig, k, T_after, film, edges=True,
                                     margin_px=margin_px) & through
    y, x = np.nonzero(covered)
    return np.column_stack([x, y])


def board_lines_mm(board) -> np.ndarray:
    """(m, 2, 3) segments, board frame (mm), across which the printed side's albedo can
    change: every line of the squares' grid, over the whole pattern, and the printed area's
    outline (where the board ends)."""
    s = float(board.square_mm)
    X, Y = board.squares_x * s, board.squares_y * s
    m = float(board.margin_mm)
    xs, ys = np.arange(board.squares_x + 1) * s, np.arange(board.squares_y + 1) * s
    vert = [[[x, 0.0, 0.0], [x, Y, 0.0]] for x in xs]
    horiz = [[[0.0, y, 0.0], [X, y, 0.0]] for y in ys]
    c = [[-m, -m, 0.0], [X + m, -m, 0.0], [X + m, Y + m, 0.0], [-m, Y + m, 0.0]]
    outline = [[c[i], c[(i + 1) % 4]] for i in range(4)]
    return np.array(vert + horiz + outline, dtype=float)


def board_edge_pixels(rig, board, *, thin_lens: bool = True, max_bounces: int = 2,
                      scale: float = 1.0, margin_px: float = SAFETY_MARGIN_PX) -> np.ndarray:
    """Pixels of a picture of ``rig`` + ``board`` whose rays may meet different albedos or
    different things: the images of the board's square edges and outline
    (:func:`board_lines_mm`), seen directly and through every mirror sequence the renderer
    follows (each kept where the rays can go through that sequence's mirrors), padded as
    :func:`view_box` pads (the lens blur, the sample spacing, the pixel footprint and
    ``margin_px``), and the mirrors' edges (:func:`mirror_edge_pixels`).

    Elsewhere on the board every ray of a pixel meets one square of the print (one albedo),
    through one mirror sequence.  Same parameters as :func:`board_pixels`.

    Returns
    -------
    (n, 2) int
        ``(x, y)`` of each pixel once, row-major.
    """
    film = _film(rig, scale, thin_lens)
    K, dist, W, H, lens, stretch, R, t = film
    lines = board_lines_mm(board)
    T_b = np.asarray(board.T_world_board, dtype=float)
    world = lines @ T_b[:3, :3].T + T_b[:3, 3]
    covered = np.zeros((H, W), bool)
    for seq, T in mirror_paths(rig.mirrors, max_bounces):
        through = _through(rig, seq, film, margin_px)[0] if seq else True
        X = (world @ T[:3, :3].T + T[:3, 3]) @ R.T + t
        covered |= segments_mask(X, K, dist, W, H, margin_px=margin_px, stretch=stretch,
                                 **lens) & through
    if rig.mirrors:
        px = mirror_edge_pixels(rig, thin_lens=thin_lens, max_bounces=max_bounces, scale=scale,
                                margin_px=margin_px)
        covered[px[:, 1], px[:, 0]] = True
    y, x = np.nonzero(covered)
    return np.column_stack([x, y])

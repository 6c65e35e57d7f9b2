"""The pixel support of a frame: every pixel that can carry laser light, plus a margin.

Only ~1 % of a frame's pixels carry laser light (the paper rig, a Ø20 mm gauge); rendering
only those (:func:`lts360.simulator.render.render_pixels`) is what makes a frame cheap.  This
module says which pixels those are, from the scene itself (no render):

1. **Where the light can land.**  The integrator evaluates the laser at the *unfolded* point
   ``x' = T_a T_b … x`` of every laser-side mirror sequence and truncates the sheet's Gaussian
   profile at ``|h| = √(GAUSS_CUT / 2) · w`` (``h`` the distance from the sheet plane, ``w``
   the 1/e² half-thickness at that distance from the apex): outside that, its laser term is
   exactly 0.  So direct laser light can only land on surface points inside one of the slabs
   ``|n_s · x − d_s| ≤ t_s``, one slab per laser-side mirror sequence (the sheet plane
   reflected by the mirrors; on a rig whose mirrors are parallel to the sheet normal they all
   coincide).  Every shape of the scene (the object, extra meshes, the base plate) is clipped
   to each slab and the clipped triangles are sampled with points no farther apart than
   :data:`SAMPLE_SPACING_PX` pixels in the nearest view.
2. **Where it is seen.**  Each point is projected (with distortion) directly and through every
   camera-side mirror sequence up to ``max_bounces`` (its mirror image ``T_c1 … T_ck x``),
   where the line from the camera centre to that image crosses each mirror of the sequence
   inside its rectangle grown by the lens aperture + 1 mm (rays from the whole pupil reach a
   mirror's edge), and where the point's face turns towards the (unfolded) camera: the
   BSDFs are one-sided, a face seen from behind holds no light.  Occlusion by other surfaces
   is not tested: the support is a superset (a hidden image costs render time, never light).
3. **How far it spreads.**  Each image point is widened by its defocus blur (the thin lens's
   circle of confusion at its own path length, :func:`blur_diameter_px`) and by
   :data:`MARGIN_PX` (the pixel's box, the sampling's jitter and the spacing of the points).

What it covers: *direct* laser light, ``L (S)* D (S)* E``, as the integrator renders it today.
Light the laser puts elsewhere by scattering off a non-delta surface first (interreflections,
a glint carried by a mirror) can land outside it.  That light still leaves a shape (a non-delta
surface) last before the camera: :func:`hull_support` bounds it by every pixel that can see a
shape at all, from the shapes' convex hulls seen through every view — the support of frames
with interreflections.  A pilot render (:func:`pilot_support`) is cheaper but misses glints;
:func:`lts360.simulator.frame.simulate_frame`'s ``support=`` chooses.

Conventions: OpenCV pixels (centres at integers), millimetres, the rendered (scaled) film.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lts360.geometry.camera import project_camera_points, scale_intrinsics, world_to_camera

__all__ = ["PixelSupport", "SUPPORT_METHODS", "MARGIN_PX", "SAMPLE_SPACING_PX", "PILOT_SPP",
           "PILOT_THRESHOLD", "sheet_slabs", "slab_triangles", "slab_points", "blur_diameter_px",
           "geometric_support", "hull_support", "pilot_support", "full_support",
           "support_from_mask", "film_size"]

#: How a frame's rendered pixels are chosen (``simulate_frame(support=...)``).
SUPPORT_METHODS = ("geometric", "hull", "pilot", "full")
#: Largest distance (pixels) between the points of a hull's outline that are distorted and
#: filled (:func:`hull_support`): the outline's curvature between them is far below a pixel.
HULL_OUTLINE_STEP_PX = 0.5
#: Margin added around every image point beyond its defocus blur (pixels of the rendered
#: film): a lit pixel's centre lies within 0.71 px (its box) of a lit point's image, and that
#: image within 1.15 · 1.1 px of a sample's (row sampling 0.71 + de-duplication 0.44 spacings of
#: SAMPLE_SPACING_PX, 1.1 for the field angle's stretch): 1.98 px.  The splat adds √2/2 px
#: for rounding the samples' images to pixels.
MARGIN_PX = 2.0
#: Largest distance between neighbouring surface samples, in pixels of the nearest view.
SAMPLE_SPACING_PX = 1.0
#: A surface point counts as seen by a view while its face normal makes at most
#: arccos(−BACKFACE_COS) ≈ 91.1° with the direction to the camera (the pupil's rays spread
#: ~0.6° about the chief ray at these distances).
BACKFACE_COS = 0.02
#: Samples per pixel of a pilot render (:func:`pilot_support`).
PILOT_SPP = 4
#: A pilot pixel belongs to the support when its laser radiance exceeds this fraction of the
#: pilot's peak (a decade below the 1e-4 that the support must contain).
PILOT_THRESHOLD = 1e-5


@dataclass(frozen=True, eq=False)
class PixelSupport:
    """Pixels of the (scaled) film that are rendered.

    Attributes
    ----------
    mask : (H, W) bool
        True where the pixel is rendered.
    method : str
        ``geometric``, ``pilot`` or ``full``.
    margin_px : float
        Margin beyond the blur (geometric) or dilation (pilot), in pixels.
    """

    mask: np.ndarray
    method: str
    margin_px: float

    @property
    def pixels_xy(self) -> np.ndarray:
        """(n, 2) int ``(x, y)`` of the rendered pixels, row-major."""
        ys, xs = np.nonzero(self.mask)
        return np.column_stack([xs, ys]).astype(np.int64)

    @property
    def fraction(self) -> float:
        """Share of the film's pixels rendered."""
        return float(self.mask.mean())

    def to_dict(self) -> dict:
        return {"method": self.method, "pixels": int(self.mask.sum()),
                "fraction": round(self.fraction, 6), "margin_px": float(self.margin_px)}


def film_size(camera, scale: float) -> tuple[int, int]:
    """``(width, height)`` of the rendered film at ``scale`` (as the camera plugin's)."""
    return (max(1, int(round(camera.width_px * scale))),
            max(1, int(round(camera.height_px * scale))))


def full_support(camera, scale: float = 1.0) -> PixelSupport:
    """Every pixel (today's full-frame render)."""
    w, h = film_size(camera, scale)
    return PixelSupport(mask=np.ones((h, w), bool), method="full", margin_px=0.0)


# ----------------------------------------------------------------------------- mirrors
def _reflection(mirror) -> tuple[np.ndarray, np.ndarray]:
    """``(A, b)`` of the mirror's reflection ``x ↦ A x + b`` (paper Eq. 3)."""
    n = np.asarray(mirror.normal, float)
    return np.eye(3) - 2.0 * np.outer(n, n), 2.0 * float(mirror.d_mm) * n


def _compose(mirrors, seq) -> tuple[np.ndarray, np.ndarray]:
    """``x ↦ T_seq[0] ∘ T_seq[1] ∘ … (x)`` as ``(A, b)`` (the last mirror is applied first)."""
    A, b = np.eye(3), np.zeros(3)
    for k in seq:  # T = T_prev ∘ T_k
        Ak, bk = _reflection(mirrors[k])
        A, b = A @ Ak, A @ bk + b
    return A, b


def _sequences(rig, max_bounces: int) -> list[tuple[int, ...]]:
    from lts360.scenes.coverage import mirror_sequences

    return mirror_sequences(tuple(rig.mirrors), int(max_bounces))


# --------------------------------------------------------------------------------- slabs
def _cut_half_widths() -> float:
    """The integrator's truncation of the sheet's Gaussian, in 1/e² half-thicknesses."""
    from lts360.simulator.integrator import _GAUSS_CUT

    return math.sqrt(_GAUSS_CUT / 2.0)


def sheet_slabs(rig, vertices_world_mm: np.ndarray, max_bounces: int = 2) -> list[tuple]:
    """The slabs that can hold direct laser light, one per distinct laser-side mirror sequence.

    Parameters
    ----------
    rig : Rig
    vertices_world_mm : (n, 3) float
        Points of the scene's shapes (the sheet's thickness is taken at the largest distance
        from the apex among them, unfolded).
    max_bounces : int

    Returns
    -------
    list of (normal (3,), d_mm, half_thickness_mm)
        Slab ``|normal · x − d_mm| ≤ half_thickness_mm`` (``normal`` a unit vector).
    """
    las = rig.laser
    n_l, O = np.asarray(las.normal, float), np.asarray(las.origin_mm, float)
    w0 = las.waist_um * 1e-3
    cut = _cut_half_widths()
    P = np.asarray(vertices_world_mm, float).reshape(-1, 3)
    # The sheet is thickest farthest from its waist: bound the distance from the apex by the
    # shapes' bounding box (a mirror image is as far from the virtual apex as the point is
    # from the real one along the unfolded path: unfold the box's corners).
    corners = (np.array(np.meshgrid(*zip(*_bounds(P)))).reshape(3, -1).T
               if len(P) else O[None, :])
    out: list[tuple] = []
    for seq in _sequences(rig, max_bounces):
        A, b = _compose(rig.mirrors, seq)
        normal = A.T @ n_l                      # h(x) = n·(A x + b − O)
        d = -float(n_l @ (b - O))
        rho_max = float(np.linalg.norm(corners @ A.T + b - O, axis=1).max())
        far = max(rho_max - las.waist_distance_mm, las.waist_distance_mm)
        half = cut * w0 * math.sqrt(1.0 + (far / las.rayleigh_range_mm) ** 2)
        if any(np.allclose(normal, s[0], atol=1e-12) and abs(d - s[1]) < 1e-9 for s in out):
            continue
        out.append((normal, d, half))
    return out


def _bounds(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and largest coordinate of the points ``P`` (n, 3), column by column (a reduction
    along axis 0 of an (n, 3) array is ~25 times slower)."""
    return (np.array([P[:, k].min() for k in range(3)]),
            np.array([P[:, k].max() for k in range(3)]))


def _clip_to_slab(V: np.ndarray, F: np.ndarray, normal, d: float, half: float):
    """The parts of the triangles ``(V, F)`` inside the slab, as triangles (vertices, faces)."""
    from trimesh.intersections import slice_faces_plane

    h = V @ normal - d
    # The faces' least and largest h from their three corners (a min / max along the rows of
    # an (n, 3) array is ~20 times slower than the two element-wise ones).
    h0, h1, h2 = h[F[:, 0]], h[F[:, 1]], h[F[:, 2]]
    keep = np.flatnonzero((np.minimum(np.minimum(h0, h1), h2) <= half)
                          & (np.maximum(np.maximum(h0, h1), h2) >= -half))
    if keep.size == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), int)
    used, F1 = np.unique(F[keep], return_inverse=True)
    V1, F1 = V[used], F1.reshape(-1, 3)
    V1, F1 = slice_faces_plane(V1, F1, plane_normal=-normal, plane_origin=normal * (d + half))[:2]
    if len(F1):
        V1, F1 = slice_faces_plane(V1, F1, plane_normal=normal,
                                   plane_origin=normal * (d - half))[:2]
    return np.asarray(V1, float), np.asarray(F1, np.int64)


def _sample_triangles(tri: np.ndarray, step_mm: float) -> np.ndarray:
    """Points on triangles (m, 3, 3), every point of a triangle within ``step_mm`` of one.

    Rows parallel to each triangle's longest edge, ``≤ step`` apart, each sampled every
    ``≤ step``: the number of points follows the area (plus the perimeter), so long slivers
    (a flat face clipped to a thin slab) cost no more than their area.
    """
    if len(tri) == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    e = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]], axis=1)
    lens = np.linalg.norm(e, axis=2)
    k = np.argmax(lens, axis=1)                       # longest edge: vertices k, k+1
    idx = np.arange(len(tri))
    A, B, C = tri[idx, k], tri[idx, (k + 1) % 3], tri[idx, (k + 2) % 3]
    L = lens[idx, k]
    area2 = np.linalg.norm(np.cross(B - A, C - A), axis=1)
    hgt = np.where(L > 0, area2 / np.maximum(L, 1e-300), 0.0)
    n_rows = np.maximum(1, np.ceil(hgt / step_mm)).astype(np.int64)
    # Rows t = j / n_rows, j = 0..n_rows, from A + t (C − A) to B + t (C − B).
    tri_of_row = np.repeat(idx, n_rows + 1)
    first = np.cumsum(n_rows + 1) - (n_rows + 1)
    j = np.arange(tri_of_row.size) - np.repeat(first, n_rows + 1)
    t = j / n_rows[tri_of_row]
    m = np.ceil(L[tri_of_row] * (1.0 - t) / step_mm).astype(np.int64) + 1
    row_of_pt = np.repeat(np.arange(t.size), m)
    first_pt = np.cumsum(m) - m
    i = np.arange(row_of_pt.size) - np.repeat(first_pt, m)
    s = i / np.maximum(m[row_of_pt] - 1, 1)
    # Each row's ends once (the same numbers as point by point), then spread to its points.
    P0 = A[tri_of_row] + t[:, None] * (C[tri_of_row] - A[tri_of_row])
    P1 = B[tri_of_row] + t[:, None] * (C[tri_of_row] - B[tri_of_row])
    return P0[row_of_pt] + s[:, None] * (P1 - P0)[row_of_pt], tri_of_row[row_of_pt]


def slab_triangles(rig, shapes, *, max_bounces: int = 2) -> np.ndarray:
    """(m, 3, 3) triangles: every shape clipped to every slab of :func:`sheet_slabs`.

    Parameters
    ----------
    shapes : sequence of (vertices (n, 3) float, faces (k, 3) int)
        World millimetres.
    """
    allv = np.concatenate([np.asarray(v, float) for v, _ in shapes]) if shapes else np.zeros((0, 3))
    slabs = sheet_slabs(rig, allv, max_bounces)
    tris = [np.zeros((0, 3, 3))]
    for V, F in shapes:
        V, F = np.asarray(V, float), np.asarray(F, np.int64)
        for normal, d, half in slabs:
            Vc, Fc = _clip_to_slab(V, F, normal, d, half)
            if len(Fc):
                tris.append(Vc[Fc])
    return np.concatenate(tris)


def slab_points(tris: np.ndarray, *, step_mm: float, return_normals: bool = False):
    """Points, ``≤ step_mm`` apart, covering the triangles ``tris`` (m, 3, 3) (from
    :func:`slab_triangles`): every point of a triangle lies within ``0.71 step_mm`` of one.

    With ``return_normals``, also the (n, 3) unit normal of each point's triangle (by its
    vertex order, as the renderer's face normals; NaN for a degenerate triangle)."""
    if not step_mm > 0:
        raise ValueError(f"step_mm must be > 0, got {step_mm!r}")
    t = np.asarray(tris, float).reshape(-1, 3, 3)
    P, tri_index = _sample_triangles(t, step_mm)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
    N = n[tri_index]
    if len(P):
        # Neighbouring triangles sample their shared edges twice: keep one point per cube of
        # side step/4 (a dropped point lies within step/4·√3 < 0.44 step of a kept one) and
        # per facing (normals in bins of 0.25: a point of a face turned away from a view
        # never stands in for one of a face turned towards it).
        _, first = np.unique(_cell_keys(P, N, 0.25 * step_mm), return_index=True)
        keep = np.sort(first)
        P, N = P[keep], N[keep]
    return (P, N) if return_normals else P


def _cell_keys(P: np.ndarray, N: np.ndarray, cell_mm: float) -> np.ndarray:
    """(n,) int64: one key per (cube of side ``cell_mm``, normal bin of 0.25 per component)
    of the points ``P`` with unit normals ``N`` (NaN: a bin of its own); equal keys, same cell
    and bin.  Computed on the components as rows (column reductions of (n, 3) are slow)."""
    c = np.floor(np.ascontiguousarray(P.T) / cell_mm).astype(np.int64)
    c -= c.min(axis=1, keepdims=True)
    d = c.max(axis=1) + 1
    q = np.floor(np.ascontiguousarray(N.T) * 4.0)
    q = np.where(np.isnan(q), 4.0, q).astype(np.int64) + 4       # 0 .. 8 (NaN: 8)
    if float(d[0]) * float(d[1]) * float(d[2]) * 729.0 >= 2.0 ** 62:  # a huge extent
        cq = np.concatenate([c, q]).T
        return np.unique(cq, axis=0, return_inverse=True)[1].reshape(-1)
    key = (c[0] * d[1] + c[1]) * d[2] + c[2]
    key *= 729
    key += q[0] * 81 + q[1] * 9 + q[2]
    return key


# ---------------------------------------------------------------------------------- blur
def blur_diameter_px(depth_mm, camera, *, scale: float = 1.0, thin_lens: bool = True) -> np.ndarray:
    """Diameter of the thin lens's circle of confusion, in pixels of the rendered film.

    ``c = (f / N) · f · |z − s_f| / (z (s_f − f))`` on the sensor for a point at depth ``z``
    along the optical axis (its path length for a mirror image), ``s_f`` the focus distance;
    0 for a pinhole.
    """
    z = np.asarray(depth_mm, float)
    if not thin_lens:
        return np.zeros_like(z)
    f, s_f = camera.focal_length_mm, camera.focus_distance_mm
    c_mm = camera.aperture_diameter_mm * f * np.abs(z - s_f) / (np.maximum(z, 1e-9) * (s_f - f))
    return c_mm / (camera.pixel_pitch_um * 1e-3) * float(scale)


# ------------------------------------------------------------------------------- supports
def _scene_shapes(spec) -> list[tuple[np.ndarray, np.ndarray]]:
    """Triangles of every non-mirror shape of a SceneSpec (meshes, targets, base plate)."""
    shapes = [(np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))
              for _, m, _ in spec.meshes]
    for board in spec.targets:
        T = np.asarray(board.rectangle_transform(), float)
        corners = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
        shapes.append((corners @ T[:3, :3].T + T[:3, 3], np.array([[0, 1, 2], [0, 2, 3]])))
    if spec.background_z_mm is not None:  # as scene_dict's base plate, 400 × 400 mm
        z = float(spec.background_z_mm)
        V = np.array([[-200, -200, z], [200, -200, z], [200, 200, z], [-200, 200, z]], float)
        shapes.append((V, np.array([[0, 1, 2], [0, 2, 3]])))
    return shapes


def _support_inputs(spec, scale: float, margin_px: float):
    """What a geometric or hull support starts from: the rig, its camera, the (scaled) film
    size, the scaled intrinsics and the scene's shapes; a negative margin refused."""
    if not margin_px >= 0:
        raise ValueError(f"margin_px must be >= 0, got {margin_px!r}")
    cam = spec.rig.camera
    return (spec.rig, cam, film_size(cam, scale), scale_intrinsics(cam.K, scale),
            _scene_shapes(spec))


def geometric_support(spec, *, scale: float = 1.0, max_bounces: int = 2, thin_lens: bool = True,
                      margin_px: float = MARGIN_PX) -> PixelSupport:
    """The pixels that can hold direct laser light in ``spec`` (module docstring), from geometry.

    Parameters
    ----------
    spec : lts360.simulator.scene.SceneSpec
    scale, max_bounces, thin_lens
        As the render's.
    margin_px : float, >= 0
        Added to each image point's blur radius.
    """
    rig, cam, (w, h), K, shapes = _support_inputs(spec, scale, margin_px)
    mask = np.zeros((h, w), bool)
    tris = slab_triangles(rig, shapes, max_bounces=max_bounces)
    if len(tris) == 0:
        return PixelSupport(mask=mask, method="geometric", margin_px=float(margin_px))
    # Sample spacing: SAMPLE_SPACING_PX at the nearest depth of a clipped vertex in any view.
    maps = [_compose(rig.mirrors, s) for s in _sequences(rig, max_bounces)]
    # Depth is affine in the point: its minimum over the clipped triangles' bounding box is
    # at a corner, and bounds theirs from below (finer spacing, never coarser).
    tv = tris.reshape(-1, 3)
    box = np.array(np.meshgrid(*zip(*_bounds(tv)))).reshape(3, -1).T
    zmin = min(_depth_range(box @ A.T + b, cam)[0] for A, b in maps)
    if not (math.isfinite(zmin) and all(np.all(world_to_camera(box @ A.T + b, cam.R, cam.t_mm)
                                                [:, 2] > 1e-6) for A, b in maps)):
        zmin = min(_depth_range(tv @ A.T + b, cam)[0] for A, b in maps)
    if not math.isfinite(zmin):
        return PixelSupport(mask=mask, method="geometric", margin_px=float(margin_px))
    pts, normals = slab_points(tris, step_mm=SAMPLE_SPACING_PX * zmin / K[0, 0],
                               return_normals=True)
    uv_all, r_all = [], []
    C = cam.center_mm
    # A ray through a mirror passes within the aperture's radius of the chief ray: a mirror
    # edge is blurred over that much (plus 1 mm).
    edge_mm = cam.aperture_diameter_mm + 1.0 if thin_lens else 1.0
    no_normal = np.isnan(normals[:, 0])
    # n · (c − p) and |c − p|² for every view's camera c from n · p and |p|², computed once.
    n_dot_p = np.einsum("ij,ij->i", normals, pts)
    p_dot_p = np.einsum("ij,ij->i", pts, pts)
    for seq, (A, b) in zip(_sequences(rig, max_bounces), maps):
        # One-sided surfaces (no BSDF here is two-sided): a point seen from behind its face
        # holds no light for this view.  The pupil's rays reach up to ~1° around the chief
        # ray: keep faces down to BACKFACE_COS edge-on.  Tested where the points are, against
        # the camera centre unfolded by the view's mirrors (A is orthogonal: the angle and the
        # distance are those of the mirror image and the camera).
        c = A.T @ (C - b)
        dist2 = np.maximum(float(c @ c) - 2.0 * (pts @ c) + p_dot_p, 0.0)
        facing = normals @ c - n_dot_p > -BACKFACE_COS * np.sqrt(dist2)
        # The mirror checks and the projection on the points that face the view only (half of
        # them: a convex object turns half its section away).
        Xv = pts[facing | no_normal] @ A.T + b
        if seq:
            Xv = Xv[_through_mirrors(rig, seq, C, Xv, edge_mm)]
        Pc = world_to_camera(Xv, cam.R, cam.t_mm)
        front = Pc[:, 2] > 1e-6
        if not front.any():
            continue
        uv = project_camera_points(Pc[front], K, cam.distortion)
        r = 0.5 * blur_diameter_px(Pc[front, 2], cam, scale=scale, thin_lens=thin_lens) + margin_px
        ok = np.all(np.isfinite(uv), axis=1)
        uv_all.append(uv[ok])
        r_all.append(r[ok])
    if not uv_all:
        return PixelSupport(mask=mask, method="geometric", margin_px=float(margin_px))
    return PixelSupport(mask=_splat(np.concatenate(uv_all), np.concatenate(r_all), (h, w)),
                        method="geometric", margin_px=float(margin_px))


def _through_mirrors(rig, seq, C: np.ndarray, Xv: np.ndarray, edge_mm: float) -> np.ndarray:
    """(n,) bool: whether the straight line from the camera centre ``C`` to the mirror images
    ``Xv`` (n, 3) of sequence ``seq`` crosses each mirror of ``seq`` (unfolded) inside its
    rectangle grown by ``edge_mm``, in order, before the image.  Occlusion is not tested."""
    ok = np.ones(len(Xv), bool)
    d = Xv - C
    t_prev = np.zeros(len(Xv))
    for j, k in enumerate(seq):
        m = rig.mirrors[k]
        A, b = _compose(rig.mirrors, seq[:j])          # unfolds mirror k's plane
        Ai, bi = _compose(rig.mirrors, tuple(reversed(seq[:j])))
        n = A @ np.asarray(m.normal, float)
        c = A @ np.asarray(m.center_mm, float) + b
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((c - C) @ n) / den
        q = C + t[:, None] * d
        p = q @ Ai.T + bi - np.asarray(m.center_mm, float)
        u = np.abs(p @ np.asarray(m.u_axis, float))
        v = np.abs(p @ np.asarray(m.v_axis, float))
        ok &= (np.abs(den) > 1e-12) & (t > t_prev) & (t < 1.0) \
            & (u <= m.width_mm / 2 + edge_mm) & (v <= m.height_mm / 2 + edge_mm)
        t_prev = np.where(ok, t, t_prev)
    return ok


def _depth_range(P_world: np.ndarray, cam) -> tuple[float, float]:
    """Smallest and largest depth in front of the camera (``inf, -inf`` if none)."""
    z = world_to_camera(P_world, cam.R, cam.t_mm)[:, 2]
    z = z[z > 1e-6]
    return (float(z.min()), float(z.max())) if z.size else (math.inf, -math.inf)


def _splat(uv: np.ndarray, radius_px: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Mask of every pixel centre within ``radius_px`` of a point ``uv``: the points are rounded
    to their pixel, which moves them by ≤ √2/2 px, so each is dilated by the disk of radius
    ``radius_px + √2/2`` — the integer offsets ``(dx, dy)`` with ``dx² + dy² ≤ R²`` exactly
    (points grouped by ``⌊R²⌋``, which fixes the offsets, each group dilated once)."""
    import cv2

    h, w = shape
    R = radius_px + np.sqrt(0.5)
    key = np.floor(R * R + 1e-9).astype(np.int64)        # offsets have integer d²
    pad = math.isqrt(int(key.max())) + 1
    iu = np.rint(uv[:, 0]).astype(np.int64) + pad
    iv = np.rint(uv[:, 1]).astype(np.int64) + pad
    inside = (iu >= 0) & (iu < w + 2 * pad) & (iv >= 0) & (iv < h + 2 * pad)
    out = np.zeros((h + 2 * pad, w + 2 * pad), np.uint8)
    for k in np.unique(key[inside]).tolist():
        sel = inside & (key == k)
        rr = math.isqrt(k)
        d = np.arange(-rr, rr + 1)
        kernel = ((d[:, None] ** 2 + d[None, :] ** 2) <= k).astype(np.uint8)
        x0, x1 = max(0, iu[sel].min() - rr), min(out.shape[1], iu[sel].max() + rr + 1)
        y0, y1 = max(0, iv[sel].min() - rr), min(out.shape[0], iv[sel].max() + rr + 1)
        canvas = np.zeros((y1 - y0, x1 - x0), np.uint8)
        canvas[iv[sel] - y0, iu[sel] - x0] = 1
        out[y0:y1, x0:x1] |= cv2.dilate(canvas, kernel)
    return out[pad:pad + h, pad:pad + w].astype(bool)


def hull_support(spec, *, scale: float = 1.0, max_bounces: int = 2, thin_lens: bool = True,
                 margin_px: float = MARGIN_PX) -> PixelSupport:
    """Every pixel whose camera path can reach a shape: the support of any light that leaves a
    shape last (interreflections, glints carried by a mirror, the direct stripe too).

    Light the camera receives through ``≤ max_bounces`` mirror reflections left a non-delta
    surface last (the integrator renders no emitter directly; the mirrors are delta surfaces).
    So a pixel holds light only if its rays reach a shape through some view.  For each view
    (the camera direct and through every mirror sequence, unfolded as in
    :func:`geometric_support`; no mirror rectangle is tested: a superset), the shapes' vertices
    are seen in the pinhole's normalised coordinates, where the image of their convex hull is
    the 2-D convex hull of theirs (a straight projection maps a convex set onto a convex set);
    its outline, sampled every :data:`HULL_OUTLINE_STEP_PX`, is distorted and filled, then
    dilated by the largest defocus blur radius of the view's depths plus ``margin_px`` (+ √2/2
    for the fill's rounding).  A view in which any vertex lies at or behind the camera's plane
    makes the support the full frame.
    """
    import cv2

    rig, cam, (w, h), K, shapes = _support_inputs(spec, scale, margin_px)
    mask = np.zeros((h, w), np.uint8)
    if not shapes:
        return PixelSupport(mask=mask.astype(bool), method="hull", margin_px=float(margin_px))
    # The vertices as rows (3, n): each view's camera coordinates row by row (an (n, 3) @ (3, 3)
    # product goes through a threaded BLAS that costs ten times as much on a busy machine).
    Vt = np.ascontiguousarray(np.concatenate([v for v, _ in shapes]).T)
    R, t_cam = np.asarray(cam.R, float), np.asarray(cam.t_mm, float).reshape(3)
    for A, b in (_compose(rig.mirrors, s) for s in _sequences(rig, max_bounces)):
        M, c = R @ A, R @ b + t_cam                 # X_cam = M X + c of the unfolded point
        x, y, z = (M[i, 0] * Vt[0] + M[i, 1] * Vt[1] + M[i, 2] * Vt[2] + c[i] for i in range(3))
        if not z.min() > 1e-6:
            return full_support(cam, scale)
        xn = np.column_stack([x / z, y / z]).astype(np.float32)
        H = cv2.convexHull(xn)[:, 0, :].astype(float)               # (k, 2), in order
        E = np.roll(H, -1, axis=0) - H
        n = np.maximum(1, np.ceil(np.hypot(E[:, 0] * K[0, 0], E[:, 1] * K[1, 1])
                                  / HULL_OUTLINE_STEP_PX)).astype(np.int64)
        k = np.repeat(np.arange(len(H)), n)
        f = (np.arange(k.size) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
        outline = H[k] + f[:, None] * E[k]
        uv = project_camera_points(np.column_stack([outline, np.ones(len(outline))]), K,
                                   cam.distortion)
        view = np.zeros((h, w), np.uint8)
        cv2.fillPoly(view, [np.rint(uv * 16.0).astype(np.int32)], 1, lineType=cv2.LINE_8,
                     shift=4)
        blur = float(blur_diameter_px(np.array([z.min(), z.max()]), cam, scale=scale,
                                      thin_lens=thin_lens).max())
        r = 0.5 * blur + margin_px + math.sqrt(0.5)
        rr = int(math.floor(r))
        d = np.arange(-rr, rr + 1)
        kernel = ((d[:, None] ** 2 + d[None, :] ** 2) <= r * r).astype(np.uint8)
        mask |= cv2.dilate(view, kernel)
    return PixelSupport(mask=mask.astype(bool), method="hull", margin_px=float(margin_px))


def support_from_mask(lit: np.ndarray, *, margin_px: float, method: str) -> PixelSupport:
    """A support: the pixels ``lit`` (H, W) bool, dilated by a disk of ``margin_px``."""
    import cv2

    r = int(math.ceil(margin_px))
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    mask = cv2.dilate(np.asarray(lit, np.uint8), k).astype(bool) if r > 0 else np.asarray(lit, bool)
    return PixelSupport(mask=mask, method=method, margin_px=float(margin_px))


def pilot_support(spec, *, scale: float = 1.0, max_bounces: int = 2, thin_lens: bool = True,
                  spp: int = PILOT_SPP, seed: int = 0, threshold: float = PILOT_THRESHOLD,
                  margin_px: float = MARGIN_PX, prepared=None, max_scatter: int = 0
                  ) -> PixelSupport:
    """The pixels where a low-spp full-frame render of the real integrator shows laser light.

    For light the geometric support does not bound (an integrator that scatters the laser off
    a non-delta surface first): the support is every pixel whose laser radiance in a
    ``spp``-sample render exceeds ``threshold`` × its peak, dilated by ``margin_px`` plus the
    largest defocus blur radius of the scene's depths (a faint pixel the pilot's few samples
    missed next to a lit one is still covered; an isolated faint one may not be: raise
    ``spp`` for such light).  Costs a full-frame render at ``spp``.

    ``prepared`` : (scene, integrator) from :func:`lts360.simulator.render.prepare_scene`
    with the frame's arguments — the pilot then renders exactly that integrator, at that
    scene's sample count (its sampler's), not ``spp``.
    """
    from lts360.simulator.render import render_pixels

    cam = spec.rig.camera
    w, h = film_size(cam, scale)
    px = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).reshape(-1, 2)
    _, laser, _ = render_pixels(spec, px, spp=spp, seed=seed, scale=scale,
                                max_bounces=max_bounces, thin_lens=thin_lens, prepared=prepared,
                                max_scatter=max_scatter)
    laser = laser.reshape(h, w)
    peak = float(laser.max(initial=0.0))
    if peak <= 0:
        return PixelSupport(mask=np.zeros((h, w), bool), method="pilot", margin_px=float(margin_px))
    allv = np.concatenate([v for v, _ in _scene_shapes(spec)])
    zs = np.array([z for A, b in (_compose(spec.rig.mirrors, s)
                                  for s in _sequences(spec.rig, max_bounces))
                   for z in _depth_range(allv @ A.T + b, cam) if math.isfinite(z)])
    blur = float(blur_diameter_px(zs, cam, scale=scale, thin_lens=thin_lens).max(initial=0.0))
    return support_from_mask(laser > threshold * peak, margin_px=margin_px + 0.5 * blur,
                             method="pilot")

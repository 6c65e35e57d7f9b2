"""A measured section as a closed profile, the prism that extrudes it, and the exact radii of
that profile along the measurement's rays.

The profile is polar about the least-squares centre of the measured points: ``ρ(φ)`` on a
regular φ grid, each bin the mean of its points, a circular median then a moving average over
``smooth_deg``, gaps closed by periodic interpolation.  It is the twin's geometry: it must be
right to a few µm where the bias varies (millimetres), not to the noise of one point.

The points' own noise sets how far the profile is smoothed (:func:`section_profile`): their
robust scatter about the profile ``σ`` is estimated, points beyond ``4σ`` are dropped as
outliers, and the moving average is widened until it averages ``σ`` down to
``noise_target_um`` (at most ``max_smooth_deg``).  A noise-free image keeps ``smooth_deg``; on
a speckled one (σ ≈ 35 µm) a profile smoothed over 1° keeps ~30 µm of noise, a false form
whose slopes the twin renders as bias, and its correction then put the noise back into the
points (the plug-gauge study: std of the point radii 36.8 → 44.4 µm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

from lts360.geometry.fit import fit_circle

__all__ = ["SectionProfile", "section_profile", "NOISE_TARGET_UM", "MAX_SMOOTH_DEG", "prism_mesh", "ray_radii", "AxialForm",
           "axial_form", "loft_mesh", "view_offsets", "placed_profile"]


@dataclass(frozen=True, eq=False)
class SectionProfile:
    """A closed star-shaped section profile (measurement frame, mm).

    ``center_mm`` (2,); ``phi_rad`` (n,) regular on [0, 2π); ``rho_mm`` (n,) the distance from
    the centre; ``coverage`` the share of φ bins that held a measured point; ``largest_gap_deg``.
    """

    center_mm: np.ndarray
    phi_rad: np.ndarray
    rho_mm: np.ndarray
    coverage: float
    largest_gap_deg: float
    #: The points' robust scatter about the profile (µm), the smoothing it was given (°) and
    #: the points dropped as outliers.
    noise_um: float = float("nan")
    smooth_deg: float = float("nan")
    n_outliers: int = 0

    @property
    def vertices_mm(self) -> np.ndarray:
        """(n, 2) the polygon, counter-clockwise."""
        return self.center_mm + self.rho_mm[:, None] * np.column_stack(
            [np.cos(self.phi_rad), np.sin(self.phi_rad)])


def _largest_gap(filled: np.ndarray) -> int:
    """Longest circular run of False."""
    if filled.all():
        return 0
    if not filled.any():
        return filled.size
    k = int(np.argmax(filled))
    f = np.roll(filled, -k)  # starts on a filled bin
    idx = np.flatnonzero(f)
    return int(np.max(np.diff(np.append(idx, f.size)) - 1))


#: What the profile's moving average leaves of the points' noise (µm, white-noise estimate).
NOISE_TARGET_UM = 2.0
#: The widest smoothing of a noisy profile (°): the form a twin keeps from a noisy image.
MAX_SMOOTH_DEG = 30.0
#: Points farther from the profile than this many robust σ, and than ``OUTLIER_FLOOR_UM``, are
#: outliers of the profile (the floor keeps a noise-free image's points whose line-centre bias
#: moves them a few µm: they are the measurement's, the twin models them).
OUTLIER_SIGMA = 4.0
OUTLIER_FLOOR_UM = 10.0


def _polar(p: np.ndarray):
    c = fit_circle(p).center_mm
    d = p - c
    return c, np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi), np.hypot(d[:, 0], d[:, 1])


def _binned(phi, rho, n_bins: int, k_median: int, k_mean: int):
    """ρ on the regular grid: bin means, gaps interpolated, a circular median over
    ``k_median`` bins then a moving average over ``k_mean``; and the bins that held a point."""
    b = np.minimum((phi / (2 * np.pi) * n_bins).astype(np.int64), n_bins - 1)
    cnt = np.bincount(b, minlength=n_bins)
    mean = np.bincount(b, weights=rho, minlength=n_bins) / np.maximum(cnt, 1)
    grid = (np.arange(n_bins) + 0.5) * 2 * np.pi / n_bins
    filled = cnt > 0
    rho_b = np.interp(grid, grid[filled], mean[filled], period=2 * np.pi)
    rho_b = median_filter(rho_b, size=k_median | 1, mode="wrap")
    return grid, uniform_filter1d(rho_b, size=k_mean, mode="wrap"), filled


def section_profile(points_xy_mm, *, n_bins: int = 1440, smooth_deg: float = 1.0,
                    min_points: int = 50, noise_target_um: float | None = NOISE_TARGET_UM,
                    max_smooth_deg: float = MAX_SMOOTH_DEG) -> SectionProfile:
    """The closed profile of one section's measured points ``(k, 2)``.

    Smoothed over ``smooth_deg``, or wider where the points are noisy: the points' robust
    scatter ``σ`` about the ``smooth_deg`` profile (1.4826 · MAD) gives the width ``w`` over
    which the moving average leaves ``σ / √(points in w)`` ≤ ``noise_target_um``, within
    [``smooth_deg``, ``max_smooth_deg``]; points beyond 4σ (and 10 µm) are dropped first.
    ``noise_target_um=None``: ``smooth_deg`` as given, every point kept.

    Raises
    ------
    ValueError
        Fewer than ``min_points`` finite points.
    """
    p = np.asarray(points_xy_mm, float).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < min_points:
        raise ValueError(f"section profile: {len(p)} measured points, need {min_points}")
    if not 0 < smooth_deg <= 30:
        raise ValueError(f"smooth_deg must be in (0, 30], got {smooth_deg}")
    if not smooth_deg <= max_smooth_deg <= 90:
        raise ValueError(f"max_smooth_deg must be in [smooth_deg, 90], got {max_smooth_deg}")
    k = max(1, int(round(smooth_deg / 360.0 * n_bins)))
    c, phi, rho = _polar(p)
    grid, rho_m, _ = _binned(phi, rho, n_bins, k, 1)  # the median alone keeps a flank's step
    grid, rho_b, filled = _binned(phi, rho, n_bins, k, k)
    res = rho - np.interp(phi, grid, rho_m, period=2 * np.pi)
    sigma = float(1.4826 * np.median(np.abs(res - np.median(res))))
    width, n_out = float(smooth_deg), 0
    if noise_target_um is not None and sigma > 0:
        if not noise_target_um > 0:
            raise ValueError(f"noise_target_um must be > 0, got {noise_target_um}")
        keep = np.abs(res) <= max(OUTLIER_SIGMA * sigma, 1e-3 * OUTLIER_FLOOR_UM)
        if keep.sum() >= min_points and not keep.all():
            n_out = int((~keep).sum())
            c, phi, rho = _polar(p[keep])
            grid, rho_b, filled = _binned(phi, rho, n_bins, k, k)
        # Doubling the width while the profile still moves by more than the target: a noisy
        # profile changes everywhere (the robust rms of the change is its noise), a noise-free
        # one only at its sharp features (a groove's flank), which the median ignores.
        while width < max_smooth_deg:
            w2 = min(2.0 * width, max_smooth_deg)
            g2, rho_2, _ = _binned(phi, rho, n_bins, k, max(1, int(round(w2 / 360.0 * n_bins))))
            d = rho_b - rho_2
            if 1e3 * 1.4826 * np.median(np.abs(d - np.median(d))) <= noise_target_um:
                break
            width, rho_b = w2, rho_2
    return SectionProfile(center_mm=c, phi_rad=grid, rho_mm=rho_b,
                          coverage=float(filled.mean()),
                          largest_gap_deg=_largest_gap(filled) * 360.0 / n_bins,
                          noise_um=1e3 * sigma, smooth_deg=width, n_outliers=n_out)


def prism_mesh(profile: SectionProfile, *, half_length_mm: float = 30.0):
    """A watertight prism: the profile extruded along the measurement z over ±half_length_mm
    (outward normals)."""
    import trimesh

    v2 = profile.vertices_mm
    n = len(v2)
    bottom = np.column_stack([v2, np.full(n, -half_length_mm)])
    top = np.column_stack([v2, np.full(n, half_length_mm)])
    c = profile.center_mm
    verts = np.vstack([bottom, top, [[c[0], c[1], -half_length_mm], [c[0], c[1], half_length_mm]]])
    i = np.arange(n)
    j = (i + 1) % n
    cb, ct = 2 * n, 2 * n + 1
    faces = np.vstack([
        np.column_stack([i, j, n + j]),          # sides (counter-clockwise profile, +z up)
        np.column_stack([i, n + j, n + i]),
        np.column_stack([np.full(n, ct), n + i, n + j]),  # top cap, normal +z
        np.column_stack([np.full(n, cb), j, i]),           # bottom cap, normal −z
    ])
    return trimesh.Trimesh(vertices=verts, faces=faces, process=False)


@dataclass(frozen=True, eq=False)
class AxialForm:
    """How the surface runs along the axis about a section: ``ρ(φ, dz) = ρ(φ) + slope·dz +
    curvature·dz²/2`` on the profile's φ grid (radii from the section's own centre), valid for
    ``|dz| ≤ reach_mm``; ``dz_mm`` the neighbouring sections it was fitted to."""

    slope: np.ndarray
    curvature_per_mm: np.ndarray
    reach_mm: float
    dz_mm: tuple

    def rho_at(self, rho_mm: np.ndarray, dz_mm: float) -> np.ndarray:
        return rho_mm + self.slope * dz_mm + 0.5 * self.curvature_per_mm * dz_mm * dz_mm


def _robust_harmonics(phi: np.ndarray, y: np.ndarray, order: int, iters: int = 5) -> np.ndarray:
    """``y(φ)`` (NaN = none) by a Fourier series up to ``order``, fitted by iteratively
    reweighted least squares (Tukey's biweight at 4.685 robust σ), evaluated on ``phi``."""
    cols = [np.ones_like(phi)]
    for m in range(1, order + 1):
        cols += [np.cos(m * phi), np.sin(m * phi)]
    X = np.column_stack(cols)
    ok = np.isfinite(y)
    w = ok.astype(float)
    yy = np.where(ok, y, 0.0)
    beta = np.zeros(X.shape[1])
    for _ in range(iters):
        sw = np.sqrt(w)
        beta = np.linalg.lstsq(X * sw[:, None], yy * sw, rcond=None)[0]
        res = yy - X @ beta
        s = 1.4826 * np.median(np.abs(res[ok])) if ok.any() else 0.0
        if not s > 0:
            break
        u = res / (4.685 * s)
        w = np.where(ok & (np.abs(u) < 1), (1 - u * u) ** 2, 0.0)
    return X @ beta


def axial_form(profile: SectionProfile, neighbours, *, order: int = 2,
               reach_mm: float | None = None) -> AxialForm | None:
    """The axial form about ``profile`` from the neighbouring sections' profiles.

    Parameters
    ----------
    profile : SectionProfile
        The section's own profile (its ``dz`` is 0).
    neighbours : iterable of (dz_mm, SectionProfile)
        Other sections of the scan, ``dz`` their axial distance from this one (the same frame).
    order : int
        Slope and curvature are Fourier series in φ up to this order (0: a taper and a
        waviness, 1: a tilted or bent axis, 2: an oval that changes), fitted robustly to the
        per-φ solutions: a section's line-centre bias varies with φ (a glint), and a per-φ
        form would carry its difference between sections into the twin as a false slope.
    reach_mm : float, optional
        The largest ``|dz|`` the form is used over (default: the neighbours' largest).

    Per φ, each neighbour's radius along the ray from this section's centre gives
    ``ρ_j − ρ = slope·dz_j + curvature·dz_j²/2``, solved by least squares: with neighbours on
    both sides (or two distinct ``dz`` on one side) slope and curvature, with one neighbour the
    slope alone.  ``None`` without a usable neighbour.
    """
    rows, dzs = [], []
    for dz, prof in neighbours:
        dz = float(dz)
        if not np.isfinite(dz) or dz == 0:
            continue
        r = ray_radii(prof.vertices_mm - profile.center_mm, profile.phi_rad)
        if np.isfinite(r).mean() < 0.9:
            continue
        rows.append(r - profile.rho_mm)
        dzs.append(dz)
    if not rows:
        return None
    d = np.array(rows)  # (m, n)
    dz = np.array(dzs)
    quad = np.unique(np.round(dz, 9)).size >= 2
    A = np.column_stack([dz, 0.5 * dz * dz]) if quad else dz[:, None]
    ok = np.isfinite(d)
    d = np.where(ok, d, 0.0)
    # per φ a small weighted least squares (weights 0 where a neighbour's ray missed)
    W = ok.T.astype(float)  # (n, m)
    AtA = np.einsum("nm,mi,mj->nij", W, A, A)
    Atb = np.einsum("nm,mi,mn->ni", W, A, d)
    det_ok = np.abs(np.linalg.det(AtA)) > 1e-12
    coef = np.zeros((profile.rho_mm.size, A.shape[1]))
    coef[det_ok] = np.linalg.solve(AtA[det_ok], Atb[det_ok][..., None])[..., 0]
    if not 0 <= int(order) <= 8:
        raise ValueError(f"axial_form: order must be in [0, 8], got {order}")
    phi = profile.phi_rad
    coef[~det_ok] = np.nan
    slope = _robust_harmonics(phi, coef[:, 0], int(order))
    curv = _robust_harmonics(phi, coef[:, 1], int(order)) if quad else np.zeros_like(slope)
    reach = float(np.max(np.abs(dz))) if reach_mm is None else float(reach_mm)
    return AxialForm(slope=slope, curvature_per_mm=curv, reach_mm=reach,
                     dz_mm=tuple(float(v) for v in dz))


def _ring_offsets(reach_mm: float, half_length_mm: float, fine_mm: float = 0.02,
                  fine_reach_mm: float = 1.0, coarse_mm: float = 0.1) -> np.ndarray:
    """Axial positions of a loft's rings: ``fine_mm`` apart within ``±fine_reach_mm`` (the
    sheet's width), ``coarse_mm`` to ``±reach_mm``, then the ends ``±half_length_mm``."""
    f = min(fine_reach_mm, reach_mm)
    fine = np.linspace(-f, f, 2 * max(1, int(np.ceil(f / fine_mm))) + 1)
    out = [fine]
    if reach_mm > f:
        n = max(1, int(np.ceil((reach_mm - f) / coarse_mm)))
        side = np.linspace(f, reach_mm, n + 1)[1:]
        out += [side, -side]
    out.append(np.array([-half_length_mm, half_length_mm]))
    return np.unique(np.concatenate(out))


def loft_mesh(profile: SectionProfile, form: AxialForm | None = None, *,
              half_length_mm: float = 30.0):
    """A watertight tube through the section: the profile carried along the axis by ``form``
    within its reach and straight beyond it (``form = None``: the straight prism), closed by
    flat caps at ``±half_length_mm`` (outward normals)."""
    import trimesh

    if form is None:
        return prism_mesh(profile, half_length_mm=half_length_mm)
    reach = min(form.reach_mm, 0.5 * half_length_mm)
    zs = _ring_offsets(reach, half_length_mm)
    u = np.column_stack([np.cos(profile.phi_rad), np.sin(profile.phi_rad)])
    n = profile.rho_mm.size
    rings = []
    for z in zs:
        rho = form.rho_at(profile.rho_mm, float(np.clip(z, -reach, reach)))
        rings.append(np.column_stack([profile.center_mm + rho[:, None] * u, np.full(n, z)]))
    m = zs.size
    c = profile.center_mm
    verts = np.vstack(rings + [[[c[0], c[1], zs[0]], [c[0], c[1], zs[-1]]]])
    i = np.arange(n)
    j = (i + 1) % n
    quads = []
    for r in range(m - 1):
        a, b = r * n, (r + 1) * n
        quads.append(np.column_stack([a + i, a + j, b + j]))
        quads.append(np.column_stack([a + i, b + j, b + i]))
    cb, ct = m * n, m * n + 1
    top = (m - 1) * n
    faces = np.vstack(quads + [np.column_stack([np.full(n, ct), top + i, top + j]),
                               np.column_stack([np.full(n, cb), j, i])])
    return trimesh.Trimesh(vertices=verts, faces=faces, process=False)


def ray_radii(vertices_mm, theta_rad, near_mm=None) -> np.ndarray:
    """Where the rays from the origin at angles ``theta_rad`` cross the closed polygon
    ``vertices_mm`` (n, 2): the distance along each ray, the crossing nearest ``near_mm``
    (per ray; default: the farthest; a tie goes to the first edge).  NaN for a ray that
    crosses nothing.

    Each edge is tested only against the rays within the angle it subtends at the origin (a
    wider one, or an edge through the origin, against every ray): O(rays + edges + crossings)
    instead of every ray against every edge, with the same arithmetic on the pairs tested."""
    v = np.asarray(vertices_mm, float).reshape(-1, 2)
    e = np.roll(v, -1, axis=0) - v
    th = np.asarray(theta_rad, float).ravel()
    ray, edge = _ray_edge_pairs(v, th)
    u = np.column_stack([np.cos(th), np.sin(th)])[ray]
    ve, ee = v[edge], e[edge]
    pxe = ve[:, 0] * ee[:, 1] - ve[:, 1] * ee[:, 0]
    uxe = u[:, 0] * ee[:, 1] - u[:, 1] * ee[:, 0]
    pxu = ve[:, 0] * u[:, 1] - ve[:, 1] * u[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = pxe / uxe
        s = pxu / uxe
    hit = (uxe != 0) & (s >= 0) & (s < 1) & (t > 0)
    ray, edge, t = ray[hit], edge[hit], t[hit]
    out = np.full(th.size, np.nan)
    if near_mm is None:
        best = np.full(th.size, -np.inf)
        np.maximum.at(best, ray, t)
        out = np.where(np.isfinite(best), best, np.nan)
    elif ray.size:
        near = np.broadcast_to(np.asarray(near_mm, float), th.shape)
        order = np.lexsort((edge, np.abs(t - near[ray]), ray))
        first = order[np.r_[True, ray[order][1:] != ray[order][:-1]]]
        out[ray[first]] = t[first]
    out[~np.isfinite(out)] = np.nan
    return out


def _ray_edge_pairs(v: np.ndarray, th: np.ndarray, *, pad_rad: float = 1e-9,
                    wide_rad: float = 0.5 * np.pi) -> tuple[np.ndarray, np.ndarray]:
    """(ray, edge) index pairs of :func:`ray_radii` to test: each edge ``v[i] → v[i+1]`` with
    the rays whose angle lies within the angle the edge subtends at the origin (± ``pad_rad``);
    an edge subtending more than ``wide_rad`` or touching the origin with every ray.  Rays
    with a NaN angle pair with nothing (they cross nothing)."""
    a0 = np.arctan2(v[:, 1], v[:, 0])
    span = np.angle(np.exp(1j * (np.roll(a0, -1) - a0)))  # the subtended angle, (−π, π]
    lo = a0 + np.minimum(span, 0.0) - pad_rad
    hi = lo + np.abs(span) + 2.0 * pad_rad
    odd = ~np.all(np.isfinite(v), axis=1) | np.all(v == 0.0, axis=1)  # at the origin, or NaN
    wide = (np.abs(span) > wide_rad) | odd | np.roll(odd, -1) | ~np.isfinite(span)
    tw = np.mod(th + np.pi, 2.0 * np.pi) - np.pi  # [−π, π); NaN stays NaN (sorted last)
    order = np.argsort(tw, kind="stable")
    ts = tw[order]
    n_ok = int(np.count_nonzero(np.isfinite(ts)))
    ts = ts[:n_ok]
    rays, edges = [], []
    # each narrow edge's interval, split where it wraps past ±π
    narrow = np.flatnonzero(~wide)
    lo_w = np.mod(lo[narrow] + np.pi, 2.0 * np.pi) - np.pi
    hi_w = lo_w + (hi[narrow] - lo[narrow])
    for start, stop in ((lo_w, np.minimum(hi_w, np.pi)), (lo_w - 2.0 * np.pi, hi_w - 2.0 * np.pi)):
        i0 = np.searchsorted(ts, start, side="left")
        i1 = np.searchsorted(ts, stop, side="right")
        count = np.maximum(i1 - i0, 0)
        total = int(count.sum())
        if total:
            edge = np.repeat(narrow, count)
            offset = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
            rays.append(order[np.repeat(i0, count) + offset])
            edges.append(edge)
    for i in np.flatnonzero(wide):
        rays.append(order[:n_ok])
        edges.append(np.full(n_ok, i))
    if not rays:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    return np.concatenate(rays), np.concatenate(edges)


#: Rays a shared curve's slope is taken over (median), and the steepest incidence of a ray on
#: it (the views measure up to ~70° of incidence) in :func:`view_offsets`.
SLOPE_RAYS = 11
MAX_INCIDENCE_DEG = 75.0


def _ray_jacobian(theta: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(n, 2): how the radius along each ray from the origin moves when the curve ``r(θ)`` is
    translated by ``t`` (first order): ``∂r/∂t = u − (r′/r) w``, ``u`` the ray's direction and
    ``w`` its normal (``n ∝ r u − r′ w`` is the curve's normal; ``Δr = (n·t)/(n·u)``)."""
    u = np.column_stack([np.cos(theta), np.sin(theta)])
    w = np.column_stack([-np.sin(theta), np.cos(theta)])
    if r.size < 2:
        return u
    # the slope of the curve, not of a spike: a median over SLOPE_RAYS rays first, and the
    # ray's incidence on the curve kept below MAX_INCIDENCE_DEG
    r_m = median_filter(r, size=min(SLOPE_RAYS, r.size) | 1, mode="nearest")
    k = np.clip(np.gradient(r_m, theta) / r_m, -np.tan(np.radians(MAX_INCIDENCE_DEG)),
                np.tan(np.radians(MAX_INCIDENCE_DEG)))
    return u - k[:, None] * w


def view_offsets(theta_rad, radii_mm: dict, *, min_overlap: int = 10, ridge: float = 1e-3,
                 iters: int = 5) -> dict:
    """Per view the translation (mm, in the rays' plane) that best aligns the views where
    they measured the same rays.

    Parameters
    ----------
    theta_rad : (n,) float
        The rays (from the origin), increasing.
    radii_mm : dict name -> (n,) float
        Each view's radius along the rays, NaN where it has none.
    min_overlap : int
        A pair of views sharing fewer rays than this does not count.
    ridge : float
        Weight (per ray, relative) pulling each translation towards 0: it fixes what the
        overlaps leave free (their common translation, and a component along a short overlap).
    iters : int
        Reweighting passes (Tukey's biweight at 4.685 robust σ).

    For views ``a``, ``b`` and every shared ray, ``r_b − r_a = J·(t_b − t_a)`` with ``J`` the
    ray's Jacobian (:func:`_ray_jacobian`, from the pair's mean curve), solved jointly by
    robust least squares with the ridge: the minimum-norm solution has ``Σ t = 0``.  A view
    without a shared ray keeps ``t = 0``.  Exact for data that follow the linear model; a
    translated circle about the origin is recovered to ``O(|t|² / R)``.
    """
    th = np.asarray(theta_rad, float).ravel()
    names = list(radii_mm)
    m = 2 * len(names)
    blocks, rhs = [], []
    for i, a in enumerate(names):
        ra = np.asarray(radii_mm[a], float).ravel()
        for b in names[i + 1:]:
            rb = np.asarray(radii_mm[b], float).ravel()
            both = np.isfinite(ra) & np.isfinite(rb)
            if both.sum() < max(int(min_overlap), 3):
                continue
            mean = np.where(both, 0.5 * (ra + rb), np.nan)
            J = np.full((th.size, 2), np.nan)
            idx = np.flatnonzero(both)
            # the slope along each run of shared rays (a gap's two sides are not neighbours)
            for run in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
                J[run] = _ray_jacobian(th[run], mean[run])
            A = np.zeros((idx.size, m))
            A[:, 2 * names.index(b):2 * names.index(b) + 2] = J[idx]
            A[:, 2 * i:2 * i + 2] = -J[idx]
            blocks.append(A)
            rhs.append(rb[idx] - ra[idx])
    if not blocks:
        return {n: np.zeros(2) for n in names}
    A, y = np.vstack(blocks), np.concatenate(rhs)
    lam = np.sqrt(float(ridge) * len(y) / m)
    w = np.ones_like(y)
    x = np.zeros(m)
    for _ in range(int(iters)):
        sw = np.sqrt(w)
        x = np.linalg.lstsq(np.vstack([A * sw[:, None], lam * np.eye(m)]),
                            np.concatenate([y * sw, np.zeros(m)]), rcond=None)[0]
        res = y - A @ x
        s = 1.4826 * np.median(np.abs(res - np.median(res)))
        if not s > 0:
            break
        q = res / (4.685 * s)
        w = np.where(np.abs(q) < 1, (1 - q * q) ** 2, 0.0)
    return {n: x[2 * k:2 * k + 2].copy() for k, n in enumerate(names)}


#: A view's point farther than this many robust σ (and this many µm) from its first fit does
#: not bend its placed profile (a spike); a plain least-squares fit otherwise: a view's own
#: points near its arc's ends depart most (grazing incidence), and a robust weighting that
#: dropped them moved the perturbed calibration's right-view correction by +0.3 µm.
PLACED_OUTLIER_SIGMA = 6.0
PLACED_OUTLIER_FLOOR_UM = 30.0


def placed_profile(profile: SectionProfile, own_points_mm, offset_mm, *, degree: int = 4,
                   min_points: int = 50) -> SectionProfile:
    """The section where one view measured it: ``profile`` (all views' points, aligned) moved
    by the view's offset (:func:`view_offsets`) and bent by the view's own points' smooth
    departure from it.

    The departure is the radial distance of ``own_points_mm`` (k, 2) from the moved profile,
    fitted by a polynomial of ``degree`` in φ over the view's own arc (least squares, spikes
    beyond :data:`PLACED_OUTLIER_SIGMA` dropped) and held at the arc's ends beyond it.  A calibration's error
    maps a section smoothly (a mirror plane off moves, tilts and slightly stretches its view's
    points), which this carries; the view's point-scale ripple (a shiny surface's glints,
    render noise) is its own bias, which a twin must not carry (on the wavy alu pipe a twin
    made of each view's own points raised the corrected section's scatter by ~10 %).  With
    fewer than ``min_points`` own points the profile is only moved.
    """
    c = np.asarray(profile.center_mm, float) + np.asarray(offset_mm, float).reshape(2)
    p = np.asarray(own_points_mm, float).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    bend = np.zeros_like(profile.rho_mm)
    if len(p) >= max(int(min_points), int(degree) + 2):
        d = p - c
        phi = np.arctan2(d[:, 1], d[:, 0])
        res = np.hypot(d[:, 0], d[:, 1]) - np.interp(np.mod(phi, 2 * np.pi), profile.phi_rad,
                                                     profile.rho_mm, period=2 * np.pi)
        mid = float(np.angle(np.mean(np.exp(1j * phi))))
        x = np.angle(np.exp(1j * (phi - mid))) / np.pi  # in [-1, 1] about the arc's middle
        X = np.vander(x, int(degree) + 1)
        keep = np.ones(res.shape, bool)
        for _ in range(2):  # a fit, then again without the gross outliers
            beta = np.linalg.lstsq(X[keep], res[keep], rcond=None)[0]
            r = res - X @ beta
            s = 1.4826 * np.median(np.abs(r - np.median(r)))
            keep = np.abs(r) <= max(PLACED_OUTLIER_SIGMA * s, 1e-3 * PLACED_OUTLIER_FLOOR_UM)
            if keep.all() or keep.sum() < X.shape[1] + 1:
                break
        xg = np.clip(np.angle(np.exp(1j * (profile.phi_rad - mid))) / np.pi, x.min(), x.max())
        bend = np.vander(xg, int(degree) + 1) @ beta
    return SectionProfile(center_mm=c, phi_rad=profile.phi_rad, rho_mm=profile.rho_mm + bend,
                          coverage=profile.coverage, largest_gap_deg=profile.largest_gap_deg,
                          noise_um=profile.noise_um, smooth_deg=profile.smooth_deg,
                          n_outliers=profile.n_outliers)

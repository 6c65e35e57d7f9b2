"""Inverse triangulation of one section (paper §3.2) — the pure-numpy reference path.

Pipeline, one function per stage (so that a faster backend can replace any of them and be
tested against these):

1. :func:`plan_inverse` — per view, the θ window (:func:`lts360.recon.triangulation.views.view_windows`) and
   the projection of the windowed cylindrical grid (:func:`project_grid`, paper Eq. 4:
   ``g = P · T_view · T_cam_meas · G``, with distortion); optionally a precomputed
   :class:`~lts360.recon.triangulation.interp.CubicSampler` (the projection is the same for every image of a
   scan);
2. :func:`sample_profiles` — bicubic sampling of the image along every radial direction (Keys
   by default, cubic B-spline on request: :mod:`lts360.recon.triangulation.interp`);
3. :func:`lts360.recon.triangulation.peaks.detect_peaks` — one line centre per radial direction;
4. :func:`assemble_view` — radius, flags and points per θ, residual compensation (§4.4).

:func:`inverse_triangulate` runs all four; :func:`estimate_view_offsets` computes the §4.4
compensation from a result.

Fusion of overlapping views (:class:`InverseResult`): the labelled cloud keeps every valid
point of every view; the per-θ fused radius is the mean of the views valid at that θ weighted
by their peak intensity (a brighter line has the better signal-to-noise ratio).

This module imports no ground truth: it runs on real images and real calibration files.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from lts360.geometry.fit import fit_circle
from lts360.recon.images import default_saturation, default_threshold
from lts360.recon.model import Calibration
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.interp import INTERPOLATIONS, CubicSampler, sample_cubic
from lts360.recon.triangulation.peaks import PeakResult, Quality, detect_peaks
from lts360.recon.triangulation.views import (
    DEFAULT_MAX_INCIDENCE_DEG,
    DIRECT,
    View,
    get_views,
    project_meas_points,
    seen_through_mirrors,
    view_windows,
)
from lts360.recon.view_points import raw_view_points

__all__ = ["ViewPlan", "InversePlan", "ViewResult", "FusedCloud", "InverseResult",
           "plan_inverse", "plan_pixels", "project_grid", "sample_profiles", "assemble_view", "compensation_of",
           "inverse_triangulate", "recompensated", "estimate_view_offsets", "DEFAULT_ACCEPT",]

#: Qualities whose radius is kept: a saturated line still has a usable centre; a profile with
#: a second comparable peak is ambiguous and dropped.
DEFAULT_ACCEPT = (Quality.FOUND, Quality.SATURATED)


# -- stage 1: plan -----------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ViewPlan:
    """Projection of one view's windowed grid.

    Attributes
    ----------
    view : View
    window : (nθ,) bool
        θ of the grid this view measures.
    theta_index : (k,) int
        ``flatnonzero(window)``.
    uv : (k, nr, 2) float
        Pixel coordinates of the windowed grid points.
    sampler : CubicSampler or None
        Precomputed sampling of ``uv`` (see :func:`plan_inverse`).
    interpolation : {"keys", "bspline"}
    """

    view: View
    window: np.ndarray
    theta_index: np.ndarray
    uv: np.ndarray
    sampler: CubicSampler | None
    interpolation: str = "keys"


@dataclass(frozen=True, eq=False)
class InversePlan:
    """Everything of an inverse triangulation that does not depend on the image."""

    cal: Calibration
    grid: CylGrid
    views: dict[str, ViewPlan]
    interpolation: str = "keys"

    @property
    def nbytes(self) -> int:
        return int(sum(vp.uv.nbytes + (vp.sampler.nbytes if vp.sampler else 0)
                       for vp in self.views.values()))


def project_grid(cal: Calibration, grid: CylGrid, view: View, theta_index=None) -> np.ndarray:
    """Pixels of the grid points in a view (paper Eq. 4).

    Parameters
    ----------
    cal : Calibration
    grid : CylGrid
    view : View
    theta_index : (k,) int or (nθ,) bool, optional
        Rows of the grid to project (all by default).

    Returns
    -------
    (k, nr, 2) float
        ``(u, v)``; NaN behind the (virtual) camera.
    """
    return project_meas_points(grid.points_meas(theta_index), cal, view)


def _resolve_windows(cal, grid, views, windows, max_incidence_deg) -> dict[str, np.ndarray]:
    n = grid.n_theta
    if windows is None:
        return view_windows(cal, (grid.r_mm[0] + grid.r_shift_mm, grid.r_mm[-1] + grid.r_shift_mm),
                            grid.theta_rad, max_incidence_deg, views=views)
    if isinstance(windows, str):
        if windows != "all":
            raise ValueError(f"windows must be None (derive), 'all' or a mapping, got {windows!r}")
        return {v.name: np.ones(n, dtype=bool) for v in views}
    if not isinstance(windows, Mapping):
        raise ValueError("windows must be None (derive), 'all' or a mapping view -> (nθ,) bool")
    out = {}
    for v in views:
        if v.name not in windows:
            raise ValueError(f"windows: no window for view {v.name!r}")
        mask = np.asarray(windows[v.name])
        if mask.shape != (n,) or mask.dtype != bool:
            raise ValueError(f"windows[{v.name}]: must be a bool array of shape ({n},), got "
                             f"{mask.dtype} {mask.shape}")
        out[v.name] = mask
    return out


def _mask_unseen(cal: Calibration, grid: CylGrid, view: View, idx: np.ndarray,
                 uv: np.ndarray) -> np.ndarray:
    """``uv`` with NaN where :func:`seen_through_mirrors` fails.

    Along one ray the points seen inside a mirror's (convex) extent form an interval, so the
    test runs at both ends and the middle of every row first and on every sample only of the
    rows where one of those fails (~0.4 % of the cost of testing every point when nothing is
    cut).  A mirror's edge is then exact; another mirror crossing the middle of a row whose
    three tested points all pass would be missed.
    """
    if idx.size == 0:
        return uv
    th = grid.theta_rad[idx]
    radii = grid.radii_mm(idx)
    probe = radii[:, [0, grid.n_r // 2, grid.n_r - 1]]
    pts = np.stack([probe * np.cos(th)[:, None], probe * np.sin(th)[:, None],
                    np.zeros_like(probe)], axis=-1)
    rows = np.flatnonzero(~seen_through_mirrors(cal, view, pts).all(axis=1))
    if rows.size == 0:
        return uv
    seen = seen_through_mirrors(cal, view, grid.points_meas(idx[rows]))
    uv = uv.copy()
    uv[rows] = np.where(seen[..., None], uv[rows], np.nan)
    return uv


def plan_inverse(cal: Calibration, grid: CylGrid, *, views=None, windows=None,
                 max_incidence_deg: float = DEFAULT_MAX_INCIDENCE_DEG, precompute: bool = True,
                 weights_dtype=np.float32, interpolation: str = "keys",
                 mirror_edges: bool = True) -> InversePlan:
    """Windows and projections of every view, optionally with precomputed samplers.

    Parameters
    ----------
    cal : Calibration
    grid : CylGrid
    views : sequence of str, optional
        Default: ``("direct", *mirror names)``; double reflections by name (``"left-right"``).
    windows : None, "all" or mapping str → (nθ,) bool
        ``None`` derives them from the calibration (:func:`view_windows`); ``"all"`` uses every θ.
    max_incidence_deg : float
        For derived windows.
    precompute : bool
        Build a :class:`CubicSampler` per view: 69 bytes per windowed grid point with
        ``float32`` weights, plus 16 for the stored ``uv`` (≈ 0.3 GB for the standard
        0.1° × 5 µm × ±2 mm grid in three views, 3.5 M points), in exchange for sampling each
        image in one gather (≈ 0.16 s instead of ≈ 0.6 s per image for the whole pipeline).
    weights_dtype : numpy float dtype
        Storage of the sampler weights (``float32``: relative rounding ~1e-7 of a sample).
    interpolation : {"keys", "bspline"}
        Keys cubic convolution (the paper's) or cubic B-spline interpolation: a smaller
        sub-pixel error of the line centre on a ~1 px wide line (3.2 → 2.4 µm rms on the
        rendered plug gauge) but more noise passed, and a prefilter of each image per view
        (~17 ms at 1280×1024) (:mod:`lts360.recon.triangulation.interp`).
    mirror_edges : bool
        Leave out (NaN) the grid points a mirror view cannot see because their path misses the
        mirror's known extent (:func:`seen_through_mirrors`).
    """
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    if not isinstance(cal, Calibration):
        raise ValueError(f"cal must be a Calibration, got {type(cal).__name__}")
    if not isinstance(grid, CylGrid):
        raise ValueError(f"grid must be a CylGrid, got {type(grid).__name__}")
    names = (DIRECT,) + cal.mirror_names if views is None else tuple(views)
    if not names:
        raise ValueError("views: at least one view is needed")
    view_list = get_views(cal, names)
    masks = _resolve_windows(cal, grid, view_list, windows, max_incidence_deg)
    w, h = cal.image_size
    plans = {}
    for v in view_list:
        idx = np.flatnonzero(masks[v.name])
        uv = project_grid(cal, grid, v, idx)
        if mirror_edges and v.mirrors:
            # Grid points beyond a mirror's edge are not seen in this view: NaN, so that a line
            # cut there is TRUNCATED rather than centred on what the image shows beyond.
            uv = _mask_unseen(cal, grid, v, idx, uv)
        sampler = CubicSampler.from_points(uv, (h, w), dtype=weights_dtype,
                                           interpolation=interpolation) if precompute else None
        plans[v.name] = ViewPlan(view=v, window=masks[v.name].copy(), theta_index=idx, uv=uv,
                                 sampler=sampler, interpolation=interpolation)
    return InversePlan(cal=cal, grid=grid, views=plans, interpolation=interpolation)


# -- stage 2: sampling -------------------------------------------------------------------------

#: plan_pixels per plan (a twin renders a section's pixels for every section of a plan).
_PLAN_PIXELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def plan_pixels(plan: InversePlan, *, margin_px: int = 4) -> np.ndarray:
    """(n, 2) int ``(x, y)``: every pixel the plan's cubic samples read (the 4 × 4
    neighbourhood of each grid point's projection), widened by ``margin_px``, inside the
    image; row-major, each once.

    What a simulation must render for this plan to measure as it would on the full image
    (the margin keeps the pixels that speckle and defocus couple to the read ones)."""
    if margin_px < 0:
        raise ValueError(f"margin_px must be >= 0, got {margin_px}")
    cached = _PLAN_PIXELS.get(plan, {}).get(int(margin_px))
    if cached is not None:
        return cached.copy()
    w, h = plan.cal.image_size
    mask = np.zeros((h, w), bool)
    for vp in plan.views.values():
        uv = vp.uv.reshape(-1, 2)
        uv = uv[np.all(np.isfinite(uv), axis=1)]
        base = np.floor(uv).astype(np.int64)
        ok = (base[:, 0] >= -2) & (base[:, 0] < w + 1) & (base[:, 1] >= -2) & (base[:, 1] < h + 1)
        base = base[ok]
        mask[np.clip(base[:, 1], 0, h - 1), np.clip(base[:, 0], 0, w - 1)] = True
    # floor(u) - 1 ... floor(u) + 2, then the margin: a box of half-widths (1 + m, 2 + m)
    # about the marked pixel, made symmetric (one pixel more on the left and top).
    r = 2 + int(margin_px)
    from scipy.ndimage import maximum_filter1d

    # the square box as two 1-D passes (the same pixels, a tenth of the time)
    m = mask.view(np.uint8)
    for axis in (0, 1):
        m = maximum_filter1d(m, 2 * r + 1, axis=axis, mode="constant", cval=0)
    ys, xs = np.nonzero(m)
    out = np.column_stack([xs, ys])
    _PLAN_PIXELS.setdefault(plan, {})[int(margin_px)] = out
    return out.copy()


def sample_profiles(image: np.ndarray, view_plan: ViewPlan) -> np.ndarray:
    """Intensity profiles of one view: (k, nr) float, NaN where the grid leaves the image."""
    if view_plan.sampler is not None:
        return view_plan.sampler(image)
    return sample_cubic(image, view_plan.uv, interpolation=view_plan.interpolation)


# -- stage 4: assembly -------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ViewResult:
    """One view's measurement of the section, on the grid's θ.

    Attributes
    ----------
    name : str
    theta_rad : (nθ,) float
    r_mm : (nθ,) float
        Line-centre radius (compensated if :attr:`offset_mm` is non-zero); NaN where not valid.
    r_raw_mm : (nθ,) float
        Radius before compensation and before the ``accept`` filter (NaN where no peak).
    quality : (nθ,) uint8
        :class:`Quality`; ``OUTSIDE_WINDOW`` for θ outside the view's window.
    intensity : (nθ,) float
        Largest sample of the profile; NaN outside the window.
    window : (nθ,) bool
    offset_mm : (2,) float
        Residual compensation applied (zeros if none).
    second : (nθ,) float or None
        Largest sample of the profile's other runs above the threshold (NaN where there is
        none or outside the window; ``None`` where the detector did not say).
    """

    name: str
    theta_rad: np.ndarray
    r_mm: np.ndarray
    r_raw_mm: np.ndarray
    quality: np.ndarray
    intensity: np.ndarray
    window: np.ndarray
    offset_mm: np.ndarray
    second: np.ndarray | None = None

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.r_mm)

    @property
    def points_meas_mm(self) -> np.ndarray:
        """(nθ, 3) points ``(r cos θ, r sin θ, 0)`` (measurement frame); NaN where invalid."""
        return _points(self.theta_rad, self.r_mm)

    @property
    def raw_points_meas_mm(self) -> np.ndarray:
        """(nθ, 3) points from :attr:`r_raw_mm` (no compensation, no quality filter)."""
        return _points(self.theta_rad, self.r_raw_mm)


def _points(theta: np.ndarray, r: np.ndarray) -> np.ndarray:
    return np.stack([r * np.cos(theta), r * np.sin(theta), np.zeros_like(r)], axis=-1)


def _shift_on_rays(theta: np.ndarray, r: np.ndarray, offset: np.ndarray,
                   periodic: bool) -> np.ndarray:
    """Radii along the grid rays of the polyline of points ``r(θ)·u(θ)`` moved by ``offset``.

    Each grid ray ``θ_j`` is intersected with the segments joining consecutive valid points
    after translation (vectorised over a band of neighbouring segments wide enough for the
    shift).  Rays that meet no segment — at the ends of a valid run, where the shift moves the
    curve off them — get NaN.
    """
    n = theta.size
    if not np.any(offset) or n < 2:
        return r.copy()
    u = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    q = r[:, None] * u + offset
    valid = np.isfinite(r)
    if not valid.any():
        return r.copy()
    dtheta = float(np.min(np.diff(theta)))
    rmin = float(np.nanmin(r))
    m = int(np.ceil(np.linalg.norm(offset) / max(rmin * dtheta, 1e-12))) + 1
    m = min(m, n)
    k = np.arange(n)[:, None] + np.arange(-m, m + 1)[None, :]        # (n, 2m+1) segment starts
    if periodic:
        k0, k1 = k % n, (k + 1) % n
        seg_ok = np.ones_like(k, dtype=bool)
    else:
        seg_ok = (k >= 0) & (k + 1 < n)
        k0, k1 = np.clip(k, 0, n - 1), np.clip(k + 1, 0, n - 1)
    seg_ok &= valid[k0] & valid[k1]
    a, b = q[k0], q[k1]                                               # (n, 2m+1, 2)
    e = b - a
    uj = u[:, None, :]
    cross_ua = uj[..., 0] * a[..., 1] - uj[..., 1] * a[..., 0]
    cross_ue = uj[..., 0] * e[..., 1] - uj[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = -cross_ua / cross_ue
        s = np.einsum("jkc,jkc->jk", a + tau[..., None] * e, np.broadcast_to(uj, a.shape))
    hit = seg_ok & (tau >= -1e-12) & (tau <= 1 + 1e-12) & (s > 0)
    first = np.argmax(hit, axis=1)
    rows = np.arange(n)
    return np.where(hit[rows, first], s[rows, first], np.nan)


def compensation_of(cal: Calibration, name: str, compensate: bool) -> dict:
    """:func:`assemble_view`'s compensation keywords for view ``name``: the §4.4 translation
    (mirror views) and the mastering's radial offset and scale (every view); none unless
    ``compensate``."""
    if not compensate:
        return {}
    out = {"radial_offset_mm": float(cal.view_radial_offsets_mm.get(name, 0.0)),
           "scale": float(cal.view_scales.get(name, 1.0))}
    if name != DIRECT:
        out["offset_mm"] = np.asarray(cal.view_offsets_mm.get(name, np.zeros(2)), dtype=float)
    return out


def _compensated_radii(grid: CylGrid, r_raw: np.ndarray, quality: np.ndarray, accept,
                       offset_mm, radial_offset_mm: float, scale: float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """A view's ``r_mm`` from its raw radii: the accepted qualities kept, mastered
    (``scale·r + radial_offset_mm``), then translated by ``offset_mm`` and re-sampled on the
    grid's rays; and the offset as an array."""
    keep = np.isin(quality, np.asarray([int(q) for q in accept], dtype=np.uint8))
    r = np.where(keep, r_raw, np.nan)
    if radial_offset_mm != 0.0 or scale != 1.0:
        r = float(scale) * r + float(radial_offset_mm)
    offset = np.asarray(offset_mm, dtype=float).reshape(2)
    return _shift_on_rays(grid.theta_rad, r, offset, grid.is_full_turn), offset


def assemble_view(view_plan: ViewPlan, grid: CylGrid, peaks: PeakResult, *,
                  accept=DEFAULT_ACCEPT, offset_mm=(0.0, 0.0), radial_offset_mm: float = 0.0,
                  scale: float = 1.0) -> ViewResult:
    """Scatter a view's peaks onto the grid's θ, filter by quality, apply a compensation offset.

    Parameters
    ----------
    view_plan : ViewPlan
    grid : CylGrid
    peaks : PeakResult
        Of the windowed profiles (``len(view_plan.theta_index)`` entries).
    accept : sequence of Quality
        Qualities whose radius is kept in ``r_mm``.
    offset_mm : (2,) float
        Translation (measurement frame) of this view's points (paper §4.4); the compensated
        curve is re-sampled on the grid rays (:func:`_shift_on_rays`).
    radial_offset_mm, scale : float
        Mastering (``Calibration.view_radial_offsets_mm``, ``view_scales``): the radii become
        ``scale·r + radial_offset_mm`` before the translation.
    """
    n = grid.n_theta
    idx = view_plan.theta_index
    r_raw = np.full(n, np.nan)
    quality = np.full(n, Quality.OUTSIDE_WINDOW, dtype=np.uint8)
    intensity = np.full(n, np.nan)
    r_raw[idx] = peaks.r_mm + grid.r_shift_mm[idx]  # base radii -> this θ's band
    quality[idx] = peaks.quality
    intensity[idx] = peaks.intensity
    second = None
    if peaks.second is not None:
        second = np.full(n, np.nan)
        second[idx] = peaks.second
    r, offset = _compensated_radii(grid, r_raw, quality, accept, offset_mm, radial_offset_mm,
                                   scale)
    return ViewResult(name=view_plan.view.name, theta_rad=grid.theta_rad, r_mm=r, r_raw_mm=r_raw,
                      quality=quality, intensity=intensity, window=view_plan.window,
                      offset_mm=offset, second=second)


# -- results -----------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class FusedCloud:
    """All valid points of all views, labelled.

    Attributes
    ----------
    points_meas_mm : (m, 3) float
    theta_rad, r_mm, intensity : (m,) float
    view : (m,) int
        Index into ``view_names``.
    view_names : tuple of str
    """

    points_meas_mm: np.ndarray
    theta_rad: np.ndarray
    r_mm: np.ndarray
    intensity: np.ndarray
    view: np.ndarray
    view_names: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class InverseResult:
    """Inverse triangulation of one image.

    Attributes
    ----------
    grid : CylGrid
    views : dict str → ViewResult
    peak : str
        Detector used.
    threshold : float
    saturation : float or None
    compensated : bool
        Whether ``cal.view_offsets_mm`` was applied.
    accept : tuple of Quality
        Qualities kept as valid points.
    """

    grid: CylGrid
    views: dict[str, ViewResult]
    peak: str
    threshold: float
    saturation: float | None
    compensated: bool
    accept: tuple = DEFAULT_ACCEPT

    @property
    def theta_rad(self) -> np.ndarray:
        return self.grid.theta_rad

    @property
    def n_views(self) -> np.ndarray:
        """(nθ,) int: number of views with a valid point at each θ."""
        return np.sum([v.valid for v in self.views.values()], axis=0)

    @property
    def fused_r_mm(self) -> np.ndarray:
        """(nθ,) float: peak-intensity-weighted mean radius of the views valid at each θ.

        NaN where no view is valid.
        """
        r = np.stack([v.r_mm for v in self.views.values()])
        w = np.stack([np.where(v.valid, v.intensity, 0.0) for v in self.views.values()])
        w = np.where(np.isfinite(w) & (w > 0), w, 0.0)
        sw = w.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(sw > 0, np.nansum(w * np.nan_to_num(r), axis=0) / sw, np.nan)

    @property
    def fused_points_meas_mm(self) -> np.ndarray:
        """(nθ, 3) points of :attr:`fused_r_mm`."""
        return _points(self.grid.theta_rad, self.fused_r_mm)

    @property
    def coverage_deg(self) -> float:
        """Angle covered by at least one view (sum of the θ steps of covered samples)."""
        covered = self.n_views > 0
        if self.grid.n_theta < 2:
            return 0.0
        return float(np.degrees(covered.sum() * self.grid.theta_step_rad))

    def overlap_deg(self, view_a: str, view_b: str) -> float:
        both = self.views[view_a].valid & self.views[view_b].valid
        return float(np.degrees(both.sum() * self.grid.theta_step_rad))

    @property
    def cloud(self) -> FusedCloud:
        """Every valid point of every view with its view label."""
        names = tuple(self.views)
        parts = [(i, v, v.valid) for i, v in enumerate(self.views.values())]
        theta = np.concatenate([v.theta_rad[m] for _, v, m in parts])
        r = np.concatenate([v.r_mm[m] for _, v, m in parts])
        return FusedCloud(points_meas_mm=_points(theta, r), theta_rad=theta, r_mm=r,
                          intensity=np.concatenate([v.intensity[m] for _, v, m in parts]),
                          view=np.concatenate([np.full(m.sum(), i, dtype=np.int16)
                                               for i, _, m in parts]),
                          view_names=names)


# -- the whole pipeline ------------------------------------------------------------------------

def inverse_triangulate(image, cal: Calibration, grid: CylGrid, *, views=None, windows=None,
                        peak: str = "centroid", threshold: float | None = None,
                        saturation: float | None = None, accept=DEFAULT_ACCEPT,
                        compensate: bool = False, plan: InversePlan | None = None,
                        max_incidence_deg: float = DEFAULT_MAX_INCIDENCE_DEG,
                        peak_options: Mapping | None = None,
                        interpolation: str | None = None) -> InverseResult:
    """Measure the laser section in one image (paper §3.2).

    Parameters
    ----------
    image : (h, w) array
        Greyscale image of the size ``cal.image_size`` (any integer or float dtype).
    cal : Calibration
    grid : CylGrid
    views : sequence of str, optional
        Default ``("direct", *mirror names)``.  Ignored when ``plan`` is given.
    windows : None, "all" or mapping str → (nθ,) bool
        ``None`` derives them from the calibration.  Ignored when ``plan`` is given.
    peak : {"centroid", "gauss", "steger"}
    threshold : float, optional
        Default :func:`default_threshold`.
    saturation : float, optional
        Default :func:`default_saturation` (full scale of integer images).
    accept : sequence of Quality
        Qualities kept as valid points (default ``FOUND`` and ``SATURATED``).
    compensate : bool
        Translate each mirror view's points by ``cal.view_offsets_mm`` (paper §4.4).
    plan : InversePlan, optional
        From :func:`plan_inverse` with this very ``cal`` and ``grid``: reuses the projection
        and precomputed samplers across the images of a scan.
    max_incidence_deg : float
        For derived windows.
    peak_options : mapping, optional
        Extra keyword arguments of the detector (``second_peak_fraction``, ``fit``,
        ``line_width_mm``, ``sigma_mm``, ``subtract_threshold``, ...).
    interpolation : {"keys", "bspline"}, optional
        Sampling of the image (:func:`plan_inverse`); default: the plan's, or ``"keys"``.
    """
    img = np.asarray(image)
    w, h = cal.image_size
    if img.ndim != 2 or img.shape != (h, w):
        raise ValueError(f"image: must be a 2-D array of shape ({h}, {w}) (cal.image_size), "
                         f"got {img.shape}")
    if plan is None:
        plan = plan_inverse(cal, grid, views=views, windows=windows,
                            max_incidence_deg=max_incidence_deg, precompute=False,
                            interpolation="keys" if interpolation is None else interpolation)
    elif plan.cal is not cal or plan.grid is not grid:
        raise ValueError("plan: was built for another calibration or grid")
    elif interpolation is not None and interpolation != plan.interpolation:
        raise ValueError(f"interpolation: {interpolation!r} differs from the plan's "
                         f"{plan.interpolation!r}")
    thr = default_threshold(img) if threshold is None else float(threshold)
    sat = default_saturation(img) if saturation is None else float(saturation)
    if sat is not None and sat <= thr:
        sat = None  # a float image scaled below the threshold cannot saturate meaningfully
    options = dict(peak_options or {})
    results = {}
    for name, vp in plan.views.items():
        profiles = sample_profiles(img, vp)
        peaks = detect_peaks(peak, profiles, grid.r_mm, threshold=thr, saturation=sat, **options)
        results[name] = assemble_view(vp, grid, peaks, accept=accept,
                                      **compensation_of(cal, name, compensate))
    return InverseResult(grid=grid, views=results, peak=peak, threshold=thr, saturation=sat,
                         compensated=bool(compensate), accept=tuple(Quality(q) for q in accept))


def recompensated(result: InverseResult, cal: Calibration,
                  compensate: bool = True) -> InverseResult:
    """``result`` as :func:`inverse_triangulate` returns it for the same image and plan with
    ``cal`` and ``compensate``, where ``cal`` differs from the measured one only by its
    compensation (§4.4 offsets, mastering): the views' peaks are kept (their raw radii and
    qualities), only the compensation is applied anew (:func:`_compensated_radii`, as
    :func:`assemble_view` applies it).  For one image measured with several compensations of one
    calibration (the configurations of a Monte Carlo draw) without sampling it again."""
    views = {}
    for name, v in result.views.items():
        kw = compensation_of(cal, name, compensate)
        r, offset = _compensated_radii(result.grid, v.r_raw_mm, v.quality, result.accept,
                                       kw.get("offset_mm", (0.0, 0.0)),
                                       kw.get("radial_offset_mm", 0.0), kw.get("scale", 1.0))
        views[name] = replace(v, r_mm=r, offset_mm=offset)
    return replace(result, views=views, compensated=bool(compensate))


def estimate_view_offsets(result: InverseResult, *, reference: str = DIRECT,
                          min_points: int = 10) -> dict[str, np.ndarray]:
    """Residual compensation of paper §4.4 from the measurement of a round section.

    A circle is fitted (:func:`lts360.geometry.fit_circle`) to each view's points *before*
    compensation (``r_raw_mm`` filtered by the accepted qualities); the offset of a mirror view
    is the translation of its centre onto the reference view's centre.  The returned values
    are absolute: store them as ``Calibration.view_offsets_mm``
    (``dataclasses.replace(cal, view_offsets_mm=offsets)``) whatever the result's own
    compensation was.  the calibration part's ``joint_view_offsets`` fits one circle
    to all views instead (better conditioned for ~150° arcs).

    Raises
    ------
    ValueError
        No reference view, or a view with fewer than ``min_points`` valid points.
    """
    pts = raw_view_points(result, reference=reference, min_points=min_points)
    centres = {name: fit_circle(p).center_mm for name, p in pts.items()}
    return {name: centres[reference] - c for name, c in centres.items() if name != reference}

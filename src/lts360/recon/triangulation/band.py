"""The radial band found from the image: a coarse pass over every radius the rig can image,
then a fine band that follows the first-pass profile.

With no radius given, nothing is known of the object but that it lies in the laser plane
between the axis and the mirrors.  :class:`BandSearch` measures a coarse cylindrical grid
(1° × 50 µm by default) over the whole measurable range (:func:`measurable_radii`), with the
same detector and kernel as the fine pass.  Each view gives, per coarse θ, the strongest
stripe on its radial line; :func:`follow_profile` turns those candidates into one profile
``r₀(θ)`` for all views together:

1. per θ, the median of the views' candidates (all views see the same section);
2. a running median along θ (±3 coarse steps), robust to a view's isolated wrong pick (a
   reflection, a stripe of another view that its radial line crosses);
3. candidates farther than ``outlier_mm`` from it are dropped and steps 1–2 repeated;
4. θ with no candidate are filled by linear interpolation along θ (periodic on a full turn),
   and a ±1-step moving average smooths the median's staircase;
5. (:meth:`BandSearch.profile`) candidates deeper than the fine band's half-width inside the
   profile's least-squares circle that the profile hides from their own view are dropped and
   steps 1–4 repeated: a run of picks of light scattered inside a shiny pipe
   (interreflections) can outvote the pipe's few candidates where its line is dim, but its
   view cannot see the bottom of the pit it makes.

The fine grid is then ``r₀(θ) ± half_width`` per θ (:meth:`CylGrid.following`) and each
view's θ window is derived with the profile's own surface normal (``θ − atan(r₀′/r₀)``), so a
part off the axis keeps the right facing test, joined with the window of the profile's
least-squares circle (a valley's far flank stays in the window, where its fading is read);
the θ whose path to the view's camera the profile itself crosses are marked ``HIDDEN``
(:func:`hidden_rows`).  A line that still leaves the band is flagged
``TRUNCATED`` by the detector, never measured.

What it assumes: one section (a closed or open curve, star-shaped about the axis: one
surface point per θ) brighter than anything else on most radial lines.  A second object, or a
reflection brighter than the stripe over many degrees, would be followed instead.

This module imports no ground truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lts360.geometry.mirror import transform_plane
from lts360.recon.model import Calibration
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import InversePlan, InverseResult, plan_inverse
from lts360.recon.triangulation.peaks import Quality
from lts360.recon.triangulation.views import (
    DEFAULT_MAX_INCIDENCE_DEG,
    DIRECT,
    get_views,
    view_windows,
)

__all__ = ["BandSearch", "Profile", "follow_profile", "measurable_radii", "profile_windows",
           "self_occluded", "hidden_rows",
           "DEFAULT_COARSE_THETA_STEP_DEG", "DEFAULT_COARSE_R_STEP_MM",
           "DEFAULT_FOLLOW_HALF_WIDTH_MM", "DEFAULT_OUTLIER_MM", "DEFAULT_FIXED_RADIUS_MM",
           "DEFAULT_FIXED_HALF_WIDTH_MM"]

DEFAULT_COARSE_THETA_STEP_DEG = 1.0
#: A third of the line's σ along the ray on the paper rig (~0.15 mm): the coarse centroid is
#: then good to a few µm, far inside the fine band.
DEFAULT_COARSE_R_STEP_MM = 0.05
#: Half-width of the fine band about the first-pass profile: the main run of the line
#: (±0.4 mm above a 10 % threshold) plus what the running median smooths away.
DEFAULT_FOLLOW_HALF_WIDTH_MM = 1.0
#: The fixed band, where the band is not found from the image (a radius given, or the classic
#: baseline): ``radius ± half-width`` about the axis.  Without a radius, the plug gauge's
#: (Ø 19.9987 mm); the half-width is the fixed band's when only the radius is given.
DEFAULT_FIXED_RADIUS_MM = 10.0
DEFAULT_FIXED_HALF_WIDTH_MM = 2.0
#: A candidate this far from the running median is not part of the profile.
DEFAULT_OUTLIER_MM = 0.5
#: Running median half-length along θ, in coarse steps.
_MEDIAN_HALF = 3
#: The coarse pass stops this fraction short of the nearest mirror plane.
_MIRROR_CLEARANCE = 0.95
#: Candidates of the coarse pass: the strongest run, even where another run is comparable.
_CANDIDATE = (Quality.FOUND, Quality.SATURATED, Quality.SEVERAL_PEAKS, Quality.SATURATED_PLATEAU)


def measurable_radii(cal: Calibration, *, r_step_mm: float = DEFAULT_COARSE_R_STEP_MM
                     ) -> tuple[float, float]:
    """Radii (mm) the rig can measure about its axis: from two coarse steps to 95 % of the
    distance from the axis to the nearest mirror plane (a section cannot reach through a
    mirror).  Radii whose points fall outside the image are sampled as NaN and cost nothing
    more than their share of the coarse grid."""
    T = cal.T_meas_cam
    dist = [abs(transform_plane(m.n, m.d_mm, T[:3, :3], T[:3, 3])[1]) for m in cal.mirrors]
    cam = float(np.linalg.norm(T[:3, 3][:2]))
    r_max = _MIRROR_CLEARANCE * min(dist + [cam])
    r_min = 2.0 * r_step_mm
    if not r_max > r_min + 2 * r_step_mm:
        raise ValueError(f"calibration: the mirrors lie {min(dist + [cam]):.3f} mm from the axis, "
                         f"no room for a section")
    return r_min, r_max


@dataclass(frozen=True, eq=False)
class Profile:
    """A first-pass profile of the section.

    Attributes
    ----------
    theta_rad : (n,) float
        The coarse angles.
    r_mm : (n,) float
        The profile ``r₀(θ)`` (smoothed, gaps filled; finite everywhere).
    measured : (n,) bool
        θ where a view's candidate agreed with the profile (the rest is interpolated).
    periodic : bool
        Whether θ covers a full turn.
    """

    theta_rad: np.ndarray
    r_mm: np.ndarray
    measured: np.ndarray
    periodic: bool

    def at(self, theta_rad) -> np.ndarray:
        """``r₀`` at other angles (linear along θ; periodic on a full turn)."""
        th = np.asarray(theta_rad, dtype=float)
        if self.periodic:
            return np.interp(th, self.theta_rad, self.r_mm, period=2 * np.pi)
        return np.interp(th, self.theta_rad, self.r_mm)

    def normal_angle_at(self, theta_rad) -> np.ndarray:
        """Direction of the outward normal of the curve ``r₀(θ)``: ``θ − atan(r₀′ / r₀)``."""
        th = np.asarray(theta_rad, dtype=float)
        # Over ±3 coarse steps: the median's steps do not turn into noise of the slope.
        h = 3.0 * float(np.median(np.diff(self.theta_rad))) if self.theta_rad.size > 1 else 1e-3
        dr = (self.at(th + h) - self.at(th - h)) / (2 * h)
        return th - np.arctan2(dr, self.at(th))

    def circle_normal_angle_at(self, theta_rad) -> np.ndarray | None:
        """Direction of the outward normal of the profile's least-squares circle at the
        profile's points ``r₀(θ)`` (``None`` if no circle fits the measured θ)."""
        from lts360.geometry.fit import fit_circle

        th = np.asarray(theta_rad, dtype=float)
        pts = np.column_stack([self.r_mm * np.cos(self.theta_rad),
                               self.r_mm * np.sin(self.theta_rad)])
        try:
            c = fit_circle(pts[self.measured]).center_mm
        except ValueError:
            return None
        r = self.at(th)
        return np.arctan2(r * np.sin(th) - c[1], r * np.cos(th) - c[0])


def _running_nanmedian(values: np.ndarray, half: int, periodic: bool) -> np.ndarray:
    """Median of the finite values of ``values[..., i − half : i + half + 1]`` (rows: last
    axis is θ; earlier axes are pooled, e.g. views)."""
    n = values.shape[-1]
    k = np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :]
    if periodic:
        k = k % n
        stack = values[..., k]
    else:
        ok = (k >= 0) & (k < n)
        stack = np.where(ok, values[..., np.clip(k, 0, n - 1)], np.nan)
    stack = np.moveaxis(stack, -2, 0).reshape(n, -1) if values.ndim > 1 else stack
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmedian(stack, axis=1)


def follow_profile(theta_rad, candidates_mm, *, periodic: bool,
                   outlier_mm: float = DEFAULT_OUTLIER_MM, min_points: int = 3) -> Profile | None:
    """One profile ``r₀(θ)`` from every view's per-θ candidates (see the module docstring).

    Parameters
    ----------
    theta_rad : (n,) float
        Increasing angles.
    candidates_mm : (v, n) float
        Each view's candidate radius per θ; NaN where it has none.
    periodic : bool
        θ spans a full turn (the ends neighbour each other).
    outlier_mm : float, >0
    min_points : int
        Fewer θ with a candidate give ``None`` (no section found).

    Returns
    -------
    Profile or None
    """
    th = np.asarray(theta_rad, dtype=float).ravel()
    cand = np.atleast_2d(np.asarray(candidates_mm, dtype=float))
    if cand.shape[1] != th.size:
        raise ValueError(f"candidates_mm must have shape (views, {th.size}), got {cand.shape}")
    if not outlier_mm > 0:
        raise ValueError(f"outlier_mm must be > 0, got {outlier_mm}")
    cand = np.where(np.isfinite(cand), cand, np.nan)
    for _ in range(2):
        smooth = _running_nanmedian(cand, _MEDIAN_HALF, periodic)
        keep = np.abs(cand - smooth[None, :]) <= outlier_mm
        cand = np.where(keep, cand, np.nan)
    measured = np.isfinite(cand).any(axis=0)
    if measured.sum() < min_points:
        return None
    smooth = _running_nanmedian(cand, _MEDIAN_HALF, periodic)
    ok = np.isfinite(smooth)
    if periodic:
        r = np.interp(th, th[ok], smooth[ok], period=2 * np.pi)
    else:
        r = np.interp(th, th[ok], smooth[ok])
    # A ±1 step moving average takes the staircase out of the median.
    k = np.arange(th.size)[:, None] + np.arange(-1, 2)[None, :]
    r = r[k % th.size].mean(axis=1) if periodic else r[np.clip(k, 0, th.size - 1)].mean(axis=1)
    return Profile(theta_rad=th, r_mm=r, measured=measured, periodic=periodic)


def profile_windows(cal: Calibration, grid: CylGrid, profile: Profile, *, views=None,
                    max_incidence_deg: float = DEFAULT_MAX_INCIDENCE_DEG) -> dict[str, np.ndarray]:
    """θ windows of a grid that follows ``profile``: where the profile's own surface normal
    faces the view, or the normal of the profile's least-squares circle does.

    The profile's normal keeps the facing test right for a part off the axis and for a cube's
    faces.  The circle's keeps a valley's far flank (a cable's, a groove's) inside the window
    although the profile turns away there: a line that fades out inside the window is what
    the truth-free ``FADING`` test reads (:mod:`lts360.recon.triangulation.reject`), and a
    window that ended with the turning profile would hide that fading from it.  On a round
    section the two normals agree and so do the windows.  What the profile hides from a view
    inside its window is found by :func:`hidden_rows`.
    """
    names = (DIRECT,) + cal.mirror_names if views is None else tuple(views)
    r = grid.radii_mm()
    rng = (r[:, 0], r[:, -1])
    own = view_windows(cal, rng, grid.theta_rad, max_incidence_deg, views=names,
                       normal_angle_rad=profile.normal_angle_at(grid.theta_rad))
    circle = profile.circle_normal_angle_at(grid.theta_rad)
    if circle is None:
        return own
    round_ = view_windows(cal, rng, grid.theta_rad, max_incidence_deg, views=names,
                         normal_angle_rad=circle)
    return {name: own[name] | round_[name] for name in own}


def hidden_rows(cal: Calibration, grid: CylGrid, profile: Profile,
                windows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per view, the θ of its window whose path to the view's (virtual) camera the profile
    itself crosses (:func:`self_occluded`): a strand's flank behind its neighbour, the far
    side of a cable whose valleys tilt the normal towards a camera.  Marked ``HIDDEN`` by the
    rejection (:func:`lts360.recon.triangulation.reject.mark_hidden`); never set on a convex
    section."""
    th = grid.theta_rad
    r0 = profile.at(th)
    pts = np.column_stack([r0 * np.cos(th), r0 * np.sin(th)])
    T = cal.T_meas_cam
    out = {}
    for view in get_views(cal, tuple(windows)):
        win = np.asarray(windows[view.name], bool)
        mask = np.zeros(th.size, bool)
        idx = np.flatnonzero(win)
        if idx.size:
            c = T[:3, :3] @ view.virtual_camera_cam_mm + T[:3, 3]
            mask[idx] = self_occluded(profile, th[idx], c[None, :2] - pts[idx])
        out[view.name] = mask
    return out


#: The march of :func:`self_occluded`: its step (a path through a strand's edge shorter than
#: that may be missed), where it starts off the surface, and how deep below the profile a
#: sample must lie to count as inside (the profile's smoothing is ~10 µm)...
_OCCLUSION_STEP_MM = 0.1
_OCCLUSION_START_MM = 0.05
_OCCLUSION_TOL_MM = 0.02
#: ... and, from this far on along the path, how close above the profile it may pass and still
#: count as hidden: the coarse profile (1°, medians over ±3°) shaves a strand's crest and
#: cannot clear a path that grazes it.  A convex section's own path rises above it by more
#: (at 80° incidence on a Ø6 mm gauge, 0.13 mm at 0.5 mm).
_GRAZE_FROM_MM = 0.5
_GRAZE_CLEARANCE_MM = 0.05


def self_occluded(profile: Profile, theta_rad, direction_xy) -> np.ndarray:
    """(n,) bool: whether the ray from the profile's point at each θ, along ``direction_xy``
    (n, 2) (the path to a camera projected on the laser plane), passes inside the profile, or
    grazes it (within ``_GRAZE_CLEARANCE_MM`` from ``_GRAZE_FROM_MM`` on).

    The section is taken as a prism along the axis, so a path that rises out of the laser plane
    towards a camera is hidden exactly where its projection enters the section.  The ray is
    marched in ``_OCCLUSION_STEP_MM`` steps from ``_OCCLUSION_START_MM`` off the surface until
    it leaves the profile's largest radius.
    """
    th = np.asarray(theta_rad, dtype=float).ravel()
    d = np.asarray(direction_xy, dtype=float).reshape(th.size, 2)
    norm = np.linalg.norm(d, axis=1)
    hidden = np.zeros(th.size, bool)
    ok = norm > 0
    if not ok.any():
        return hidden
    d = d[ok] / norm[ok, None]
    r0 = profile.at(th[ok])
    p = np.column_stack([r0 * np.cos(th[ok]), r0 * np.sin(th[ok])])
    r_out = float(np.max(profile.r_mm)) + _GRAZE_CLEARANCE_MM
    # where the ray leaves the circle of radius r_out: |p + t d| = r_out
    pd = np.einsum("ij,ij->i", p, d)
    t_exit = -pd + np.sqrt(np.maximum(pd**2 - np.einsum("ij,ij->i", p, p) + r_out**2, 0.0))
    n_steps = int(np.ceil(max(float(t_exit.max()) - _OCCLUSION_START_MM, 0.0)
                          / _OCCLUSION_STEP_MM)) + 1
    t = _OCCLUSION_START_MM + _OCCLUSION_STEP_MM * np.arange(n_steps)
    margin = np.where(t < _GRAZE_FROM_MM, -_OCCLUSION_TOL_MM, _GRAZE_CLEARANCE_MM)
    inside = np.zeros(d.shape[0], bool)
    for chunk in np.array_split(np.arange(n_steps), max(1, n_steps // 64)):
        q = p[:, None, :] + t[None, chunk, None] * d[:, None, :]
        rq = np.hypot(q[..., 0], q[..., 1])
        below = rq < profile.at(np.arctan2(q[..., 1], q[..., 0])) + margin[None, chunk]
        inside |= np.any(below & (t[None, chunk] <= t_exit[:, None]), axis=1)
    hidden[ok] = inside
    return hidden


class BandSearch:
    """The coarse pass over the measurable radii, planned once for a calibration.

    Parameters
    ----------
    cal : Calibration
    runner : callable (InversePlan) -> callable (image) -> InverseResult
        Builds the measurement of one plan (the Dr.Jit kernel or the numpy reference), so that
        the coarse pass runs on the same detector as the fine one.
    theta_step_deg, r_step_mm : float
        The coarse grid.
    views : sequence of str, optional
    max_incidence_deg : float
    """

    def __init__(self, cal: Calibration, runner, *,
                 theta_step_deg: float = DEFAULT_COARSE_THETA_STEP_DEG,
                 r_step_mm: float = DEFAULT_COARSE_R_STEP_MM, views=None,
                 max_incidence_deg: float = DEFAULT_MAX_INCIDENCE_DEG) -> None:
        self.cal = cal
        self.r_range_mm = measurable_radii(cal, r_step_mm=r_step_mm)
        self.grid = CylGrid.from_ranges(self.r_range_mm, theta_step_deg=theta_step_deg,
                                        r_step_mm=r_step_mm)
        names = (DIRECT,) + cal.mirror_names if views is None else tuple(views)
        self.views = tuple(v.name for v in get_views(cal, names))
        # Windows: the facing test with radial normals, and the path at the smallest radius;
        # points beyond a mirror's edge (or the image) are left out point by point by the plan.
        r0 = self.r_range_mm[0]
        windows = view_windows(cal, (r0, r0), self.grid.theta_rad, max_incidence_deg,
                               views=self.views, n_radii=1)
        self.plan: InversePlan = plan_inverse(cal, self.grid, views=self.views, windows=windows,
                                              precompute=False)
        self._measure = runner(self.plan)

    def candidates(self, image) -> tuple[np.ndarray, InverseResult]:
        """(views, nθ) strongest-stripe radius per coarse θ (NaN where none) and the result."""
        res = self._measure(image)
        rows = []
        for v in res.views.values():
            ok = np.isin(v.quality, np.asarray([int(q) for q in _CANDIDATE], np.uint8))
            rows.append(np.where(ok, v.r_raw_mm, np.nan))
        return np.array(rows), res

    def profile(self, image) -> Profile | None:
        """The first-pass profile of the section in ``image`` (``None``: no stripe found).

        Candidates that lie deeper than ``DEFAULT_FOLLOW_HALF_WIDTH_MM`` inside the profile's
        least-squares circle *and* that the profile itself hides from their view
        (:func:`self_occluded`) are dropped and the profile followed again: a view cannot see
        the bottom of a pit narrower than its own depth, so such a run of picks is light
        scattered there, not the section (measured on the aluminium pipe with
        interreflections, ``max_scatter`` 1: picks of one view 5 mm inside the pipe where its
        own line is dim made 4.5–5 mm pits in the profile, and the band then missed the line
        there in every section that reused it; STUDIES.md, Interreflections).  A convex
        section's candidates are never hidden, a cable's valley is shallower than the band's
        half-width."""
        cand, _ = self.candidates(image)
        th = self.grid.theta_rad
        prof = follow_profile(th, cand, periodic=self.grid.is_full_turn)
        if prof is None:
            return None
        drop = self._hidden_pits(prof, cand)
        if not drop.any():
            return prof
        again = follow_profile(th, np.where(drop, np.nan, cand), periodic=self.grid.is_full_turn)
        return prof if again is None else again

    def _hidden_pits(self, prof: Profile, cand: np.ndarray) -> np.ndarray:
        """(views, nθ) bool: candidates deeper than the fine band's half-width inside the
        profile's least-squares circle that the profile hides from their view."""
        from lts360.geometry.fit import fit_circle

        th = prof.theta_rad
        drop = np.zeros(cand.shape, bool)
        m = np.asarray(prof.measured, bool)
        if m.sum() < 10:
            return drop
        try:
            fit = fit_circle(np.column_stack([prof.r_mm[m] * np.cos(th[m]),
                                              prof.r_mm[m] * np.sin(th[m])]))
        except ValueError:
            return drop
        with np.errstate(invalid="ignore"):
            depth = fit.radius_mm - np.hypot(cand * np.cos(th) - fit.center_mm[0],
                                             cand * np.sin(th) - fit.center_mm[1])
        deep = np.isfinite(cand) & (depth > DEFAULT_FOLLOW_HALF_WIDTH_MM)
        if not deep.any():
            return drop
        r0 = prof.at(th)
        pts = np.column_stack([r0 * np.cos(th), r0 * np.sin(th)])
        T = self.cal.T_meas_cam
        for row, view in enumerate(get_views(self.cal, self.views)):
            idx = np.flatnonzero(deep[row])
            if idx.size:
                c = T[:3, :3] @ view.virtual_camera_cam_mm + T[:3, 3]
                drop[row, idx] = self_occluded(prof, th[idx], c[None, :2] - pts[idx])
        return drop

    def fine_grid(self, profile: Profile, *, theta_step_deg: float, r_step_mm: float,
                  half_width_mm: float = DEFAULT_FOLLOW_HALF_WIDTH_MM,
                  theta_range_deg=(-180.0, 180.0)) -> CylGrid:
        """The fine grid ``r₀(θ) ± half_width`` on the requested θ sampling."""
        base = CylGrid.from_ranges((1.0, 2.0), theta_range_deg=theta_range_deg,
                                   theta_step_deg=theta_step_deg, r_step_mm=r_step_mm)
        rc = np.maximum(profile.at(base.theta_rad), half_width_mm + r_step_mm)
        return CylGrid.following(base.theta_rad, rc, half_width_mm, r_step_mm=r_step_mm)

    def describe(self) -> str:
        """The coarse search, in words (for a refusal line)."""
        r0, r1 = self.r_range_mm
        return (f"r = {r0:.2f}–{r1:.2f} mm searched in {math.degrees(self.grid.theta_step_rad):g}° "
                f"× {self.grid.r_step_mm * 1e3:g} µm steps")

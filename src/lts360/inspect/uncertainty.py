"""Standard uncertainty u and expanded uncertainty U (k = 2) of every reported quantity.

Two components, combined in quadrature (GUM):

1. **Point scatter** (type A, from the section itself): ``σ``, the standard deviation of one
   point about the binned profile (:mod:`lts360.inspect.section`; view-to-view offsets in the
   overlaps are part of it).  Propagated linearly with ``n`` valid points, ``m`` points per
   0.5° bin and ``N`` bins:

   ========================================  ==================
   quantity                                  u from scatter
   ========================================  ==================
   LS centre x, y                            σ √(2/n)
   LS diameter, mean two-point diameter      2σ / √n
   one two-point diameter, Dmin, Dmax,       σ √(2/m)
   calliper widths
   ovality Dmax − Dmin                       2σ / √m
   RONt (every reference), MCCI/MICI size    σ √(2/m)
   harmonic amplitude Aₖ                     σ √(2/n)
   a point's deviation from the nominal      σ
   ========================================  ==================

   (Extremes of noisy bins are biased upwards by about σ/√m; that bias is not corrected.)

   The points are not independent: neighbouring θ share pixels, blur, speckle grains and, on a
   synthetic frame, render noise, so errors come in runs longer than a bin.  From the binned
   profile: ``h`` the bins' residuals about the LS circle less their circular moving average
   over :data:`FORM_WINDOW_DEG` (the form, which is not noise); the bins' noise modelled as
   AR(1), its variance ``s_h²`` and lag-1 correlation ρ those that give ``h``'s after the same
   moving average (exact, by the spectrum), ``τ = (1 + ρ)/(1 − ρ)`` and ``u(r̄) = s_h √(τ / N)``
   over ``N`` bins (:func:`correlated_mean_u`).  The whole-section averages take the larger of the table's
   value and 2 u(r̄) (diameters) or √2 u(r̄) (centre, amplitudes); the quantities read at
   single bins (two-point diameters, callipers, ovality, RONt) use ``max(σ/√m, s_h)`` for one
   bin's error.  Form shorter than the window (a dent's flank) counts as noise: conservative.
   On the noise-free gauge (Ø19.9987 mm, 16 spp, twin-corrected) τ = 2.1 and u(D_LS) =
   0.57 µm, where independent points give 0.17 µm.

2. **Calibration** (type B, from ``--calibration``'s covariance, see
   :mod:`lts360.recon.calibration.uncertainty`): a Monte Carlo over ``n_draws`` calibrations
   drawn from it.  Every valid point is re-triangulated: projected into its view's image with
   the calibration it was measured with, then intersected, through the drawn calibration's
   view, with the drawn laser plane (the forward triangulation of
   :mod:`lts360.recon.triangulation.classic`), and moved by the difference.  The section is
   inspected again with the moved points and the standard deviation over the draws is the
   calibration's u.  A calibration error is the same for every section, so this runs on at most
   :data:`MC_SECTIONS` sections spread over the scan and each section takes the u of the
   nearest one.  The minimum-zone, MCCI and MICI roundness take the LS roundness's
   calibration u, the reference circles' sizes the LS diameter's.

A calibration without covariance (a rendered frame's ``frame.json``, the true rig) gives a
calibration u of zero, and the report says so.
"""

from __future__ import annotations

import numpy as np

from lts360.inspect.circles import least_squares_circle
from lts360.inspect.diameters import diameters
from lts360.inspect.harmonics import fit_harmonics
from lts360.inspect.profile import bin_profile, uniform_profile

__all__ = ["scatter_u", "correlated_mean_u", "retriangulate", "calibration_u", "combine", "MC_SECTIONS",
           "DEFAULT_DRAWS", "CAL_QUANTITIES"]

#: Sections the calibration Monte Carlo runs on.
MC_SECTIONS = 5
#: Calibration draws (20 give u to about ±16 %, enough for a k = 2 statement).
DEFAULT_DRAWS = 20
#: The quantities the calibration Monte Carlo recomputes.
CAL_QUANTITIES = ("centre_x_mm", "centre_y_mm", "d_ls_mm", "d_mean_mm", "d_min_mm",
                  "d_max_mm", "ovality_mm", "ront_lsci_mm", "a2_mm", "a3_mm")


#: Window of the moving average taken as the form when the bins' correlation is estimated.
FORM_WINDOW_DEG = 10.0


def scatter_u(sigma_mm: float, n: int, m: float, *, u_mean_radius_mm: float = 0.0,
              u_bin_mm: float = 0.0) -> dict[str, float]:
    """The scatter component of each quantity (table in the module docstring); with
    ``u_mean_radius_mm`` and ``u_bin_mm`` (:func:`correlated_mean_u`) each quantity takes the
    larger of the independent-point and the correlated figure."""
    s, n, m = float(sigma_mm), max(int(n), 1), max(float(m), 1.0)
    ur = float(u_mean_radius_mm) if np.isfinite(u_mean_radius_mm) else 0.0
    ub = float(u_bin_mm) if np.isfinite(u_bin_mm) else 0.0
    bin_u = max(s / np.sqrt(m), ub)  # one bin's error
    one = np.sqrt(2.0) * bin_u
    centre = max(s * np.sqrt(2.0 / n), np.sqrt(2.0) * ur)
    size = max(2 * s / np.sqrt(n), 2 * ur)
    return {"centre_x_mm": centre, "centre_y_mm": centre,
            "d_ls_mm": size, "d_mean_mm": size,
            "d_min_mm": one, "d_max_mm": one, "calliper_mm": one,
            "ovality_mm": 2 * bin_u, "ront_mm": one, "size_ref_mm": one,
            "harmonic_mm": centre, "deviation_mm": s}


def _ar1_after_highpass(n: int, w: int, rhos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For AR(1) noise of unit variance and lag-1 correlation ``rhos``, after subtracting its
    circular ``w``-bin moving average: the variance left and the lag-1 correlation (exact on
    ``n`` circular bins, by the spectrum)."""
    f = np.fft.rfftfreq(n)
    z = np.exp(-2j * np.pi * f)
    spec = (1 - rhos[:, None] ** 2) / np.abs(1 - rhos[:, None] * z[None, :]) ** 2
    k = np.arange(w) - (w - 1) / 2.0
    ma = np.exp(-2j * np.pi * np.outer(f, k)).mean(axis=1)  # the moving average's response
    s = spec * np.abs(1 - ma[None, :]) ** 2
    wts = np.where((np.arange(f.size) == 0) | ((n % 2 == 0) & (np.arange(f.size) == f.size - 1)),
                   1.0, 2.0)
    var = (s * wts).sum(axis=1) / n
    lag1 = (s * wts * np.cos(2 * np.pi * f)).sum(axis=1) / n
    return var, lag1 / var


def correlated_mean_u(theta_rad, r_mm, radius_mm: float, *, bin_deg: float = 0.5,
                      form_window_deg: float = FORM_WINDOW_DEG) -> tuple[float, float, float]:
    """``(u(r̄), τ, s)`` of a binned profile (module docstring): ``theta_rad``, ``r_mm`` its
    bins, ``radius_mm`` the LS circle's; ``s`` one bin's noise.  NaNs for fewer than four
    windows of bins.

    The bins' noise is modelled as AR(1): its lag-1 correlation ρ and variance are those that,
    after the form's moving average is subtracted, give the residuals' lag-1 correlation and
    variance; τ = (1 + ρ)/(1 − ρ)."""
    from scipy.ndimage import uniform_filter1d

    th = np.asarray(theta_rad, float)
    res = np.asarray(r_mm, float) - float(radius_mm)
    n = len(res)
    w = max(3, int(round(form_window_deg / bin_deg)))
    if n < 4 * w:
        return float("nan"), float("nan"), float("nan")
    res = res[np.argsort(th)]
    h = res - uniform_filter1d(res, w, mode="wrap")
    var_h = float(np.mean(h * h))
    if var_h == 0:
        return 0.0, 1.0, 0.0
    r1 = float(np.mean(h * np.roll(h, 1))) / var_h
    rhos = np.linspace(0.0, 0.95, 96)
    kept, lag1 = _ar1_after_highpass(n, w, rhos)
    rho = float(np.interp(r1, lag1, rhos)) if r1 > lag1[0] else 0.0
    kept_at = float(np.interp(rho, rhos, kept))
    sigma2 = var_h / kept_at
    tau = (1 + rho) / (1 - rho)
    return float(np.sqrt(sigma2 * tau / n)), tau, float(np.sqrt(sigma2))


def retriangulate(points_xy_mm, view_names, cal_from, cal_to) -> np.ndarray:
    """Where the pixels of measured points land with another calibration.

    Parameters
    ----------
    points_xy_mm : (n, 2) float
        Points in the laser plane (measurement frame of ``cal_from``).
    view_names : (n,) str
        The view each point was measured in (``direct``, ``left``, ...).
    cal_from, cal_to : Calibration

    Returns
    -------
    (n, 2) float
        The same pixels triangulated with ``cal_to`` (its measurement frame); NaN for a view
        ``cal_to`` does not have.
    """
    from lts360.geometry.camera import backproject_pixels
    from lts360.recon.triangulation.views import get_views, project_meas_points

    xy = np.asarray(points_xy_mm, float)
    names = np.asarray(view_names)
    out = np.full_like(xy, np.nan)
    n_l, d_l = cal_to.laser_plane
    T_meas_cam = cal_to.T_meas_cam
    for name in np.unique(names):
        sel = names == name
        try:
            v_from = get_views(cal_from, [str(name)])[0]
            v_to = get_views(cal_to, [str(name)])[0]
        except ValueError:
            continue
        P = np.column_stack([xy[sel], np.zeros(int(sel.sum()))])
        uv = project_meas_points(P, cal_from, v_from)
        d = backproject_pixels(uv, cal_to.K, cal_to.dist)
        Tinv = np.linalg.inv(v_to.T_cam)
        A, b = Tinv[:3, :3], Tinv[:3, 3]
        Ad = d @ A.T
        s = (d_l - n_l @ b) / (Ad @ n_l)
        X = (s[:, None] * Ad + b) @ T_meas_cam[:3, :3].T + T_meas_cam[:3, 3]
        out[sel] = X[:, :2]
    return out


def _quantities(xy: np.ndarray) -> dict[str, float]:
    ls = least_squares_circle(xy)
    prof = bin_profile(xy, ls.centre_mm)
    dia = diameters(prof)
    th, r = uniform_profile(prof)
    h = fit_harmonics(th, r) if np.all(np.isfinite(r)) else fit_harmonics(prof.theta_rad,
                                                                           prof.r_mm)
    return {"centre_x_mm": ls.centre_mm[0], "centre_y_mm": ls.centre_mm[1],
            "d_ls_mm": ls.diameter_mm, "d_mean_mm": dia.d_mean_mm, "d_min_mm": dia.d_min_mm,
            "d_max_mm": dia.d_max_mm, "ovality_mm": dia.ovality_mm,
            "ront_lsci_mm": ls.ront_mm, "a2_mm": h.amplitude(2), "a3_mm": h.amplitude(3)}


def calibration_u(sections_xy, sections_views, cal, *, n_draws: int = DEFAULT_DRAWS,
                  seed: int = 0) -> list[dict[str, float]] | None:
    """The calibration component per section (``None`` when ``cal`` has no covariance).

    Parameters
    ----------
    sections_xy : list of (n_i, 2) float
        Each section's valid points.
    sections_views : list of (n_i,) str
        Their views.
    cal : Calibration
        The calibration the cloud was measured with, with ``uncertainty``.
    """
    from lts360.recon.calibration.uncertainty import sample_calibration

    u = cal.uncertainty or {}
    if not any(u.get(k) for k in ("camera", "mirrors", "laser_plane")):
        return None
    if n_draws < 2:
        raise ValueError(f"n_draws must be >= 2, got {n_draws}")
    n_sec = len(sections_xy)
    picks = np.unique(np.round(np.linspace(0, n_sec - 1, min(MC_SECTIONS, n_sec))).astype(int))
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    draws = [sample_calibration(cal, rng) for _ in range(n_draws)]
    per_pick = {}
    for i in picks:
        xy, views = sections_xy[i], sections_views[i]
        base = retriangulate(xy, views, cal, cal)  # the round trip, removed from every draw
        rows = []
        for c in draws:
            moved = xy + (retriangulate(xy, views, cal, c) - base)
            ok = np.all(np.isfinite(moved), axis=1)
            rows.append(_quantities(moved[ok]))
        per_pick[int(i)] = {k: float(np.std([r[k] for r in rows], ddof=1))
                            for k in CAL_QUANTITIES}
    keys = np.array(sorted(per_pick))
    return [per_pick[int(keys[np.argmin(np.abs(keys - j))])] for j in range(n_sec)]


def combine(*components: float | None) -> dict[str, float]:
    """``{"u": √Σuᵢ², "U_k2": 2u}`` over the components given (``None`` ones left out)."""
    u = float(np.sqrt(sum(c * c for c in components if c is not None)))
    return {"u": u, "U_k2": 2.0 * u}

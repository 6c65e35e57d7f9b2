"""Along a scan: trends, lumps and neck-downs, the axis through the section centres,
straightness, cylindricity and the spectrum of the diameter along z.

Inputs are the per-section results (:class:`lts360.inspect.section.SectionResult`), each at its
stage position ``z_mm``.

* **Trend**: the least-squares line of a quantity over z (slope in mm per mm).
* **Lumps and neck-downs**: runs of consecutive sections whose largest (smallest) two-point
  diameter exceeds (falls below) the scan's median of it by more than ``threshold_mm``; each
  with its start and end z, its length (number of sections × pitch), the z of its extreme and
  the extreme deviation.  A local bump or dent changes Dmax or Dmin long before it moves the
  LS diameter.
* **Axis**: the line ``x = x₀ + aₓ z``, ``y = y₀ + a_y z`` fitted to the LS centres; tilt is its
  angle to the stage's z.  **Straightness** (ISO 12780's median line, about the LS axis): the
  diameter of the smallest cylinder coaxial with the LS axis that holds every centre.
* **Cylindricity** (ISO 12180, LS reference): the least-squares cylinder (axis and radius)
  fitted to the binned profiles of every section; CYLt is the peak-to-valley of the radial
  deviations about it.  Meaningful where the object is nominally a cylinder.
* **Spectrum**: the amplitude spectrum of the detrended LS diameter over z (uniform pitch; an
  uneven one is resampled), wavelength in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Event", "AxisFit", "trend", "lumps_and_necks", "fit_axis", "cylindricity",
           "diameter_spectrum", "DEFAULT_LUMP_MM"]

#: Default threshold of a lump or neck-down (mm): 50 µm, a cable gauge's usual setting.
DEFAULT_LUMP_MM = 0.05


def trend(z_mm, values) -> dict:
    """Least-squares line of ``values`` over ``z_mm``: slope per mm, value at the mean z, rms
    about the line."""
    z = np.asarray(z_mm, float)
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    if ok.sum() < 2 or np.ptp(z[ok]) == 0:
        return {"slope_per_mm": None, "mean": float(np.nanmean(v)) if ok.any() else None,
                "rms_about_line": None}
    a, b = np.polyfit(z[ok], v[ok], 1)
    res = v[ok] - (a * z[ok] + b)
    return {"slope_per_mm": float(a), "mean": float(v[ok].mean()),
            "rms_about_line": float(np.sqrt(np.mean(res**2)))}


@dataclass(frozen=True)
class Event:
    """A lump or a neck-down (mm)."""

    kind: str
    z_start_mm: float
    z_end_mm: float
    length_mm: float
    z_extreme_mm: float
    deviation_mm: float
    sections: list


def _pitch(z: np.ndarray) -> float:
    dz = np.diff(np.sort(z))
    return float(np.median(dz)) if dz.size else 0.0


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def lumps_and_necks(z_mm, d_min_mm, d_max_mm, *, threshold_mm: float = DEFAULT_LUMP_MM,
                    indices=None) -> list[Event]:
    """Lumps (Dmax above its median by more than ``threshold_mm``) and neck-downs (Dmin below
    its median by more than it), as runs of consecutive sections in z order."""
    if not threshold_mm > 0:
        raise ValueError(f"threshold_mm must be > 0, got {threshold_mm}")
    z = np.asarray(z_mm, float)
    order = np.argsort(z, kind="stable")
    z = z[order]
    ids = (np.arange(len(z)) if indices is None else np.asarray(indices))[order]
    pitch = _pitch(z)
    out = []
    for kind, v, sign in (("lump", np.asarray(d_max_mm, float)[order], 1.0),
                          ("neck-down", np.asarray(d_min_mm, float)[order], -1.0)):
        if not np.isfinite(v).any():
            continue
        dev = sign * (v - np.nanmedian(v))
        for run in _runs(np.nan_to_num(dev, nan=-np.inf) > threshold_mm):
            k = run[np.argmax(dev[run])]
            out.append(Event(kind, float(z[run[0]]), float(z[run[-1]]),
                             float(z[run[-1]] - z[run[0]] + pitch), float(z[k]),
                             float(sign * dev[k]), [int(i) for i in ids[run]]))
    return sorted(out, key=lambda e: e.z_start_mm)


@dataclass(frozen=True)
class AxisFit:
    """The LS line through the section centres (mm, deg)."""

    x0_mm: float
    y0_mm: float
    slope_x: float
    slope_y: float
    tilt_deg: float
    tilt_azimuth_deg: float
    straightness_mm: float
    residuals_mm: np.ndarray


def fit_axis(z_mm, centres_mm) -> AxisFit:
    """The axis through the LS centres ``centres_mm : (n, 2)`` at ``z_mm : (n,)``, n >= 2."""
    z = np.asarray(z_mm, float)
    c = np.asarray(centres_mm, float)
    if len(z) < 2 or np.ptp(z) == 0:
        raise ValueError("an axis needs at least two sections at different z")
    A = np.column_stack([np.ones_like(z), z])
    coef = np.linalg.solve(A.T @ A, A.T @ c)  # (2, 2): rows (x0, y0), (ax, ay)
    res = c - A @ coef
    ax, ay = coef[1]
    d = np.hypot(res[:, 0], res[:, 1])
    return AxisFit(float(coef[0, 0]), float(coef[0, 1]), float(ax), float(ay),
                   float(np.degrees(np.arctan(np.hypot(ax, ay)))),
                   float(np.degrees(np.arctan2(ay, ax))), float(2.0 * d.max()), d)


def cylindricity(z_mm, profiles_xy_mm, *, start: AxisFit | None = None,
                 max_points: int = 20000) -> dict:
    """LS cylinder through the profiles (a list of (m_i, 2) arrays at ``z_mm``).

    The fit uses at most ``max_points`` points (every k-th of each profile); CYLt is taken over
    all of them.

    Returns the cylinder's radius, its axis (point at z = 0 and direction) and CYLt, the
    peak-to-valley of the radial deviations about it (mm).
    """
    from scipy.optimize import least_squares

    all_pts = np.vstack([np.column_stack([p, np.full(len(p), z)])
                         for z, p in zip(z_mm, profiles_xy_mm)])
    pts = all_pts[::max(1, -(-len(all_pts) // max_points))]
    if start is None:
        start = fit_axis(z_mm, [p.mean(axis=0) for p in profiles_xy_mm])
    r0 = float(np.mean(np.hypot(pts[:, 0] - start.x0_mm - start.slope_x * pts[:, 2],
                                pts[:, 1] - start.y0_mm - start.slope_y * pts[:, 2])))

    def residual(p, pts=pts):
        x0, y0, ax, ay, r = p
        d = np.array([ax, ay, 1.0]) / np.sqrt(1.0 + ax * ax + ay * ay)
        q = pts - np.array([x0, y0, 0.0])
        perp = q - np.outer(q @ d, d)
        return np.hypot(np.hypot(perp[:, 0], perp[:, 1]), perp[:, 2]) - r

    sol = least_squares(residual, [start.x0_mm, start.y0_mm, start.slope_x, start.slope_y, r0],
                        method="lm", xtol=1e-12, ftol=1e-12)
    res = residual(sol.x, all_pts)
    x0, y0, ax, ay, r = sol.x
    return {"radius_mm": float(r), "diameter_mm": float(2 * r), "axis_x0_mm": float(x0),
            "axis_y0_mm": float(y0), "axis_slope_x": float(ax), "axis_slope_y": float(ay),
            "cylt_mm": float(res.max() - res.min()), "rms_mm": float(np.sqrt(np.mean(res**2)))}


def diameter_spectrum(z_mm, d_mm) -> dict:
    """Amplitude spectrum of the detrended diameter along z (needs ≥ 4 sections).

    Returns ``wavelength_mm`` and ``amplitude_mm`` (one-sided, the amplitude of a sinusoid of
    that wavelength) without the zero frequency, and the dominant component.
    """
    z = np.asarray(z_mm, float)
    d = np.asarray(d_mm, float)
    ok = np.isfinite(d)
    z, d = z[ok], d[ok]
    if len(z) < 4:
        return {"wavelength_mm": [], "amplitude_mm": [], "dominant_wavelength_mm": None,
                "dominant_amplitude_mm": None}
    o = np.argsort(z)
    z, d = z[o], d[o]
    pitch = _pitch(z)
    zu = z[0] + pitch * np.arange(int(round((z[-1] - z[0]) / pitch)) + 1)
    du = np.interp(zu, z, d)
    du = du - np.polyval(np.polyfit(zu, du, 1), zu)
    n = len(du)
    amp = 2.0 * np.abs(np.fft.rfft(du)) / n
    freq = np.fft.rfftfreq(n, d=pitch)
    amp, freq = amp[1:], freq[1:]
    if n % 2 == 0 and amp.size:
        amp[-1] /= 2.0
    k = int(np.argmax(amp)) if amp.size else None
    return {"wavelength_mm": (1.0 / freq).tolist(), "amplitude_mm": amp.tolist(),
            "dominant_wavelength_mm": None if k is None else float(1.0 / freq[k]),
            "dominant_amplitude_mm": None if k is None else float(amp[k])}

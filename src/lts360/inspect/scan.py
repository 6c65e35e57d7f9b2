"""Along a scan: trends, lumps and neck-downs, the axis through the section centres,
straightness, cylindricity and the spectrum of the diameter along z.

Inputs are the per-section results (:class:`lts360.inspect.section.SectionResult`), each at its
stage position ``z_mm``.

* **Trend**: the least-squares line of a quantity over z (slope in mm per mm).
* **Lumps and neck-downs**: runs of consecutive sections whose largest (smallest) two-point
  diameter exceeds (falls below) the scan's median of it by more than ``threshold_mm``; each
  with its start and end z, its length (number of sections × pitch), the z of its extreme and
  the extreme deviation.  A local bump or dent changes Dmax or Dmin long before it moves the
  LS diameter.  Given each section's noise u of Dmax and Dmin, an event must also be
  significant against that noise (``u² = u_section² + u_median²``,
  ``u_median = 1.2533 · median(u_section) / √n``; the calibration is common to every section
  and cancels, and each section's own noise bias is removed first).  ``u_section`` is the
  larger of the section's u and the scan's own section-to-section noise ``u_scan = 1.4826 ·
  MAD(Δ²dev) / √6`` from the second differences of the deviations along z (robust: a few
  sections with an event leave it alone, and a smooth change along z, a long dent or a
  waviness, does not count as noise; on a smooth pipe it is the section-to-section noise the
  model may miss).  Dmax is the largest of many noisy diameters, so its noise is not normal:
  its upper tail is an extreme-value (Gumbel) one, of scale ``β = u √6 / π`` (the Monte Carlo's u of
  the extremes, :mod:`lts360.inspect.extremes`), and likewise Dmin's lower tail.
  ``p_noise`` is the probability that noise alone moves one section's Dmax (Dmin) this far
  from the scan's median, ``1 − exp(−exp(−dev/β − 0.3665))`` (0.3665 = −ln ln 2: the
  median's place in the Gumbel); an event is significant where ``p_noise`` is below half of
  :data:`FALSE_EVENT_RATE` shared by the scan's ``2 n`` tests (the lump and the neck-down of
  each section; the other half is the arc-matched detector's,
  :mod:`lts360.inspect.local_events`), so a smooth scan shows a false event of either
  detector in about 1 of 20 scans (on the
  realistic smooth PVC scan one section's noise moved Dmax 54 µm above the median: a lump by
  the earlier rule, dev > U(k = 2); its p_noise, 0.01–0.04, is far above 0.025 / 40).  Each
  event also reports its confidence, the probability that the true deviation exceeds the
  threshold (normal, ``Φ((|dev| − threshold) / u)``).  Runs beyond the threshold but not
  significant are returned apart.
* **Axis**: the line ``x = x₀ + aₓ z``, ``y = y₀ + a_y z`` fitted to the LS centres; tilt is its
  angle to the stage's z.  **Straightness** (ISO 12780's median line, about the LS axis): the
  diameter of the smallest cylinder coaxial with the LS axis that holds every centre.
  The tilt carries its U(k = 2) from the centres' u (or their scatter about the line, the
  larger); when that U exceeds :data:`TILT_TELL_DEG` the scan is too short to tell the axis'
  direction and says so instead of a number.
* **Cylindricity** (ISO 12180, LS reference): the cylinder about the axis through the section
  centres, its radius the mean distance of the binned profiles from that axis; CYLt is the
  peak-to-valley of the radial deviations about it.  The axis is not fitted freely to the
  points: over a short scan of an oval tube a free LS cylinder tilts until the oblique cut of
  the cylinder mimics the ovality (a tilt φ makes an ellipse of Dmax − Dmin ≈ D φ²/2; seen on a
  4 mm scan of the PVC pipe: 5.3° where the centres tilt 0.055°).  Meaningful where the object
  is nominally a cylinder.
* **Spectrum**: the amplitude spectrum of the detrended LS diameter over z (uniform pitch; an
  uneven one is resampled), wavelength in mm; the dominant wavelength only among those that
  fit at least twice in the scan's length (``n`` sections × pitch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Event", "AxisFit", "trend", "lumps_and_necks", "fit_axis", "cylindricity",
           "tilt_uncertainty", "diameter_spectrum", "DEFAULT_LUMP_MM", "TILT_TELL_DEG",
           "FALSE_EVENT_RATE",
           "MIN_PERIODS"]

#: Default threshold of a lump or neck-down (mm): 50 µm, a cable gauge's usual setting.
DEFAULT_LUMP_MM = 0.05
#: A tilt whose U(k = 2) exceeds this (deg) is "too short to tell".
TILT_TELL_DEG = 0.05
#: The scan's chance of one false lump or neck-down from noise alone (half for the diameter
#: detector here, half for the arc-matched one, :mod:`lts360.inspect.local_events`).
FALSE_EVENT_RATE = 0.05
#: Periods a wavelength must fit in the scan to be named dominant.
MIN_PERIODS = 2


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
    u_mm: float | None = None
    U_k2_mm: float | None = None
    confidence: float | None = None
    p_noise: float | None = None
    significant: bool = True


def _pitch(z: np.ndarray) -> float:
    dz = np.diff(np.sort(z))
    return float(np.median(dz)) if dz.size else 0.0


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def lumps_and_necks(z_mm, d_min_mm, d_max_mm, *, threshold_mm: float = DEFAULT_LUMP_MM,
                    indices=None, u_d_min_mm=None, u_d_max_mm=None) -> list[Event]:
    """Lumps (Dmax above its median by more than ``threshold_mm``) and neck-downs (Dmin below
    its median by more than it), as runs of consecutive sections in z order.

    With ``u_d_min_mm``, ``u_d_max_mm`` (each section's noise u) every event carries its u,
    U(k = 2), confidence and ``p_noise``, and ``significant`` is False when noise alone explains
    it (module docstring); without them every event counts as significant."""
    if not threshold_mm > 0:
        raise ValueError(f"threshold_mm must be > 0, got {threshold_mm}")
    z = np.asarray(z_mm, float)
    order = np.argsort(z, kind="stable")
    z = z[order]
    ids = (np.arange(len(z)) if indices is None else np.asarray(indices))[order]
    pitch = _pitch(z)
    out = []
    from scipy.stats import norm

    for kind, v, sign, u in (("lump", np.asarray(d_max_mm, float)[order], 1.0, u_d_max_mm),
                             ("neck-down", np.asarray(d_min_mm, float)[order], -1.0,
                              u_d_min_mm)):
        if not np.isfinite(v).any():
            continue
        dev = sign * (v - np.nanmedian(v))
        if u is not None:
            d2 = np.diff(dev[np.isfinite(dev)], 2)
            u_scan = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0) \
                if d2.size >= 3 else 0.0
            u = np.maximum(np.asarray(u, float)[order], u_scan)
            u_med = 1.2533 * float(np.nanmedian(u)) / np.sqrt(np.isfinite(v).sum())
            n_tests = int(np.isfinite(v).sum())
        for run in _runs(np.nan_to_num(dev, nan=-np.inf) > threshold_mm):
            k = run[np.argmax(dev[run])]
            extra = {}
            if u is not None:
                ue = float(np.hypot(u[k], u_med))
                beta = ue * np.sqrt(6.0) / np.pi
                p = float(-np.expm1(-np.exp(-dev[k] / beta - 0.3665))) if beta > 0 else 0.0
                extra = {"u_mm": ue, "U_k2_mm": 2 * ue,
                         "confidence": float(norm.cdf((dev[k] - threshold_mm) / ue))
                         if ue > 0 else 1.0, "p_noise": p,
                         "significant": bool(p < FALSE_EVENT_RATE / 2 / (2 * n_tests))}
            out.append(Event(kind, float(z[run[0]]), float(z[run[-1]]),
                             float(z[run[-1]] - z[run[0]] + pitch), float(z[k]),
                             float(sign * dev[k]), [int(i) for i in ids[run]], **extra))
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


def cylindricity(z_mm, profiles_xy_mm, *, start: AxisFit | None = None) -> dict:
    """The cylinder about the axis through the section centres (module docstring), for the
    profiles (a list of (m_i, 2) arrays at ``z_mm``).

    Parameters
    ----------
    start : AxisFit, optional
        That axis (default: the LS line through the profiles' mean points).

    Returns the cylinder's radius, its axis (point at z = 0 and direction) and CYLt, the
    peak-to-valley of the radial deviations about it (mm).
    """
    all_pts = np.vstack([np.column_stack([p, np.full(len(p), z)])
                         for z, p in zip(z_mm, profiles_xy_mm)])
    if start is None:
        start = fit_axis(z_mm, [p.mean(axis=0) for p in profiles_xy_mm])
    x0, y0, ax, ay = start.x0_mm, start.y0_mm, start.slope_x, start.slope_y
    d = np.array([ax, ay, 1.0]) / np.sqrt(1.0 + ax * ax + ay * ay)
    q = all_pts - np.array([x0, y0, 0.0])
    perp = q - np.outer(q @ d, d)
    dist = np.linalg.norm(perp, axis=1)
    r = float(dist.mean())
    res = dist - r
    return {"radius_mm": float(r), "diameter_mm": float(2 * r), "axis_x0_mm": float(x0),
            "axis_y0_mm": float(y0), "axis_slope_x": float(ax), "axis_slope_y": float(ay),
            "axis": "the LS line through the section centres",
            "cylt_mm": float(res.max() - res.min()), "rms_mm": float(np.sqrt(np.mean(res**2)))}


def tilt_uncertainty(z_mm, axis: AxisFit, u_centre_mm: float) -> dict:
    """``{u_tilt_deg, U_tilt_deg, too_short}`` of the axis through centres at ``z_mm`` with a
    standard uncertainty ``u_centre_mm`` each (the larger of it and the centres' scatter about
    the line when there are three or more)."""
    z = np.asarray(z_mm, float)
    n = len(z)
    s = float(u_centre_mm)
    if n > 2:
        s = max(s, float(np.sqrt(np.sum(axis.residuals_mm ** 2) / (n - 2) / 2)))
    sxx = float(np.sum((z - z.mean()) ** 2))
    u = float(np.degrees(s / np.sqrt(sxx))) if sxx > 0 else float("inf")
    return {"u_tilt_deg": u, "U_tilt_deg": 2 * u, "too_short": bool(not 2 * u <= TILT_TELL_DEG)}


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
    length = n * pitch
    fits = (1.0 / np.maximum(freq, 1e-300)) * MIN_PERIODS <= length + 1e-9 * pitch
    k = int(np.flatnonzero(fits)[np.argmax(amp[fits])]) if fits.any() else None
    out = {"wavelength_mm": (1.0 / freq).tolist(), "amplitude_mm": amp.tolist(),
           "dominant_wavelength_mm": None if k is None else float(1.0 / freq[k]),
           "dominant_amplitude_mm": None if k is None else float(amp[k])}
    if k is None:
        out["note"] = (f"too short to tell: no wavelength fits {MIN_PERIODS} times in the "
                       f"scan's {length:g} mm")
    return out

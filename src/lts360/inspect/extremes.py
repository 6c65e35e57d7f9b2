"""The ISO 12181-2 default filter of a section and the noise bias of its extremes.

**Default filter.**  Roundness is defined on the profile through the Gaussian filter of ISO
16610-21 with a cut-off in undulations per revolution (UPR) chosen from the diameter
(:data:`ISO_DEFAULT_UPR`: 15 UPR up to Ø 8 mm, 50 up to 25, 150 up to 80, 500 up to 250, 1500
above: the standard series of cut-offs, each band's upper diameter keeping the cut-off
wavelength π D / UPR at 1.57–1.68 mm; the breakpoints are not verified against the text of
ISO 12181-2, which was not in reach: docs/inspection.md says what public sources do say).  :func:`default_upr` picks it; ``lts360 inspect`` applies
it unless told ``--filter-upr N`` or ``--filter none``.

**Extremes of noisy data are biased.**  D max, D min, ovality and RONt are read at the
profile's extremes; noise on the bins pushes a maximum up and a minimum down, by more the more
independent bins sit near the extreme — a bias, not only a spread.  :func:`extreme_noise`
estimates both from the section's own noise by a Monte Carlo about the section's **form**, the
profile without its noise (:func:`denoised_form`): each order of the profile's Fourier series
is kept whole where its power stands out of the noise's power at that order (more than
:func:`form_threshold` times it: a pure-noise order passes once in n/2 profiles), dropped
otherwise.  The noise (its standard deviation per bin ``s`` and lag-1 correlation ``ρ``) is
measured as the residuals about that form (twice: the form from the caller's ``s``, ``ρ``, the
noise about it, the form again).  The residuals are redrawn in two ways, and each quantity
takes the larger bias and the larger u of the two: (a) a stationary Gaussian AR(1) noise with
that ``s`` and ``ρ``, its level raised where needed until the noise the filter passes has the
variance the residuals have through it; (b) a wild block bootstrap — each block of neighbouring
bins keeps its residuals, multiplied by a random sign (blocks of about twice the bins'
correlation length τ = (1 + ρ)/(1 − ρ), with a random start per draw), so a noisier view or a
stray point weighs in the draws as in the measurement.  The redrawn noise is passed through
the same filter and added to the form, and every extreme quantity is recomputed.  The mean
shift over the draws is the bias, their standard deviation the noise's u.  The reported value
is not corrected (a gauge reports the filtered extreme); the bias enters U linearly:
``U = 2 u_c + |bias|`` (:func:`lts360.inspect.run`).

Why a form without noise: the bias depends on the shape at the extremes (noise raises a flat
top more than a sharp peak).  A form that still carries noise (the profile through a filter at
a third of the cut-off, the earlier choice) has noise peaks for extremes, so noise added to it
raised them less than noise raises the true form's: measured on a realistic scan of the smooth
oval PVC pipe (20 sections, 150 UPR), RONt against the LS circle erred by +87 µm on average
while that form's bias was +59 µm; with the true form the same noise model gave +85 µm, and
with :func:`denoised_form` +80 µm.  The AR(1) model of the bins itself matched the error's
spectrum there (rendered error about the truth against the model, per band of orders).

RONt against the LS circle is recomputed on every draw about the linearised LS circle (the
first harmonic removed), and the MZCI's RONt takes its bias and u (both are peak-to-valleys of
the same radii about centres a few µm apart; the MZCI's is the smaller, so this errs on the
safe side); against the MCCI and MICI the circles are fitted again on the first
``circle_draws`` draws of each model (the MCCI and MICI of an oval are ill-conditioned: their
centre slides along a flat valley with the noise, so their RONt moves far more than the LS
one).  Those refits cost most of the time (~0.025 s a draw).
Gaps are left out of every extreme (their noise is filtered as if the profile were closed: a
small error at a gap's edge).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.inspect.profile import DEFAULT_GAP_DEG, BinnedProfile, uniform_profile

__all__ = ["ISO_DEFAULT_UPR", "default_upr", "gaussian_transfer", "filter_grid",
           "extreme_quantities", "ExtremeNoise", "extreme_noise", "DEFAULT_EXTREME_DRAWS",
           "EXTREME_KEYS", "FILTER_UPR_RANGE", "denoised_form", "form_threshold"]

#: Default cut-off (UPR) by diameter: ``(largest diameter in mm, UPR)`` (the breakpoints are
#: not verified against ISO 12181-2's text; docs/inspection.md).
ISO_DEFAULT_UPR = ((8.0, 15.0), (25.0, 50.0), (80.0, 150.0), (250.0, 500.0),
                   (float("inf"), 1500.0))
#: The cut-offs (UPR) a filter may be given, inclusive: from one undulation per revolution to
#: beyond the standard's finest default (ISO_DEFAULT_UPR's 500 UPR below Ø 250 mm).
FILTER_UPR_RANGE = (1.0, 1000.0)
#: Noise draws per section (64 give the bias to about ±12 % of u and u to ±9 %).
DEFAULT_EXTREME_DRAWS = 64
#: The quantities the Monte Carlo recomputes.
EXTREME_KEYS = ("d_min_mm", "d_max_mm", "ovality_mm", "ront_LSCI_mm", "ront_MZCI_mm",
                "ront_MCCI_mm", "ront_MICI_mm")
#: Draws on which the MCCI and MICI are fitted again, half from each noise model (32: bias to
#: ±18 % of u; each draw costs the two fits, ~0.025 s).  Every section is fitted: one section's
#: bias and u do not stand for its neighbours' (taking the nearest of five fitted sections' on
#: the realistic scans, RONt(MCCI) fell outside U in 5 of 89 sections; fitting each, in none).
DEFAULT_CIRCLE_DRAWS = 32


def default_upr(diameter_mm: float) -> float:
    """The default cut-off (UPR) for a diameter (mm, > 0), :data:`ISO_DEFAULT_UPR`."""
    if not (np.isfinite(diameter_mm) and diameter_mm > 0):
        raise ValueError(f"diameter_mm must be finite and > 0, got {diameter_mm}")
    return next(upr for d_max, upr in ISO_DEFAULT_UPR if diameter_mm <= d_max)


def gaussian_transfer(n_bins: int, upr: float) -> np.ndarray:
    """``(n_bins // 2 + 1,)`` transmission of order k = 0 … n_bins/2 through the Gaussian
    filter of cut-off ``upr``: ``exp(−π (α k / upr)²)``, ``α = √(ln 2 / π)`` (50 % at k = upr)."""
    if not upr > 0:
        raise ValueError(f"filter cut-off must be > 0 UPR, got {upr}")
    k = np.arange(n_bins // 2 + 1)
    return np.exp(-np.pi * (np.sqrt(np.log(2) / np.pi) * k / upr) ** 2)


def filter_grid(r_mm: np.ndarray, upr: float) -> np.ndarray:
    """The Gaussian filter on a uniform periodic grid ``r_mm : (..., n)`` (NaN: no bin): a
    normalised convolution, so a gap is neither filled in nor pulls its edges towards zero."""
    r = np.asarray(r_mm, float)
    w = np.isfinite(r).astype(float)
    H = gaussian_transfer(r.shape[-1], upr)
    num = np.fft.irfft(H * np.fft.rfft(np.where(w > 0, r, 0.0)), n=r.shape[-1])
    den = np.fft.irfft(H * np.fft.rfft(w), n=r.shape[-1])
    return np.where(w > 0, num / np.where(w > 0, den, 1.0), np.nan)


def extreme_quantities(r_mm: np.ndarray) -> dict[str, np.ndarray]:
    """Extremes of profiles on a uniform grid from −π, ``r_mm : (M, n)`` (n even, NaN: no bin).

    Two-point diameters ``r(θ) + r(θ + π)``, their min, max and range (ovality), and RONt about
    the linearised LS circle (the mean and the first harmonic fitted on the bins present and
    removed).  Each value ``(M,)``; NaN where no diameter is measured.
    """
    r = np.atleast_2d(np.asarray(r_mm, float))
    n = r.shape[1]
    if n % 2:
        raise ValueError(f"the grid needs an even number of bins, got {n}")
    d = r[:, : n // 2] + r[:, n // 2:]
    has_d = np.isfinite(d).any(axis=1)
    dd = np.where(np.isfinite(d), d, np.nan)
    with np.errstate(all="ignore"):
        d_min = np.where(has_d, np.nanmin(np.where(has_d[:, None], dd, 0.0), axis=1), np.nan)
        d_max = np.where(has_d, np.nanmax(np.where(has_d[:, None], dd, 0.0), axis=1), np.nan)
    th = -np.pi + 2 * np.pi * np.arange(n) / n
    ok = np.isfinite(r).all(axis=0)  # the bins present in every row (the same gaps)
    A = np.column_stack([np.ones(ok.sum()), np.cos(th[ok]), np.sin(th[ok])])
    coef = np.linalg.lstsq(A, r[:, ok].T, rcond=None)[0]
    res = r[:, ok] - (A @ coef).T
    ront = np.ptp(res, axis=1) if ok.sum() >= 3 else np.full(len(r), np.nan)
    return {"d_min_mm": d_min, "d_max_mm": d_max, "ovality_mm": d_max - d_min,
            "ront_LSCI_mm": ront}


def _circle_ront(centre_mm, r_mm: np.ndarray) -> dict[str, np.ndarray]:
    """RONt against the MCCI and MICI of each row of ``r_mm : (M, n)`` (grid from −π)."""
    from lts360.inspect.circles import maximum_inscribed_circle, minimum_circumscribed_circle

    n = r_mm.shape[1]
    th = -np.pi + 2 * np.pi * np.arange(n) / n
    ok = np.isfinite(r_mm).all(axis=0)
    out = {f"ront_{k}_mm": np.empty(len(r_mm)) for k in ("MCCI", "MICI")}
    for i, r in enumerate(r_mm):
        xy = np.asarray(centre_mm) + np.column_stack([r[ok] * np.cos(th[ok]),
                                                      r[ok] * np.sin(th[ok])])
        out["ront_MCCI_mm"][i] = minimum_circumscribed_circle(xy).ront_mm
        out["ront_MICI_mm"][i] = maximum_inscribed_circle(xy).ront_mm
    return out


@dataclass(frozen=True)
class ExtremeNoise:
    """The noise's bias and standard uncertainty of each extreme quantity (mm).

    Attributes
    ----------
    bias_mm, u_mm : dict name → float
        For :data:`EXTREME_KEYS`: mean shift over the draws (value with noise − value of the
        form) and the draws' standard deviation.
    n_draws : int
    s_bin_mm, rho : float
        The bins' noise model (standard deviation of one bin, lag-1 correlation).
    upr : float or None
        The filter the draws went through.
    """

    bias_mm: dict
    u_mm: dict
    n_draws: int
    s_bin_mm: float
    rho: float
    upr: float | None


def _ar1_noise(rng: np.random.Generator, m: int, n: int, s: float, rho: float) -> np.ndarray:
    """``(m, n)`` circular AR(1) noise of standard deviation ``s`` and lag-1 correlation ρ
    (white noise shaped by the AR(1) spectrum, normalised to unit variance)."""
    spec = _ar1_spectrum(n, rho)
    white = rng.standard_normal((m, n))
    return s * np.fft.irfft(np.sqrt(spec) * np.fft.rfft(white, axis=1), n=n, axis=1)


def _ar1_spectrum(n: int, rho: float) -> np.ndarray:
    """``(n // 2 + 1,)`` power of each order of circular AR(1) noise of unit variance on ``n``
    bins (mean 1 over the circle's ``n`` orders)."""
    f = np.fft.rfftfreq(n)
    spec = (1 - rho * rho) / np.abs(1 - rho * np.exp(-2j * np.pi * f)) ** 2
    wts = np.where((np.arange(f.size) == 0) | ((n % 2 == 0) & (np.arange(f.size) == f.size - 1)),
                   1.0, 2.0)
    return spec / ((spec * wts).sum() / n)


def denoised_form(r_mm: np.ndarray, s_bin_mm: float, rho: float) -> np.ndarray:
    """The form of a profile ``r_mm : (n,)`` (uniform grid, NaN: gap) without its noise.

    Each order k of the profile's Fourier series is kept whole or dropped: kept where its
    power exceeds :func:`form_threshold` times the power the bins' AR(1) noise (``s_bin_mm``,
    ``rho``) puts there, or where k <= 1 (the mean and the centre).  A gap is bridged by a
    straight line for the transform and is NaN again in the form.  With ``s_bin_mm`` = 0 the
    form is the profile.
    """
    r = np.asarray(r_mm, float)
    n = r.size
    ok = np.isfinite(r)
    if not ok.any() or not s_bin_mm > 0:
        return r.copy()
    idx = np.arange(n)
    filled = np.interp(idx, idx[ok], r[ok], period=n) if not ok.all() else r
    X = np.fft.rfft(filled)
    noise = n * s_bin_mm ** 2 * _ar1_spectrum(n, rho)
    keep = np.abs(X) ** 2 > form_threshold(n) * noise
    keep[:2] = True
    return np.where(ok, np.fft.irfft(np.where(keep, X, 0.0), n=n), np.nan)


def form_threshold(n_bins: int) -> float:
    """``2 ln(n_bins / 2)``: an order of pure noise (its power exponential about its mean)
    exceeds this many times its mean power with probability ``(2 / n_bins)²``, so on the
    ``n_bins / 2`` orders of a profile of noise alone the form keeps an order once in
    ``n_bins / 2`` profiles."""
    return 2.0 * float(np.log(max(n_bins, 4) / 2.0))


def _residual_noise(r: np.ndarray, form: np.ndarray, s: float, rho: float) -> tuple[float, float]:
    """``(s, ρ)`` of the residuals ``r − form`` (uniform grid, NaN: gap): their RMS and
    lag-1 correlation (clipped to [0, 0.99]); the given ``(s, ρ)`` where fewer than 8 bins."""
    res = r - form
    ok = np.isfinite(res)
    pair = ok & np.roll(ok, -1)
    if ok.sum() < 8 or pair.sum() < 8:
        return s, rho
    var = float(np.mean(res[ok] ** 2))
    if var == 0:
        return 0.0, 0.0
    r1 = float(np.mean((res * np.roll(res, -1))[pair])) / var
    return float(np.sqrt(var)), float(np.clip(r1, 0.0, 0.99))


def _wild_block_noise(rng: np.random.Generator, m: int, resid: np.ndarray,
                      rho: float) -> np.ndarray:
    """``(m, n)`` redraws of the residuals ``resid : (n,)``: each block of
    ``max(2, ⌈2τ⌉)`` neighbouring bins (τ = (1 + ρ)/(1 − ρ)) multiplied by a random sign,
    the blocks' start shifted at random per draw."""
    n = len(resid)
    L = int(max(2, np.ceil(2 * (1 + rho) / (1 - rho))))
    nb = -(-n // L) + 1
    signs = rng.choice([-1.0, 1.0], size=(m, nb))
    shift = rng.integers(0, L, size=m)
    block = (np.arange(n)[None, :] + shift[:, None]) // L
    return resid[None, :] * np.take_along_axis(signs, block, axis=1)


def extreme_noise(raw: BinnedProfile, *, upr: float | None, s_bin_mm: float, rho: float,
                  n_draws: int = DEFAULT_EXTREME_DRAWS, rng=None,
                  circle_draws: int = DEFAULT_CIRCLE_DRAWS, circles: bool = True,
                  gap_deg: float = DEFAULT_GAP_DEG) -> ExtremeNoise:
    """Bias and u of the extremes of one section from its own noise (module docstring).

    Parameters
    ----------
    raw : BinnedProfile
        The unfiltered binned profile.
    upr : float or None
        The filter the reported values went through (None: none).
    s_bin_mm : float, >= 0
        Standard deviation of one bin's noise.
    rho : float, [0, 1)
        Lag-1 correlation of neighbouring bins' noise.
    n_draws : int, >= 2
    circle_draws : int, [4, 2 n_draws]
        Draws (half of each noise model) on which the MCCI and MICI are fitted again.
    circles : bool
        False: leave the MCCI's and MICI's RONt out (NaN; they cost most of the time).
    rng : Generator | int | None
    """
    if n_draws < 2:
        raise ValueError(f"n_draws must be >= 2, got {n_draws}")
    rng = np.random.default_rng(rng)
    _, r = uniform_profile(raw, gap_deg=gap_deg)
    s = float(s_bin_mm) if np.isfinite(s_bin_mm) else 0.0
    rho = float(np.clip(rho if np.isfinite(rho) else 0.0, 0.0, 0.99))
    for _ in range(2):  # the form, then the noise about it, then the form again
        form = denoised_form(r, s, rho)
        s, rho = _residual_noise(r, form, s, rho)
    q0 = extreme_quantities(form[None, :])
    nan = np.full(1, np.nan)
    q0.update(_circle_ront(raw.centre_mm, form[None, :]) if circles else
              {"ront_MCCI_mm": nan, "ront_MICI_mm": nan})
    q0["ront_MZCI_mm"] = q0["ront_LSCI_mm"]
    m = int(np.clip(circle_draws // 2, 2, n_draws))
    bias = {k: float("nan") for k in EXTREME_KEYS}
    u = dict(bias)
    gauss = _ar1_noise(rng, n_draws, len(r), s, rho)
    resid = np.where(np.isfinite(r), r - form, 0.0)
    # the Gaussian model's level where it matters: the noise the filter passes must have the
    # variance the section's own residuals about the form have through that filter (a lag-1
    # model misses longer-range correlation, which the filter passes in full)
    passed = (lambda x: filter_grid(x, upr)) if upr is not None else (lambda x: x)
    obs = passed(np.where(np.isfinite(r), r - form, np.nan))
    var_obs = float(np.nanmean(obs ** 2)) if np.isfinite(obs).any() else 0.0
    var_mod = float(np.mean(passed(gauss) ** 2))
    if var_mod > 0 and var_obs > var_mod:
        gauss = gauss * np.sqrt(var_obs / var_mod)
    for noise in (gauss, _wild_block_noise(rng, n_draws, resid, rho)):
        if upr is not None:
            noise = np.fft.irfft(gaussian_transfer(len(r), upr) * np.fft.rfft(noise, axis=1),
                                 n=len(r), axis=1)
        q = extreme_quantities(form[None, :] + noise)
        q.update(_circle_ront(raw.centre_mm, form[None, :] + noise[:m]) if circles else
                 {"ront_MCCI_mm": nan, "ront_MICI_mm": nan})
        q["ront_MZCI_mm"] = q["ront_LSCI_mm"]
        for k in EXTREME_KEYS:
            v = q[k][np.isfinite(q[k])]
            if v.size < 2 or not np.isfinite(q0[k][0]):
                continue
            b, sd = float(v.mean() - q0[k][0]), float(v.std(ddof=1))
            if not abs(b) <= abs(bias[k]):  # NaN (the first) or larger
                bias[k] = b
            if not sd <= u[k]:
                u[k] = sd
    return ExtremeNoise(bias, u, int(n_draws), s, rho, upr)

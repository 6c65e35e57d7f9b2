"""Pixel locking of the line centre: a smooth fit of the rms sub-pixel error against line width.

The measurement samples the image along each radial search line with Keys' cubic kernel
(``a = −0.5``) and takes the centroid of ``I − threshold`` over the run above a 10 % threshold
(:mod:`lts360.recon.triangulation.peaks`).  For a Gaussian line of optical standard deviation
``σ`` (before pixel integration) imaged on square pixels (box integration, fill factor 1),
:func:`locking_rms_px` computes the error of that centroid numerically over sub-pixel phases
and returns its rms.  It is not monotonic in ``σ`` (the run's ends jump between samples), so
the model uses a smooth envelope: a cubic in ``σ`` fitted to ``log rms`` over
``[SIGMA_MIN, SIGMA_MAX]`` (:func:`locking_fit`), which its derivative can follow.

The threshold is taken as 1/8 of the line's peak (the 10 %-of-full-scale threshold on a line
exposed to 80 % of saturation).  Noise is not included here; it adds independently.
"""

from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["locking_rms_px", "locking_fit", "LOCKING_COEFFS", "SIGMA_MIN", "SIGMA_MAX",
           "THRESHOLD_FRACTION"]

#: Range of optical line σ (px) over which the fit holds; the model clamps σ into it.
SIGMA_MIN, SIGMA_MAX = 0.3, 4.0
#: Threshold as a fraction of the line's peak.
THRESHOLD_FRACTION = 0.125
_KEYS_A = -0.5
#: :func:`locking_fit` as computed (3 s); tests/design/test_locking.py checks it is current.
LOCKING_COEFFS = (0.414509921303487, -7.9555466443722, 2.269452488484479, -0.24667616077924237)


def _keys(x: np.ndarray) -> np.ndarray:
    a, x = _KEYS_A, np.abs(x)
    return np.where(x <= 1, (a + 2) * x**3 - (a + 3) * x**2 + 1,
                    np.where(x < 2, a * x**3 - 5 * a * x**2 + 8 * a * x - 4 * a, 0.0))


def locking_rms_px(sigma_px: float, *, phases: int = 32, step_px: float = 0.01,
                   threshold_fraction: float = THRESHOLD_FRACTION) -> float:
    """Rms over sub-pixel phase of the threshold-centroid error of a Gaussian line (px).

    Parameters
    ----------
    sigma_px : float, >0
        Optical standard deviation of the line across itself, before pixel integration.
    phases : int
        Sub-pixel phases, uniform in [0, 1).
    step_px : float
        Sampling step of the interpolated profile (the measurement's radial step is ~0.03 px).
    """
    from scipy.special import erf

    k = np.arange(-int(6 * sigma_px) - 8, int(6 * sigma_px) + 9)
    xs = np.arange(k[0] + 2, k[-1] - 2, step_px)
    taps = _keys(xs[:, None] - k[None, :])
    errs = []
    for ph in (np.arange(phases) + 0.5) / phases:
        pix = 0.5 * (erf((k + 0.5 - ph) / (math.sqrt(2) * sigma_px))
                     - erf((k - 0.5 - ph) / (math.sqrt(2) * sigma_px)))
        f = taps @ pix
        w = np.clip(f - threshold_fraction * pix.max(), 0.0, None)
        errs.append(float((w * xs).sum() / w.sum() - ph))
    e = np.asarray(errs)
    return float(np.sqrt(np.mean((e - e.mean()) ** 2)))


@functools.lru_cache(maxsize=1)
def locking_fit() -> tuple[float, float, float, float]:
    """Coefficients ``(c0, c1, c2, c3)``: ``log rms ≈ c0 + c1 σ + c2 σ² + c3 σ³`` on the
    upper envelope of :func:`locking_rms_px` (the running maximum over ±0.15 px of σ)."""
    sig = np.linspace(SIGMA_MIN, SIGMA_MAX, 75)
    fine = np.linspace(SIGMA_MIN - 0.15, SIGMA_MAX + 0.15, 180)
    rms = np.array([locking_rms_px(s, phases=16, step_px=0.02) for s in fine])
    env = np.array([rms[np.abs(fine - s) <= 0.15].max() for s in sig])
    c = np.polynomial.polynomial.polyfit(sig, np.log(env), 3)
    return tuple(float(v) for v in c)

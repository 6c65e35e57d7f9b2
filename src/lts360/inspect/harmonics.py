"""Harmonic content of r(θ): the lobes of a section.

``r(θ) ≈ a₀ + Σₖ (aₖ cos kθ + bₖ sin kθ)`` for k = 1 … K, fitted by least squares to the
profile's points about its centre — the points need not be uniform in θ and a gap is not
filled in (with a wide gap the high orders are ill-determined: the coverage says how far to
trust them).  A full circle sampled uniformly is solved by the FFT, which is the same
least-squares series.  The
amplitude of order k is ``Aₖ = √(aₖ² + bₖ²)`` (mm), its phase ``atan2(bₖ, aₖ)/k`` the
direction of one lobe.  About the LS centre A₁ ≈ 0; an ellipse has A₂ = (Dmax − Dmin)/4; a
three-lobed profile shows in A₃ (the peak-to-valley it causes is 2·A₃).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

__all__ = ["Harmonics", "fit_harmonics", "DEFAULT_MAX_ORDER"]

#: Orders fitted by default (cable strands up to 19 and their doubles fit below).
DEFAULT_MAX_ORDER = 50


@dataclass(frozen=True)
class Harmonics:
    """Fourier series of r(θ) (mm).

    Attributes
    ----------
    mean_mm : float
        a₀.
    amplitude_mm : (K,) float
        Aₖ for k = 1 … K.
    phase_deg : (K,) float
        Direction of a maximum of order k, in [0, 360/k).
    residual_rms_mm : float
        RMS of the points about the series (the profile's scatter beyond order K).
    n_points : int
    """

    mean_mm: float
    amplitude_mm: np.ndarray
    phase_deg: np.ndarray
    residual_rms_mm: float
    n_points: int

    @property
    def orders(self) -> np.ndarray:
        return np.arange(1, len(self.amplitude_mm) + 1)

    def amplitude(self, k: int) -> float:
        """Aₖ (mm), NaN for an order that was not fitted."""
        return float(self.amplitude_mm[k - 1]) if 1 <= k <= len(self.amplitude_mm) else np.nan

    def dominant(self, *, from_order: int = 2) -> tuple[int, float]:
        """``(k, Aₖ)`` of the largest amplitude from ``from_order`` up."""
        a = self.amplitude_mm[from_order - 1:]
        if a.size == 0:
            return from_order, float("nan")
        k = int(np.argmax(a)) + from_order
        return k, float(self.amplitude_mm[k - 1])


def fit_harmonics(theta_rad, r_mm, *, max_order: int = DEFAULT_MAX_ORDER) -> Harmonics:
    """Least-squares Fourier series of ``r_mm(theta_rad)`` (both (n,) float) up to
    ``max_order`` (reduced to (n − 1)/2 for few points)."""
    th = np.asarray(theta_rad, dtype=float)
    r = np.asarray(r_mm, dtype=float)
    if th.shape != r.shape or th.ndim != 1 or th.size < 3:
        raise ValueError(f"theta_rad and r_mm must be (n,) with n >= 3, got {th.shape}, {r.shape}")
    K = int(max(1, min(max_order, (th.size - 1) // 2)))
    k = np.arange(1, K + 1)
    n = th.size
    grid = th[0] + 2 * np.pi * np.arange(n) / n
    if np.max(np.abs(np.angle(np.exp(1j * (th - grid))))) < 1e-9 and n >= 2 * K + 1:
        # a full, uniform circle: the least-squares series is the DFT
        f = np.fft.rfft(r) / n * np.exp(-1j * np.arange(n // 2 + 1) * th[0])
        a0 = float(f[0].real)
        ab = 2.0 * f[1:K + 1]
        a, b = ab.real, -ab.imag
        if 2 * K == n:
            a[-1] /= 2.0
        res = r - a0 - np.cos(np.outer(th, k)) @ a - np.sin(np.outer(th, k)) @ b
    else:
        kt = np.outer(th, k)
        A = np.column_stack([np.ones_like(th), np.cos(kt), np.sin(kt)])
        N = np.einsum("ij,ik->jk", A, A)  # normal equations (small: BLAS threads cost more)
        N[np.diag_indices_from(N)] *= 1.0 + 1e-10
        try:
            coef = cho_solve(cho_factor(N), np.einsum("ij,i->j", A, r))
        except np.linalg.LinAlgError:  # a wide gap: the high orders are not determined
            coef = np.linalg.lstsq(A, r, rcond=1e-10)[0]
        a0, a, b = float(coef[0]), coef[1:K + 1], coef[K + 1:]
        res = r - A @ coef
    dof = max(1, n - (2 * K + 1))
    return Harmonics(a0, np.hypot(a, b), np.degrees(np.mod(np.arctan2(b, a), 2 * np.pi) / k),
                     float(np.sqrt(res @ res / dof)), int(n))

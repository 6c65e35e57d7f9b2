"""Laser speckle: theory (integrated speckle over a square pixel) and the simulated pattern.

Assumptions tested are those of :mod:`lts360.simulator.speckle`: fully developed speckle (a
circular complex Gaussian field), a circular pupil, pixels integrating their full square,
mean-1 multiplicative pattern.  Not modelled (not tested): partially developed speckle from
smooth surfaces (only a phenomenological contrast scale), coherent imaging of the narrow
stripe, defocus-dependent statistics, temporal decorrelation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from lts360.simulator import speckle as SP

# ---- tolerances (one place, each with its reason) ------------------------------------------
#: Simulated vs theoretical contrast at the default oversampling: the Riemann sum over
#: s × s samples per pixel biases the contrast by +1–2 % (measured, module docstring); the
#: sampling error of the 3 × 128² estimate is < 1 %.
CONTRAST_RTOL = 0.05
#: Goodman's Gaussian-correlation approximation vs the exact Airy correlation: it overstates
#: C by up to ~5 % between the limits (3.8 % at f/1.4, 4.9 % at f/2.8 for 5.3 µm, 660 nm).
GOODMAN_RTOL = 0.06
#: Large-speckle contrast from 4 × 512² px with ~1800 correlation cells each: ±1.2 % (1 sigma).
LARGE_SPECKLE_RTOL = 0.05

#: The position-keyed pattern's PSF is truncated at 16 λ N_w: its exact contrast lies +1.9 %
#: (f/1.4) and +2.1 % (f/2.8) above the theory (Riemann bias plus truncation); bounded at 3 %.
KEYED_BIAS_RTOL = 0.03
#: Contrast of 3 × 256² px of keyed speckle against its exact value: ~0.5 % (1 sigma).
KEYED_SAMPLING_RTOL = 0.015

PAPER = dict(pixel_pitch_um=5.3, wavelength_nm=660.0)


# ---- theory ------------------------------------------------------------------------------------
def test_theory_at_paper_settings():
    # Anchors of the exact formula (quadrature converged to ~1e-10): see the module docstring.
    assert SP.speckle_contrast_theory(f_number=1.4, **PAPER) == pytest.approx(0.17775, abs=2e-5)
    assert SP.speckle_contrast_theory(f_number=2.8, **PAPER) == pytest.approx(0.32804, abs=2e-5)
    assert SP.speckle_size_um(660.0, 1.4) == pytest.approx(1.22 * 0.66 * 1.4, rel=1e-3)
    assert SP.correlation_area_um2(660.0, 1.4) == pytest.approx(4 * (0.66 * 1.4) ** 2 / math.pi)


def test_exact_theory_agrees_with_frequency_domain_integral():
    """1/M = (1/(π f_c²)) ∬ sinc²(p fx) sinc²(p fy) H(|f|) df, H the incoherent OTF of the
    circular pupil (cut-off 2 f_c): the Fourier-side form of the same integral."""
    for N in (1.4, 2.8, 8.0):
        fc = SP.coherent_cutoff_cyc_per_um(660.0, N)
        p = 5.3
        f = np.linspace(-2 * fc, 2 * fc, 1201)
        FX, FY = np.meshgrid(f, f)
        nu = np.minimum(np.hypot(FX, FY) / (2 * fc), 1.0)
        H = 2 / np.pi * (np.arccos(nu) - nu * np.sqrt(1 - nu * nu))
        integrand = np.sinc(p * FX) ** 2 * np.sinc(p * FY) ** 2 * H
        m_inv = np.trapezoid(np.trapezoid(integrand, f, axis=1), f) / (math.pi * fc * fc)
        # 3e-4: trapezoid rule on the OTF's (1 − ν)^{3/2} edge with 1201² nodes.
        assert SP.speckle_cells_per_pixel(p, 660.0, N) == pytest.approx(1 / m_inv, rel=3e-4)


def test_theory_limits_and_goodman_approximation():
    # Pixel ≪ speckle: one cell, C → 1; pixel ≫ speckle: M → p² / A_c (from above: edges).
    for method in ("exact", "goodman"):
        assert SP.speckle_cells_per_pixel(0.02, 660.0, 1.4, method=method) == pytest.approx(1.0, abs=1e-3)
        big = SP.speckle_cells_per_pixel(200.0, 660.0, 1.4, method=method)
        assert big / (200.0 ** 2 / SP.correlation_area_um2(660.0, 1.4)) == pytest.approx(1.0, abs=0.01)
    for N in (1.4, 2.8, 8.0, 16.0):
        exact = SP.speckle_contrast_theory(f_number=N, **PAPER)
        approx = SP.speckle_contrast_theory(f_number=N, method="goodman", **PAPER)
        assert approx == pytest.approx(exact, rel=GOODMAN_RTOL)
    # Depolarised: twice the cells; contrast_scale: proportional.
    c = SP.speckle_contrast_theory(f_number=2.8, **PAPER)
    assert SP.speckle_contrast_theory(f_number=2.8, polarization="depolarized", **PAPER) == \
        pytest.approx(c / math.sqrt(2))
    assert SP.speckle_contrast_theory(f_number=2.8, contrast_scale=0.5, **PAPER) == pytest.approx(c / 2)
    # The working f-number: magnification m acts as N (1 + m).
    assert SP.speckle_contrast_theory(f_number=1.4, magnification=1.0, **PAPER) == \
        pytest.approx(SP.speckle_contrast_theory(f_number=2.8, **PAPER))


# ---- simulated pattern ---------------------------------------------------------------------------
def test_pattern_mean_one_and_dtype():
    P = SP.speckle_pattern((96, 128), f_number=2.8, rng=0, **PAPER)
    assert P.shape == (96, 128) and P.dtype == np.float32
    assert P.mean(dtype=np.float64) == pytest.approx(1.0, abs=1e-6)
    assert P.min() >= 0


@pytest.mark.parametrize("f_number", [1.4, 2.8])
def test_contrast_matches_theory_at_paper_settings(f_number):
    theory = SP.speckle_contrast_theory(f_number=f_number, **PAPER)
    c = np.mean([SP.speckle_pattern((128, 128), f_number=f_number, rng=k, **PAPER).std()
                 for k in range(3)])
    assert c == pytest.approx(theory, rel=CONTRAST_RTOL)


def test_large_speckle_is_fully_developed():
    # 0.5 µm pixels, f/8: speckle 6.4 µm across, M = 1.007, C_theory = 0.996.
    kw = dict(pixel_pitch_um=0.5, wavelength_nm=660.0, f_number=8.0)
    theory = SP.speckle_contrast_theory(**kw)
    assert theory > 0.99
    P = np.stack([SP.speckle_pattern((512, 512), rng=k, **kw) for k in range(4)]).astype(float)
    assert P.std() == pytest.approx(theory, rel=LARGE_SPECKLE_RTOL)
    # Exponential moments <I²> = 2, <I³> = 6 (gamma with M ≈ 1): 6 % / 12 % for the
    # correlated 4 × 512² samples (~7000 cells; the third moment is heavy-tailed).
    M = SP.speckle_cells_per_pixel(**kw)
    assert np.mean(P ** 2) == pytest.approx(1 + 1 / M, rel=0.06)
    assert np.mean(P ** 3) == pytest.approx((1 + 1 / M) * (1 + 2 / M), rel=0.12)


def test_point_intensity_is_exponential():
    """Chi-square of point samples against Exp(1): the field is circular complex Gaussian.

    Samples 4 µm apart (> 1.22 λN = 3.2 µm, the first zero of the correlation; the side lobes
    are < 2 %) are treated as independent; 20 equiprobable bins, 19 degrees of freedom,
    rejected at p = 0.001 (fixed seeds: deterministic)."""
    x = np.concatenate([
        SP.speckle_intensity((512, 512), sample_pitch_um=0.5, wavelength_nm=660.0, f_number=4.0,
                             rng=k)[::8, ::8].ravel() for k in range(4)]).astype(float)
    n_bins = 20
    edges = stats.expon.ppf(np.linspace(0.0, 1.0, n_bins + 1))
    counts = np.histogram(x, edges)[0]
    expected = x.size / n_bins
    chi2 = float(np.sum((counts - expected) ** 2 / expected))
    assert chi2 < stats.chi2.ppf(0.999, n_bins - 1), chi2
    assert np.mean(x ** 2) == pytest.approx(2.0, rel=0.05)     # 16384 samples: ±1.7 %
    assert np.mean(x ** 3) == pytest.approx(6.0, rel=0.12)     # heavy tail: ±4 %


def test_depolarized_and_contrast_scale():
    c1 = np.mean([SP.speckle_pattern((128, 128), f_number=2.8, rng=k, **PAPER).std()
                  for k in range(3)])
    c2 = np.mean([SP.speckle_pattern((128, 128), f_number=2.8, rng=k, polarization="depolarized",
                                     **PAPER).std() for k in range(3)])
    assert c2 / c1 == pytest.approx(1 / math.sqrt(2), rel=CONTRAST_RTOL)
    full = SP.speckle_pattern((64, 64), f_number=2.8, rng=5, **PAPER)
    half = SP.speckle_pattern((64, 64), f_number=2.8, rng=5, contrast_scale=0.5, **PAPER)
    assert np.allclose(half, 1 + 0.5 * (full - 1), atol=1e-6)


def test_determinism():
    kw = dict(f_number=1.4, **PAPER)
    a = SP.speckle_pattern((64, 80), rng=3, **kw)
    assert np.array_equal(a, SP.speckle_pattern((64, 80), rng=3, **kw))
    assert np.array_equal(a, SP.speckle_pattern((64, 80), rng=3, workers=1, **kw))
    ss = np.random.SeedSequence(3)
    assert np.array_equal(SP.speckle_pattern((64, 80), rng=ss, **kw),
                          SP.speckle_pattern((64, 80), rng=ss, **kw))
    assert not np.array_equal(a, SP.speckle_pattern((64, 80), rng=4, **kw))
    g = np.random.default_rng(9)
    assert not np.array_equal(SP.speckle_pattern((32, 32), rng=g, **kw),
                              SP.speckle_pattern((32, 32), rng=g, **kw))
    assert np.array_equal(SP.speckle_pattern((32, 32), rng=np.random.default_rng(9), **kw),
                          SP.speckle_pattern((32, 32), rng=np.random.default_rng(9), **kw))


@pytest.mark.parametrize("kwargs, match", [
    (dict(oversample=5), "oversample=5 is too small"),
    (dict(oversample=0), "oversample must be an integer in"),
    (dict(polarization="circular"), "polarization must be one of"),
    (dict(contrast_scale=1.5), "contrast_scale must be in"),
    (dict(pixel_pitch_um=-1.0), "pixel_pitch_um must be a positive"),
])
def test_validation(kwargs, match):
    kw = dict(f_number=1.4, rng=0, **PAPER)
    kw.update(kwargs)
    with pytest.raises(ValueError, match=match):
        SP.speckle_pattern((16, 16), **kw)


def test_full_frame_smoke():
    P = SP.speckle_pattern((1024, 1280), f_number=1.4, rng=0, **PAPER)
    assert P.shape == (1024, 1280) and P.dtype == np.float32 and np.isfinite(P).all()
    assert P.mean(dtype=np.float64) == pytest.approx(1.0, abs=1e-6)
    assert P.std() == pytest.approx(SP.speckle_contrast_theory(f_number=1.4, **PAPER),
                                    rel=CONTRAST_RTOL)


# ---- position-keyed speckle on the lit tiles only ----------------------------------------------
def test_tiles_have_the_patterns_contrast_and_correlation():
    """Speckle drawn on the lit tiles of a frame (a stripe): its contrast is the one computed
    exactly from its PSF, within CONTRAST_RTOL of the theory; its correlation at one and two
    pixels is a whole pattern's, across tile edges too; unlit tiles are 1; the same seed gives
    the same pattern."""
    kw = dict(f_number=1.4, **PAPER)
    lit = np.zeros((512, 640), bool)
    lit[100:104, :] = True           # a horizontal stripe: 20 tiles
    lit[200:500, 300:303] = True     # a vertical one: 10 tiles
    P = SP.speckle_on_tiles(lit, rng=7, **kw)
    assert P.shape == lit.shape and P.dtype == np.float32
    T = SP.keyed_tile_px(**kw)
    assert SP.SPECKLE_TILE_PX * 3 // 4 <= T <= SP.SPECKLE_TILE_PX
    # Computed: each lit tile's groups of _ROW_GROUP rows that hold a lit pixel of the tile.
    G = SP._ROW_GROUP
    ys, xs = np.mgrid[:512, :640]
    groups = {(y // T, x // T, (y % T) // G) for y, x in zip(*np.nonzero(lit))}
    on = np.array([(y // T, x // T, (y % T) // G) in groups
                   for y, x in zip(ys.ravel(), xs.ravel())]).reshape(lit.shape)
    assert np.all(P[~on] == 1.0) and np.all(P[on] != 1.0)
    assert np.array_equal(P, SP.speckle_on_tiles(lit, rng=7, **kw))
    theory = SP.speckle_contrast_theory(**kw)
    assert SP.keyed_contrast(**kw) == pytest.approx(theory, rel=KEYED_BIAS_RTOL)
    # 30 tiles of 32² px (~1000 speckle cells each at f/1.4): the contrast to CONTRAST_RTOL.
    assert P[on].std() == pytest.approx(theory, rel=CONTRAST_RTOL)
    whole = np.stack([SP.speckle_pattern((256, 256), rng=k, **kw) for k in range(2)])

    def corr(a, lag):
        return np.corrcoef(a[..., :-lag].ravel(), a[..., lag:].ravel())[0, 1]

    g0 = 100 // T * T + (100 % T) // G * G
    row = P[g0:g0 + G]                              # the horizontal stripe's 20 tiles in a row
    for lag in (1, 2):
        # Correlation estimates from ~20 000 pixel pairs: ±0.02 (their sampling error).
        assert corr(row, lag) == pytest.approx(corr(whole, lag), abs=0.03)


def test_keyed_speckle_is_a_function_of_position():
    """A pixel's speckle depends on its position and the seed only: drawn with fewer lit
    tiles (a support frame) it is the same bit for bit; with another tile size it is the same
    field (to float32 rounding of other FFT sizes), so tiles leave no seam; another seed
    gives another pattern; threads do not change it."""
    kw = dict(f_number=2.8, magnification=0.043, **PAPER)
    lit = np.zeros((300, 400), bool)
    lit[40:260, 180:186] = True
    lit[150:153, 20:380] = True
    A = SP.speckle_on_tiles(lit, rng=11, **kw)
    part = np.zeros_like(lit)
    part[140:160, 200:300] = lit[140:160, 200:300]
    B = SP.speckle_on_tiles(part, rng=11, **kw)
    on = B != 1.0
    assert on.sum() >= 600 and np.array_equal(A[on], B[on])   # 4 tiles × 8 rows
    C = SP.speckle_on_tiles(lit, rng=11, tile_px=48, **kw)
    both = (A != 1.0) & (C != 1.0)
    # float32 FFTs of other lengths: agreement to ~1e-6 of the values (3e-5 with margin).
    np.testing.assert_allclose(C[both], A[both], rtol=3e-5, atol=3e-5)
    assert np.array_equal(A, SP.speckle_on_tiles(lit, rng=11, workers=1, **kw))
    assert not np.allclose(A[on], SP.speckle_on_tiles(lit, rng=12, **kw)[on])
    ss = np.random.SeedSequence(4)
    assert np.array_equal(SP.speckle_on_tiles(part, rng=ss, **kw),
                          SP.speckle_on_tiles(part, rng=ss, **kw))


@pytest.mark.parametrize("f_number", [1.4, 2.8])
def test_keyed_contrast_mean_and_polarisation(f_number):
    """On a whole 256² image: the contrast is :func:`keyed_contrast` (±1 % sampling error of
    3 × 256² px) and within CONTRAST_RTOL of the theory; the mean is 1 (expectation, not
    normalised: ±0.3 % for ~10⁵ cells); two fields divide the contrast by √2; the contrast
    scale scales I − 1."""
    kw = dict(f_number=f_number, **PAPER)
    lit = np.ones((256, 256), bool)
    P = np.stack([SP.speckle_on_tiles(lit, rng=k, **kw) for k in range(3)]).astype(float)
    assert P.std() == pytest.approx(SP.keyed_contrast(**kw), rel=KEYED_SAMPLING_RTOL)
    assert P.std() == pytest.approx(SP.speckle_contrast_theory(**kw), rel=CONTRAST_RTOL)
    assert P.mean() == pytest.approx(1.0, abs=3e-3)
    D = np.stack([SP.speckle_on_tiles(lit, rng=k, polarization="depolarized", **kw)
                  for k in range(3)]).astype(float)
    assert D.std() / P.std() == pytest.approx(1 / math.sqrt(2), rel=CONTRAST_RTOL)
    half = SP.speckle_on_tiles(lit, rng=0, contrast_scale=0.5, **kw)
    np.testing.assert_allclose(half, 1 + 0.5 * (P[0] - 1), atol=1e-6)


def test_keyed_tiles_take_a_smooth_fft_length():
    """The tile side is the largest within a quarter below ``tile_px`` whose padded tile is a
    2-3-5-smooth FFT length (the paper rig at f/2.8: 31 px, 256 fine samples); a pixel's value
    is the same at another side (to float32 rounding), and never below the PSF's diameter."""
    kw = dict(f_number=2.8, magnification=0.043, **PAPER)
    T = SP.keyed_tile_px(**kw)
    s = SP.auto_oversample(PAPER["pixel_pitch_um"], PAPER["wavelength_nm"], 2.8, 0.043)
    fcd = SP.coherent_cutoff_cyc_per_um(PAPER["wavelength_nm"], 2.8, 0.043) \
        * PAPER["pixel_pitch_um"] / s
    radius = math.ceil(SP.KEYED_PSF_RADIUS / (2.0 * fcd))
    n = T * s + 2 * radius
    assert 24 <= T <= 32 and SP._fft_len(n) == n
    assert all(SP._fft_len(t * s + 2 * radius) != t * s + 2 * radius for t in range(T + 1, 33))
    assert SP.keyed_tile_px(tile_px=4, **kw) == 2 * -(-radius // s)
    lit = np.zeros((96, 96), bool)
    lit[40:44, 10:90] = True
    A = SP.speckle_on_tiles(lit, rng=5, **kw)
    assert SP.keyed_tile_px(tile_px=T - 1, **kw) < T
    B = SP.speckle_on_tiles(lit, rng=5, tile_px=T - 1, **kw)   # another tile grid
    both = (A != 1.0) & (B != 1.0)
    assert both.sum() >= 320
    np.testing.assert_allclose(A[both], B[both], rtol=3e-5, atol=3e-5)

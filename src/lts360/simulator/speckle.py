"""Laser speckle: a statistical model of the speckle pattern seen by the pixels.

Model and assumptions
---------------------
* Fully developed speckle: the surface is optically rough (height variations ≫ λ over a
  resolution cell), so the scattered phases are uniform and independent, and the field in the
  image plane is a circular complex Gaussian process (Goodman).
* Imaging through a circular pupil, in focus: the image-plane field is white complex noise
  low-pass filtered by the coherent transfer function, a disk of radius
  ``f_c = 1 / (2 λ N_w)`` [cycles/µm], ``N_w = N (1 + |m|)`` the working f-number.  (The
  *intensity* spectrum reaches twice that, ``1 / (λ N_w)`` — the incoherent OTF cut-off.)
  The intensity correlation is ``|μ(r)|² = [2 J1(x) / x]²``, ``x = π r / (λ N_w)``; its first
  zero, the "speckle size", is at ``r = 1.22 λ N_w``; the correlation area is
  ``A_c = ∫|μ|² = 4 λ² N_w² / π``.
* Pixels integrate the intensity over their full square area (fill factor 1).  The result is
  a multiplicative pattern with mean 1 whose contrast ``C = σ_I / <I>`` falls below 1 when the
  speckle is comparable to or smaller than the pixel (``C = 1 / √M``, ``M`` speckle
  "correlation cells" per pixel, see :func:`speckle_cells_per_pixel`).
* One polarisation by default; ``polarization="depolarized"`` adds two independent patterns
  (a depolarising, e.g. volume-scattering, surface), ``C → C / √2``.  Partially developed
  speckle (roughness ≲ λ) is not modelled physically; ``contrast_scale`` scales the deviation
  from the mean, ``1 + s (I − 1)``, as a phenomenological knob.
* The pattern multiplies the laser's share of the expected radiance.  That is valid when the
  speckle is small compared with the scale on which that radiance varies (the stripe width);
  for speckle as large as the stripe a coherent image model would be needed (not done).
  Defocus (the mirror views lie farther than the focus) does not change the statistics: a
  pupil phase multiplies white circular noise by a unit phasor, which leaves it white and
  circular, so the same pupil cut-off holds for every view.
* Time: the pattern is a function of its seed only.  A static object under a static laser
  has the *same* speckle in every frame — pass the same ``rng`` seed; moving the stage by
  more than the illuminated spot decorrelates it — pass a new one.
* The pattern is periodic over the image (FFT), which is harmless for a stationary process.

Numerics
--------
The field is synthesised on a grid ``oversample`` (``s``) times finer than the pixels: i.i.d.
complex Gaussian coefficients inside the pupil disk (the DFT of white noise is white noise, so
no forward FFT is needed), an inverse FFT, ``|u|²``, then a box sum over each pixel's
``s × s`` samples (a Riemann sum of the pixel integral).  The field is
represented exactly once ``oversample > 2 f_c p``; the intensity, band-limited to ``2 f_c``,
is then aliased only at spatial frequencies above ``oversample/p − 2 f_c``, where the pixel's
sinc² transfer is small.  The remaining error is a small positive bias of the contrast (the
Riemann sum of ``s × s`` point samples slightly over-weights high frequencies).  The default
``oversample = ceil(2 f_c p + 2.5)`` (at least 3) keeps it within about 2 % of
:func:`speckle_contrast_theory` (measured over 16 × 256² px: +1.4 % at f/1.4 and +1.6 % at
f/2.8 for 660 nm, 5.3 µm; it falls roughly as 1/s², e.g. +0.5 % at s = 16).  At f/1.4 the
default is s = 9: for 1280 × 1024 pixels the field has 34 M random coefficients, and the
inverse DFT runs along y for the pupil's 7349 columns (a 7349 × 9216 complex64 array,
0.54 GB) and then along x in strips of rows, so the full 11520 × 9216 grid is never held.
Measured on 2 cores: ~0.9–2.5 s at f/1.4 (the first call in a process pays the page faults),
~0.3 s at f/2.8.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from lts360.scenes.checks import check_positive as _positive
from lts360.simulator.sensor import _run_blocks, block_threads, seed_sequence, spawn_generators

__all__ = ["working_f_number", "coherent_cutoff_cyc_per_um", "speckle_size_um",
           "correlation_area_um2", "speckle_cells_per_pixel", "speckle_contrast_theory",
           "auto_oversample", "speckle_pattern", "speckle_intensity", "speckle_on_tiles",
           "keyed_contrast", "keyed_tile_px", "POLARIZATIONS", "MAX_FIELD_SAMPLES",
           "SPECKLE_TILE_PX", "KEYED_PSF_RADIUS"]

#: Polarisation states: one speckle pattern, or the sum of two independent ones.
POLARIZATIONS = ("polarized", "depolarized")
#: Largest intermediate field (pupil columns × fine rows) the synthesis holds: 2.1 GB of
#: complex64 (0.54 GB at f/1.4 for 1280 × 1024 pixels).
MAX_FIELD_SAMPLES = 2 ** 28
#: Margin (in cycles per pixel) of the default oversampling above the field's bandwidth.
OVERSAMPLE_MARGIN = 2.5
#: Spawn key of the speckle stream of an integer seed.
_SPECKLE_KEY = 0x5BEC1E
#: Blocks of spectrum columns, each with its own child stream (fixed: thread-count independent).
_N_BLOCKS = 64
_METHODS = ("exact", "goodman")
#: Largest side of the tiles on which :func:`speckle_on_tiles` draws speckle (pixels); the side
#: used is the largest within a quarter below it whose padded tile is a 2-3-5-smooth FFT length
#: (:func:`keyed_tile_px`).
SPECKLE_TILE_PX = 32
#: Radius, in ``λ N_w``, at which :func:`speckle_on_tiles` truncates the amplitude PSF (it
#: keeps 98.7 % of its energy; the pixel contrast is +1.9–2.1 % above the theory's, see there).
KEYED_PSF_RADIUS = 16.0
#: Pixel rows of a tile computed together by :func:`speckle_on_tiles`'s last inverse DFT: only
#: the groups that hold a lit pixel are computed (each group alone: the same arithmetic
#: whichever other groups are).
_ROW_GROUP = 8
#: Fine samples per strip of the final inverse DFT along x (bounds the working memory).
_STRIP_SAMPLES = 2 ** 20


# --------------------------------------------------------------------------------- optics
def working_f_number(f_number: float, magnification: float = 0.0) -> float:
    """Image-side working f-number ``N_w = N (1 + |m|)`` (pupil magnification 1)."""
    _positive("f_number", f_number)
    if not math.isfinite(float(magnification)):
        raise ValueError(f"magnification must be finite, got {magnification!r}")
    return float(f_number) * (1.0 + abs(float(magnification)))


def coherent_cutoff_cyc_per_um(wavelength_nm: float, f_number: float,
                               magnification: float = 0.0) -> float:
    """Radius of the coherent transfer function in the image plane, ``1 / (2 λ N_w)``."""
    _positive("wavelength_nm", wavelength_nm)
    return 1.0 / (2.0 * float(wavelength_nm) * 1e-3 * working_f_number(f_number, magnification))


def speckle_size_um(wavelength_nm: float, f_number: float, magnification: float = 0.0) -> float:
    """``1.22 λ N_w``: radius of the first zero of the intensity correlation (Airy pattern)."""
    return 0.5 * 1.2196698912665045 / coherent_cutoff_cyc_per_um(wavelength_nm, f_number,
                                                                 magnification)


def correlation_area_um2(wavelength_nm: float, f_number: float, magnification: float = 0.0
                         ) -> float:
    """``A_c = ∫ |μ|² dA = 4 λ² N_w² / π`` — the area of one speckle correlation cell."""
    fc = coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification)
    return 1.0 / (math.pi * fc * fc)


# --------------------------------------------------------------------------------- theory
def speckle_cells_per_pixel(pixel_pitch_um: float, wavelength_nm: float, f_number: float, *,
                            magnification: float = 0.0, method: str = "exact") -> float:
    """Number ``M`` of speckle correlation cells integrated by one square pixel.

    ``method="exact"`` (default): Goodman's second-moment result for intensity integrated over
    an aperture, ``1/M = (1/A²) ∬ K_pix(Δ) |μ(Δ)|² dΔ`` with ``K_pix(Δ) = (p − |Δx|)(p − |Δy|)``
    the pixel's autocorrelation and ``|μ|² = [2 J1(x)/x]²`` the correlation of speckle behind a
    circular pupil — exact for the contrast of fully developed speckle; evaluated by
    composite Gauss–Legendre quadrature (converged to ~1e-10).

    ``method="goodman"``: Goodman's closed-form approximation that replaces ``|μ|²`` by a
    Gaussian of the same correlation area ``A_c`` (``ℓ = √A_c``), per axis
    ``1/M_x = (ℓ/p) erf(√π p/ℓ) − (ℓ/p)² (1 − exp(−π p²/ℓ²)) / π`` and ``M = M_x²``.
    It agrees with ``exact`` in both limits (``M → 1`` for small pixels, ``M → p²/A_c`` for
    large ones) and within a few per cent of ``C`` in between.

    References: J. W. Goodman, *Statistical Optics* (Wiley), and *Speckle Phenomena in
    Optics* (Roberts, 2007), the sections on integrated speckle.
    """
    if method not in _METHODS:
        raise ValueError(f"method must be one of {', '.join(_METHODS)}, got {method!r}")
    _positive("pixel_pitch_um", pixel_pitch_um)
    p = float(pixel_pitch_um)
    fc = coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification)
    if method == "goodman":
        from scipy.special import erf

        r = p / math.sqrt(1.0 / (math.pi * fc * fc))      # p / ℓ
        mx_inv = erf(math.sqrt(math.pi) * r) / r - (1.0 - math.exp(-math.pi * r * r)) / (math.pi * r * r)
        return float(1.0 / (mx_inv * mx_inv))
    from scipy.special import j1

    lam_n = 1.0 / (2.0 * fc)                             # λ N_w in µm
    # Composite Gauss–Legendre on [0, p]: 32 nodes per panel of <= 4 λN (the Airy correlation
    # oscillates with period ~λN), ~1e-10 relative.
    panels = max(1, math.ceil(p / (4.0 * lam_n)))
    xr, wr = np.polynomial.legendre.leggauss(32)
    h = p / panels
    x = (np.arange(panels)[:, None] * h + 0.5 * h * (xr[None, :] + 1.0)).ravel()
    w = np.tile(0.5 * h * wr, panels)
    kx = w * (p - x)                                     # 1-D weights × (p − x)
    a = (math.pi / lam_n) * np.hypot(x[:, None], x[None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        g = np.where(a > 1e-12, 2.0 * j1(a) / a, 1.0)
    m_inv = 4.0 / p ** 4 * float(kx @ (g * g) @ kx)
    return float(1.0 / m_inv)


def speckle_contrast_theory(pixel_pitch_um: float, wavelength_nm: float, f_number: float, *,
                            magnification: float = 0.0, polarization: str = "polarized",
                            method: str = "exact", contrast_scale: float = 1.0) -> float:
    """Contrast ``σ_I / <I>`` of pixel-integrated, fully developed speckle.

    ``C = contrast_scale / √(M · P)``, ``M`` from :func:`speckle_cells_per_pixel` (``method``),
    ``P = 1`` polarised, ``2`` depolarised.  At 660 nm and 5.3 µm pixels: ``C ≈ 0.178`` at
    f/1.4 and ``≈ 0.328`` at f/2.8 (exact method).
    """
    _check_polarization(polarization)
    _check_scale(contrast_scale)
    M = speckle_cells_per_pixel(pixel_pitch_um, wavelength_nm, f_number,
                                magnification=magnification, method=method)
    P = 1.0 if polarization == "polarized" else 2.0
    return float(contrast_scale) / math.sqrt(M * P)


# ------------------------------------------------------------------------------ simulation
def auto_oversample(pixel_pitch_um: float, wavelength_nm: float, f_number: float,
                    magnification: float = 0.0) -> int:
    """Default oversampling ``max(3, ceil(2 f_c p + OVERSAMPLE_MARGIN))`` (module docstring)."""
    _positive("pixel_pitch_um", pixel_pitch_um)
    band = 2.0 * coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification) \
        * float(pixel_pitch_um)
    return max(3, math.ceil(band + OVERSAMPLE_MARGIN))


def speckle_pattern(shape: tuple[int, int], *, pixel_pitch_um: float, wavelength_nm: float,
                    f_number: float, rng, oversample: int | None = None,
                    magnification: float = 0.0, polarization: str = "polarized",
                    contrast_scale: float = 1.0, workers: int | None = None) -> np.ndarray:
    """A multiplicative, pixel-integrated speckle pattern with mean 1.

    Parameters
    ----------
    shape : (H, W) int
        Image size in pixels.
    pixel_pitch_um : float, > 0
        Pixel pitch (the pixel integrates its full square).
    wavelength_nm : float, > 0
    f_number : float, > 0
        Lens f-number ``N``; with ``magnification`` it sets the pupil cut-off.
    rng : Generator, SeedSequence, int or None
        Speckle stream.  The same seed gives the same pattern (a static object).
    oversample : int, optional
        Fine-grid samples per pixel and axis; must exceed ``2 f_c p``.  Default
        :func:`auto_oversample`.
    magnification : float
        Lateral magnification of the imaged surface (``N_w = N (1 + |m|)``); default 0.
    polarization : {"polarized", "depolarized"}
    contrast_scale : float, [0, 1]
        ``1`` fully developed; below 1 scales ``I − 1`` (phenomenological, see module doc).
    workers : int, optional
        Threads for the noise and the FFT; the result does not depend on it.

    Returns
    -------
    (H, W) float32
        Pattern whose spatial mean is 1 (the realised mean is normalised out: the scattered
        power is conserved) and whose contrast follows :func:`speckle_contrast_theory`.
    """
    H, W = _check_shape(shape)
    p, fc, s = _fine_grid(pixel_pitch_um, wavelength_nm, f_number, magnification, oversample,
                          polarization, contrast_scale)
    J = _intensity_sum(H * s, W * s, fc * p / s, s, polarization, rng, workers)
    return _finish(J, contrast_scale)


def _fine_grid(pixel_pitch_um, wavelength_nm, f_number, magnification, oversample,
               polarization, contrast_scale) -> tuple[float, float, int]:
    """The arguments of a pixel pattern checked; its pixel pitch (µm), the coherent cut-off
    (cycles/µm) and the fine samples per pixel."""
    _positive("pixel_pitch_um", pixel_pitch_um)
    _check_polarization(polarization)
    _check_scale(contrast_scale)
    p = float(pixel_pitch_um)
    fc = coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification)
    return p, fc, _check_oversample(oversample, p, fc, wavelength_nm, f_number, magnification)


def speckle_on_tiles(lit, *, pixel_pitch_um: float, wavelength_nm: float, f_number: float,
                     rng, tile_px: int = SPECKLE_TILE_PX, oversample: int | None = None,
                     magnification: float = 0.0, polarization: str = "polarized",
                     contrast_scale: float = 1.0, workers: int | None = None) -> np.ndarray:
    """A position-keyed speckle pattern, drawn only on the tiles that hold laser light.

    The value of a pixel is a function of its absolute position and of the seed alone, not
    of which other pixels are lit: a frame rendered on its pixel support and a full frame of
    the same seed get the same speckle, bit for bit, on every pixel both light.

    The field is ``u = h ⊛ n`` on the fine grid (``oversample`` samples per pixel and axis,
    as :func:`speckle_pattern`): ``n`` is white circular complex Gaussian noise whose value
    at a fine sample is a counter-based hash (SplitMix64) of the sample's absolute position
    and the seed, and ``h`` is the circular pupil's amplitude PSF (the Airy amplitude
    ``2 J1(2π f_c r) / (2π f_c r)``) truncated at :data:`KEYED_PSF_RADIUS` ``× λ N_w`` and
    normalised to ``Σ h² = 1`` (so ``<|u|²> = 1``: the pattern's expectation is exactly 1;
    its realised mean is not normalised out).  The image is cut into tiles on a grid anchored
    at pixel (0, 0); each tile with a ``lit`` pixel is computed alone, with the same array
    shapes whichever tiles are lit, by a linear convolution (FFT of the tile's noise padded by
    the PSF's radius), then ``|u|²`` is averaged over each pixel's ``s × s`` samples.  Pixels
    in neighbouring tiles are correlated as neighbours in one pattern are (the padding holds
    the neighbours' noise).  The truncated PSF passes a slightly smoothed pupil: the pixel
    contrast is +1.9 % (f/1.4) and +2.1 % (f/2.8) above :func:`speckle_contrast_theory`
    (660 nm, 5.3 µm; computed exactly from ``h`` by :func:`keyed_contrast`), against
    +1.4–1.6 % for :func:`speckle_pattern` (the Riemann sum's bias, module docstring).

    Parameters
    ----------
    lit : (H, W) bool
        Pixels that carry laser light.
    tile_px : int, >= 4
        Largest side of the tiles (:func:`keyed_tile_px` gives the side used); raised to the
        PSF's diameter in pixels when that is larger.
    rng : Generator, SeedSequence, int or None
        Speckle stream: the same seed gives the same value at a pixel in every call.
    pixel_pitch_um, wavelength_nm, f_number, oversample, magnification, polarization,
    contrast_scale, workers
        As :func:`speckle_pattern`.

    Returns
    -------
    (H, W) float32
        1 on the pixels of unlit tiles (no laser light: nothing to modulate), and on the
        rows of a lit tile whose group of :data:`_ROW_GROUP` rows holds no lit pixel.
    """
    lit = np.asarray(lit, bool)
    if lit.ndim != 2:
        raise ValueError(f"lit must be a 2-D mask, got shape {lit.shape}")
    if not (isinstance(tile_px, (int, np.integer)) and tile_px >= 4):
        raise ValueError(f"tile_px must be an integer >= 4, got {tile_px!r}")
    p, fc, s = _fine_grid(pixel_pitch_um, wavelength_nm, f_number, magnification, oversample,
                          polarization, contrast_scale)
    fcd = fc * p / s
    radius = int(math.ceil(KEYED_PSF_RADIUS / (2.0 * fcd)))     # fine samples
    T = _tile_side(int(tile_px), radius, s)
    H, W = lit.shape
    nty, ntx = -(-H // T), -(-W // T)
    padded = np.zeros((nty * T, ntx * T), bool)
    padded[:H, :W] = lit
    tiles = np.flatnonzero(padded.reshape(nty, T, ntx, T).any(axis=(1, 3)))
    out = np.ones((nty * T, ntx * T), np.float32)
    if tiles.size:
        keys = _field_keys(rng, 1 if polarization == "polarized" else 2)
        n = T * s + 2 * radius
        spectrum = _psf_spectrum(round(fcd, 12), radius, _fft_len(n))
        view = out.reshape(nty, T, ntx, T).transpose(0, 2, 1, 3)   # (nty, ntx, T, T), a view
        workers = block_threads() if workers is None else max(1, int(workers))
        edges = np.linspace(0, tiles.size, min(tiles.size, 4 * workers) + 1).round().astype(int)

        starts = np.arange(0, T, _ROW_GROUP)
        groups = padded.reshape(nty, T, ntx, T).any(axis=3)             # (nty, T, ntx)
        groups = np.add.reduceat(groups, starts, axis=1) > 0            # (nty, groups, ntx)

        def block(i: int) -> None:
            for t in tiles[edges[i]:edges[i + 1]].tolist():
                ty, tx = divmod(t, ntx)
                rows = [(int(a), min(T, int(a) + _ROW_GROUP))
                        for a in starts[groups[ty, :, tx]]]
                J = sum(_keyed_tile(k, ty * T * s - radius, tx * T * s - radius, n, T, s,
                                    spectrum, rows) for k in keys) / len(keys)
                if contrast_scale != 1.0:
                    J = 1.0 + float(contrast_scale) * (J - 1.0)
                view[ty, tx] = J

        _run_blocks(block, len(edges) - 1, workers)
    return np.ascontiguousarray(out[:H, :W])


def keyed_tile_px(pixel_pitch_um: float, wavelength_nm: float, f_number: float, *,
                  tile_px: int = SPECKLE_TILE_PX, oversample: int | None = None,
                  magnification: float = 0.0) -> int:
    """The side (pixels) of the tiles :func:`speckle_on_tiles` computes with these arguments.

    The largest side ``T`` in ``[3/4 tile_px, tile_px]`` whose padded tile ``T s + 2 radius``
    fine samples is an FFT length with no prime factor above 5 (the FFT of a tile costs ~8 %
    less than at the next such length: 256 against 264 samples at f/2.8), else ``tile_px``;
    never below the PSF's diameter.  A pixel's value does not depend on it (to float32
    rounding of the FFT lengths)."""
    p = float(pixel_pitch_um)
    fc = coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification)
    s = _check_oversample(oversample, p, fc, wavelength_nm, f_number, magnification)
    return _tile_side(int(tile_px), int(math.ceil(KEYED_PSF_RADIUS / (2.0 * fc * p / s))), s)


def _tile_side(tile_px: int, radius: int, s: int) -> int:
    """:func:`keyed_tile_px` from the PSF's radius in fine samples and the oversampling."""
    least = 2 * -(-radius // s)
    if tile_px <= least:
        return least
    for T in range(tile_px, max(least, (3 * tile_px) // 4) - 1, -1):
        if _smooth(T * s + 2 * radius):
            return T
    return tile_px


def _smooth(n: int) -> bool:
    """Whether ``n`` has no prime factor above 5."""
    for q in (2, 3, 5):
        while n % q == 0:
            n //= q
    return n == 1


def keyed_contrast(pixel_pitch_um: float, wavelength_nm: float, f_number: float, *,
                   oversample: int | None = None, magnification: float = 0.0) -> float:
    """The exact contrast of :func:`speckle_on_tiles`'s polarised pattern, from its PSF.

    For a circular Gaussian field with correlation ``Γ = h ⋆ h`` (``Γ(0) = 1``), the
    variance of the mean of ``|u|²`` over a pixel's ``s × s`` samples is
    ``(1/s⁴) Σ_Δ (s − |Δx|)(s − |Δy|) Γ(Δ)²`` (the discrete form of Goodman's integral).
    """
    import scipy.signal

    p = float(pixel_pitch_um)
    fc = coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification)
    s = _check_oversample(oversample, p, fc, wavelength_nm, f_number, magnification)
    fcd = fc * p / s
    radius = int(math.ceil(KEYED_PSF_RADIUS / (2.0 * fcd)))
    h = _psf(fcd, radius)
    G = scipy.signal.fftconvolve(h, h[::-1, ::-1])[2 * radius - s + 1:2 * radius + s,
                                                    2 * radius - s + 1:2 * radius + s]
    w = s - np.abs(np.arange(1 - s, s))
    return float(math.sqrt(float(w @ (G * G) @ w)) / (s * s))


def _keyed_tile(key: int, y0: int, x0: int, n: int, T: int, s: int,
                spectrum: np.ndarray, rows=None) -> np.ndarray:
    """The pixel-integrated intensity of one tile, (T, T) float32: the fine field on the
    ``n × n`` noise block whose corner is the fine sample ``(y0, x0)``, the tile being its
    centre ``T s × T s`` (the rest is the PSF's reach).  ``rows``: the ranges ``(a, b)`` of
    pixel rows computed (default all); the others are 1."""
    import scipy.fft

    noise = _keyed_noise(key, y0, x0, n)
    N = spectrum.shape[0]
    P = scipy.fft.fft2(noise, (N, N), workers=1, overwrite_x=True)
    P *= spectrum
    # The inverse DFT along y, then along x for the tile's own rows only (its centre), range
    # by range (each alone: its values do not depend on which other rows are computed).
    r = (n - T * s) // 2
    Y = scipy.fft.ifft(P, axis=0, workers=1, overwrite_x=True)[r:r + T * s]
    J = np.ones((T, T), np.float32)
    for a, b in ([(0, T)] if rows is None else rows):
        u = scipy.fft.ifft(Y[a * s:b * s], axis=1, workers=1)[:, r:r + T * s]
        v = u.real * u.real + u.imag * u.imag
        J[a:b] = v.reshape(b - a, s, T, s).mean(axis=(1, 3), dtype=np.float64)
    return J


def _keyed_noise(key: int, y0: int, x0: int, n: int) -> np.ndarray:
    """White circular complex Gaussian noise (``<|z|²> = 1``) on the ``n × n`` fine samples
    from ``(y0, x0)``: SplitMix64 of the sample's counter ``(y << 32) | x`` (two's
    complement, so negative positions are counters too), then Box–Muller on its two 24-bit
    halves → (n, n) complex64."""
    u64 = np.uint64
    gamma = u64(0x9E3779B97F4A7C15)
    with np.errstate(over="ignore"):
        # key + (counter + 1) γ, the counter's row and column terms added by broadcasting.
        row = (np.arange(y0, y0 + n, dtype=np.int64).astype(u64) << u64(32)) * gamma \
            + u64(key) + gamma
        col = (np.arange(x0, x0 + n, dtype=np.int64).astype(u64) & u64(0xFFFFFFFF)) * gamma
        z = np.add.outer(row, col)
        t = z >> u64(30)
        z ^= t
        z *= u64(0xBF58476D1CE4E5B9)
        np.right_shift(z, u64(27), out=t)
        z ^= t
        z *= u64(0x94D049BB133111EB)
        np.right_shift(z, u64(31), out=t)
        z ^= t
    r = (z >> u64(40)).astype(np.float32)                 # 24 bits: exact in float32
    r += np.float32(0.5)
    r *= np.float32(2.0 ** -24)                           # uniform on (0, 1)
    np.log(r, out=r)
    np.negative(r, out=r)
    np.sqrt(r, out=r)
    phase = (z & u64(0xFFFFFF)).astype(np.float32)
    phase *= np.float32(2.0 * math.pi * 2.0 ** -24)
    out = np.empty((n, n), np.complex64)
    out.real = r * np.cos(phase)
    out.imag = r * np.sin(phase)
    return out


@functools.lru_cache(maxsize=16)
def _psf_spectrum(fcd: float, radius: int, N: int) -> np.ndarray:
    """DFT (size ``N × N``) of the truncated amplitude PSF on the fine grid, ``f_c d`` =
    ``fcd``, kept for ``r <= radius`` samples, ``Σ h² = 1``, centred on index 0 (wrapped)."""
    import scipy.fft

    k = np.arange(-radius, radius + 1)
    h = _psf(fcd, radius)
    g = np.zeros((N, N))
    g[np.ix_(k % N, k % N)] = h
    return scipy.fft.fft2(g).astype(np.complex64)


def _psf(fcd: float, radius: int) -> np.ndarray:
    """The truncated amplitude PSF on the fine grid, (2 radius + 1)², ``Σ h² = 1``."""
    from scipy.special import j1

    k = np.arange(-radius, radius + 1)
    r = np.hypot(k[:, None], k[None, :])
    a = 2.0 * math.pi * fcd * r
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(a > 1e-12, 2.0 * j1(a) / a, 1.0)
    h[r > radius] = 0.0
    return h / math.sqrt(float(np.sum(h * h)))


def _field_keys(rng, n_fields: int) -> list[int]:
    """64-bit keys of the position-keyed fields of ``rng`` (one per polarisation)."""
    if isinstance(rng, np.random.Generator):
        return [int(v) for v in rng.integers(0, 2 ** 63, size=n_fields, dtype=np.int64)]
    return [int(v) for v in seed_sequence(rng, key=_SPECKLE_KEY).generate_state(n_fields,
                                                                                  np.uint64)]


def _fft_len(n: int) -> int:
    import scipy.fft

    return int(scipy.fft.next_fast_len(int(n), real=False))


def speckle_intensity(shape: tuple[int, int], *, sample_pitch_um: float, wavelength_nm: float,
                      f_number: float, rng, magnification: float = 0.0,
                      polarization: str = "polarized", contrast_scale: float = 1.0,
                      workers: int | None = None) -> np.ndarray:
    """Point samples of the speckle intensity (no pixel integration), mean 1.

    The same field as :func:`speckle_pattern` but sampled at ``sample_pitch_um`` and not
    integrated: what an ideal point detector would see.  Fully developed, polarised speckle
    is exponentially distributed here (contrast 1).  ``sample_pitch_um`` must be below
    ``1 / (2 f_c) = λ N_w`` (the field's Nyquist pitch) so that the field is exact.

    Returns
    -------
    (H, W) float32
    """
    H, W = _check_shape(shape)
    _positive("sample_pitch_um", sample_pitch_um)
    _check_polarization(polarization)
    _check_scale(contrast_scale)
    fc = coherent_cutoff_cyc_per_um(wavelength_nm, f_number, magnification)
    d = float(sample_pitch_um)
    if d >= 1.0 / (2.0 * fc):
        raise ValueError(f"sample_pitch_um={d:g} must be below the field's Nyquist pitch "
                         f"λ N_w = {1.0 / (2.0 * fc):.4g} µm")
    J = _intensity_sum(H, W, fc * d, 1, polarization, rng, workers)
    return _finish(J, contrast_scale)


def _finish(J: np.ndarray, contrast_scale: float) -> np.ndarray:
    J /= J.mean(dtype=np.float64)
    if contrast_scale != 1.0:
        J -= 1.0
        J *= float(contrast_scale)
        J += 1.0
    return J.astype(np.float32, copy=False)


def _intensity_sum(Hf: int, Wf: int, fcd: float, s: int, polarization: str, rng,
                   workers: int | None) -> np.ndarray:
    """Sum of ``|u|²`` over ``s × s`` blocks of an ``Hf × Wf`` fine grid (pitch ``d``,
    ``fcd = f_c d``), for one or two independent fields → (Hf/s, Wf/s) float64."""
    n_mid = (2 * math.floor(fcd * Wf) + 1) * Hf
    if n_mid > MAX_FIELD_SAMPLES:
        raise ValueError(f"speckle field of {n_mid} samples ({Hf} fine rows) exceeds "
                         f"MAX_FIELD_SAMPLES={MAX_FIELD_SAMPLES}; use a smaller image")
    n_fields = 1 if polarization == "polarized" else 2
    gens = spawn_generators(rng, n_fields * _N_BLOCKS, key=_SPECKLE_KEY)
    workers = block_threads() if workers is None else max(1, int(workers))
    J = np.zeros((Hf // s, Wf // s), dtype=np.float64)
    for f in range(n_fields):
        Yt, kx_max = _field_columns(Hf, Wf, fcd, gens[f * _N_BLOCKS:(f + 1) * _N_BLOCKS],
                                    workers)
        _accumulate_rows(J, Yt, kx_max, Wf, s, workers)
        del Yt
    return J


def _field_columns(Hf: int, Wf: int, fcd: float, gens, workers: int) -> tuple[np.ndarray, int]:
    """The field after the inverse DFT along y, for the pupil's columns only.

    The field's spectrum holds i.i.d. complex normals inside the pupil disk and zeros outside
    (the DFT of white complex Gaussian noise is white complex Gaussian noise, so the
    coefficients are drawn directly).  DFT index ``(ky, kx)`` is the frequency
    ``(ky / (Hf d), kx / (Wf d))``, so the disk ``|f| <= f_c`` is
    ``(kx / Wf)² + (ky / Hf)² <= (f_c d)²``.  Returns ``(Yt, kx_max)``: ``Yt`` is
    (2 kx_max + 1, Hf) complex64 — transposed, so that both the filling and the transform run
    along contiguous memory — row ``j`` holding ``kx = j − kx_max``.
    """
    import scipy.fft

    kx_max = int(math.floor(fcd * Wf))
    ky_max = int(math.floor(fcd * Hf))
    if 2 * kx_max + 1 > Wf or 2 * ky_max + 1 > Hf:  # guarded by the callers
        raise ValueError("pupil does not fit the fine grid")
    P = np.zeros((2 * kx_max + 1, Hf), dtype=np.complex64)
    kx_all = np.arange(-kx_max, kx_max + 1)
    half_all = np.floor(Hf * np.sqrt(np.maximum(fcd * fcd - (kx_all / Wf) ** 2, 0.0)))
    half_all = np.minimum(half_all, ky_max).astype(np.int64)
    edges = np.linspace(0, kx_all.size, len(gens) + 1).round().astype(int)

    def block(i: int) -> None:
        j0, j1 = int(edges[i]), int(edges[i + 1])
        if j1 <= j0:
            return
        half = half_all[j0:j1]
        lengths = 2 * half + 1
        z = gens[i].standard_normal(2 * int(lengths.sum()), dtype=np.float32).view(np.complex64)
        start = 0
        for j, h, n in zip(range(j0, j1), half.tolist(), lengths.tolist()):
            seg = z[start:start + n]                 # ky = −h .. h
            P[j, :h + 1] = seg[h:]
            if h:
                P[j, Hf - h:] = seg[:h]
            start += n

    _run_blocks(block, len(gens), workers)
    return scipy.fft.ifft(P, axis=-1, workers=workers, overwrite_x=True), kx_max


def _accumulate_rows(J: np.ndarray, Yt: np.ndarray, kx_max: int, Wf: int, s: int,
                     workers: int) -> None:
    """Finish the inverse DFT along x strip by strip and add ``|u|²`` summed over ``s × s``
    blocks to ``J`` (H, W).  Strips run on ``workers`` threads (deterministic: no randomness,
    each strip writes its own rows)."""
    import scipy.fft

    Hf = Yt.shape[1]
    W = Wf // s
    rows_per_strip = s * max(1, _STRIP_SAMPLES // (s * Wf))
    starts = list(range(0, Hf, rows_per_strip))

    def strip(i: int) -> None:
        r0 = starts[i]
        r1 = min(Hf, r0 + rows_per_strip)
        X = np.zeros((r1 - r0, Wf), dtype=np.complex64)
        X[:, :kx_max + 1] = Yt[kx_max:, r0:r1].T
        if kx_max > 0:
            X[:, Wf - kx_max:] = Yt[:kx_max, r0:r1].T
        x = scipy.fft.ifft(X, axis=-1, workers=1, overwrite_x=True)
        v = x.view(np.float32)                  # (rows, 2 Wf): re, im interleaved
        np.square(v, out=v)
        # Columns [2 s j, 2 s (j+1)) of a fine row hold re² and im² of block column j.
        sums = np.einsum("rwk->rw", v.reshape(r1 - r0, W, 2 * s))
        J[r0 // s:r1 // s] += sums.reshape((r1 - r0) // s, s, W).sum(axis=1, dtype=np.float64)

    _run_blocks(strip, len(starts), workers)


# ------------------------------------------------------------------------------------ checks
def _check_shape(shape) -> tuple[int, int]:
    try:
        H, W = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape must be (H, W), got {shape!r}") from None
    if H < 1 or W < 1:
        raise ValueError(f"shape must be positive, got {shape!r}")
    return H, W


def _check_oversample(oversample, p: float, fc: float, wavelength_nm: float, f_number: float,
                      magnification: float) -> int:
    s = auto_oversample(p, wavelength_nm, f_number, magnification) if oversample is None \
        else oversample
    if not (isinstance(s, (int, np.integer)) and not isinstance(s, bool) and 1 <= s <= 64):
        raise ValueError(f"oversample must be an integer in [1, 64], got {oversample!r}")
    s = int(s)
    if s <= 2.0 * fc * p:
        raise ValueError(f"oversample={s} is too small: the pupil's band is {2 * fc * p:.3g} "
                         f"cycles per pixel (2 f_c p); use > that, or leave the default "
                         f"{auto_oversample(p, wavelength_nm, f_number, magnification)}")
    return s


def _check_polarization(polarization: str) -> None:
    if polarization not in POLARIZATIONS:
        raise ValueError(f"polarization must be one of {', '.join(POLARIZATIONS)}, "
                         f"got {polarization!r}")


def _check_scale(contrast_scale: float) -> None:
    try:
        c = float(contrast_scale)
    except (TypeError, ValueError):
        c = math.nan
    if not (0.0 <= c <= 1.0):
        raise ValueError(f"contrast_scale must be in [0, 1], got {contrast_scale!r}")

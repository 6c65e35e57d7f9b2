"""Camera sensor: radiance at the lens → mean electrons → the digital image (EMVA 1288).

Pure functions on numpy arrays (no Mitsuba).  The renderer gives the noise-free radiance
arriving at the lens for each pixel, ``L`` [W m⁻² sr⁻¹] at the laser wavelength; here it is
turned into the image the camera outputs.

Modelled
--------
* Radiometry: the on-axis camera equation ``E = π T L / (4 N_w²)`` with the working f-number
  ``N_w = N (1 + |m|)`` (pupil magnification 1), optionally times a per-pixel ``cos⁴`` map;
  photons ``E · A_pix · t · λ / (h c)``; photo-electrons ``QE · photons``; monochromatic light.
* The EMVA 1288 linear camera model (Release 4.0): photon shot noise and dark-current shot
  noise (one Poisson draw of the total mean charge), PRNU (a fixed per-pixel gain) and DSNU
  (a fixed per-pixel offset) drawn from the *sensor's* seed so that the same camera has the
  same pattern in every frame, Gaussian read noise, system gain ``K``, black level, rounding
  to integer DN (uniform quantisation noise of 1/12 DN² follows when the analogue noise is
  ≳ 0.5 DN), saturation at the full well and at ``2**bits − 1``.
* Auto-exposure like the paper's setting of the exposure time: a high percentile of the mean
  signal is placed at a fraction of the saturation level, clamped to the camera's range.

Left out
--------
Pixel crosstalk and the pixel MTF beyond the box integration done by the renderer; blooming
(charge above the full well is lost, not spread); non-linearity; row/column fixed-pattern
structure (PRNU/DSNU are white); dark-current non-uniformity and its temperature dependence;
rolling-shutter effects (the sensor is global shutter); lens vignetting other than an optional
``cos⁴`` map; stray light; defect pixels; the spectral shape of QE (light is monochromatic).

Randomness
----------
No global state.  Temporal noise comes from the ``rng`` argument (a ``Generator``, a
``SeedSequence``, an ``int`` frame seed, or ``None`` for fresh OS entropy); the fixed pattern
from ``sensor.sensor_seed``.  Both are turned into streams with ``np.random.SeedSequence``
and distinct spawn keys, so that a frame seed equal to the sensor seed still gives
independent streams.  Images are generated in a fixed number of row blocks, each with its
own child stream, so the result does not depend on the number of threads used.
"""

from __future__ import annotations

import math
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from lts360.scenes.checks import check_positive as _positive
from lts360.scenes.sensor import SensorModel

__all__ = [
    "PLANCK_J_S", "SPEED_OF_LIGHT_M_S", "QUANTISATION_VARIANCE_DN2",
    "photon_energy_J", "image_irradiance_W_m2", "radiance_to_electrons_mean",
    "FixedPattern", "fixed_pattern", "expose", "expose_held", "expected_dn",
    "AutoExposure", "ExposureWarning", "ExposureError", "plan_exposure", "auto_exposure",
    "temporal_stats", "spatial_stats", "predicted_photon_transfer",
    "seed_sequence", "spawn_generators",
]

PLANCK_J_S = 6.62607015e-34          # exact (SI 2019)
SPEED_OF_LIGHT_M_S = 299_792_458.0   # exact
#: Variance of uniform quantisation noise of a 1 DN step (EMVA 1288: sigma_q^2 = 1/12).
QUANTISATION_VARIANCE_DN2 = 1.0 / 12.0

#: Spawn keys separating the temporal and the fixed-pattern streams of one seed.
_TEMPORAL_KEY = 0x7E3901
_FIXED_PATTERN_KEY = 0xF1CED
#: Row blocks of an image: each gets its own child stream (fixed, so results do not depend on
#: the number of threads).
_N_BLOCKS = 8
#: Mean charge is capped at ``_LAMBDA_CAP_FACTOR · full_well + _LAMBDA_CAP_E`` before the
#: Poisson draw: such a pixel saturates anyway (the probability of a draw below the full well
#: is < 1e-12 for full_well >= 100), and the cap keeps huge radiances from overflowing.
_LAMBDA_CAP_FACTOR = 2.0
_LAMBDA_CAP_E = 1000.0
#: Largest mean charge shared by many pixels (the dark current's, in pixels without light) that
#: is drawn as one Poisson total scattered over the pixels (:func:`_poisson_draws`); above it
#: (or below 0, to turn it off) every pixel is drawn alone.  The scatter is cheaper while the
#: total is small: 0.7 against 2.3 ms for 164 000 pixels at a mean of 0.05 e⁻, 3.8 against 7.5
#: at 5 e⁻.
_SCATTER_MAX_MEAN = 8.0



# ---------------------------------------------------------------------------------- randomness
def seed_sequence(seed, *, key: int) -> np.random.SeedSequence:
    """A ``SeedSequence`` for the stream ``key`` of ``seed`` (int, SeedSequence or None).

    ``None`` draws fresh OS entropy (not reproducible).
    """
    if isinstance(seed, np.random.SeedSequence):
        return np.random.SeedSequence(seed.entropy, spawn_key=tuple(seed.spawn_key) + (key,),
                                      pool_size=seed.pool_size)
    if seed is None or (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool)
                        and seed >= 0):
        return np.random.SeedSequence(None if seed is None else int(seed), spawn_key=(key,))
    raise ValueError(f"rng must be a numpy Generator, a SeedSequence, a non-negative int or "
                     f"None, got {seed!r}")


def spawn_generators(rng, n: int, *, key: int = _TEMPORAL_KEY) -> list[np.random.Generator]:
    """``n`` independent Generators from ``rng`` (Generator, SeedSequence, int or None).

    A ``Generator`` is consumed through :meth:`numpy.random.Generator.spawn` (or, when its bit
    generator has no seed sequence, by drawing 128 bits of entropy from it).
    """
    if isinstance(rng, np.random.Generator):
        try:
            return rng.spawn(n)
        except (TypeError, ValueError, AttributeError):
            entropy = rng.integers(0, 2 ** 63, size=2, dtype=np.uint64).tolist()
            return [np.random.default_rng(s) for s in np.random.SeedSequence(entropy).spawn(n)]
    return [np.random.default_rng(s) for s in seed_sequence(rng, key=key).spawn(n)]


def _row_blocks(n_rows: int) -> list[slice]:
    edges = np.linspace(0, n_rows, _N_BLOCKS + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def block_threads() -> int:
    """The threads a block loop (sensor, speckle) uses by default: ``OMP_NUM_THREADS`` where
    it is set to a positive integer (the usual cap of a process's compute threads; a study's
    worker processes set it to their share of the cores), else the CPU count."""
    value = os.environ.get("OMP_NUM_THREADS", "").strip()
    if value.isdigit() and int(value) > 0:
        return int(value)
    return os.cpu_count() or 1


def _run_blocks(func, n: int, workers: int | None) -> None:
    """Call ``func(i)`` for ``i < n``, on up to ``workers`` threads (numpy's random
    generators and ufuncs release the GIL; default :func:`block_threads`)."""
    workers = min(n, block_threads()) if workers is None else max(1, min(int(workers), n))
    if workers == 1:
        for i in range(n):
            func(i)
        return
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for f in [pool.submit(func, i) for i in range(n)]:
            f.result()


# ---------------------------------------------------------------------------------- radiometry
def photon_energy_J(wavelength_nm: float) -> float:
    """Energy ``h c / λ`` of one photon [J]."""
    _positive("wavelength_nm", wavelength_nm)
    return PLANCK_J_S * SPEED_OF_LIGHT_M_S / (float(wavelength_nm) * 1e-9)


def image_irradiance_W_m2(radiance_W_m2_sr, *, f_number: float, transmittance: float = 1.0,
                          magnification: float = 0.0, cos4_factor=None) -> np.ndarray:
    """Irradiance on the sensor from the radiance arriving at the lens (camera equation).

    ``E = π · T · L / (4 · N_w²) · cos4``, ``N_w = N · (1 + |m|)``.

    This is the on-axis image irradiance of an aplanatic lens (Abbe sine condition,
    ``sin θ' = 1 / (2 N_w)``) focused at an object with lateral magnification ``m``;
    ``magnification = 0`` (default) is the object-at-infinity limit.  At the paper's rig
    (8 mm lens focused at ~170 mm) ``|m| ≈ 0.05`` and neglecting it overestimates ``E`` by
    ``(1 + |m|)² ≈ 10 %``: pass ``m = f / (s − f)`` for the exact value.  The pupil
    magnification is taken as 1.  (EMVA 1288's own set-up formula ``π L / (1 + 4 N²)`` is
    for a flat disk source seen without a lens; it differs by ``1 + 1/(4N²)``.)

    Parameters
    ----------
    radiance_W_m2_sr : (...) float, >= 0
        Radiance arriving at the lens, per pixel.
    f_number : float, > 0
        Lens f-number ``N`` (focal length / entrance pupil diameter).
    transmittance : float, (0, 1]
        Lens (and window/filter) transmittance ``T``.
    magnification : float
        Lateral magnification ``m`` of the imaged object (sign ignored).
    cos4_factor : None, float or (...) float in [0, 1]
        Off-axis fall-off map (``cos⁴`` of the field angle, or any vignetting map),
        broadcast against the radiance.  ``None``: no fall-off.

    Returns
    -------
    (...) float64
        Irradiance [W m⁻²].
    """
    L = _as_nonneg_array(radiance_W_m2_sr, "radiance_W_m2_sr")
    _positive("f_number", f_number)
    _in_unit("transmittance", transmittance, lo_open=True)
    if not math.isfinite(float(magnification)):
        raise ValueError(f"magnification must be finite, got {magnification!r}")
    n_w = float(f_number) * (1.0 + abs(float(magnification)))
    E = L * (math.pi * float(transmittance) / (4.0 * n_w * n_w))
    if cos4_factor is not None:
        c = np.asarray(cos4_factor, dtype=np.float64)
        if not (np.all(np.isfinite(c)) and np.all((c >= 0) & (c <= 1))):
            raise ValueError("cos4_factor must lie in [0, 1]")
        try:
            E = E * c
        except ValueError:
            raise ValueError(f"cos4_factor of shape {c.shape} does not broadcast against the "
                             f"radiance of shape {L.shape}") from None
    return E


def radiance_to_electrons_mean(radiance_W_m2_sr, *, wavelength_nm: float, f_number: float,
                               pixel_pitch_um: float, exposure_time_s: float,
                               quantum_efficiency: float, transmittance: float = 1.0,
                               magnification: float = 0.0, cos4_factor=None) -> np.ndarray:
    """Mean photo-electrons per pixel from the radiance arriving at the lens.

    ``mu_e = QE · E · A_pix · t · λ / (h c)`` with ``E`` from :func:`image_irradiance_W_m2`
    and ``A_pix = pixel_pitch²`` (fill factor 1: micro-lenses, or a QE that already includes
    the fill factor).  Monochromatic light at ``wavelength_nm``.

    Parameters
    ----------
    radiance_W_m2_sr : (...) float, >= 0
        Radiance at the lens [W m⁻² sr⁻¹].
    wavelength_nm : float, > 0
    f_number : float, > 0
    pixel_pitch_um : float, > 0
        Pixel pitch (square pixels) — the :class:`~lts360.scenes.rig.Camera`'s field.
    exposure_time_s : float, >= 0
    quantum_efficiency : float, (0, 1]
    transmittance, magnification, cos4_factor
        See :func:`image_irradiance_W_m2`.

    Returns
    -------
    (...) float64
        Mean photo-electrons ``mu_e`` (not clipped, no noise).
    """
    _positive("pixel_pitch_um", pixel_pitch_um)
    _in_unit("quantum_efficiency", quantum_efficiency, lo_open=True)
    t = float(exposure_time_s)
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"exposure_time_s must be finite and >= 0, got {exposure_time_s!r}")
    E = image_irradiance_W_m2(radiance_W_m2_sr, f_number=f_number, transmittance=transmittance,
                              magnification=magnification, cos4_factor=cos4_factor)
    area_m2 = (float(pixel_pitch_um) * 1e-6) ** 2
    scale = float(quantum_efficiency) * area_m2 * t / photon_energy_J(wavelength_nm)
    E *= scale
    return E


# ------------------------------------------------------------------------------- fixed pattern
@dataclass(frozen=True, eq=False)
class FixedPattern:
    """The fixed-pattern noise of one sensor at one image shape (read-only arrays).

    Attributes
    ----------
    prnu_gain : (H, W) float32
        Per-pixel gain ``1 + prnu_fraction · z`` (z standard normal, clipped at 0); mean ≈ 1.
    dsnu_e : (H, W) float32
        Per-pixel dark offset ``dsnu_e · z'`` [e⁻]; mean ≈ 0.
    """

    prnu_gain: np.ndarray
    dsnu_e: np.ndarray


def fixed_pattern(shape: tuple[int, ...], sensor: SensorModel) -> FixedPattern:
    """PRNU gain and DSNU offset maps of ``sensor`` for images of ``shape``.

    Drawn from ``sensor.sensor_seed`` only (stream key ``_FIXED_PATTERN_KEY``): the same
    sensor gives the same pattern in every frame; a different image shape gives a different
    pattern (a crop is not a sub-pattern).  The two unit-normal maps do not depend on
    ``prnu_fraction``/``dsnu_e``, which only scale them.  Cached (small LRU).
    """
    shape = tuple(int(s) for s in shape)
    if not shape or any(s < 1 for s in shape):
        raise ValueError(f"shape must be positive integers, got {shape}")
    return _fixed_pattern_cached(shape, int(sensor.sensor_seed), float(sensor.prnu_fraction),
                                 float(sensor.dsnu_e))


@lru_cache(maxsize=4)
def _fixed_pattern_cached(shape, seed, prnu, dsnu) -> FixedPattern:
    z = _unit_normals(shape, seed)
    gain = np.maximum(1.0 + prnu * z[0], 0.0).astype(np.float32)
    off = (dsnu * z[1]).astype(np.float32)
    gain.setflags(write=False)
    off.setflags(write=False)
    return FixedPattern(prnu_gain=gain, dsnu_e=off)


@lru_cache(maxsize=2)
def _unit_normals(shape, seed) -> np.ndarray:
    gen = np.random.default_rng(seed_sequence(seed, key=_FIXED_PATTERN_KEY))
    z = gen.standard_normal((2,) + tuple(shape), dtype=np.float32)
    z.setflags(write=False)
    return z


# -------------------------------------------------------------------------------------- expose
def expose(electrons_mean, sensor: SensorModel, *, rng, noise: bool = True,
           fixed_pattern_noise: bool | None = None, exposure_time_s: float | None = None,
           workers: int | None = None) -> np.ndarray:
    """The digital image of a sensor exposed to ``electrons_mean`` (EMVA 1288 linear model).

    With ``noise=True``, per pixel::

        n   = Poisson(mu_e · g + mu_d)             shot noise of photo + dark charge
        n   = min(n, full_well_e)                  well saturation
        a   = n + o + sigma_d0 · N(0, 1)           DSNU offset o, read noise
        y   = clip(floor(K · a + offset + 1/2), 0, 2**bits − 1)

    with ``g`` the PRNU gain and ``o`` the DSNU offset of :func:`fixed_pattern` and
    ``mu_d = dark_current_e_per_s · t``.  The mean is ``mu_y = K (mu_e + mu_d) + offset`` and
    the temporal variance ``K² (sigma_d0² + mu_d + mu_e) + 1/12`` (the 1/12 DN² of rounding
    holds when the analogue noise is ≳ 0.5 DN; at 8 bits the dark noise of the default sensor
    is 0.25 DN, so dark frames are almost noise-free integers, as with the real camera).

    With ``noise=False`` the deterministic expected value:
    ``y = clip(floor(K · min(mu_e + mu_d, full_well_e) + offset + 1/2), 0, 2**bits − 1)`` —
    the model's mean before saturation, then clipped and still quantised (near saturation this
    is not the mean of noisy frames, which are clipped draw by draw).  By default it also leaves
    out the fixed pattern (``fixed_pattern_noise`` follows ``noise``).

    Parameters
    ----------
    electrons_mean : (H, W) float, >= 0
        Mean photo-electrons ``mu_e`` per pixel (:func:`radiance_to_electrons_mean`).
        Any shape with at least one axis is accepted; blocks are split along axis 0.
    sensor : SensorModel
    rng : Generator, SeedSequence, int or None
        Temporal noise stream (a per-frame seed).  The fixed pattern comes from
        ``sensor.sensor_seed``, not from here.
    noise : bool
        Temporal noise (shot, dark, read) on/off.
    fixed_pattern_noise : bool or None
        PRNU/DSNU on/off; ``None``: same as ``noise``.
    exposure_time_s : float, optional
        For the dark current; default ``sensor.exposure_time_s``.  Pass the exposure used to
        compute ``electrons_mean``.
    workers : int, optional
        Threads (default: all cores, at most 8).  The result does not depend on it.

    Returns
    -------
    (H, W) uint8 (8 bits) or uint16
    """
    if not isinstance(sensor, SensorModel):
        raise TypeError(f"sensor must be a SensorModel, got {type(sensor).__name__}")
    mu = _as_nonneg_array(electrons_mean, "electrons_mean")
    if mu.ndim < 1 or mu.size == 0:
        raise ValueError(f"electrons_mean must be a non-empty array, got shape {mu.shape}")
    return _expose(mu.shape, None, mu, sensor, rng=rng, noise=noise,
                   fixed_pattern_noise=fixed_pattern_noise, exposure_time_s=exposure_time_s,
                   workers=workers)


def _expose(shape: tuple[int, ...], index, mu: np.ndarray, sensor: SensorModel, *, rng,
            noise: bool, fixed_pattern_noise, exposure_time_s, workers,
            fpn: FixedPattern | None = None) -> np.ndarray:
    """:func:`expose` of the mean electrons ``mu`` (checked): the dense image when ``index``
    is None, else the values at the flat indices ``index`` (sorted, each once; 0 elsewhere).
    A pixel without light has ``0 · gain + mu_d = mu_d`` before its draws: the same numbers
    whether it is multiplied out or filled in.  ``fpn``: the fixed pattern to use (of
    ``shape``) instead of the sensor's for ``shape``."""
    t = sensor.exposure_time_s if exposure_time_s is None else float(exposure_time_s)
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"exposure_time_s must be finite and >= 0, got {exposure_time_s!r}")
    use_fpn = noise if fixed_pattern_noise is None else bool(fixed_pattern_noise)
    if not use_fpn:
        fpn = None
    elif fpn is None:
        fpn = fixed_pattern(shape, sensor)
    K = sensor.system_gain
    offset = float(sensor.dark_offset_dn)
    full_well = float(sensor.full_well_e)
    top = float(sensor.full_scale_dn)
    mu_d = float(sensor.dark_current_e_per_s) * t
    sigma_read = float(sensor.dark_noise_e)
    out = np.empty(shape, dtype=sensor.dtype)
    if not noise and fpn is None:  # deterministic: each pixel alone; a dark one is a constant
        if index is None:
            flat = mu.reshape(-1)
            index = np.flatnonzero(flat)
            mu = flat[index]
        _expected_into(out, index, mu, mu_d=mu_d, full_well=full_well, K=K, offset=offset,
                       top=top)
        return out
    blocks = _row_blocks(shape[0])
    gens = spawn_generators(rng, len(blocks)) if noise else [None] * len(blocks)
    cap = _LAMBDA_CAP_FACTOR * full_well + _LAMBDA_CAP_E
    row = int(np.prod(shape[1:], dtype=np.int64))

    def mean_charge(sl: slice) -> np.ndarray:
        if index is None:
            m = mu[sl]
            lam = m * fpn.prnu_gain[sl] if fpn is not None else m.copy()
            lam += mu_d
            return lam
        lam = np.full((sl.stop - sl.start,) + tuple(shape[1:]), mu_d)
        a, b = np.searchsorted(index, [sl.start * row, sl.stop * row])
        at = index[a:b] - sl.start * row
        v = mu[a:b] * fpn.prnu_gain[sl].reshape(-1)[at] if fpn is not None else mu[a:b].copy()
        v += mu_d
        if noise and mu_d <= cap:  # the cap only touches the lit pixels (a dark one is mu_d)
            np.minimum(v, cap, out=v)
        lam.reshape(-1)[at] = v
        return lam

    def block(i: int) -> None:
        sl = blocks[i]
        if sl.stop <= sl.start:
            return
        lam = mean_charge(sl)
        if noise:
            gen = gens[i]
            if index is None or mu_d > cap:
                np.minimum(lam, cap, out=lam)
            a = _poisson_draws(gen, lam, mu_d)
            np.minimum(a, full_well, out=a)
            if sigma_read > 0:
                z = gen.standard_normal(a.shape)
                z *= sigma_read
                a += z
        else:
            a = np.minimum(lam, full_well, out=lam)
        if fpn is not None:
            a += fpn.dsnu_e[sl]
        a *= K
        a += offset + 0.5
        np.floor(a, out=a)
        np.clip(a, 0.0, top, out=a)
        out[sl] = a

    _run_blocks(block, len(blocks), workers)
    return out


def _poisson_draws(gen: np.random.Generator, lam: np.ndarray, shared: float) -> np.ndarray:
    """Independent ``Poisson(lam)`` draws (float64, the shape of ``lam``).

    Where the pixels mostly share the mean ``shared`` (those without light: the dark current's
    charge) and it is at most :data:`_SCATTER_MAX_MEAN`, all ``N`` pixels first get the counts
    of a ``Poisson(N · shared)`` total of charges each put in a uniformly drawn pixel
    (``integers`` + ``bincount``): by the splitting property of the Poisson process these
    counts are exactly independent ``Poisson(shared)`` draws, one per pixel.  The pixels whose
    mean differs are then drawn alone and replace theirs (independent of the rest).  The
    distribution is that of one ``gen.poisson(lam)``; the realisation is another."""
    n = lam.size
    if not 0.0 <= shared <= _SCATTER_MAX_MEAN:
        return gen.poisson(lam).astype(np.float64)
    flat = lam.reshape(-1)
    other = np.flatnonzero(flat != shared)
    if 2 * other.size > n:  # mostly lit: one draw per pixel costs less
        return gen.poisson(lam).astype(np.float64)
    total = int(gen.poisson(shared * n))
    a = np.bincount(gen.integers(0, n, size=total), minlength=n).astype(np.float64)
    a[other] = gen.poisson(flat[other])
    return a.reshape(lam.shape)


def _expected_into(out: np.ndarray, index: np.ndarray, mu: np.ndarray, *, mu_d: float,
                   full_well: float, K: float, offset: float, top: float) -> None:
    """``out`` = the noise-free digital values (``expose(noise=False)`` without the fixed
    pattern) of an image whose mean electrons are ``mu`` at the flat indices ``index`` and 0
    elsewhere: the pixels without light all take the value of 0 electrons, the others are
    converted one by one (the same operations, in the same order, as over the whole frame)."""

    def dn(m: np.ndarray) -> np.ndarray:
        a = m + mu_d
        np.minimum(a, full_well, out=a)
        a *= K
        a += offset + 0.5
        np.floor(a, out=a)
        np.clip(a, 0.0, top, out=a)
        return a

    out.fill(dn(np.zeros(1))[0])
    out.reshape(-1)[index] = dn(mu)


def expose_held(shape: tuple[int, ...], index, electrons_mean, sensor: SensorModel, *, rng,
                noise: bool = True, exposure_time_s: float | None = None,
                workers: int | None = None, read=None) -> np.ndarray:
    """:func:`expose` of an image of ``shape`` whose mean electrons are ``electrons_mean`` at
    the flat indices ``index`` (each once) and 0 elsewhere — a frame whose light is held by a
    few pixels.  The same image as ``expose`` of the dense array, bit for bit (the same draws
    from the same streams); the dark pixels are not converted from a dense array.

    ``read`` (sorted flat indices, each once; with ``noise``): the only pixels the caller
    reads — an inverse-triangulation plan's taps (:func:`lts360.recon.triangulation.inverse.
    plan_pixels`), ~1 % of a frame.  The temporal and fixed-pattern noise is drawn on them
    alone (the fixed pattern is the sensor's at those pixels; the temporal draws are another
    realisation of the full frame's distribution); every other pixel holds its noise-free
    value, as ``noise=False`` gives it."""
    shape = tuple(int(n) for n in shape)
    if not shape or any(n < 1 for n in shape):
        raise ValueError(f"shape must be positive integers, got {shape}")
    idx = _flat_index(index, shape, "index")
    mu = _as_nonneg_array(electrons_mean, "electrons_mean").reshape(-1)
    if mu.shape != idx.shape:
        raise ValueError(f"index and electrons_mean differ in length: {idx.size} != {mu.size}")
    if read is None or not noise:
        return _expose(shape, idx, mu, sensor, rng=rng, noise=noise, fixed_pattern_noise=None,
                       exposure_time_s=exposure_time_s, workers=workers)
    read = _flat_index(read, shape, "read")
    out = _expose(shape, idx, mu, sensor, rng=None, noise=False, fixed_pattern_noise=False,
                  exposure_time_s=exposure_time_s, workers=workers)
    at = np.searchsorted(idx, read)
    hit = at < idx.size
    hit[hit] = idx[at[hit]] == read[hit]
    mu_read = np.zeros(read.size)
    mu_read[hit] = mu[at[hit]]
    fp = fixed_pattern(shape, sensor)
    sub = FixedPattern(prnu_gain=fp.prnu_gain.reshape(-1)[read], dsnu_e=fp.dsnu_e.reshape(-1)[read])
    out.reshape(-1)[read] = _expose((read.size,), None, mu_read, sensor, rng=rng, noise=True,
                                    fixed_pattern_noise=True, exposure_time_s=exposure_time_s,
                                    workers=workers, fpn=sub)
    return out


def _flat_index(index, shape: tuple[int, ...], name: str) -> np.ndarray:
    """``index`` as int64 flat indices, checked: sorted, each once, inside ``shape``."""
    idx = np.asarray(index, np.int64).reshape(-1)
    if idx.size and (idx[0] < 0 or idx[-1] >= math.prod(shape) or np.any(np.diff(idx) <= 0)):
        raise ValueError(f"{name} must be sorted flat indices inside the image, each once")
    return idx


def expected_dn(electrons_mean, sensor: SensorModel, *, exposure_time_s: float | None = None
                ) -> np.ndarray:
    """Noise-free quantised image: ``expose(..., noise=False)`` (no fixed pattern)."""
    return expose(electrons_mean, sensor, rng=None, noise=False, exposure_time_s=exposure_time_s)


# ------------------------------------------------------------------------------- auto-exposure
class ExposureWarning(UserWarning):
    """Auto-exposure had to clamp the exposure time to the camera's range."""


class ExposureError(ValueError):
    """Auto-exposure cannot reach its target within the camera's exposure range."""


@dataclass(frozen=True)
class AutoExposure:
    """Result of :func:`plan_exposure`.

    Attributes
    ----------
    exposure_time_s : float
        Exposure to use (clamped to the range).
    required_exposure_s : float
        Exposure that would put the signal statistic at the target (``inf`` with no signal).
    clamped : {"", "min", "max"}
        ``"max"``: the laser is too weak for the target even at the longest exposure;
        ``"min"``: too bright even at the shortest (the image saturates).
    signal_e_per_s : float
        The statistic: the chosen percentile of the mean photo-electron rate per pixel.
    target_dn : float
        Mean digital value the statistic is put at.
    expected_dn : float
        Mean digital value the statistic gets at ``exposure_time_s``.
    message : str
        One line describing the clamping (empty when not clamped).
    """

    exposure_time_s: float
    required_exposure_s: float
    clamped: str
    signal_e_per_s: float
    target_dn: float
    expected_dn: float
    message: str = ""


def plan_exposure(radiance_W_m2_sr, sensor: SensorModel, *, wavelength_nm: float,
                  f_number: float, pixel_pitch_um: float, target_fraction: float = 0.8,
                  percentile: float = 99.9, mask=None, transmittance: float = 1.0,
                  magnification: float = 0.0, cos4_factor=None,
                  min_exposure_s: float | None = None,
                  max_exposure_s: float | None = None) -> AutoExposure:
    """Exposure time that puts a high percentile of the mean signal at a target level.

    Like the paper's manual setting of the exposure time: the ``percentile`` of the mean
    signal over the pixels (or over ``mask``) — i.e. the brightest part of the laser stripe,
    robust to a few hot pixels — is placed at ``target_fraction`` of the signal range above
    the black level::

        K · (s + i_d) · t + offset = offset + target_fraction · (saturation_dn − offset)

    with ``s`` the percentile of the photo-electron rate and ``i_d`` the dark current.  Use
    ``percentile=100`` for the maximum.  With the default 99.9 the statistic lies in the
    stripe only if the stripe covers more than 0.1 % of the pixels (~1300 of 1280×1024);
    pass ``mask`` (e.g. the laser's share > 0) otherwise.  PRNU is ignored.

    Parameters
    ----------
    radiance_W_m2_sr : (H, W) float, >= 0
    sensor : SensorModel
    wavelength_nm, f_number, pixel_pitch_um, transmittance, magnification, cos4_factor
        As in :func:`radiance_to_electrons_mean`.
    target_fraction : float, (0, 1]
    percentile : float, [0, 100]
    mask : (H, W) bool, optional
        Pixels the statistic is taken over.
    min_exposure_s, max_exposure_s : float, optional
        Range; default the sensor's ``exposure_min_us``/``exposure_max_us``.
    """
    _in_unit("target_fraction", target_fraction, lo_open=True)
    if not (0.0 <= float(percentile) <= 100.0):
        raise ValueError(f"percentile must be in [0, 100], got {percentile!r}")
    t_min = sensor.exposure_min_us * 1e-6 if min_exposure_s is None else float(min_exposure_s)
    t_max = sensor.exposure_max_us * 1e-6 if max_exposure_s is None else float(max_exposure_s)
    if not (0 < t_min <= t_max and math.isfinite(t_max)):
        raise ValueError(f"exposure range must satisfy 0 < min <= max < inf, got "
                         f"[{t_min!r}, {t_max!r}] s")
    rate = radiance_to_electrons_mean(
        radiance_W_m2_sr, wavelength_nm=wavelength_nm, f_number=f_number,
        pixel_pitch_um=pixel_pitch_um, exposure_time_s=1.0,
        quantum_efficiency=sensor.quantum_efficiency, transmittance=transmittance,
        magnification=magnification, cos4_factor=cos4_factor)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != rate.shape:
            raise ValueError(f"mask must have the radiance's shape {rate.shape}, got {m.shape}")
        rate = rate[m]
    if rate.size == 0:
        raise ValueError("no pixels to take the exposure statistic over (empty mask)")
    s = float(np.percentile(rate, float(percentile)))
    K = sensor.system_gain
    offset = float(sensor.dark_offset_dn)
    target_dn = offset + float(target_fraction) * (sensor.saturation_dn - offset)
    per_s = K * (s + float(sensor.dark_current_e_per_s))
    t_req = (target_dn - offset) / per_s if per_s > 0 else math.inf
    t = min(max(t_req, t_min), t_max)
    clamped, msg = "", ""
    if t_req > t_max:
        clamped = "max"
        what = "no signal" if s <= 0 else f"the {percentile:g}th-percentile signal {s:.3g} e-/s"
        msg = (f"auto-exposure: laser too weak: {what} needs {t_req:.3g} s to reach "
               f"{target_fraction:.0%} of saturation; clamped to the longest exposure "
               f"{t_max:.3g} s (reaches {offset + per_s * t_max:.3g} of {target_dn:.3g} DN)")
    elif t_req < t_min:
        clamped = "min"
        msg = (f"auto-exposure: too bright: {target_fraction:.0%} of saturation needs "
               f"{t_req:.3g} s, below the shortest exposure {t_min:.3g} s; the brightest "
               f"pixels will saturate")
    return AutoExposure(exposure_time_s=float(t), required_exposure_s=float(t_req),
                        clamped=clamped, signal_e_per_s=s, target_dn=float(target_dn),
                        expected_dn=float(offset + per_s * t), message=msg)


def auto_exposure(radiance_W_m2_sr, sensor: SensorModel, *, wavelength_nm: float,
                  f_number: float, pixel_pitch_um: float, target_fraction: float = 0.8,
                  percentile: float = 99.9, on_clamp: str = "warn", **kwargs) -> float:
    """Exposure time [s] from :func:`plan_exposure` (same arguments).

    ``on_clamp``: what to do when the exposure had to be clamped to the camera's range —
    ``"warn"`` (default, :class:`ExposureWarning`), ``"raise"`` (:class:`ExposureError`) or
    ``"ignore"``.  Use :func:`plan_exposure` to get the flag and numbers as data.
    """
    if on_clamp not in ("warn", "raise", "ignore"):
        raise ValueError(f"on_clamp must be 'warn', 'raise' or 'ignore', got {on_clamp!r}")
    plan = plan_exposure(radiance_W_m2_sr, sensor, wavelength_nm=wavelength_nm,
                         f_number=f_number, pixel_pitch_um=pixel_pitch_um,
                         target_fraction=target_fraction, percentile=percentile, **kwargs)
    if plan.clamped:
        if on_clamp == "raise":
            raise ExposureError(plan.message)
        if on_clamp == "warn":
            warnings.warn(plan.message, ExposureWarning, stacklevel=2)
    return plan.exposure_time_s


# ---------------------------------------------------------------------- photon transfer (EMVA)
def temporal_stats(frame_a, frame_b) -> tuple[float, float]:
    """EMVA 1288 mean and temporal variance from two frames taken at the same exposure.

    ``mu_y = (<y_A> + <y_B>) / 2`` and
    ``sigma_y² = 1/(2 N) Σ ((y_A − <y_A>) − (y_B − <y_B>))²`` — the difference of two
    frames cancels the fixed pattern (same sensor), leaving twice the temporal variance.

    Returns
    -------
    (mean_dn, temporal_variance_dn2) : (float, float)
    """
    a = np.asarray(frame_a, dtype=np.float64)
    b = np.asarray(frame_b, dtype=np.float64)
    if a.shape != b.shape or a.size < 2:
        raise ValueError(f"frames must have the same shape with >= 2 pixels, got {a.shape} "
                         f"and {b.shape}")
    ma, mb = a.mean(), b.mean()
    d = (a - ma) - (b - mb)
    return float(0.5 * (ma + mb)), float(0.5 * np.mean(d * d))


def spatial_stats(frames) -> tuple[float, float]:
    """EMVA 1288 spatial variance from a stack of ``L`` frames at the same exposure.

    ``s_y² = var(<y>) − sigma_y²_stack / L``: the variance over pixels of the frame average,
    less the temporal noise left in that average (``sigma_y²_stack``: mean over pixels of the
    per-pixel variance over the stack).

    Parameters
    ----------
    frames : (L, H, W) array, L >= 2

    Returns
    -------
    (mean_dn, spatial_variance_dn2) : (float, float)
    """
    y = np.asarray(frames, dtype=np.float64)
    if y.ndim < 2 or y.shape[0] < 2:
        raise ValueError(f"frames must be a stack (L, ...) with L >= 2, got shape {y.shape}")
    L = y.shape[0]
    avg = y.mean(axis=0)
    s2_stack = float(y.var(axis=0, ddof=1).mean())
    return float(avg.mean()), float(avg.var(ddof=1) - s2_stack / L)


def predicted_photon_transfer(electrons_mean, sensor: SensorModel, *,
                              exposure_time_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Mean and temporal variance [DN, DN²] the linear model predicts (below saturation).

    ``mu_y = K (mu_e + mu_d) + offset``;
    ``sigma_y² = K² (sigma_d0² + mu_d + mu_e) + 1/12`` with ``mu_d = i_d · t``.
    """
    mu_e = np.asarray(electrons_mean, dtype=np.float64)
    t = sensor.exposure_time_s if exposure_time_s is None else float(exposure_time_s)
    K = sensor.system_gain
    mu_d = sensor.dark_current_e_per_s * t
    mu_y = K * (mu_e + mu_d) + sensor.dark_offset_dn
    var_y = K * K * (sensor.dark_noise_e ** 2 + mu_d + mu_e) + QUANTISATION_VARIANCE_DN2
    return mu_y, var_y


# ------------------------------------------------------------------------------------- checks
def _in_unit(name: str, value, *, lo_open: bool = False) -> None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}") from None
    ok = math.isfinite(v) and (v > 0 if lo_open else v >= 0) and v <= 1
    if not ok:
        raise ValueError(f"{name} must be in {'(' if lo_open else '['}0, 1], got {value!r}")


def _as_nonneg_array(x, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.size and not (np.isfinite(arr).all() and arr.min() >= 0):
        bad = "non-finite" if not np.isfinite(arr).all() else f"negative (min {arr.min():.3g})"
        raise ValueError(f"{name} must be finite and >= 0, got {bad} values")
    return arr

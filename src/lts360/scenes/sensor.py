"""The camera's image sensor as an EMVA 1288 linear camera model (parameters only).

The physics that uses these parameters (radiance → electrons → digital numbers) lives in
:mod:`lts360.simulator.sensor`; this module only describes and validates a sensor, so that
the rig description may hold one without importing the simulator.  The pixel pitch and the
lens (f-number) belong to :class:`lts360.scenes.rig.Camera` and are not repeated here.

EMVA 1288 (Release 4.0) linear model, in the symbols of the standard::

    mu_y      = K (mu_e + mu_d) + offset           mean digital value [DN]
    sigma_y^2 = K^2 (sigma_d^2 + mu_e) + sigma_q^2  temporal variance [DN^2]

with ``mu_e = QE · mu_p`` photo-electrons, ``mu_d`` the mean dark electrons (dark current ×
exposure), ``sigma_d^2 = dark_noise_e^2 + mu_d`` and ``sigma_q^2 = 1/12 DN^2``.

Default values: the paper's camera, a Ximea MQ013MG-E2 (e2v EV76C560 CMOS, 1280×1024,
5.3 µm global-shutter pixels, 8-bit output).  Only "peak QE > 60 %" comes from the paper;
the rest are datasheet-like values recalled for this class of sensor and are *assumed* (no
measured EMVA 1288 report of this camera was available here) — see the comment on each field.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from lts360.scenes.checks import RigError, _check, _in_range

__all__ = ["SensorModel", "BIT_DEPTHS", "RigError"]  # RigError: what validation raises

#: Output bit depths a sensor may have.
BIT_DEPTHS = (8, 10, 12, 14, 16)


@dataclass(frozen=True)
class SensorModel:
    """EMVA 1288 parameters of an image sensor (monochrome, global shutter).

    Attributes
    ----------
    quantum_efficiency : float, (0, 1]
        ``QE`` at the laser wavelength (660 nm): photo-electrons per incident photon.
    full_well_e : float, [100, 1e7]
        Saturation capacity in electrons; the photo + dark charge of a pixel is clipped here.
    dark_noise_e : float, [0, 1000]
        Temporal dark (read) noise ``sigma_d0`` in electrons rms, without dark-current shot noise.
    dark_current_e_per_s : float, [0, 1e7]
        Mean dark current; ``mu_d = dark_current_e_per_s · t_exp`` (Poisson distributed).
    dsnu_e : float, [0, 1e4]
        Dark signal non-uniformity: spatial standard deviation of a fixed per-pixel offset,
        in electrons (EMVA's DSNU1288 expressed in e⁻).
    prnu_fraction : float, [0, 0.2]
        Photo response non-uniformity: spatial standard deviation of the per-pixel gain,
        relative to its mean (0.01 = 1 %).
    bit_depth : int, one of 8, 10, 12, 14, 16
        Output word length; the image is ``uint8`` for 8 bits and ``uint16`` above.
    gain_dn_per_e : float or None, (0, 1000]
        Overall system gain ``K`` in DN per electron.  ``None`` (default) derives it so that the
        full well maps to full scale: ``K = (2**bit_depth − 1 − dark_offset_dn) / full_well_e``
        (see :attr:`system_gain`).
    dark_offset_dn : float, [0, (2**bit_depth − 1) / 2]
        Black level added after the gain, in DN.
    exposure_time_us : float, [exposure_min_us, exposure_max_us]
        Default exposure time.
    exposure_min_us, exposure_max_us : float
        Range the camera can set (auto-exposure clamps to it).
    sensor_seed : int, [0, 2**63)
        Seed of the fixed pattern (PRNU/DSNU): the same camera has the same pattern in every
        frame.  Temporal noise is seeded per frame, separately.
    """

    # e2v EV76C560 mono QE curve peaks a little above 60 % (paper: "peak QE > 60 %") in the
    # green–orange; at 660 nm it is lower.  0.55: assumed, read off the typical curve shape.
    quantum_efficiency: float = 0.55
    # ~10 ke- is the datasheet-like full well of this 5.3 µm 8-transistor global-shutter pixel
    # (assumed; consistent with the quoted ~60 dB dynamic range and ~40 dB max SNR).
    full_well_e: float = 10_000.0
    # Assumed: 10 e- rms makes the dynamic range 10 000 / 10 = 60 dB, as quoted for the camera.
    dark_noise_e: float = 10.0
    # Assumed, typical of a small-pixel CMOS at ~30 °C; 0.05 e- at 1 ms, i.e. negligible here.
    dark_current_e_per_s: float = 50.0
    # Assumed (a few e- to tens of e- is typical of CMOS; 0.25 DN at 8 bits).
    dsnu_e: float = 10.0
    # Assumed: 1 % is typical of CMOS sensors (EMVA reports 0.5–2 %).
    prnu_fraction: float = 0.01
    # Paper: 8-bit images.
    bit_depth: int = 8
    # Derived when None: full well → full scale, K = 253 / 10 000 = 0.0253 DN/e- at 8 bits.
    gain_dn_per_e: float | None = None
    # Assumed black level of 2 DN (keeps the dark noise from being clipped at 0).
    dark_offset_dn: float = 2.0
    # Default exposure 1 ms; range assumed (1 µs .. 1 s): the laser stripe of a 1 mW sheet on a
    # white surface needs only a few µs at f/1.4, so a 10 µs floor would clamp often.
    exposure_time_us: float = 1000.0
    exposure_min_us: float = 1.0
    exposure_max_us: float = 1_000_000.0
    sensor_seed: int = 1288

    def __post_init__(self) -> None:
        _in_range("sensor.quantum_efficiency", self.quantum_efficiency, 0.0, 1.0, lo_open=True)
        _in_range("sensor.full_well_e", self.full_well_e, 100.0, 1e7)
        _in_range("sensor.dark_noise_e", self.dark_noise_e, 0.0, 1000.0)
        _in_range("sensor.dark_current_e_per_s", self.dark_current_e_per_s, 0.0, 1e7)
        _in_range("sensor.dsnu_e", self.dsnu_e, 0.0, 1e4)
        _in_range("sensor.prnu_fraction", self.prnu_fraction, 0.0, 0.2)
        bd = self.bit_depth
        _check(isinstance(bd, (int, np.integer)) and not isinstance(bd, bool) and bd in BIT_DEPTHS,
               "sensor.bit_depth", f"must be one of {', '.join(map(str, BIT_DEPTHS))}, got {bd!r}")
        full_scale = float(2 ** int(bd) - 1)
        _in_range("sensor.dark_offset_dn", self.dark_offset_dn, 0.0, full_scale / 2.0)
        if self.gain_dn_per_e is not None:
            _in_range("sensor.gain_dn_per_e", self.gain_dn_per_e, 0.0, 1000.0, lo_open=True)
        _in_range("sensor.exposure_min_us", self.exposure_min_us, 0.001, 1e9)
        _in_range("sensor.exposure_max_us", self.exposure_max_us, self.exposure_min_us, 1e9)
        _in_range("sensor.exposure_time_us", self.exposure_time_us, self.exposure_min_us,
                  self.exposure_max_us)
        seed = self.sensor_seed
        _check(isinstance(seed, (int, np.integer)) and not isinstance(seed, bool)
               and 0 <= seed < 2 ** 63, "sensor.sensor_seed",
               f"must be an integer in [0, 2**63), got {seed!r}")

    # ------------------------------------------------------------------ derived values
    @property
    def full_scale_dn(self) -> int:
        """Largest digital value, ``2**bit_depth − 1``."""
        return 2 ** int(self.bit_depth) - 1

    @property
    def system_gain(self) -> float:
        """Overall system gain ``K`` [DN/e⁻] (explicit, or derived: full well → full scale)."""
        if self.gain_dn_per_e is not None:
            return float(self.gain_dn_per_e)
        return (self.full_scale_dn - float(self.dark_offset_dn)) / float(self.full_well_e)

    @property
    def saturation_dn(self) -> float:
        """Mean digital value at saturation: the ADC's full scale or the full well, whichever
        comes first, ``min(2**bits − 1, K · full_well_e + offset)``."""
        return min(float(self.full_scale_dn),
                   self.system_gain * float(self.full_well_e) + float(self.dark_offset_dn))

    @property
    def exposure_time_s(self) -> float:
        return float(self.exposure_time_us) * 1e-6

    @property
    def dtype(self) -> type:
        """``np.uint8`` for 8 bits, else ``np.uint16``."""
        return np.uint8 if self.bit_depth <= 8 else np.uint16

    @property
    def dynamic_range_db(self) -> float:
        """EMVA dynamic range ``20 log10(full_well / sigma_d)`` (read noise only, dark
        current and quantisation ignored); ``inf`` without read noise."""
        if self.dark_noise_e == 0:
            return math.inf
        return 20.0 * math.log10(self.full_well_e / self.dark_noise_e)

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict:
        """Plain JSON-able dict of the fields, plus the derived ``system_gain``."""
        d = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in asdict(self).items()}
        d["system_gain_dn_per_e"] = self.system_gain
        return d

    @classmethod
    def from_dict(cls, data: dict) -> "SensorModel":
        """Build from a dict (e.g. a ``[sensor]`` TOML table); unknown keys raise ``RigError``.

        The derived key ``system_gain_dn_per_e`` written by :meth:`to_dict` is accepted and
        ignored (the gain is ``gain_dn_per_e``, or derived again).
        """
        names = {f.name for f in fields(cls)}
        data = {k: v for k, v in dict(data).items() if k != "system_gain_dn_per_e"}
        unknown = sorted(set(data) - names)
        _check(not unknown, "sensor", f"unknown field(s) {', '.join(unknown)}; allowed: "
               f"{', '.join(sorted(names))}")
        return cls(**data)


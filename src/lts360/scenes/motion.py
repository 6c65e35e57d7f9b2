"""An object moving on a production line, and how the camera exposes it.

The rig (camera, laser, mirrors) stays fixed; the object moves.  Its pose at time ``t`` (s,
from the trigger of the frame) is the stage transform of today's still frames composed with

* a feed along the axis: ``z(t) = z₀ + v t`` (``speed_mm_s``);
* a lateral vibration: ``x(t) = A_x sin(2π f t + φ_x)``, ``y(t) = A_y sin(2π f t + φ_y)``
  (``vibration_kind="sine"``), or a seeded random one (``"random"``): in each axis a stationary
  Gaussian process of rms ``A`` whose spectrum is a Lorentzian of corner ``f`` cut at ``10 f``
  (a band-limited Ornstein–Uhlenbeck walk: correlation ≈ exp(−2π f |τ|)), synthesised as
  :data:`RANDOM_VIBRATION_TERMS` cosines with frequencies drawn from that spectrum and random
  phases, so that the same seed gives the same path at any time;
* an optional rotation about the axis at ``rotation_rate_deg_s``,

``T(t) = Translate(x(t), y(t), z(t)) · Rot_z(ω t)`` applied after the object's own placement.

The camera's :class:`Shutter` sets when each image row integrates light: a global shutter
exposes every row over ``[t₀, t₀ + E]``; a rolling shutter starts row ``y`` at
``t₀ + y · line_time_s``.  A :class:`Trigger` gives the frames' trigger times: a fixed profile
rate, or encoder pulses every ``pitch_mm`` of feed, each with a seeded timing jitter.  A scan is
then a time series of frames.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["Motion", "Shutter", "Trigger", "Acquisition", "RANDOM_VIBRATION_TERMS",
           "RANDOM_VIBRATION_CUTOFF"]

#: Cosines summed for a random vibration (its values are Gaussian to within ~1/√N).
RANDOM_VIBRATION_TERMS = 64
#: The random vibration's spectrum is cut at this multiple of its corner frequency.
RANDOM_VIBRATION_CUTOFF = 10.0


def _finite(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class Motion:
    """The object's motion during a frame (see the module docstring).

    Parameters
    ----------
    speed_mm_s : float
        Feed along +z (the object's axis), mm/s; may be negative.
    vibration_amplitude_mm : (2,) float, >= 0
        Lateral amplitude in x and y, mm: the peak of a sine, the rms of a random vibration.
    vibration_frequency_hz : float, >= 0
        The sine's frequency, or the random vibration's corner frequency.
    vibration_phase_deg : (2,) float
        Phases φ_x, φ_y at t = 0 (sine).
    rotation_rate_deg_s : float
        About the axis (+z), degrees per second.
    vibration_kind : {"sine", "random"}
    vibration_seed : int
        The random vibration's path.
    """

    speed_mm_s: float = 0.0
    vibration_amplitude_mm: tuple[float, float] = (0.0, 0.0)
    vibration_frequency_hz: float = 0.0
    vibration_phase_deg: tuple[float, float] = (0.0, 90.0)
    rotation_rate_deg_s: float = 0.0
    vibration_kind: str = "sine"
    vibration_seed: int = 0

    def __post_init__(self):
        if self.vibration_kind not in ("sine", "random"):
            raise ValueError(f"vibration_kind must be 'sine' or 'random', got "
                             f"{self.vibration_kind!r}")
        if isinstance(self.vibration_seed, bool) or int(self.vibration_seed) != self.vibration_seed \
                or self.vibration_seed < 0:
            raise ValueError(f"vibration_seed must be an integer >= 0, got {self.vibration_seed!r}")
        object.__setattr__(self, "vibration_seed", int(self.vibration_seed))
        _finite("speed_mm_s", self.speed_mm_s)
        _finite("rotation_rate_deg_s", self.rotation_rate_deg_s)
        amp = tuple(_finite("vibration_amplitude_mm", a) for a in self.vibration_amplitude_mm)
        if len(amp) != 2 or min(amp) < 0:
            raise ValueError("vibration_amplitude_mm must be two amplitudes >= 0 (x, y), got "
                             f"{self.vibration_amplitude_mm!r}")
        if _finite("vibration_frequency_hz", self.vibration_frequency_hz) < 0:
            raise ValueError(f"vibration_frequency_hz must be >= 0, got {self.vibration_frequency_hz}")
        if len(tuple(self.vibration_phase_deg)) != 2:
            raise ValueError("vibration_phase_deg must be two phases (x, y)")
        object.__setattr__(self, "vibration_amplitude_mm", amp)
        object.__setattr__(self, "vibration_phase_deg",
                           tuple(float(p) for p in self.vibration_phase_deg))

    @property
    def still(self) -> bool:
        """No motion at all: a moving-frame render is then today's still render."""
        return (self.speed_mm_s == 0.0 and self.rotation_rate_deg_s == 0.0
                and (max(self.vibration_amplitude_mm) == 0.0
                     or self.vibration_frequency_hz == 0.0))

    def offset_mm(self, t_s) -> np.ndarray:
        """(n, 3) translation of the object at times ``t_s`` (s), from its pose at t = 0
        minus the vibration's value at t = 0 is *not* removed: x(0) = A_x sin φ_x."""
        t = np.atleast_1d(np.asarray(t_s, float))
        ax, ay = self.vibration_amplitude_mm
        if self.vibration_kind == "random":
            f, phase = self._random_terms()
            arg = 2.0 * math.pi * f[:, None, :] * t[None, :, None] + phase[:, None, :]
            xy = np.sqrt(2.0 / f.shape[1]) * np.cos(arg).sum(axis=2)  # (2, n), unit rms
            return np.column_stack([ax * xy[0], ay * xy[1], self.speed_mm_s * t])
        w = 2.0 * math.pi * self.vibration_frequency_hz
        px, py = np.radians(self.vibration_phase_deg)
        return np.column_stack([ax * np.sin(w * t + px), ay * np.sin(w * t + py),
                                self.speed_mm_s * t])

    def _random_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """(2, N) frequencies (Hz) drawn from the Lorentzian of corner f cut at
        ``RANDOM_VIBRATION_CUTOFF · f``, and (2, N) phases, from ``vibration_seed``."""
        rng = np.random.default_rng([self.vibration_seed, 0x7A1B])
        u = rng.uniform(0.0, 1.0, (2, RANDOM_VIBRATION_TERMS))
        f = self.vibration_frequency_hz * np.tan(u * math.atan(RANDOM_VIBRATION_CUTOFF))
        return f, rng.uniform(0.0, 2.0 * math.pi, (2, RANDOM_VIBRATION_TERMS))

    def transform(self, t_s: float) -> np.ndarray:
        """4 × 4 ``T(t)`` (module docstring), applied after the object's still placement."""
        a = math.radians(self.rotation_rate_deg_s * float(t_s))
        c, s = math.cos(a), math.sin(a)
        T = np.eye(4)
        T[:2, :2] = [[c, -s], [s, c]]
        T[:3, 3] = self.offset_mm(t_s)[0]
        return T

    def max_point_speed_mm_s(self, radius_mm: float) -> float:
        """Upper bound of the speed of any object point within ``radius_mm`` of the axis."""
        if self.vibration_kind == "random":  # the bound of this path: Σ 2π f_k |term|
            f, _ = self._random_terms()
            amp = np.asarray(self.vibration_amplitude_mm) * np.sqrt(2.0 / f.shape[1])
            lateral = float(np.hypot(*(amp * 2.0 * math.pi * f.sum(axis=1))))
        else:
            w = 2.0 * math.pi * self.vibration_frequency_hz
            lateral = w * math.hypot(*self.vibration_amplitude_mm)
        return (abs(self.speed_mm_s) + lateral
                + abs(math.radians(self.rotation_rate_deg_s)) * float(radius_mm))


@dataclass(frozen=True)
class Shutter:
    """``kind``: ``"global"`` (every row exposed at once) or ``"rolling"`` (row ``y`` starts
    ``y · line_time_s`` after row 0)."""

    kind: str = "global"
    line_time_s: float = 0.0

    def __post_init__(self):
        if self.kind not in ("global", "rolling"):
            raise ValueError(f"shutter kind must be 'global' or 'rolling', got {self.kind!r}")
        lt = _finite("line_time_s", self.line_time_s)
        if lt < 0:
            raise ValueError(f"line_time_s must be >= 0, got {lt}")
        if self.kind == "rolling" and lt == 0:
            raise ValueError("a rolling shutter needs line_time_s > 0")

    def row_start_s(self, rows) -> np.ndarray:
        """Start of each row's exposure after the trigger, s."""
        rows = np.asarray(rows, float)
        return rows * self.line_time_s if self.kind == "rolling" else np.zeros_like(rows)


@dataclass(frozen=True)
class Trigger:
    """Frame triggers: every ``1 / profile_rate_hz`` s, or (``encoder_pitch_mm``) every that
    much feed; each with a Gaussian timing jitter of ``jitter_s`` (seeded)."""

    profile_rate_hz: float | None = None
    encoder_pitch_mm: float | None = None
    jitter_s: float = 0.0

    def __post_init__(self):
        if (self.profile_rate_hz is None) == (self.encoder_pitch_mm is None):
            raise ValueError("a trigger needs exactly one of profile_rate_hz and encoder_pitch_mm")
        for name in ("profile_rate_hz", "encoder_pitch_mm"):
            v = getattr(self, name)
            if v is not None and not _finite(name, v) > 0:
                raise ValueError(f"{name} must be > 0, got {v}")
        if _finite("jitter_s", self.jitter_s) < 0:
            raise ValueError(f"jitter_s must be >= 0, got {self.jitter_s}")

    def times_s(self, n: int, speed_mm_s: float, *, rng=None) -> np.ndarray:
        """Trigger times of ``n`` frames (the first at 0 before jitter), s."""
        k = np.arange(int(n), dtype=float)
        if self.profile_rate_hz is not None:
            t = k / self.profile_rate_hz
        else:
            if speed_mm_s == 0:
                raise ValueError("an encoder trigger needs a moving object (speed_mm_s != 0)")
            t = k * self.encoder_pitch_mm / abs(speed_mm_s)
        if self.jitter_s > 0:
            t = t + np.random.default_rng(rng).normal(0.0, self.jitter_s, t.shape)
        return t


@dataclass(frozen=True)
class Acquisition:
    """How a frame is taken: exposure, shutter, the object's motion, and the trigger."""

    exposure_time_s: float
    shutter: Shutter = field(default_factory=Shutter)
    motion: Motion = field(default_factory=Motion)
    trigger: Trigger | None = None

    def __post_init__(self):
        if not _finite("exposure_time_s", self.exposure_time_s) > 0:
            raise ValueError(f"exposure_time_s must be > 0, got {self.exposure_time_s}")

    def readout_s(self, n_rows: int) -> float:
        """From the first row's start to the last row's end of exposure, s."""
        return float(self.shutter.row_start_s(n_rows - 1)) + self.exposure_time_s

    def check_frame(self, n_rows: int) -> None:
        """A frame must be read out before the next trigger (profile-rate triggers)."""
        if self.trigger is not None and self.trigger.profile_rate_hz is not None:
            period = 1.0 / self.trigger.profile_rate_hz
            if self.readout_s(n_rows) > period:
                raise ValueError(f"the frame takes {self.readout_s(n_rows) * 1e3:.3g} ms to read out "
                                 f"({n_rows} rows), longer than the trigger period "
                                 f"{period * 1e3:.3g} ms")

    def to_dict(self) -> dict:
        return asdict(self)

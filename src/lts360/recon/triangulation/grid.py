"""The cylindrical grid of inverse triangulation (paper §3.2) in the measurement frame.

The grid lies in the laser plane (``z = 0`` of the measurement frame): angles ``θ`` (radians,
0 along +X, counter-clockwise seen from +Z) times radii ``r`` (millimetres).  Degrees only at
the interface (:meth:`CylGrid.from_ranges`).

A grid either spans the same radii at every θ (a band about the axis) or follows a profile:
the radii at ``θ_i`` are ``r_mm + r_shift_mm[i]`` (:meth:`CylGrid.following`), a band of the
same uniform samples centred on a first-pass profile ``r₀(θ)``.  The peak detectors work on the
base radii ``r_mm``; the shift of each θ is added when the peaks are assembled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CylGrid", "DEFAULT_THETA_STEP_DEG", "DEFAULT_R_STEP_MM"]

DEFAULT_THETA_STEP_DEG = 0.1
DEFAULT_R_STEP_MM = 0.005

#: Relative slack when a range is an integer number of steps (floating-point rounding).
_STEP_SLACK = 1e-9


def _uniform(values: np.ndarray) -> bool:
    if values.size < 3:
        return True
    d = np.diff(values)
    return bool(np.all(np.abs(d - d[0]) <= 1e-9 * max(abs(d[0]), 1e-300) + 1e-12))


@dataclass(frozen=True, eq=False)
class CylGrid:
    """Cylindrical sample grid ``θ × r`` in the plane ``z = 0`` of the measurement frame.

    Attributes
    ----------
    theta_rad : (nθ,) float
        Strictly increasing angles (radians), spanning at most one turn.
    r_mm : (nr,) float
        Strictly increasing, uniformly spaced radii (millimetres), > 0.
    r_shift_mm : (nθ,) float, optional
        Radial shift of each θ's samples (mm; zeros by default): the samples of ``θ_i`` lie at
        ``r_mm + r_shift_mm[i]``, all > 0.
    """

    theta_rad: np.ndarray
    r_mm: np.ndarray
    r_shift_mm: np.ndarray | None = None

    def __post_init__(self) -> None:
        th = np.array(self.theta_rad, dtype=float).ravel()
        r = np.array(self.r_mm, dtype=float).ravel()
        if th.size < 1 or not np.all(np.isfinite(th)):
            raise ValueError("theta_rad: must be at least one finite angle")
        if np.any(np.diff(th) <= 0) or th[-1] - th[0] >= 2 * np.pi:
            raise ValueError("theta_rad: must be strictly increasing and span less than one turn")
        if r.size < 3 or not np.all(np.isfinite(r)) or r[0] <= 0 or np.any(np.diff(r) <= 0):
            raise ValueError("r_mm: must be at least 3 strictly increasing finite radii > 0")
        if not _uniform(r):
            raise ValueError("r_mm: must be uniformly spaced (the peak detectors assume it)")
        shift = (np.zeros(th.size) if self.r_shift_mm is None
                 else np.array(self.r_shift_mm, dtype=float).ravel())
        if shift.shape != th.shape or not np.all(np.isfinite(shift)):
            raise ValueError(f"r_shift_mm: must be {th.size} finite shifts (one per θ), got "
                             f"shape {shift.shape}")
        if np.any(r[0] + shift <= 0):
            raise ValueError("r_shift_mm: every radius r_mm + r_shift_mm must be > 0")
        th.setflags(write=False)
        r.setflags(write=False)
        shift.setflags(write=False)
        object.__setattr__(self, "theta_rad", th)
        object.__setattr__(self, "r_mm", r)
        object.__setattr__(self, "r_shift_mm", shift)

    @classmethod
    def following(cls, theta_rad, r_centre_mm, half_width_mm: float, *,
                  r_step_mm: float = DEFAULT_R_STEP_MM) -> "CylGrid":
        """A band ``r₀(θ) ± half_width`` that follows a profile.

        Parameters
        ----------
        theta_rad : (nθ,) float
            Strictly increasing angles.
        r_centre_mm : (nθ,) float
            The band's centre ``r₀(θ)`` at each angle, > ``half_width_mm``.
        half_width_mm : float, >0
        r_step_mm : float, >0
        """
        th = np.asarray(theta_rad, dtype=float).ravel()
        rc = np.asarray(r_centre_mm, dtype=float).ravel()
        if rc.shape != th.shape or not np.all(np.isfinite(rc)):
            raise ValueError(f"r_centre_mm: must be {th.size} finite radii, got shape {rc.shape}")
        if not half_width_mm > 0 or not r_step_mm > 0:
            raise ValueError(f"half_width_mm and r_step_mm must be > 0, got {half_width_mm}, "
                             f"{r_step_mm}")
        if np.any(rc - half_width_mm <= 0):
            raise ValueError(f"r_centre_mm: the band r₀ ± {half_width_mm:g} mm must stay > 0, "
                             f"got r₀ down to {rc.min():g} mm")
        n_half = int(math.floor(half_width_mm / r_step_mm * (1 + _STEP_SLACK)))
        mid = float(np.median(rc))
        offsets = np.arange(-n_half, n_half + 1) * r_step_mm
        # Base radii about the median centre; the shifts place each θ's band on r₀(θ).
        base = mid + offsets
        if base[0] <= 0:
            base = base - base[0] + r_step_mm
        shift = rc - (base[0] + n_half * r_step_mm)
        return cls(theta_rad=th, r_mm=base, r_shift_mm=shift)
    @classmethod
    def from_ranges(cls, r_range_mm: tuple[float, float], *,
                    theta_range_deg: tuple[float, float] = (-180.0, 180.0),
                    theta_step_deg: float = DEFAULT_THETA_STEP_DEG,
                    r_step_mm: float = DEFAULT_R_STEP_MM) -> "CylGrid":
        """Grid from ranges and steps (the user interface: degrees for θ).

        Parameters
        ----------
        r_range_mm : (float, float)
            ``(r_min, r_max)``, ``0 < r_min < r_max``; both ends included (``r_max`` rounded to
            a whole number of steps).
        theta_range_deg : (float, float)
            ``(start, stop)``; a full turn (``stop − start == 360``) is sampled half-open,
            ``[start, stop)``, so that no angle appears twice; a partial range includes both
            ends when ``stop`` falls on a step.
        theta_step_deg : float, (0, 10]
        r_step_mm : float, >0
        """
        if not 0 < theta_step_deg <= 10:
            raise ValueError(f"theta_step_deg: must be in (0, 10], got {theta_step_deg}")
        if not r_step_mm > 0:
            raise ValueError(f"r_step_mm: must be > 0, got {r_step_mm}")
        r0, r1 = (float(v) for v in r_range_mm)
        if not (math.isfinite(r0) and math.isfinite(r1) and 0 < r0 < r1):
            raise ValueError(f"r_range_mm: must satisfy 0 < r_min < r_max, got {r_range_mm}")
        t0, t1 = (float(v) for v in theta_range_deg)
        span = t1 - t0
        if not (math.isfinite(t0) and math.isfinite(t1) and 0 < span <= 360.0 + 1e-9):
            raise ValueError(f"theta_range_deg: must satisfy 0 < stop − start <= 360, got "
                             f"{theta_range_deg}")
        steps = span / theta_step_deg
        if abs(span - 360.0) <= 1e-9:
            whole = abs(steps - round(steps)) < 1e-6
            n_theta = int(round(steps)) if whole else int(math.ceil(steps))
        else:
            n_theta = int(math.floor(steps * (1 + _STEP_SLACK))) + 1
        theta = np.radians(t0 + np.arange(n_theta) * theta_step_deg)
        n_r = int(math.floor((r1 - r0) / r_step_mm * (1 + _STEP_SLACK))) + 1
        return cls(theta_rad=theta, r_mm=r0 + np.arange(n_r) * r_step_mm)

    @property
    def n_theta(self) -> int:
        return int(self.theta_rad.size)

    @property
    def n_r(self) -> int:
        return int(self.r_mm.size)

    @property
    def shape(self) -> tuple[int, int]:
        """``(nθ, nr)``."""
        return self.n_theta, self.n_r

    @property
    def follows_profile(self) -> bool:
        """Whether the radii differ between θ (a band about a profile, not about the axis)."""
        return bool(np.any(self.r_shift_mm != 0))

    @property
    def r_range_mm(self) -> tuple[float, float]:
        """Smallest and largest radius sampled at any θ."""
        return (float(self.r_mm[0] + self.r_shift_mm.min()),
                float(self.r_mm[-1] + self.r_shift_mm.max()))

    def radii_mm(self, theta_index=None) -> np.ndarray:
        """(nθ or k, nr) radii of each θ's samples: ``r_mm + r_shift_mm[i]``."""
        sh = self.r_shift_mm if theta_index is None else self.r_shift_mm[theta_index]
        return sh[:, None] + self.r_mm[None, :]

    @property
    def r_step_mm(self) -> float:
        return float(self.r_mm[1] - self.r_mm[0])

    @property
    def theta_step_rad(self) -> float:
        """Step between the first two angles (NaN for a single angle)."""
        return float(self.theta_rad[1] - self.theta_rad[0]) if self.n_theta > 1 else float("nan")

    @property
    def is_full_turn(self) -> bool:
        """Uniform θ covering the whole circle (periodic: the last angle neighbours the first)."""
        if self.n_theta < 3 or not _uniform(self.theta_rad):
            return False
        return abs(self.n_theta * self.theta_step_rad - 2 * np.pi) < 1e-9

    def points_meas(self, theta_index=None) -> np.ndarray:
        """Grid points in the measurement frame.

        Parameters
        ----------
        theta_index : (k,) int or bool mask, optional
            Rows to return (all by default).

        Returns
        -------
        (nθ or k, nr, 3) float
            ``(r cos θ, r sin θ, 0)`` in millimetres, ``r = r_mm + r_shift_mm[i]``.
        """
        th = self.theta_rad if theta_index is None else self.theta_rad[theta_index]
        r = self.radii_mm(theta_index)
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        out = np.zeros((th.size, self.n_r, 3))
        out[..., 0] = c * r
        out[..., 1] = s * r
        return out

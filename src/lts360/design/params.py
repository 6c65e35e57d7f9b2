"""The design parameters the model differentiates, their bounds, and the rig each design is.

A *design* is a point in a space of continuous rig parameters (:data:`PARAMETERS`); every
parameter is a field of a rig table (``[design]``, ``[camera]`` or ``[laser]``), so a design
is written as a rig TOML that :func:`lts360.scenes.rig_io.load_rig` and every command load.
Parameters not free in a :class:`DesignSpace` keep the base rig's values.

The optimiser works in scaled coordinates ``s = (x − lo) / (hi − lo)`` in ``[0, 1]``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np

from lts360.scenes.checks import RigError
from lts360.scenes.rig import Rig
from lts360.scenes.rig_io import load_rig, rig_from_dict, rig_to_toml

__all__ = ["Parameter", "PARAMETERS", "DEFAULT_FREE", "DesignSpace", "DesignError"]


class DesignError(ValueError):
    """Bad input to the design model (an unknown parameter, bounds outside the valid range)."""


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One continuous design parameter.

    Attributes
    ----------
    name : str
        The key in its rig table (``alpha_deg``, ``f_number``, ...).
    table : str
        ``"design"``, ``"camera"`` or ``"laser"``.
    bounds : (float, float)
        Default search bounds.
    valid : (float, float)
        The range the rig accepts (the table's own validation); search bounds must lie inside.
    doc : str
    """

    name: str
    table: str
    bounds: tuple[float, float]
    valid: tuple[float, float]
    doc: str


#: Every parameter the model differentiates (world millimetres, degrees at this interface).
PARAMETERS: tuple[Parameter, ...] = (
    Parameter("alpha_deg", "design", (25.0, 65.0), (10.0, 80.0),
              "triangulation angle between laser plane and optical axis"),
    Parameter("beta_deg", "design", (80.0, 120.0), (60.0, 150.0), "angle between the mirrors"),
    Parameter("camera_distance_mm", "design", (120.0, 300.0), (30.0, 5000.0),
              "camera centre to its aim point on the laser plane"),
    Parameter("camera_target_y_mm", "design", (0.0, 40.0), (-100.0, 100.0),
              "aim point (0, y, 0) of the optical axis"),
    Parameter("laser_distance_mm", "design", (60.0, 200.0), (10.0, 5000.0),
              "fan apex to the object axis"),
    Parameter("mirror_corner_distance_mm", "design", (40.0, 100.0), (1.0, 2000.0),
              "object axis to the mirrors' common edge"),
    Parameter("mirror_width_mm", "design", (60.0, 160.0), (1.0, 2000.0),
              "width of each mirror from the corner outwards"),
    Parameter("focal_length_mm", "camera", (6.0, 16.0), (1.0, 500.0), "lens focal length"),
    Parameter("f_number", "camera", (1.4, 11.0), (0.5, 64.0), "working aperture N"),
    Parameter("focus_distance_mm", "camera", (120.0, 320.0), (1.0, 1e6),
              "distance in sharp focus along the optical axis (must exceed the focal length)"),
    Parameter("waist_um", "laser", (100.0, 600.0), (1.0, 5000.0),
              "1/e² half-thickness of the sheet at its waist (Rayleigh range follows at fixed M²)"),
    Parameter("fan_angle_deg", "laser", (30.0, 90.0), (1e-3, 170.0), "full fan angle"),
)
_BY_NAME = {p.name: p for p in PARAMETERS}
#: Free by default: all of them.
DEFAULT_FREE = tuple(p.name for p in PARAMETERS)


def parameter(name: str) -> Parameter:
    try:
        return _BY_NAME[name]
    except KeyError:
        raise DesignError(f"unknown design parameter {name!r}; known: "
                          f"{', '.join(_BY_NAME)}") from None


def base_values(rig: Rig) -> dict[str, float]:
    """Every parameter's value in a rig built from a design."""
    if rig.design is None:
        raise DesignError("rig: the base rig must be built from a [design] table")
    src = {"design": rig.design, "camera": rig.camera, "laser": rig.laser}
    return {p.name: float(getattr(src[p.table], p.name)) for p in PARAMETERS}


@dataclasses.dataclass(frozen=True)
class DesignSpace:
    """A base rig, the free parameters and their bounds.

    Attributes
    ----------
    base : Rig
        Supplies every fixed parameter (sensor, pixel pitch, wavelength, mirror height, ...).
    free : tuple of str
        Names of the free parameters (order of the optimiser's vector).
    bounds : dict[str, (float, float)]
        Search bounds of each free parameter, inside its valid range.
    """

    base: Rig
    free: tuple[str, ...]
    bounds: dict

    @classmethod
    def create(cls, base: Rig | str = "paper", free=None, bounds: dict | None = None
               ) -> "DesignSpace":
        """Validated space; ``free`` defaults to :data:`DEFAULT_FREE`; ``bounds`` overrides the
        defaults of some parameters.

        Raises
        ------
        DesignError
            Unknown parameter, empty or reversed bounds, bounds outside the valid range.
        """
        rig = load_rig(base) if isinstance(base, str) else base
        values = base_values(rig)
        free = tuple(DEFAULT_FREE if free is None else free)
        if not free:
            raise DesignError("free: at least one free parameter is needed")
        for name in free:
            parameter(name)
        if len(set(free)) != len(free):
            raise DesignError(f"free: a parameter is named twice in {list(free)}")
        bounds = dict(bounds or {})
        for name in bounds:
            parameter(name)
            if name not in free:
                raise DesignError(f"bounds: {name} is not a free parameter")
        out = {}
        for name in free:
            p = parameter(name)
            lo, hi = (float(v) for v in bounds.get(name, p.bounds))
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise DesignError(f"bounds of {name}: need finite lo < hi, got ({lo:g}, {hi:g})")
            vlo, vhi = p.valid
            if name == "focus_distance_mm":  # must exceed the focal length (the lens' maximum)
                f_hi = out.get("focal_length_mm", (0.0, values["focal_length_mm"]))[1]
                vlo = max(vlo, f_hi)
            if lo < vlo or hi > vhi:
                raise DesignError(f"bounds of {name}: ({lo:g}, {hi:g}) outside the valid range "
                                  f"({vlo:g}, {vhi:g})")
            out[name] = (lo, hi)
        return cls(base=rig, free=free, bounds=out)

    # --- vectors --------------------------------------------------------------------------
    @property
    def lo(self) -> np.ndarray:
        return np.array([self.bounds[n][0] for n in self.free])

    @property
    def hi(self) -> np.ndarray:
        return np.array([self.bounds[n][1] for n in self.free])

    def to_scaled(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=float) - self.lo) / (self.hi - self.lo)

    def from_scaled(self, s: np.ndarray) -> np.ndarray:
        return self.lo + np.asarray(s, dtype=float) * (self.hi - self.lo)

    def values(self, x=None) -> dict[str, float]:
        """All parameters: the base rig's, with the free ones replaced by ``x`` (physical units)."""
        v = base_values(self.base)
        if x is not None:
            x = np.asarray(x, dtype=float).reshape(-1)
            if x.size != len(self.free):
                raise DesignError(f"x: expected {len(self.free)} values, got {x.size}")
            v.update({n: float(xi) for n, xi in zip(self.free, x)})
        return v

    def base_x(self) -> np.ndarray:
        v = base_values(self.base)
        return np.array([v[n] for n in self.free])

    # --- rigs -----------------------------------------------------------------------------
    def rig(self, x=None, name: str = "design") -> Rig:
        """The rig of a design (validated by the rig's own dataclasses; RigError if invalid)."""
        data = tomllib.loads(rig_to_toml(self.base))
        v = self.values(x)
        for p in PARAMETERS:
            data[p.table][p.name] = v[p.name]
        laser = data["laser"]
        # Fixed beam quality: the Rayleigh range follows the waist; the waist stays on the axis.
        m2 = self.base.laser.m_squared
        laser["rayleigh_range_mm"] = math.pi * (v["waist_um"] * 1e-3) ** 2 / (
            self.base.laser.wavelength_nm * 1e-6 * m2) * (1.0 - 1e-12)
        laser["waist_distance_mm"] = v["laser_distance_mm"]
        data["name"] = name
        return rig_from_dict(data)

    def toml(self, x=None, name: str = "design") -> str:
        return rig_to_toml(self.rig(x, name=name))

    def is_valid(self, x) -> str | None:
        """``None`` if the design is a valid rig, else the rig's one-line complaint."""
        try:
            self.rig(x)
        except RigError as exc:
            return str(exc)
        return None

"""Size and ovality tolerances as a production line checks them, and the verdict.

* ``--diameter-mm 32±0.3`` (:class:`DiameterTolerance`): every two-point diameter within
  ``[32 − 0.3, 32 + 0.3]``, i.e. D min ≥ the lower limit and D max ≤ the upper one (ISO 14405-1
  two-point size, as a snap gauge or a two-axis gauge checks it).
* ``--ovality-max-mm 1.0``: D max − D min ≤ 1.0 mm.

Each check is judged on the measured value (``pass``) and, separately, by ISO 14253-1's
decision rule with the value's U(k = 2): ``conforms`` when the value ± U lies inside the limit,
``does not conform`` when it lies outside, else ``inconclusive``.  The scan passes when every
section passes every check (the nominal's profile zone included); ``lts360 inspect`` exits 1 on
a FAIL, so a line can act on it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = ["DiameterTolerance", "parse_diameter_tolerance", "check_ovality_max",
           "section_checks", "CONFORMS", "DOES_NOT_CONFORM", "INCONCLUSIVE"]

CONFORMS, DOES_NOT_CONFORM, INCONCLUSIVE = "conforms", "does not conform", "inconclusive"


@dataclass(frozen=True)
class DiameterTolerance:
    """A diameter and its symmetric tolerance (mm): ``nominal_mm ± tol_mm``."""

    nominal_mm: float
    tol_mm: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.nominal_mm) and self.nominal_mm > 0):
            raise ValueError(f"--diameter-mm: the diameter must be > 0, got {self.nominal_mm}")
        if not (np.isfinite(self.tol_mm) and 0 < self.tol_mm < self.nominal_mm):
            raise ValueError(f"--diameter-mm: the tolerance must be in (0, {self.nominal_mm:g}),"
                             f" got {self.tol_mm}")

    @property
    def lower_mm(self) -> float:
        return self.nominal_mm - self.tol_mm

    @property
    def upper_mm(self) -> float:
        return self.nominal_mm + self.tol_mm

    def __str__(self) -> str:
        return f"{self.nominal_mm:g} ± {self.tol_mm:g} mm"


_TOL = re.compile(r"^\s*([^±+]+?)\s*(?:±|\+-|\+/-)\s*(\S+)\s*$")


def parse_diameter_tolerance(text: str) -> DiameterTolerance:
    """``"32±0.3"`` (also ``32+-0.3``, ``32+/-0.3``) → :class:`DiameterTolerance`."""
    m = _TOL.match(str(text))
    if not m:
        raise ValueError(f"--diameter-mm: expected DIAMETER±TOL in mm (e.g. 32±0.3), got "
                         f"{text!r}")
    try:
        d, t = float(m.group(1)), float(m.group(2))
    except ValueError:
        raise ValueError(f"--diameter-mm: expected DIAMETER±TOL in mm (e.g. 32±0.3), got "
                         f"{text!r}") from None
    return DiameterTolerance(d, t)


def check_ovality_max(value_mm) -> float:
    """``--ovality-max-mm``: finite and > 0."""
    v = float(value_mm)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"--ovality-max-mm: must be > 0, got {value_mm}")
    return v


def _decide(value, U, lower=None, upper=None) -> tuple[bool | None, str]:
    if value is None:
        return None, INCONCLUSIVE
    inside = (lower is None or value >= lower) and (upper is None or value <= upper)
    sure_in = (lower is None or value - U >= lower) and (upper is None or value + U <= upper)
    sure_out = (lower is not None and value + U < lower) or (upper is not None and
                                                             value - U > upper)
    return bool(inside), CONFORMS if sure_in else (DOES_NOT_CONFORM if sure_out
                                                   else INCONCLUSIVE)


def section_checks(row: dict, *, diameter: DiameterTolerance | None = None,
                   ovality_max_mm: float | None = None) -> dict:
    """The checks of one section (a row of ``inspection.json``): name → ``{pass,
    conformance_iso14253, ...}``; a value that could not be measured fails."""
    out = {}
    if diameter is not None:
        dmin, dmax = row["d_min_mm"], row["d_max_mm"]
        p1, c1 = _decide(dmin["value"], dmin["U_k2"], lower=diameter.lower_mm)
        p2, c2 = _decide(dmax["value"], dmax["U_k2"], upper=diameter.upper_mm)
        conf = (DOES_NOT_CONFORM if DOES_NOT_CONFORM in (c1, c2) else
                CONFORMS if c1 == c2 == CONFORMS else INCONCLUSIVE)
        out["diameter"] = {"limits_mm": [diameter.lower_mm, diameter.upper_mm],
                           "pass": bool(p1 and p2), "conformance_iso14253": conf}
    if ovality_max_mm is not None:
        ov = row["ovality_mm"]
        p, c = _decide(ov["value"], ov["U_k2"], upper=ovality_max_mm)
        out["ovality"] = {"max_mm": ovality_max_mm, "pass": bool(p), "conformance_iso14253": c}
    return out

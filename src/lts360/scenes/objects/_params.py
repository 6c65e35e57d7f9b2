"""Parameter validation shared by the object generators."""

from __future__ import annotations

import math


def check_range(obj: str, field: str, value, lo: float, hi: float) -> None:
    """Raise ``ValueError("<obj>: <field> must be in [lo, hi], got v")`` when out of range."""
    if not isinstance(value, (int, float)) or not math.isfinite(value) or not lo <= value <= hi:
        raise ValueError(f"{obj}: {field} must be in [{lo:g}, {hi:g}], got {value!r}")


def check_less(obj: str, small: str, small_value: float, big: str, big_value: float) -> None:
    """Raise when ``small_value >= big_value`` (e.g. inner diameter vs outer diameter)."""
    if not small_value < big_value:
        raise ValueError(f"{obj}: {small} ({small_value:g}) must be smaller than {big} ({big_value:g})")

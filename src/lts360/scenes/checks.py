"""The error and the range checks every rig component uses: a message that names the field."""

from __future__ import annotations

import math

__all__ = ["RigError", "check_positive"]


class RigError(ValueError):
    """A rig parameter is out of range or inconsistent; the message names the field."""


def _check(cond: bool, field_name: str, message: str) -> None:
    if not cond:
        raise RigError(f"{field_name}: {message}")


def _in_range(field_name: str, value, lo: float, hi: float, *, lo_open=False, unit="") -> None:
    ok = isinstance(value, (int, float)) and math.isfinite(value) and \
        (value > lo if lo_open else value >= lo) and value <= hi
    bracket = "(" if lo_open else "["
    _check(ok, field_name, f"must be in {bracket}{lo:g}, {hi:g}]{unit}, got {value!r}")


def check_positive(name: str, value) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``value`` is a positive finite number."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")

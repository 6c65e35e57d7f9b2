"""Rig descriptions in TOML: presets shipped with the package, files written by users.

A rig file has a top-level ``name`` and the tables ``[design]`` (:class:`RigDesign`),
``[camera]``, ``[laser]``, ``[stage]`` (component fields other than the pose, which
:func:`build_rig` derives from the design) and ``[sensor]`` (EMVA 1288 parameters).  Unknown tables or keys are errors.

A top-level ``base`` (a preset name, or a TOML file relative to this one) makes the file a
variant of another rig: its tables start from the base's and the keys given replace the
base's, key by key (``base = "paper"`` with ``[camera] f_number = 8.0`` is the paper rig
stopped down).  Bases may have bases, up to :data:`MAX_BASE_DEPTH` deep.
"""

from __future__ import annotations

import dataclasses
import tomllib
from importlib import resources
from pathlib import Path

from lts360.scenes.rig import Camera, LaserSheet, Rig, RigDesign, RigError, Stage, build_rig
from lts360.scenes.sensor import SensorModel

__all__ = ["PRESETS", "load_rig", "rig_from_dict", "rig_to_toml"]

PRESETS = ("paper", "paper-f8")
#: How many ``base`` links a rig file may follow.
MAX_BASE_DEPTH = 8

_DERIVED = {"camera": {"R", "t_mm"}, "laser": {"origin_mm", "direction", "normal"}}
_TABLES = {"design": RigDesign, "camera": Camera, "laser": LaserSheet, "stage": Stage,
           "sensor": SensorModel}


def _allowed(table: str) -> set[str]:
    return {f.name for f in dataclasses.fields(_TABLES[table])} - _DERIVED.get(table, set())


def rig_from_dict(data: dict, *, default_name: str = "custom") -> Rig:
    """Build a rig from the parsed TOML dictionary (validated; :class:`RigError` on bad input)."""
    unknown = set(data) - set(_TABLES) - {"name"}
    if unknown:
        raise RigError(f"unknown table(s) {sorted(unknown)}; allowed: name, {', '.join(_TABLES)}")
    for table in _TABLES:
        section = data.get(table, {})
        if not isinstance(section, dict):
            raise RigError(f"{table}: must be a table")
        extra = set(section) - _allowed(table)
        if extra:
            raise RigError(f"{table}.{sorted(extra)[0]}: unknown key; allowed: "
                           f"{', '.join(sorted(_allowed(table)))}")
    try:
        design = RigDesign(**data.get("design", {}))
    except TypeError as exc:
        raise RigError(f"design: {exc}") from None
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise RigError("name: must be a non-empty string")
    return build_rig(design, camera=data.get("camera"), laser=data.get("laser"),
                     stage=data.get("stage"), sensor=data.get("sensor"), name=name)


def _rig_text(source: str) -> tuple[str, str, Path | None]:
    """TOML text, default name and (for a file) its folder."""
    if source in PRESETS:
        text = resources.files("lts360.scenes").joinpath("presets", f"{source}.toml").read_text()
        return text, source, None
    path = Path(source)
    if not path.is_file():
        raise RigError(f"rig: {source!r} is neither a preset ({', '.join(PRESETS)}) "
                       "nor a readable TOML file")
    return path.read_text(), path.stem, path.parent


def _rig_data(source: str, depth: int = 0) -> tuple[dict, str]:
    """The parsed TOML of ``source`` with its ``base`` chain merged in."""
    text, default_name, folder = _rig_text(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RigError(f"rig file {source}: invalid TOML ({exc})") from None
    base = data.pop("base", None)
    if base is None:
        return data, default_name
    if not isinstance(base, str) or not base:
        raise RigError(f"rig file {source}: base must be a preset name or a file")
    if depth >= MAX_BASE_DEPTH:
        raise RigError(f"rig file {source}: more than {MAX_BASE_DEPTH} bases deep "
                       "(a base refers back to itself?)")
    if base not in PRESETS and folder is not None:
        base = str(folder / base)
    merged, _ = _rig_data(base, depth + 1)
    merged.pop("name", None)
    for key, value in data.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = value
    return merged, default_name


def load_rig(source: str | Path = "paper") -> Rig:
    """Load a preset by name (``"paper"``, ``"paper-f8"``) or a TOML file by path."""
    data, default_name = _rig_data(str(source))
    return rig_from_dict(data, default_name=default_name)


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return repr(value)


def rig_to_toml(rig: Rig) -> str:
    """TOML text that :func:`load_rig` turns back into the same rig (design-built rigs only)."""
    if rig.design is None:
        raise RigError("rig: only rigs built from a design can be written as TOML")
    lines = [f"name = {_fmt(rig.name)}", ""]
    comps = {"design": rig.design, "camera": rig.camera, "laser": rig.laser, "stage": rig.stage,
             "sensor": rig.sensor}
    for table, comp in comps.items():
        lines.append(f"[{table}]")
        for key in sorted(_allowed(table), key=[f.name for f in dataclasses.fields(comp)].index):
            value = getattr(comp, key)
            if value is not None:  # TOML has no null: an absent key means "derived"
                lines.append(f"{key} = {_fmt(value)}")
        lines.append("")
    return "\n".join(lines)

"""Every object generator, looked up by name, and the ``SPEC`` mini-language of the CLI.

Importing this module imports every generator (each registers itself in
:mod:`lts360.scenes.objects.registry`), in the order ``lts360 objects`` lists them.

A spec is ``NAME[:key=value,key=value,...]``, e.g. ``plug-gauge:d=19.9987`` or
``cable-8:strands=7,x=0.5,tilt_deg=1``.  Keys are the generator's parameter names (with
units, ``diameter_mm``) or their short aliases (``d``); ``x``, ``y``, ``tilt_deg`` and
``tilt_azimuth_deg`` place the object.  A user's part is ``mesh:path=FILE`` or
``profile:path=FILE`` (see :mod:`.mesh_part`, :mod:`.profile_part`).
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path
from typing import Any

from lts360.scenes.objects import plug_gauge  # noqa: F401
from lts360.scenes.objects import pvc_pipe  # noqa: F401
from lts360.scenes.objects import alu_pipe  # noqa: F401
from lts360.scenes.objects import undercut_shaft  # noqa: F401
from lts360.scenes.objects import cut_tube  # noqa: F401
from lts360.scenes.objects import grooved_shaft  # noqa: F401
from lts360.scenes.objects import cable  # noqa: F401
from lts360.scenes.objects import cube  # noqa: F401
from lts360.scenes.objects import polished_shaft  # noqa: F401
from lts360.scenes.objects import mesh_part  # noqa: F401
from lts360.scenes.objects import profile_part  # noqa: F401
from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.registry import ObjectType, registered

__all__ = ["object_types", "get_object_type", "parse_spec", "build_object", "object_from_truth"]

_PLACEMENT_KEYS = {"x": "x_mm", "x_mm": "x_mm", "y": "y_mm", "y_mm": "y_mm",
                   "tilt_deg": "tilt_deg", "tilt": "tilt_deg",
                   "tilt_azimuth_deg": "tilt_azimuth_deg", "azimuth_deg": "tilt_azimuth_deg"}


def object_types() -> dict[str, ObjectType]:
    """All registered object types, by name (registration order)."""
    return registered()


def get_object_type(name: str) -> ObjectType:
    types = object_types()
    if name not in types:
        raise ValueError(f"unknown object {name!r}; choose one of {', '.join(types)}")
    return types[name]


def _convert(value: str, like: Any, key: str):
    try:
        if isinstance(like, bool):
            if value.lower() in ("1", "true", "yes", "on"):
                return True
            if value.lower() in ("0", "false", "no", "off"):
                return False
            raise ValueError
        if isinstance(like, int):
            return int(value)
        if isinstance(like, float):
            return float(value)
        return value
    except ValueError:
        kind = type(like).__name__
        raise ValueError(f"object parameter {key}: expected a {kind}, got {value!r}") from None


def parse_spec(spec: str) -> tuple[ObjectType, dict[str, Any], Placement]:
    """Split a spec into its type, generator parameters and placement (validated)."""
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError("object spec is empty; expected NAME[:key=value,...]")
    name, _, rest = spec.strip().partition(":")
    entry = get_object_type(name.strip())
    fields = {f.name: f for f in dataclasses.fields(entry.params_cls)}
    params: dict[str, Any] = {}
    placement: dict[str, float] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not value.strip():
            raise ValueError(f"object spec item {item!r} is not key=value")
        if key in _PLACEMENT_KEYS:
            placement[_PLACEMENT_KEYS[key]] = _convert(value.strip(), 0.0, key)
            continue
        field_name = entry.aliases.get(key, key)
        if field_name not in fields:
            allowed = sorted(set(fields) | set(entry.aliases) | set(_PLACEMENT_KEYS))
            raise ValueError(f"object {entry.name}: unknown parameter {key!r}; allowed: "
                             f"{', '.join(allowed)}")
        default = entry.defaults.get(field_name, fields[field_name].default)
        params[field_name] = _convert(value.strip(), default, key)
    return entry, params, Placement(**placement)


def build_object(spec: str) -> SceneObject:
    """Build the object a spec describes, e.g. ``build_object("plug-gauge:d=19.9987,x=0.2")``."""
    entry, values, placement = parse_spec(spec)
    return entry.make_params(values).build(placement)


def object_from_truth(object_truth: dict, frame_dir) -> SceneObject:
    """The object a frame folder's ``frame.json["object"]`` describes.

    A part read from a file (``mesh``, ``profile``) is rebuilt from the copy of its file in
    the frame folder (``part.<suffix>``, checked against the recorded SHA-256), so the folder
    is self-contained; a catalog object from its spec.
    """
    record = object_truth.get("part")
    if not record:
        return build_object(object_truth["spec"])
    copy = Path(frame_dir) / record["file"]
    if not copy.is_file():
        raise ValueError(f"--truth: {str(copy)!r} is missing (the part the frame was rendered "
                         f"from)")
    if hashlib.sha256(copy.read_bytes()).hexdigest() != record["sha256"]:
        raise ValueError(f"--truth: {str(copy)!r} differs from the part the frame was rendered "
                         f"from (SHA-256)")
    entry, values, placement = parse_spec(_spec_without_path(object_truth["spec"]))
    values["path"] = str(copy)
    return entry.make_params(values).build(placement)


def _spec_without_path(spec: str) -> str:
    """The spec with its ``path=`` item removed (the file is given apart)."""
    name, _, rest = spec.partition(":")
    items = [i for i in rest.split(",") if not i.strip().startswith("path=")]
    return f"{name}:" + ",".join(items)

"""Registry of object generators and the ``SPEC`` mini-language of the CLI.

A spec is ``NAME[:key=value,key=value,...]``, e.g. ``plug-gauge:d=19.9987`` or
``cable-8:strands=7,x=0.5,tilt_deg=1``.  Keys are the generator's parameter names (with
units, ``diameter_mm``) or their short aliases (``d``); ``x``, ``y``, ``tilt_deg`` and
``tilt_azimuth_deg`` place the object.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

from lts360.scenes.objects.base import Placement, SceneObject

__all__ = ["ObjectType", "register", "object_types", "get_object_type", "parse_spec", "build_object"]

_PLACEMENT_KEYS = {"x": "x_mm", "x_mm": "x_mm", "y": "y_mm", "y_mm": "y_mm",
                   "tilt_deg": "tilt_deg", "tilt": "tilt_deg",
                   "tilt_azimuth_deg": "tilt_azimuth_deg", "azimuth_deg": "tilt_azimuth_deg"}


@dataclass(frozen=True)
class ObjectType:
    """One entry of the registry.

    ``params_cls`` is a frozen dataclass of the generator's parameters with the paper's values
    as defaults; it validates itself in ``__post_init__`` and has a ``build(placement)`` method
    returning a :class:`SceneObject`.  ``aliases`` maps short keys to field names.
    """

    name: str
    description: str
    params_cls: type
    aliases: dict[str, str]
    defaults: dict[str, Any] = dataclasses.field(default_factory=dict)

    def parameters(self) -> list[tuple[str, Any, str]]:
        """(field name, default, alias) for every parameter, defaults overridden by the entry."""
        inv = {v: k for k, v in self.aliases.items()}
        out = []
        for f in dataclasses.fields(self.params_cls):
            default = self.defaults.get(f.name, f.default)
            out.append((f.name, default, inv.get(f.name, "")))
        return out

    def make_params(self, values: dict[str, Any]):
        kwargs = dict(self.defaults)
        kwargs.update(values)
        return self.params_cls(**kwargs)


_REGISTRY: dict[str, ObjectType] = {}


def register(entry: ObjectType) -> ObjectType:
    if entry.name in _REGISTRY:
        raise ValueError(f"object type {entry.name!r} registered twice")
    _REGISTRY[entry.name] = entry
    return entry


def object_types() -> dict[str, ObjectType]:
    """All registered object types, by name (registration order)."""
    from lts360.scenes.objects import _load_all  # noqa: F401  (import registers the generators)

    return dict(_REGISTRY)


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


def canonical_spec(name: str, params, placement: Placement, defaults: dict | None = None) -> str:
    """Spec string holding every parameter and the placement, so the object can be rebuilt."""
    def fmt(v):
        return repr(v) if isinstance(v, float) else str(v)

    items = [f"{f.name}={fmt(getattr(params, f.name))}" for f in dataclasses.fields(params)]
    items += [f"{k}={fmt(float(getattr(placement, k)))}"
              for k in ("x_mm", "y_mm", "tilt_deg", "tilt_azimuth_deg")]
    return f"{name}:" + ",".join(items)


BuildFn = Callable[..., SceneObject]

"""The table object generators register themselves in (:func:`register`), and the spec
string that rebuilds an object (:func:`canonical_spec`).  Looking an object up and parsing the
``SPEC`` mini-language of the CLI is the job of :mod:`lts360.scenes.objects.catalog`, which
imports every generator first.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

from lts360.scenes.objects.base import Placement, SceneObject

__all__ = ["ObjectType", "register", "registered", "canonical_spec"]


@dataclass(frozen=True)
class ObjectType:
    """One entry of the registry.

    ``params_cls`` is a frozen dataclass of the generator's parameters with the paper's values
    as defaults; it validates itself in ``__post_init__`` and has a ``build(placement)`` method
    returning a :class:`SceneObject`.  ``aliases`` maps short keys to field names.
    ``from_file``: the object is a user's part read from a file (``mesh``, ``profile``); it has
    no default shape, so it cannot be built from its name alone.
    """

    name: str
    description: str
    params_cls: type
    aliases: dict[str, str]
    defaults: dict[str, Any] = dataclasses.field(default_factory=dict)
    from_file: bool = False

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


def registered() -> dict[str, ObjectType]:
    """The entries registered so far, by name (registration order); see :mod:`.catalog`."""
    return dict(_REGISTRY)


def register(entry: ObjectType) -> ObjectType:
    if entry.name in _REGISTRY:
        raise ValueError(f"object type {entry.name!r} registered twice")
    _REGISTRY[entry.name] = entry
    return entry


def canonical_spec(name: str, params, placement: Placement, defaults: dict | None = None) -> str:
    """Spec string holding every parameter and the placement, so the object can be rebuilt."""
    def fmt(v):
        return repr(v) if isinstance(v, float) else str(v)

    items = [f"{f.name}={fmt(getattr(params, f.name))}" for f in dataclasses.fields(params)]
    items += [f"{k}={fmt(float(getattr(placement, k)))}"
              for k in ("x_mm", "y_mm", "tilt_deg", "tilt_azimuth_deg")]
    return f"{name}:" + ",".join(items)


BuildFn = Callable[..., SceneObject]

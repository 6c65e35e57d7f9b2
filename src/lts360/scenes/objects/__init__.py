"""Procedural objects of the paper (§4.5–4.6), each with its exact ground truth.

Use :func:`build_object` with a spec string, or the parameter dataclasses directly.
"""

from lts360.scenes.objects.base import Placement, SceneObject
from lts360.scenes.objects.catalog import build_object, get_object_type, object_types, parse_spec
from lts360.scenes.objects.registry import ObjectType

__all__ = ["Placement", "SceneObject", "ObjectType", "build_object", "get_object_type",
           "object_types", "parse_spec"]

"""Importing this module registers every generator, in the order ``lts360 objects`` lists them."""

from lts360.scenes.objects import plug_gauge  # noqa: F401

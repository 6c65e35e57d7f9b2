"""The argument parser of every command (each sub-command's ``func`` is its handler).

``build_parser`` makes the top level; each command group adds its own sub-commands:
``parse_scene`` (objects, object, rig, render), ``parse_measure`` (measure, compensate, score,
inspect, calibrate), ``parse_studies`` (study ..., demo) and ``design`` (design ...).
"""

from __future__ import annotations

import argparse

from lts360 import __version__
from lts360.cli.design import add_design_parser
from lts360.cli.parse_measure import add_measure_parsers
from lts360.cli.parse_scene import add_scene_parsers
from lts360.cli.parse_studies import add_demo_parser, add_study_parsers
from lts360.cli.usage import _Parser


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="lts360", description="360° laser triangulation with mirrors: simulation "
                "and reconstruction testbed.")
    p.add_argument("--version", action="version", version=f"lts360 {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    add_scene_parsers(sub)
    add_measure_parsers(sub)
    add_study_parsers(sub)
    add_design_parser(sub)
    add_demo_parser(sub)
    return p

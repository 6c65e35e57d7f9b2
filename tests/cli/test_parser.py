"""The parser tree: every command and sub-command there, each one's ``--help`` parses, and the
parser kept in small functions (one per command group)."""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

import pytest

import lts360.cli
from lts360.cli import build_parser, main

TREE = {
    "objects": {}, "object": {}, "rig": {}, "render": {}, "measure": {}, "compensate": {},
    "score": {}, "inspect": {}, "calibrate": {},
    "study": {name: {} for name in ("plug-gauge", "monte-carlo", "examples", "line-speed",
                                    "interreflection", "bias", "design-space", "algorithms")},
    "design": {"optimize": {}, "map": {}, "check": {}},
    "demo": {},
}


def _tree(parser: argparse.ArgumentParser) -> dict:
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {name: _tree(p) for a in subs for name, p in a.choices.items()}


def _paths(tree: dict, prefix=()):
    for name, below in tree.items():
        yield prefix + (name,)
        yield from _paths(below, prefix + (name,))


def test_the_parser_tree_has_every_command_in_order():
    tree = _tree(build_parser())
    assert tree == TREE
    assert list(tree) == list(TREE) and list(tree["study"]) == list(TREE["study"])


@pytest.mark.parametrize("path", list(_paths(TREE)), ids=" ".join)
def test_every_command_parses_its_help(path, capsys):
    assert main([*path, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: lts360 " + " ".join(path))


def test_every_leaf_command_has_its_handler():
    parser = build_parser()
    for path in _paths(TREE):
        sub = parser
        for name in path:
            sub = next(a for a in sub._actions
                       if isinstance(a, argparse._SubParsersAction)).choices[name]
        has_children = any(isinstance(a, argparse._SubParsersAction) for a in sub._actions)
        assert has_children or callable(sub.get_default("func")), path


def test_no_cli_function_is_longer_than_120_lines():
    long = []
    for f in sorted(Path(lts360.cli.__file__).parent.glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > 120:
                    long.append(f"{f.name}:{node.lineno} {node.name} ({n} lines)")
    assert not long, long


def test_the_command_line_starts_without_the_studies_heavy_modules():
    """Building the parser (every ``lts360 ... --help``) imports no study, no xarray and no
    Mitsuba: a default the parser shows is written there, not imported from its study."""
    import subprocess
    import sys

    code = ("import sys; from lts360.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('xarray', 'mitsuba', 'lts360.experiments.monte_carlo', "
            "'lts360.experiments.gauge_study') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]", out

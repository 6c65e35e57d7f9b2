"""Every module stays readable: no source file over 800 lines, no function over 120.

The limits of the house (docs/development.md); a function is counted from its first
decorator to its last line, nested functions and methods included.
"""

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src" / "lts360"
MAX_FILE_LINES = 800
MAX_FUNCTION_LINES = 120


def _sources():
    return sorted(SRC.rglob("*.py"))


def test_the_package_is_found():
    assert len(_sources()) > 50


def test_no_file_over_800_lines():
    long = {str(p.relative_to(SRC)): n for p in _sources()
            if (n := len(p.read_text().splitlines())) > MAX_FILE_LINES}
    assert long == {}


def test_no_function_over_120_lines():
    long = {}
    for p in _sources():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                start = min([node.lineno] + [d.lineno for d in node.decorator_list])
                n = node.end_lineno - start + 1
                if n > MAX_FUNCTION_LINES:
                    long[f"{p.relative_to(SRC)}:{node.lineno} {node.name}"] = n
    assert long == {}

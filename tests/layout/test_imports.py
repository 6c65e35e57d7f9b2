"""The package's import graph: no circles, and the layers DESIGN.md names.

Built from the source (every ``import``, at module level or inside a function), so a lazy
import cannot hide a circle.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import lts360

SRC = Path(lts360.__file__).parent


def _modules() -> dict[str, Path]:
    out = {}
    for p in SRC.rglob("*.py"):
        parts = ("lts360",) + p.relative_to(SRC).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str | None:
    """The absolute module a ``from … import`` names: ``from ..x import y`` in ``a.b.c`` is
    ``a.x`` (level 1 is the module's own package; a package's ``__init__`` is its own)."""
    if node.level == 0:
        return node.module
    package = module.split(".") if is_package else module.split(".")[:-1]
    if node.level - 1 > len(package) - 1:
        return None  # beyond the top-level package: Python raises ImportError
    base = package[:len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_in(module: str, is_package: bool, source: str, mods) -> set[str]:
    """The lts360 modules that ``source`` (the text of ``module``) imports, relative imports
    resolved (``from pkg import submodule`` names the submodule)."""
    out = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            target = _absolute(module, is_package, node)
            if target is None:
                continue
            subs = {f"{target}.{a.name}" for a in node.names} & mods
            out |= subs
            if len(subs) < len(node.names) and target in mods:
                out.add(target)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names} & mods
    return out


@functools.lru_cache(maxsize=1)
def import_graph() -> dict[str, frozenset[str]]:
    """Module → the lts360 modules it imports, absolute and relative."""
    mods = _modules()
    return {m: frozenset(imports_in(m, p.name == "__init__.py", p.read_text(), mods.keys()))
            for m, p in mods.items()}


def test_relative_imports_are_resolved():
    """A relative import names the same module as its absolute spelling, so it cannot slip past
    a layer rule (a planted ``from ...simulator import frame`` in recon is seen)."""
    mods = {"lts360", "lts360.recon", "lts360.recon.triangulation",
            "lts360.recon.triangulation.inverse", "lts360.simulator", "lts360.simulator.frame",
            "lts360.scenes", "lts360.scenes.objects"}
    m = "lts360.recon.triangulation.inverse"
    assert imports_in(m, False, "from ...simulator import frame", mods) == \
        {"lts360.simulator.frame"}
    assert imports_in(m, False, "from ...scenes.objects import build_object", mods) == \
        {"lts360.scenes.objects"}
    assert imports_in(m, False, "from . import inverse", mods) == \
        {"lts360.recon.triangulation.inverse"}
    assert imports_in(m, False, "from .. import triangulation", mods) == \
        {"lts360.recon.triangulation"}
    # in a package's __init__, level 1 is the package itself
    assert imports_in("lts360.recon", True, "from ..simulator import frame", mods) == \
        {"lts360.simulator.frame"}
    assert imports_in("lts360.recon", True, "from .triangulation import inverse", mods) == \
        {"lts360.recon.triangulation.inverse"}
    # the same import written absolutely
    assert imports_in(m, False, "from lts360.simulator import frame", mods) == \
        {"lts360.simulator.frame"}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on, stack, out = {}, {}, set(), [], []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_cycle_finder_finds_a_planted_circle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(g) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circles():
    assert cycles(import_graph()) == []


def _imports_of(prefix: str) -> set[str]:
    g = import_graph()
    return {t for m, ts in g.items() if m == prefix or m.startswith(prefix + ".") for t in ts}


def test_recon_reads_images_and_calibrations_only():
    """recon runs on real images: it never imports the simulator, the scenes or a study."""
    bad = {t for t in _imports_of("lts360.recon")
           if t.split(".")[1] in ("simulator", "scenes", "experiments", "cli", "inspect")}
    assert bad == set()


def test_calibration_and_triangulation_import_neither_each_other():
    """The two parts of recon stand side by side on what both need (recon.model, images,
    lines, view_points)."""
    for part, other in (("lts360.recon.triangulation", "lts360.recon.calibration"),
                        ("lts360.recon.calibration", "lts360.recon.triangulation")):
        bad = {t for t in _imports_of(part) if t == other or t.startswith(other + ".")}
        assert bad == set(), part


def test_recon_shared_modules_import_neither_part():
    for m in ("lts360.recon.model", "lts360.recon.images", "lts360.recon.lines",
              "lts360.recon.view_points"):
        bad = {t for t in import_graph()[m] if t.startswith(("lts360.recon.calibration",
                                                             "lts360.recon.triangulation"))}
        assert bad == set(), m


def test_geometry_and_scenes_do_not_import_the_layers_above():
    for layer in ("lts360.geometry", "lts360.scenes"):
        bad = {t for t in _imports_of(layer)
               if t.split(".")[1] in ("simulator", "recon", "experiments", "cli", "inspect")}
        assert bad == set(), layer


def test_design_models_rigs_without_the_simulator_or_the_reconstruction():
    """design is an explicit model of the rig: scenes and geometry below it, never the
    simulator, the reconstruction, a study or the command line; nothing below imports it."""
    bad = {t for t in _imports_of("lts360.design")
           if t.split(".")[1] in ("simulator", "recon", "experiments", "cli", "inspect")}
    assert bad == set()
    below = {t for layer in ("lts360.geometry", "lts360.scenes", "lts360.simulator",
                             "lts360.recon")
             for t in _imports_of(layer) if t.startswith("lts360.design")}
    assert below == set()


def test_inspect_reads_clouds_and_nominals_never_the_simulator():
    """inspect works on measured clouds: recon, geometry and scenes (nominal contours, the truth
    of rendered frames) below it; never the simulator, a study or the command line."""
    bad = {t for t in _imports_of("lts360.inspect")
           if t.split(".")[1] in ("simulator", "experiments", "cli", "design")}
    assert bad == set()
    below = {t for layer in ("lts360.geometry", "lts360.scenes", "lts360.recon")
             for t in _imports_of(layer) if t.startswith("lts360.inspect")}
    assert below == set()


def test_twin_sits_above_recon_and_simulator_and_reads_no_truth():
    """The twin composes the simulator and the reconstruction; it never reads ground truth
    (experiments, the score) and nothing below it imports it (recon offers a hook instead)."""
    bad = {t for t in _imports_of("lts360.twin")
           if t.split(".")[1] in ("experiments", "cli", "inspect", "design")}
    assert bad == set()
    below = {t for layer in ("lts360.geometry", "lts360.scenes", "lts360.simulator",
                             "lts360.recon", "lts360.inspect", "lts360.design")
             for t in _imports_of(layer) if t.startswith("lts360.twin")}
    assert below == set()

"""No import circle in ``nscontrol.simulate``: its modules form a directed acyclic graph.

Every module of ``src/nscontrol/simulate`` is parsed with :mod:`ast` (nothing is imported), and
every import statement counts -- at module level, inside functions, and under
``if TYPE_CHECKING:`` -- so a circle hidden in a function-level import (which works at run time
but ties the two modules into one unit that cannot be read, tested or changed apart) is found
too. A module that needs a helper of its importer gets it from a third module both import.
"""

from __future__ import annotations

import ast
from pathlib import Path

import nscontrol

PACKAGE = "nscontrol.simulate"
ROOT = Path(nscontrol.__file__).resolve().parent / "simulate"

#: Circles another helper of issue 30 removes (the ``mj`` branch): the coordinator deletes
#: this entry when that branch is merged. Each entry is the circle's modules, sorted.
PENDING: set[tuple[str, ...]] = set()


def _module_name(path: Path, root: Path, package: str) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([package, *parts])


def import_graph(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """``module -> modules of the same package it imports``, from ``{name: (source,
    is_package)}``; ``from . import x`` and ``from .m import name`` both count as imports of
    the submodule when it is one of ``sources`` (and of the package they go through)."""
    graph: dict[str, set[str]] = {}
    for name, (source, is_package) in sources.items():
        base = name if is_package else name.rpartition(".")[0]
        deps: set[str] = set()
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    up = base.split(".")[:len(base.split(".")) - (node.level - 1)]
                    module = ".".join(up + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                targets = [module] + [f"{module}.{alias.name}" for alias in node.names]
            else:
                continue
            deps.update(t for t in targets if t in sources and t != name)
        graph[name] = deps
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted;
    a component is a set of modules that import each other, directly or through others."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _path_in(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """One closed import path through ``component`` (for the failure message)."""
    inside = set(component)
    path = [component[0]]
    while True:
        nxt = sorted(graph[path[-1]] & inside)
        step = next((m for m in nxt if m == path[0]), None) or \
            next((m for m in nxt if m not in path), None)
        if step is None:   # pragma: no cover - a component always closes
            return path
        path.append(step)
        if step == path[0]:
            return path


def _simulate_sources() -> dict[str, tuple[str, bool]]:
    return {_module_name(p, ROOT, PACKAGE): (p.read_text(encoding="utf-8"),
                                             p.name == "__init__.py")
            for p in sorted(ROOT.rglob("*.py"))}


def _short(name: str) -> str:
    return name.removeprefix(PACKAGE + ".")


def test_simulate_has_no_import_circle() -> None:
    graph = import_graph(_simulate_sources())
    assert len(graph) > 20   # every module was read
    found = [c for c in circles(graph) if tuple(_short(m) for m in c) not in PENDING]
    assert not found, "import circles in nscontrol.simulate:\n" + "\n".join(
        " -> ".join(_short(m) for m in _path_in(graph, c)) for c in found)


def test_pending_circles_still_exist() -> None:
    """A circle listed as pending that is gone must leave :data:`PENDING` (so the set only
    shrinks and never hides a new circle under an old name)."""
    present = {tuple(_short(m) for m in c) for c in circles(import_graph(_simulate_sources()))}
    assert PENDING <= present, f"remove from PENDING: {sorted(PENDING - present)}"


def test_the_check_finds_circles_through_function_imports() -> None:
    """The graph sees a function-level import and a ``TYPE_CHECKING`` one, and the search
    reports the circle they close (the check can fail)."""
    sources = {
        "pkg": ("", True),
        "pkg.a": ("from .b import f\n", False),
        "pkg.b": ("def f():\n    from . import c\n", False),
        "pkg.c": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                  "    from pkg.a import g\n", False),
        "pkg.d": ("import pkg.a\n", False),
    }
    graph = import_graph(sources)
    assert graph["pkg.b"] == {"pkg", "pkg.c"}
    assert circles(graph) == [["pkg.a", "pkg.b", "pkg.c"]]
    assert _path_in(graph, ["pkg.a", "pkg.b", "pkg.c"]) == ["pkg.a", "pkg.b", "pkg.c", "pkg.a"]
    del sources["pkg.c"]
    assert circles(import_graph(sources)) == []

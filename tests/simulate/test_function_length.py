"""No function in ``nscontrol.simulate`` is longer than 80 lines (issue 30).

A function is counted from its ``def`` line (decorators excluded) to its last line,
docstring included: what a reader has to hold at once. Every module of
``src/nscontrol/simulate`` is parsed with :mod:`ast` (nothing is imported), so numba kernels,
nested functions and methods count too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import nscontrol

ROOT = Path(nscontrol.__file__).resolve().parent / "simulate"
LIMIT = 80

#: Files other helpers of issue 30 rewrite today (relative to ``simulate/``, glob patterns):
#: their long functions are theirs to split. The coordinator shrinks this set at merge.
ALLOWED: frozenset[str] = frozenset()


def long_functions(source: str, limit: int = LIMIT) -> list[tuple[str, int, int]]:
    """``(qualified name, first line, length)`` of every function of ``source`` longer than
    ``limit`` lines."""
    out: list[tuple[str, int, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    length = (child.end_lineno or child.lineno) - child.lineno + 1
                    if length > limit:
                        out.append((name, child.lineno, length))
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return out


def _allowed(path: Path) -> bool:
    return any(path.match(pattern) for pattern in ALLOWED) and path.parent == ROOT


def test_no_function_in_simulate_is_longer_than_80_lines() -> None:
    files = sorted(ROOT.rglob("*.py"))
    assert len(files) > 20   # every module was read
    found = [f"{p.relative_to(ROOT)}:{line} {name} ({length} lines)"
             for p in files if not _allowed(p)
             for name, line, length in long_functions(p.read_text(encoding="utf-8"))]
    assert not found, (f"functions longer than {LIMIT} lines in nscontrol.simulate (split "
                       "them into well-named pieces):\n" + "\n".join(found))


def test_allowed_files_exist() -> None:
    """Each ``ALLOWED`` pattern names files that exist (a stale entry must leave the set)."""
    names = [p for p in ROOT.glob("*.py")]
    stale = sorted(pat for pat in ALLOWED if not any(p.match(pat) for p in names))
    assert not stale, f"remove from ALLOWED: {stale}"


def test_the_count_sees_nested_functions_and_kernels() -> None:
    """The check can fail: a long decorated kernel and a long method are reported, with the
    length from ``def`` to the last line, docstring included."""
    body = "\n".join(f"    x{i} = {i}" for i in range(LIMIT - 2))
    source = (f"@njit(cache=True)\ndef kernel(a):\n    '''doc'''\n{body}\n\n"
              f"class C:\n    def short(self):\n        return 1\n\n"
              f"    def long(self):\n        '''doc'''\n"
              + "\n".join(f"        y{i} = {i}" for i in range(LIMIT)) + "\n")
    assert long_functions(source) == [("C.long", LIMIT + 7, LIMIT + 2)]
    assert long_functions(source, limit=LIMIT - 1) == [("kernel", 2, LIMIT),
                                                        ("C.long", LIMIT + 7, LIMIT + 2)]

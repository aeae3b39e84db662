"""Every check of every example has a plain-language name: words a reader who never saw the
chapter's source document understands, never a section number ("5. 5.2: ...", "§6"), a
"spec" reference or a bare identifier. Machine-readable keys live in ``Check.key``.

The names are read from the source (``ast``), without running the examples: a literal first
argument of ``check(...)``, an f-string with its fields shown as ``{}``, and the
``CHECK_NAMES`` tables of the modules that keep their names in one place.
"""

import ast
import importlib
import pkgutil
import re
from pathlib import Path

import pytest

import nscontrol.examples as examples_pkg

# "5. 5.2: x", "1 CQLF", "10 max", "3.2 bound", "1a impact", "4c: wall", "§6", "spec 5.7"
# (case-sensitive: "2T orbit", twice the period, is not a section; ANYWHERE catches "Spec")
SECTION_START = re.compile(r"^\s*(§|\d+[a-z]?(\.\d+[a-z]?)*[.:)]?\s)")
ANYWHERE = re.compile(r"§|\bspec\b|\bspecification\b", re.I)
KEY = re.compile(r"^[A-Za-z0-9_.\-]+$")


def _modules():
    return [info.name for info in pkgutil.iter_modules(examples_pkg.__path__)
            if not info.name.startswith("_")]


def _text(node):
    """A string literal, or an f-string with ``{}`` for its fields; None for anything else."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "{}" for v in node.values)
    return None


def _literal_names(module):
    """``(line, name)`` of every ``check(...)`` call whose first argument is a string."""
    path = Path(examples_pkg.__path__[0]) / f"{module}.py"
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id == "check" and node.args):
            text = _text(node.args[0])
            if text is not None:
                found.append((node.lineno, text))
    return found


def _all_names():
    names = []
    for module in _modules():
        names += [(f"{module}:{line}", text) for line, text in _literal_names(module)]
        table = getattr(importlib.import_module(f"nscontrol.examples.{module}"),
                        "CHECK_NAMES", {})
        names += [(f"{module}.CHECK_NAMES[{key!r}]", text) for key, text in table.items()]
    return names


def test_names_are_found():
    # the reader above must see the three chapters' checks, or the test below proves nothing
    where = {w.split(":")[0].split(".")[0] for w, _ in _all_names()}
    assert {"ch02_impact_observer", "ch08_lure_observer", "ch11_convergent_pwa",
            "mechanics", "setvalued", "foundation"} <= where


@pytest.mark.parametrize("where,name", _all_names())
def test_check_name_is_plain_language(where, name):
    assert not SECTION_START.match(name), f"{where}: {name!r} starts with a section number"
    assert not ANYWHERE.search(name), f"{where}: {name!r} cites a section or a spec"
    assert " " in name.strip(), f"{where}: {name!r} is an identifier, not words"


@pytest.mark.parametrize("module", _modules())
def test_check_name_tables_have_stable_keys(module):
    table = getattr(importlib.import_module(f"nscontrol.examples.{module}"), "CHECK_NAMES", {})
    bad = [key for key in table if not KEY.match(key)]
    assert not bad, f"{module}: keys must be identifiers (letters, digits, _ . -): {bad}"

"""Run the ``Examples`` of every docstring of every module of the package as doctests.

Modules are found by ``pkgutil.walk_packages`` (none skipped): a module that fails to import
fails its test, a docstring example that no longer produces its documented output fails too.
"""

import doctest
import importlib
import pkgutil

import pytest

import nscontrol


def _module_names() -> list[str]:
    names = ["nscontrol"]
    for info in pkgutil.walk_packages(nscontrol.__path__, prefix="nscontrol."):
        names.append(info.name)
    return sorted(set(names))


MODULES = _module_names()


def test_every_module_is_collected():
    # the walk reaches every layer (a broken package __init__ would hide its modules)
    for name in ("nscontrol.numerics.lcp", "nscontrol.laws.relay", "nscontrol.simulate.trajectory",
                 "nscontrol.testing.check", "nscontrol.examples.foundation", "nscontrol.cli"):
        assert name in MODULES


def _doctests(name: str) -> list[doctest.DocTest]:
    """The docstring examples of the objects defined in module ``name`` (imported names are
    left to the module that defines them)."""
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder(exclude_empty=True).find(module, name)
            if t.examples]


def test_examples_are_found():
    for name in ("nscontrol.numerics.lcp", "nscontrol.laws.relay", "nscontrol.testing.check",
                 "nscontrol._validation"):
        assert _doctests(name), name
    total = sum(len(t.examples) for name in MODULES for t in _doctests(name))
    assert total >= 50


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)               # examples that write files write them here
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    failures = []
    for test in _doctests(name):
        out: list[str] = []
        if runner.run(test, out=out.append, clear_globs=True).failed:
            failures.append(f"{test.name}:\n" + "".join(out))
    assert not failures, "\n".join(failures)

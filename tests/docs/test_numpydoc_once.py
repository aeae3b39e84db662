"""docs/_ext/numpydoc_once.py renders exactly what numpydoc renders (it only keeps the
compiled template instead of compiling it for every docstring)."""

import importlib.util
import sys
from pathlib import Path

import pytest

pytest.importorskip("numpydoc", reason="the docs extra (numpydoc) is not installed")

from numpydoc import docscrape_sphinx  # noqa: E402

EXT = Path(__file__).resolve().parents[2] / "docs" / "_ext" / "numpydoc_once.py"


@pytest.fixture(scope="module")
def once():
    spec = importlib.util.spec_from_file_location("numpydoc_once", EXT)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("numpydoc_once", module)
    spec.loader.exec_module(module)
    return module


def _samples():
    from nscontrol.examples import check, format_value
    from nscontrol.laws.set_valued import Relay
    from nscontrol.systems.lure import LureSystem

    return [(check, "function"), (format_value, "function"), (Relay, "class"),
            (LureSystem, "class")]


def test_same_rendering_as_numpydoc(once):
    for obj, what in _samples() * 2:        # the second round uses the kept template
        expected = str(docscrape_sphinx.get_doc_object(obj, what=what, config={}))
        assert str(once.get_doc_object(obj, what=what, config={})) == expected, obj


def test_template_is_compiled_once_per_builder(once, monkeypatch):
    calls = []
    original = docscrape_sphinx.get_doc_object

    def counting(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(once, "_templates", {})
    monkeypatch.setattr(docscrape_sphinx, "get_doc_object", counting)
    for obj, what in _samples():
        once.get_doc_object(obj, what=what, config={})
    assert len(calls) == 1

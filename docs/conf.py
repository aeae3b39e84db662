"""Sphinx configuration for the nscontrol documentation (``make docs``).

The build runs with warnings as errors. The API reference is generated from the docstrings
(autosummary + numpydoc); the chapter and layer pages are the Markdown files of this folder,
read by myst-parser; the gallery page is written at build time from the example registry and,
when present, the figures of an ``nscontrol report --out DIR`` run.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE / "_ext"))

project = "nscontrol"
author = "the nscontrol developers"
copyright = "2026, the nscontrol developers"  # noqa: A001  (Sphinx's name)

# Build time (``make docs`` runs in CI with a two-minute limit): numpydoc is loaded through
# _ext/numpydoc_once.py, which compiles its docstring template once per build instead of for
# every docstring (52 s -> 43 s of CPU for a clean build); sphinx.ext.viewcode is not used
# (highlighting every module's source into a page cost another 6.5 s; the source is in the
# repository). Clean build: about 36 s of CPU.
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc_once",      # numpydoc, its template loaded once (_ext/numpydoc_once.py)
    "myst_parser",
    "gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build"]
templates_path = ["_templates"]
html_static_path = ["_static"]
html_theme = "furo"
html_title = "nscontrol"

myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

autosummary_generate = True
autosummary_imported_members = False
# "ignore-module-all": a subpackage's __all__ re-exports its modules' names (so that
# ``from nscontrol.laws import Relay`` works); each object is documented once, on the page of
# the module that defines it.
autodoc_default_options = {"members": True, "show-inheritance": False,
                           "ignore-module-all": True}
autodoc_typehints = "none"          # numpydoc shows the documented types

numpydoc_show_class_members = False  # autosummary lists members; no duplicate tables
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()
numpydoc_xref_param_type = False

# Unresolvable type names in docstrings (``array_like``, ``callable``) are prose, not links.
nitpicky = False

"""The package is layered: a lower layer never imports a higher one, and no module reaches
into another subpackage's private names.

Every module of ``src/nscontrol`` is parsed with :mod:`ast` (nothing is imported), so the
check also sees imports made inside functions and ``importlib.import_module("...")`` calls
with a literal name. The layers, lowest first (docs/architecture.md)::

    errors, _validation, _progress, _lazy, sweep -> numerics -> laws -> systems -> simulate
    -> design, optimal -> analysis -> testing -> examples -> cli, report, the package root

Modules of one layer may import each other. A name starting with ``_`` belongs to its
subpackage: importing it from another subpackage is refused, and so is importing a private
module of another subpackage -- except the compiled-kernel modules ``_*_kernels``, whose
public functions are the entry points numba kernels of other modules call directly (a
compiled kernel cannot call through a Python wrapper).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

import nscontrol

PACKAGE = "nscontrol"
ROOT = Path(nscontrol.__file__).resolve().parent

#: Layer of each top-level unit of the package (a subpackage or a top-level module).
LAYERS: dict[str, int] = {
    "errors": 0, "_validation": 0, "_progress": 0, "_lazy": 0, "_files": 0, "_kernel_cache": 0,
    "_compile_background": 0, "_processes": 0,
    "sweep": 0,
    "numerics": 1,
    "laws": 2,
    "systems": 3,
    "simulate": 4,
    "design": 5, "optimal": 5,   # optimal: trajectory optimisation (imports systems, numerics)
    "analysis": 6,
    "testing": 7,
    "examples": 8,
    "cli": 9, "report": 9, "__main__": 9, "": 9,   # "": the package root, nscontrol/__init__
    "_warm": 9,      # the background compiler's process: imports the package first
}


@dataclass(frozen=True)
class Import:
    """One import found in a module: the module it reaches, the names taken from it."""

    target: str
    names: tuple[str, ...]
    line: int


def module_name(path: Path) -> str:
    """``nscontrol.design.impact_observer`` for ``.../nscontrol/design/impact_observer.py``."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join([PACKAGE, *parts])


def all_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


MODULES = all_modules()


def unit_of(module: str) -> str:
    """The top-level unit of a module of the package (``""`` for the package root)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _resolve_from(importer: str, is_package: bool, node: ast.ImportFrom) -> str:
    """Absolute name of the module of ``from <module> import ...`` (relative ones resolved)."""
    if not node.level:
        return node.module or ""
    base = importer.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(source: str, importer: str, is_package: bool = False) -> list[Import]:
    """Every import of the package's own modules in ``source``, at any depth."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [Import(alias.name, (), node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve_from(importer, is_package, node)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in MODULES:   # ``from .. import sweep``: the module itself
                    found.append(Import(sub, (), node.lineno))
                else:
                    found.append(Import(base, (alias.name,), node.lineno))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == "import_module" and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            found.append(Import(node.args[0].value, (), node.lineno))
    return [imp for imp in found
            if imp.target == PACKAGE or imp.target.startswith(PACKAGE + ".")]


def _private_module(target: str) -> str | None:
    """The first private component of ``target`` below its unit, unless a compiled-kernel
    module (``_*_kernels``)."""
    for part in target.split(".")[2:]:
        if part.startswith("_") and not part.startswith("__") and not part.endswith("_kernels"):
            return part
    return None


def violations(source: str, importer: str, is_package: bool = False) -> list[str]:
    """Why the imports of ``source`` (module ``importer``) break the layering, one line each."""
    unit = unit_of(importer)
    if unit not in LAYERS:
        return [f"{importer}: unit {unit!r} has no layer; add it to LAYERS in tests/test_layers.py "
                "and to docs/architecture.md"]
    layer, out = LAYERS[unit], []
    for imp in imports_of(source, importer, is_package):
        t_unit = unit_of(imp.target)
        t_layer = LAYERS.get(t_unit)
        where = f"{importer}:{imp.line}"
        if t_layer is None:
            out.append(f"{where} imports {imp.target}, whose unit {t_unit!r} has no layer")
            continue
        if t_layer > layer:
            out.append(f"{where} imports {imp.target}: layer {layer} ({unit or PACKAGE}) must not "
                       f"import the higher layer {t_layer} ({t_unit or PACKAGE})")
        if t_unit == unit:
            continue
        private = [n for n in imp.names if n.startswith("_") and not n.startswith("__")]
        if private:
            out.append(f"{where} imports the private name(s) {', '.join(private)} of "
                       f"{imp.target} ({t_unit}, layer {t_layer}) into {unit or PACKAGE} "
                       f"(layer {layer}); make the helper public where it belongs, or move it")
        part = _private_module(imp.target)
        if part is not None:
            out.append(f"{where} imports the private module {imp.target} of {t_unit} "
                       f"(layer {t_layer}) into {unit or PACKAGE} (layer {layer})")
    return out


# ---------------------------------------------------------------------------------------------
# The package itself
# ---------------------------------------------------------------------------------------------
def test_every_unit_of_the_package_has_a_layer():
    units = {unit_of(m) for m in MODULES}
    assert units <= set(LAYERS), f"units without a layer: {sorted(units - set(LAYERS))}"
    assert len(MODULES) > 50    # the walk found the package, not an empty directory


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_import_goes_up_a_layer_or_into_private_names(module):
    path = MODULES[module]
    problems = violations(path.read_text(encoding="utf-8"), module, path.name == "__init__.py")
    assert not problems, "\n".join(problems)


def test_no_shim_of_the_hybrid_model_is_left_in_simulate():
    assert f"{PACKAGE}.systems.hybrid" in MODULES
    assert f"{PACKAGE}.simulate.hybrid" not in MODULES


# ---------------------------------------------------------------------------------------------
# The checker catches what it must (so that a green run means something)
# ---------------------------------------------------------------------------------------------
def test_an_upward_import_inside_a_function_is_named_with_both_layers():
    src = "def f():\n    from ..simulate.trajectory import Trajectory\n"
    (msg,) = violations(src, "nscontrol.systems.model_x")
    assert "nscontrol.systems.model_x:2" in msg and "nscontrol.simulate.trajectory" in msg
    assert "layer 3 (systems)" in msg and "layer 4 (simulate)" in msg


def test_relative_absolute_and_importlib_forms_are_all_seen():
    for src in ("from ..analysis import observability\n",
                "import nscontrol.analysis.observability\n",
                "from nscontrol import analysis\n",
                "import importlib\nimportlib.import_module('nscontrol.analysis.periodic')\n"):
        assert violations(src, "nscontrol.design.model_x"), src


def test_a_package_init_resolves_relative_imports_from_itself():
    assert not violations("from .lcp import solve_lcp\n", "nscontrol.numerics", True)
    assert violations("from ..design import lure_observer\n", "nscontrol.numerics", True)


def test_private_names_and_modules_of_another_subpackage_are_refused():
    (msg,) = violations("from ..systems.switched import _fd_jacobian\n",
                        "nscontrol.simulate.model_x")
    assert "_fd_jacobian" in msg and "layer 3" in msg and "layer 4" in msg
    assert violations("from ..numerics._helpers import solve\n", "nscontrol.simulate.model_x")
    # allowed: private names within a subpackage, the base layer's modules, compiled kernels
    assert not violations("from ._pwa import _integrate\n",
                          "nscontrol.simulate.switching")
    assert not violations("from .._validation import as_vector\n", "nscontrol.laws.model_x")
    assert not violations("from ..numerics._lcp_kernels import lemke_kernel\n",
                          "nscontrol.simulate.model_x")


def test_downward_and_same_layer_imports_pass():
    assert not violations("from ..numerics.lti import LTIFlow\nfrom .. import sweep\n",
                          "nscontrol.analysis.model_x")
    assert not violations("from .errors import ModelError\n", "nscontrol.sweep")

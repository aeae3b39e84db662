"""Meta-tests of the public API (python-control's docstring tests as the model).

Every subpackage lists its public names in ``__all__``; each must import from that
subpackage, carry a docstring (a constant: a ``#:`` comment above its assignment), and every
parameter of a public function or class must appear in the numpydoc ``Parameters`` section.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import pytest

import nscontrol

SUBPACKAGES = ("laws", "systems", "numerics", "simulate", "design", "optimal", "analysis",
               "testing", "examples")
SRC = Path(nscontrol.__file__).parent


def _public_names() -> list[tuple[str, str]]:
    out = []
    for sub in SUBPACKAGES:
        module = importlib.import_module(f"nscontrol.{sub}")
        out.extend((sub, name) for name in module.__all__)
    return out


PUBLIC = _public_names()


def _documented_constants() -> set[str]:
    """Module-level names assigned right below a ``#:`` comment, anywhere in the package."""
    names: set[str] = set()
    for path in SRC.rglob("*.py"):
        lines = path.read_text(encoding="utf-8").splitlines()
        for node in ast.parse("\n".join(lines)).body:
            targets = (node.targets if isinstance(node, ast.Assign)
                       else [node.target] if isinstance(node, ast.AnnAssign) else [])
            above = lines[node.lineno - 2].strip() if node.lineno >= 2 else ""
            if above.startswith("#:"):
                names.update(t.id for t in targets if isinstance(t, ast.Name))
    return names


@pytest.mark.parametrize("sub", SUBPACKAGES)
def test_every_subpackage_declares_all(sub):
    module = importlib.import_module(f"nscontrol.{sub}")
    assert module.__all__, f"nscontrol.{sub}: empty __all__"
    assert len(set(module.__all__)) == len(module.__all__), f"nscontrol.{sub}: duplicates"
    assert set(module.__all__) <= set(dir(module))


@pytest.mark.parametrize("sub", ["laws", "systems", "numerics", "design", "analysis"])
def test_subpackage_exports_every_public_module_name(sub):
    """What a public module of the package exports, the package exports (so a name added to
    a module cannot be forgotten in the package's lazy map)."""
    package = importlib.import_module(f"nscontrol.{sub}")
    missing = []
    for info in pkgutil.iter_modules(package.__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"nscontrol.{sub}.{info.name}")
        missing += [f"{info.name}.{n}" for n in getattr(module, "__all__", ())
                    if n not in package.__all__]
    assert not missing, f"nscontrol.{sub}.__all__ lacks {missing}"


def test_public_names_import_and_are_documented():
    constants = _documented_constants()
    missing = []
    for sub, name in PUBLIC:
        namespace: dict = {}
        exec(f"from nscontrol.{sub} import {name}", namespace)  # the user's spelling
        obj = namespace[name]
        if inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj):
            if not inspect.getdoc(obj) or obj.__doc__ is None:
                missing.append(f"nscontrol.{sub}.{name}")
        elif name not in constants:
            missing.append(f"nscontrol.{sub}.{name} (constant without a #: comment)")
    assert not missing, "undocumented public names:\n" + "\n".join(missing)


def test_issue_spellings():
    from nscontrol.laws import Relay
    from nscontrol.systems import LureSystem

    assert Relay.__module__ == "nscontrol.laws.relay"
    assert LureSystem.__module__ == "nscontrol.systems.lure"
    assert callable(nscontrol.design.design_lure_observer)
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        nscontrol.laws.Nope  # noqa: B018


# -- numpydoc Parameters sections -----------------------------------------------------
_SECTION = r"^(\s*){}\s*\n\1-{{3,}}\s*\n"
_HEADING = re.compile(r"^\s*[A-Z][A-Za-z ]+\s*\n\s*-{3,}\s*$", re.MULTILINE)


def documented_parameters(doc: str, section: str = "Parameters") -> set[str]:
    """Names listed in a numpydoc section (``a, b : type`` lines count each).

    >>> sorted(documented_parameters('''Do.
    ...
    ...     Parameters
    ...     ----------
    ...     a, b : float
    ...         Numbers.
    ...     **options
    ...         More.
    ...
    ...     Returns
    ...     -------
    ...     c : float
    ... '''))
    ['**options', 'a', 'b']
    """
    match = re.search(_SECTION.format(section), doc, re.MULTILINE)
    if match is None:
        return set()
    indent, body = match.group(1), doc[match.end():]
    end = _HEADING.search(body)
    body = body[:end.start()] if end else body
    names: set[str] = set()
    for line in body.splitlines():
        if line.startswith(indent) and line[len(indent):len(indent) + 1] not in (" ", ""):
            head = line[len(indent):].split(" : ")[0]
            names.update(part.strip() for part in head.split(","))
    return names


def _signature_parameters(obj) -> list[str]:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return []
    out = []
    for p in sig.parameters.values():
        if p.name in ("self", "cls"):
            continue
        if p.kind is p.VAR_POSITIONAL:
            out.append(f"*{p.name}")
        elif p.kind is p.VAR_KEYWORD:
            out.append(f"**{p.name}")
        else:
            out.append(p.name)
    return out


def _callables():
    for sub, name in PUBLIC:
        obj = getattr(importlib.import_module(f"nscontrol.{sub}"), name)
        if inspect.isfunction(obj):
            yield f"nscontrol.{sub}.{name}", obj, inspect.getdoc(obj) or ""
        elif inspect.isclass(obj) and not issubclass(obj, BaseException):
            if getattr(obj, "_is_protocol", False):
                continue  # a Protocol has no constructor of its own
            init_doc = inspect.getdoc(obj.__init__) if "__init__" in vars(obj) else ""
            doc = (inspect.getdoc(obj) or "") + "\n" + (init_doc or "")
            yield f"nscontrol.{sub}.{name}", obj, doc


@pytest.mark.parametrize("qualname,obj,doc", list(_callables()),
                         ids=lambda v: v if isinstance(v, str) and v.startswith("ns") else "")
def test_parameters_are_documented(qualname, obj, doc):
    params = _signature_parameters(obj)
    if not params:
        return
    documented = documented_parameters(doc)
    if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
        documented |= documented_parameters(doc, "Attributes")  # a record's fields
    # a "**options" entry also covers the bare name, and "*args" likewise
    plain = {d.lstrip("*") for d in documented}
    undocumented = [p for p in params if p not in documented and p.lstrip("*") not in plain]
    assert not undocumented, (f"{qualname}: parameters {undocumented} are not in the "
                              f"numpydoc Parameters section of its docstring")


def test_the_root_lists_its_lazy_names():
    # `closed_loop` and `solve_lcp` import on first use; dir() and tab completion still show
    # them, and every name dir() shows resolves
    import nscontrol

    names = dir(nscontrol)
    assert {"closed_loop", "solve_lcp", "simulate", "design"} <= set(names)
    for name in nscontrol.__all__:
        assert getattr(nscontrol, name) is not None

"""The set-valued modules' docstring examples run, and their public surface is documented
(numpydoc sections on every public function and method that takes arguments)."""

import doctest
import importlib
import inspect

import pytest

MODULES = {
    "nscontrol.systems.lure": 3, "nscontrol.systems.pwa": 3, "nscontrol.systems.switched": 5,
    "nscontrol.simulate.implicit_euler": 5, "nscontrol.simulate.implicit_euler._matrices": 2,
    "nscontrol.simulate.implicit_euler._law_data": 5, "nscontrol.simulate.switching": 1,
    "nscontrol.testing.setvalued_problems": 5,
}


@pytest.mark.parametrize("module, minimum", sorted(MODULES.items()))
def test_docstring_examples_run(module, minimum):
    failures, tried = doctest.testmod(importlib.import_module(module),
                                      optionflags=doctest.ELLIPSIS)
    assert tried >= minimum and failures == 0


def _public_members(module):
    mod = importlib.import_module(module)
    for name in getattr(mod, "__all__", ()):
        obj = getattr(mod, name)
        if inspect.isfunction(obj):
            yield name, obj
        elif inspect.isclass(obj) and obj.__module__ == mod.__name__:
            yield name, obj
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                if isinstance(member, property | classmethod) or inspect.isfunction(member):
                    yield f"{name}.{attr}", member


@pytest.mark.parametrize("module", sorted(MODULES))
def test_public_surface_has_numpydoc_sections(module):
    missing = []
    for name, obj in _public_members(module):
        fn = obj.fget if isinstance(obj, property) else getattr(obj, "__func__", obj)
        doc = inspect.getdoc(fn) or ""
        if not doc:
            missing.append(f"{name}: no docstring")
            continue
        if isinstance(obj, property) or inspect.isclass(obj):
            continue
        params = [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]
        if params and "Parameters\n----------" not in doc:
            missing.append(f"{name}: no Parameters section")
        if "Returns\n-------" not in doc:
            missing.append(f"{name}: no Returns section")
    assert not missing

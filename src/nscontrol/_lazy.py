"""Lazy public names for the subpackages (PEP 562): ``from nscontrol.laws import Relay``
imports the defining module on first use, so ``import nscontrol`` stays fast.

Also the hooks through which a lower layer calls what a higher one provides without importing
it (:func:`provide`, :func:`provided`): the package root names the provider, which is
imported at the first call.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict[str, Any]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of a package whose public names live in its modules.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping of str to str
        Public name -> the module (relative to ``package``) that defines it.
    namespace : dict
        The package's ``globals()``: a name is cached there once imported.
    """

    def getattr_(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    def dir_() -> list[str]:
        return sorted({*namespace, *exports})

    return getattr_, dir_


#: hook -> ``"module:attr"`` of its provider (set by the package root, imported on first use)
_PROVIDERS: dict[str, str] = {}


def provide(hook: str, target: str) -> None:
    """Name the function behind ``hook`` (``"package.module:function"``).

    Parameters
    ----------
    hook : str
        The hook's name.
    target : str
        ``"module:attr"``, imported on the hook's first use.
    """
    _PROVIDERS[hook] = target


def provided(hook: str) -> Any:
    """The function behind ``hook``, its module imported now.

    Parameters
    ----------
    hook : str
        A hook named by :func:`provide`.

    Returns
    -------
    callable

    Raises
    ------
    LookupError
        No provider named for ``hook``.
    """
    target = _PROVIDERS.get(hook)
    if target is None:
        raise LookupError(f"hook: nothing provides {hook!r} (known: {sorted(_PROVIDERS)})")
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)

"""Option checks shared by the set-valued integrators (``implicit_euler``, ``switching``),
beside the general helpers of :mod:`nscontrol._validation`.

Each names the option, says what was expected and what was received (``ModelError``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ..errors import ModelError

__all__ = ["check_on_failure", "check_signals"]


def check_on_failure(value: Any) -> str:
    """``"raise"`` or ``"return"``.

    Raises
    ------
    ModelError
        Any other value.
    """
    if value not in ("raise", "return"):
        raise ModelError(f"on_failure: expected 'raise' or 'return', got {value!r}")
    return str(value)


def check_signals(value: Any, offered: tuple[str, ...]) -> tuple[str, ...] | None:
    """A subset of the signal names an integrator offers (``None``: all of them).

    Raises
    ------
    ModelError
        A single string instead of a collection, or a name the integrator does not offer.
    """
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, Iterable):
        raise ModelError(f"signals: expected a collection of names from {list(offered)}, got "
                         f"{value!r}")
    names = tuple(value)
    unknown = [s for s in names if s not in offered]
    if unknown:
        raise ModelError(f"signals: unknown signal name(s) {unknown}; this integrator records "
                         f"{list(offered)}")
    return names

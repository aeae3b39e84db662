"""The deliverable's scenarios, runnable by ``nscontrol run NAME`` and ``nscontrol report``.

Each module of this package defines ``EXAMPLES``: a list of :class:`Example`. An example's
``run(out_dir)`` builds its model and design, simulates, measures the chapter's claims as
:class:`Check` objects, writes its figures into ``out_dir`` (when given) and returns an
:class:`ExampleResult`. Modules keep heavy imports inside ``run`` so that listing stays fast.
"""

from __future__ import annotations

import importlib
import operator
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Check", "Example", "ExampleResult", "check", "all_examples", "get_example"]

_OPS: dict[str, Callable[[Any, Any], bool]] = {
    "<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt,
    "==": operator.eq,
}


@dataclass(frozen=True)
class Check:
    """One measured claim: ``value <op> threshold``.

    Attributes
    ----------
    name
        The claim, in words (what ``nscontrol report`` shows).
    value, threshold
        The measured figure and the bound it is compared with.
    passed
        Whether ``value <op> threshold`` held (build it with :func:`check`).
    op
        One of ``"<="``, ``"<"``, ``">="``, ``">"``, ``"=="``.
    note
        Why the claim is checked this way (e.g. where it deviates from the spec), or ``""``.
    """

    name: str
    value: Any
    threshold: Any
    passed: bool
    op: str = "<="
    note: str = ""

    def to_json(self) -> dict[str, Any]:
        """``{"name", "value", "threshold", "op", "passed"}`` (plus ``"note"`` when there is
        one) with JSON-compatible values (numpy scalars and arrays converted, non-finite
        floats as strings)."""
        out = {"name": self.name, "value": _jsonable(self.value),
               "threshold": _jsonable(self.threshold), "op": self.op,
               "passed": bool(self.passed)}
        if self.note:
            out["note"] = self.note
        return out


def check(name: str, value: Any, threshold: Any, op: str = "<=", note: str = "") -> Check:
    """Build a :class:`Check` by comparing ``value`` with ``threshold`` using ``op``.

    A comparison that cannot be made (incomparable types) is a failed check, not an error.

    Parameters
    ----------
    name : str
        The claim, in words.
    value, threshold
        The measured figure and the bound it is compared with.
    op : {"<=", "<", ">=", ">", "=="}
        The comparison ``value <op> threshold``.
    note : str
        Why the claim is checked this way, or ``""``.

    Returns
    -------
    Check

    Examples
    --------
    >>> check("residual", 1e-13, 1e-10).passed, check("events", 3, 4, ">=").passed
    (True, False)
    """
    if op not in _OPS:
        raise ValueError(f"op: expected one of {sorted(_OPS)}, got {op!r}")
    try:
        passed = bool(_OPS[op](value, threshold))
    except TypeError:
        passed = False
    return Check(name, value, threshold, passed, op, note)


@dataclass
class ExampleResult:
    """What an example measured: metrics, checks and the figures it wrote.

    Attributes
    ----------
    example
        The example's name.
    metrics
        Named figures (numbers, lists, strings) reported as they are.
    checks
        The claims tested against thresholds.
    figures
        Paths of the figures written.
    summary
        One paragraph for the report.
    """

    example: str
    metrics: dict[str, Any] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    summary: str = ""

    @property
    def passed(self) -> bool:
        """True when every check passed (``nscontrol run`` exits 0 exactly then)."""
        return all(c.passed for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        """The stable JSON of ``nscontrol run NAME --json``:
        ``{"example": NAME, "metrics": {...}, "checks": [{"name", "value", "threshold",
        "op", "passed"}, ...]}``."""
        return {"example": self.example,
                "metrics": {k: _jsonable(v) for k, v in self.metrics.items()},
                "checks": [c.to_json() for c in self.checks]}


@dataclass(frozen=True)
class Example:
    """A named, runnable scenario.

    Attributes
    ----------
    name
        Unique name (``nscontrol run NAME``).
    title, chapter
        What it shows and where it comes from.
    run
        ``run(out_dir) -> ExampleResult``; writes figures into ``out_dir`` when it is given.
    """

    name: str
    title: str
    chapter: str
    run: Callable[[Path | None], ExampleResult]


def all_examples() -> list[Example]:
    """Every example of every module in this package, sorted by name."""
    found: list[Example] = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        found.extend(getattr(module, "EXAMPLES", []))
    return sorted(found, key=lambda e: e.name)


def get_example(name: str) -> Example:
    """The example called ``name``; a clear error lists the available ones.

    Parameters
    ----------
    name : str
        An example's name, as ``nscontrol list`` prints it.
    """
    examples = {e.name: e for e in all_examples()}
    if name not in examples:
        raise KeyError(f"no example {name!r}; available: {', '.join(sorted(examples))}")
    return examples[name]


def _jsonable(value: Any) -> Any:
    """Numbers, strings, lists and dicts only (numpy scalars and arrays converted)."""
    import numpy as np

    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if np.isfinite(v) else str(v)
    if isinstance(value, complex | np.complexfloating):
        return {"re": float(value.real), "im": float(value.imag)}
    return value

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
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Check", "Example", "ExampleResult", "check", "all_examples", "get_example",
           "format_value", "jsonable", "numeric_array", "verdict_from"]

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
        Why the claim is checked this way (e.g. where it deviates from the reference), or
        ``""``.
    key
        A stable identifier for scripts reading ``report.json`` (``snake_case``), or ``""``;
        the name is for people and may be reworded, the key is not.
    """

    name: str
    value: Any
    threshold: Any
    passed: bool
    op: str = "<="
    note: str = ""
    key: str = ""

    def to_json(self) -> dict[str, Any]:
        """``{"name", "value", "threshold", "op", "passed"}`` (plus ``"note"`` and ``"key"``
        when there are) with JSON-compatible values (numpy scalars and arrays converted,
        non-finite floats as strings)."""
        out = {"name": self.name, "value": _jsonable(self.value),
               "threshold": _jsonable(self.threshold), "op": self.op,
               "passed": bool(self.passed)}
        if self.note:
            out["note"] = self.note
        if self.key:
            out["key"] = self.key
        return out


def check(name: str, value: Any, threshold: Any, op: str = "<=", note: str = "",
          key: str = "") -> Check:
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
    key : str
        A stable ``snake_case`` identifier for scripts reading ``report.json``, or ``""``.

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
    return Check(name, value, threshold, passed, op, note, key)


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
    claim
        The chapter's claim in two or three plain sentences (opens its report section).
    verdict
        ``verdict(result) -> str``: one line with the one or two measured numbers that show
        whether this run reproduced the claim (``None``: the report counts the checks).
    captions
        Figure file stem (e.g. ``"bouncing_ball"``) to a caption saying what to look at; the
        report uses it as caption and alt text.
    key_figure
        The stem of the figure shown first (default: the first one written).
    """

    name: str
    title: str
    chapter: str
    run: Callable[[Path | None], ExampleResult]
    claim: str = ""
    verdict: Callable[[ExampleResult], str] | None = None
    captions: Mapping[str, str] = field(default_factory=dict)
    key_figure: str | None = None

    def verdict_line(self, result: ExampleResult) -> str:
        """The verdict of ``result`` in one line: ``reproduced``/``NOT reproduced`` followed by
        the example's own figures (or the number of checks that passed)."""
        n_ok = sum(c.passed for c in result.checks)
        head = "Reproduced" if result.passed else "NOT reproduced"
        detail = (self.verdict(result) if self.verdict is not None
                  else f"{n_ok} of {len(result.checks)} checks pass")
        return f"{head}: {detail}."

    def ordered_figures(self, result: ExampleResult) -> list[Path]:
        """``result.figures`` with the key figure first."""
        key = [f for f in result.figures if Path(f).stem == self.key_figure]
        return key + [f for f in result.figures if f not in key]

    def caption(self, figure: Path) -> str:
        """The caption of ``figure`` (its stem in words when the example gives none)."""
        stem = Path(figure).stem
        return self.captions.get(stem, stem.replace("_", " "))


def verdict_from(*parts: tuple[str, str]) -> Callable[[ExampleResult], str]:
    """A verdict formatter quoting checks: each ``(key, phrase)`` finds the first check whose
    key equals ``key`` or whose name contains it, and says ``"phrase <measured> (bound <op>
    <threshold>)"`` — or, when the phrase is a sentence with ``{value}`` (and ``{bound}``)
    placeholders, the sentence with the figures in place; the count of passing checks closes
    the line.

    Parameters
    ----------
    *parts : tuple of (str, str)
        ``(key, phrase)`` pairs: a check's key (or a substring of its name) and the words
        that quote it.

    Examples
    --------
    >>> res = ExampleResult("x", checks=[check("impact time error [s]", 3e-15, 1e-12)])
    >>> verdict_from(("impact time", "impact times exact to"))(res)
    'impact times exact to 3e-15 s (bound ≤ 1e-12); 1 of 1 checks pass'
    >>> verdict_from(("impact time", "the impacts fall within {value} s of the closed "
    ...               "form"))(res)
    'the impacts fall within 3e-15 s of the closed form; 1 of 1 checks pass'
    """

    def verdict(result: ExampleResult) -> str:
        said = []
        for key, phrase in parts:
            found = [c for c in result.checks if c.key == key or key in c.name]
            if not found:
                continue
            c = found[0]
            if "{value}" in phrase:
                said.append(phrase.format(value=format_value(c.value),
                                          bound=format_value(c.threshold)))
                continue
            unit = " s" if "[s]" in c.name else ""
            said.append(f"{phrase} {format_value(c.value)}{unit} "
                        f"(bound {_OP_TEXT.get(c.op, c.op)} {format_value(c.threshold)})")
        n_ok = sum(c.passed for c in result.checks)
        said.append(f"{n_ok} of {len(result.checks)} checks pass")
        return "; ".join(said)

    return verdict


_OP_TEXT = {"<=": "≤", "<": "<", ">=": "≥", ">": ">", "==": "="}


def format_value(value: Any) -> str:
    """A scalar as a reader wants it: 4 significant digits, ``yes``/``no``, ``—`` for None;
    a short sequence of scalars comma-separated; anything larger summarised.

    Parameters
    ----------
    value : object
        A number, bool, None, string or a sequence of them.
    """
    import numpy as np

    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return f"{int(value):,}".replace(",", " ")
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if np.isnan(v):
            return "not computed"
        if np.isinf(v):
            return "∞" if v > 0 else "−∞"
        if v == 0.0:
            return "0"
        return f"{v:.4g}" if 1e-3 <= abs(v) < 1e5 else f"{v:.3g}"
    if isinstance(value, (complex, np.complexfloating)):
        return f"{format_value(value.real)} {'+' if value.imag >= 0 else '−'} " \
               f"{format_value(abs(value.imag))}i"
    if isinstance(value, str):
        return value
    if isinstance(value, dict):
        return f"{len(value)} entries (see report.json)"
    arr = numeric_array(value)
    if arr is None:
        return (f"{len(value)} items (see report.json)" if hasattr(value, "__len__")
                else str(value))
    if arr.ndim == 1 and arr.size <= 6:
        return "[" + ", ".join(format_value(v) for v in arr) + "]"
    if arr.size == 0:
        return "(none)"
    shape = "×".join(str(n) for n in arr.shape)
    if np.iscomplexobj(arr):
        arr = np.abs(arr)
    return f"{shape} values from {format_value(np.min(arr))} to {format_value(np.max(arr))}"


def numeric_array(value: Any) -> Any:
    """``value`` as a numeric numpy array, or None when it is not a regular numeric array.

    Parameters
    ----------
    value : object
        Anything :func:`numpy.asarray` may take.
    """
    import numpy as np

    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        return None
    return arr if arr.dtype.kind in "biufc" else None


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
        An example's name, as ``nscontrol list`` prints it, or its chapter (``"ch08"``) when
        the chapter has one example.
    """
    examples = {e.name: e for e in all_examples()}
    if name in examples:
        return examples[name]
    in_chapter = [e.name for e in examples.values() if e.chapter == name]
    if len(in_chapter) == 1:
        return examples[in_chapter[0]]
    if in_chapter:
        raise KeyError(f"chapter {name!r} has several examples: {', '.join(in_chapter)}; "
                       f"name one")
    raise KeyError(f"no example {name!r}; available: {', '.join(sorted(examples))}")


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON data: numbers, strings, lists and dicts only (numpy scalars and
    arrays converted, non-finite floats as strings, complex numbers as ``{"re", "im"}``).

    Parameters
    ----------
    value : object
        Any nesting of dicts, sequences, numpy arrays and scalars.

    Examples
    --------
    >>> import numpy as np
    >>> jsonable({"x": np.float64(0.5), "n": np.arange(2), "bad": float("nan")})
    {'x': 0.5, 'n': [0, 1], 'bad': 'nan'}
    """
    return _jsonable(value)


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

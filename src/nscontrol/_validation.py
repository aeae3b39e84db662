"""Input checks used at every public boundary.

Each helper names the argument in its message, says what was expected and what was received,
so that a bad input is reported where the user wrote it, not deep inside a solver.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import DimensionError, ModelError

FloatArray = NDArray[np.float64]


def _to_float64(name: str, value: Any) -> FloatArray:
    """``value`` as a float64 array; complex, string and non-numeric input is refused.

    numpy would silently drop the imaginary part of a complex array (with only a
    ``ComplexWarning``) and parse strings such as ``"1.5"``; both are bad input here.
    """
    if isinstance(value, np.ndarray | np.generic):
        kind = value.dtype.kind
        if kind in "fiub":
            return np.array(value, dtype=np.float64)
    else:
        try:
            value = np.asarray(value)
        except (TypeError, ValueError) as exc:
            raise ModelError(f"{name}: expected a real numeric array, got "
                             f"{type(value).__name__} ({exc})") from None
        kind = value.dtype.kind
    if kind == "c":
        raise ModelError(f"{name}: expected real entries, got a complex array (dtype "
                         f"{value.dtype}); pass its .real or .imag explicitly if that is meant")
    if kind in "USV":
        raise ModelError(f"{name}: expected a real numeric array, got strings or bytes (dtype "
                         f"{value.dtype}): {_short(value)}")
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{name}: expected a real numeric array, got {_short(value)} "
                         f"({exc})") from None
    return arr


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def as_float_array(name: str, value: Any, *, ndim: int | None = None,
                   shape: Sequence[int | None] | None = None,
                   finite: bool = True) -> FloatArray:
    """Convert ``value`` to a float64 array, checking its rank and shape.

    ``shape`` may contain ``None`` for a free dimension. With ``finite=False`` infinite and
    NaN entries pass (the caller checks them itself, e.g. half-line bounds).

    Raises
    ------
    DimensionError
        Wrong rank or shape.
    ModelError
        NaN or infinite entries (unless ``finite=False``), or a value that is not real and
        numeric (complex, strings, objects that do not convert to float).

    Examples
    --------
    >>> as_float_array("x", [1, 2]).tolist()
    [1.0, 2.0]
    >>> as_float_array("x", [1j])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: x: expected real entries, got a complex array ...
    """
    arr = _to_float64(name, value)
    if ndim is not None and arr.ndim != ndim:
        raise DimensionError(f"{name}: expected a {ndim}-d array, got shape {arr.shape}")
    if shape is not None:
        if arr.ndim != len(shape) or any(s is not None and s != a
                                         for s, a in zip(shape, arr.shape, strict=True)):
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise DimensionError(f"{name}: expected shape {want}, got {arr.shape}")
    if finite:
        check_finite(name, arr)
    return arr


def as_vector(name: str, value: Any, size: int | None = None) -> FloatArray:
    """A finite 1-d float array (a scalar becomes a length-1 vector)."""
    arr = np.atleast_1d(as_float_array(name, value))
    if arr.ndim != 1:
        raise DimensionError(f"{name}: expected a vector, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise DimensionError(f"{name}: expected a vector of length {size}, got length "
                             f"{arr.shape[0]}")
    return arr


def as_matrix(name: str, value: Any, rows: int | None = None,
              cols: int | None = None) -> FloatArray:
    """A finite 2-d float array with optional row and column counts.

    A 1-d input is *not* silently reshaped: the caller must say whether it is a row or a column.
    """
    arr = as_float_array(name, value)
    if arr.ndim != 2:
        raise DimensionError(f"{name}: expected a 2-d matrix, got shape {arr.shape}; "
                             "reshape vectors explicitly (e.g. np.reshape(v, (-1, 1)))")
    if rows is not None and arr.shape[0] != rows:
        raise DimensionError(f"{name}: expected {rows} rows, got shape {arr.shape}")
    if cols is not None and arr.shape[1] != cols:
        raise DimensionError(f"{name}: expected {cols} columns, got shape {arr.shape}")
    return arr


def as_square(name: str, value: Any, size: int | None = None) -> FloatArray:
    """A finite square matrix, optionally of a given size."""
    arr = as_matrix(name, value)
    if arr.shape[0] != arr.shape[1]:
        raise DimensionError(f"{name}: expected a square matrix, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise DimensionError(f"{name}: expected shape ({size}, {size}), got {arr.shape}")
    return arr


def check_finite(name: str, arr: np.ndarray) -> None:
    """Raise :class:`ModelError` when ``arr`` holds NaN or infinite entries."""
    if not np.isfinite(arr).all():
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ModelError(f"{name}: expected finite entries, got {bad} NaN or infinite "
                         f"value(s)")


def check_symmetric(name: str, M: FloatArray, rtol: float = 1e-10) -> None:
    """Raise :class:`ModelError` unless ``M`` is symmetric to ``rtol`` (relative to max |M|)."""
    scale = max(float(np.max(np.abs(M), initial=0.0)), 1.0)
    asym = float(np.max(np.abs(M - M.T), initial=0.0))
    if asym > rtol * scale:
        raise ModelError(f"{name}: expected a symmetric matrix, got max |{name} - {name}^T| = "
                         f"{asym:.3g}; symmetrise it or check its construction")


def check_positive_definite(name: str, M: FloatArray) -> None:
    """Raise :class:`ModelError` unless the symmetric matrix ``M`` is positive definite."""
    check_symmetric(name, M)
    lam_min = float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])
    if lam_min <= 0.0:
        raise ModelError(f"{name}: expected a symmetric positive definite matrix, got smallest "
                         f"eigenvalue {lam_min:.3g}")


def as_real_scalar(name: str, value: Any) -> float:
    """A real scalar (Python or numpy number, or a one-element array; not bool, complex or a
    string) as a float.

    Not checked for finiteness; :func:`check_positive` and :func:`check_in_interval` do that.
    """
    if type(value) is float or type(value) is int:   # the common case, checked first (fast)
        return float(value)
    if isinstance(value, np.ndarray):
        if value.size != 1:        # a one-element array is accepted as its element
            raise ModelError(f"{name}: expected a real number, got an array of shape "
                             f"{value.shape}")
        value = value.reshape(()).item() if value.dtype.kind != "O" else value.flat[0]
    if isinstance(value, bool | np.bool_):
        raise ModelError(f"{name}: expected a real number, got {value!r}; pass a number")
    if isinstance(value, str | bytes | np.str_ | np.bytes_):
        raise ModelError(f"{name}: expected a real number, got the string {value!r}; pass a "
                         f"number, not text (e.g. float({value!r}) if that is meant)")
    if isinstance(value, complex | np.complexfloating):
        raise ModelError(f"{name}: expected a real number, got the complex {value!r}; pass its "
                         ".real explicitly if that is meant")
    if np.ndim(value) != 0:
        raise ModelError(f"{name}: expected a real number, got a sequence of shape "
                         f"{np.shape(value)}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{name}: expected a real number, got {value!r}") from None


def check_positive(name: str, value: Any, *, allow_zero: bool = False,
                   hint: str = "") -> float:
    """A finite scalar that is > 0 (or >= 0 with ``allow_zero``); ``hint`` (what the value
    means or what to pass) ends the message of a refusal."""
    v = as_real_scalar(name, value)
    if not math.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ModelError(f"{name}: expected a finite number {bound}, got {value!r}"
                         + (f"; {hint}" if hint else ""))
    return v


def check_in_interval(name: str, value: Any, lo: float, hi: float, *,
                      open_interval: bool = False, hint: str = "") -> float:
    """A finite scalar in the closed interval ``[lo, hi]`` (the open one with
    ``open_interval=True``); ``hint`` ends the message of a refusal.

    Examples
    --------
    >>> check_in_interval("margin", 0.7, 0.0, 0.5, hint="D must lie in [m, 1 - m]")
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: margin: expected a value in [0.0, 0.5], got 0.7; D must ...
    """
    v = as_real_scalar(name, value)
    inside = lo < v < hi if open_interval else lo <= v <= hi
    if not (np.isfinite(v) and inside):
        span = f"({lo}, {hi})" if open_interval else f"[{lo}, {hi}]"
        raise ModelError(f"{name}: expected a value in {span}, got {value!r}"
                         + (f"; {hint}" if hint else ""))
    return v


def check_bool(name: str, value: Any, *, allow_none: bool = False) -> Any:
    """A boolean option: ``True``/``False`` (Python or numpy), and ``None`` with
    ``allow_none`` (an option whose ``None`` means "decide for me", e.g. ``progress``).

    Anything else is refused, strings first of all: ``"no"`` is truthy, so an ``if option:``
    would silently read ``"no"`` as True. Integers are refused too (``0``/``1`` say nothing a
    bool does not, and ``2`` would be a bug).

    Returns
    -------
    bool or None

    Examples
    --------
    >>> check_bool("projection", True), check_bool("progress", None, allow_none=True)
    (True, None)
    >>> check_bool("strict", "no")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: strict: expected True or False, got the string 'no' ...
    """
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if value is None and allow_none:
        return None
    want = "True, False or None" if allow_none else "True or False"
    if isinstance(value, str | bytes | np.str_ | np.bytes_):
        got = f"the string {value!r} (any non-empty string is truthy)"
    else:
        got = f"{value!r} (a {type(value).__name__})"
    raise ModelError(f"{name}: expected {want}, got {got}; pass a bool")


def check_type(name: str, value: Any, expected: type | tuple[type, ...], *,
               hint: str = "") -> Any:
    """``value`` itself when it is an instance of ``expected``; otherwise a
    :class:`ModelError` naming the argument, the expected and the received type (and
    ``hint``: where to get the right object), instead of an ``AttributeError`` deep inside.

    Examples
    --------
    >>> check_type("system", 1.0, str, hint="build it with str()")
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: system: expected a str, got a float (1.0); build it with str()
    """
    if isinstance(value, expected):
        return value
    kinds = expected if isinstance(expected, tuple) else (expected,)
    names = " or ".join(k.__name__ for k in kinds)
    got = type(value).__name__

    def article(word: str) -> str:
        return "an" if word[:1] in "AEIOUaeiou" else "a"

    raise ModelError(f"{name}: expected {article(names)} {names}, got {article(got)} {got} "
                     f"({_short(value)})" + (f"; {hint}" if hint else ""))


def check_integer(name: str, value: Any, *, minimum: int | None = None,
                  error: type[Exception] = ModelError) -> int:
    """An integer (``int``, numpy integer, or a float with an integral value such as ``1e4``)
    that is ``>= minimum``; ``2.7``, ``True``, strings and NaN are refused with ``error``.

    Examples
    --------
    >>> check_integer("max_iter", 1e4, minimum=1)
    10000
    >>> check_integer("max_iter", 2.7, minimum=1)
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: max_iter: expected an integer >= 1, got 2.7
    """
    want = "an integer" if minimum is None else f"an integer >= {minimum}"
    if isinstance(value, bool | np.bool_):
        raise error(f"{name}: expected {want}, got {value!r}")
    if isinstance(value, int | np.integer):
        v = int(value)
    elif isinstance(value, float | np.floating) and np.isfinite(value) \
            and float(value).is_integer():
        v = int(value)
    else:
        raise error(f"{name}: expected {want}, got {value!r}")
    if minimum is not None and v < minimum:
        raise error(f"{name}: expected {want}, got {value!r}")
    return v


def as_finite_scalar(name: str, value: Any) -> float:
    """A finite real scalar (see :func:`as_real_scalar` for what counts as one) as a float.

    Examples
    --------
    >>> as_finite_scalar("decay", 0.5)
    0.5
    >>> as_finite_scalar("decay", float("nan"))
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: decay: expected a finite real number, got nan
    """
    v = as_real_scalar(name, value)
    if not np.isfinite(v):
        raise ModelError(f"{name}: expected a finite real number, got {value!r}")
    return v


def as_interval(name: str, value: Any, *, labels: tuple[str, str] = ("lo", "hi"),
                example: str = "(0.0, 1.0)") -> tuple[float, float]:
    """A pair ``(lo, hi)`` of finite real numbers with ``lo < hi`` (a range of a parameter,
    a time span); ``labels`` name the two ends in the messages.

    A string is not a pair (``"12"`` would otherwise unpack to ``1.0, 2.0``), and a reversed
    pair is refused rather than sorted: ``(2, 1)`` is more likely a slip than a range.

    Examples
    --------
    >>> as_interval("p_range", (0, 2))
    (0.0, 2.0)
    >>> as_interval("p_range", (2, 1))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: p_range: expected finite lo < hi, got (2.0, 1.0); ...
    """
    lo_name, hi_name = labels
    if isinstance(value, str | bytes):
        raise ModelError(f"{name}: expected a pair of numbers ({lo_name}, {hi_name}), got the "
                         f"string {value!r}; write e.g. {example}")
    try:
        items = list(value)
    except TypeError:
        raise DimensionError(f"{name}: expected a pair ({lo_name}, {hi_name}), got "
                             f"{value!r}") from None
    if len(items) != 2:
        raise DimensionError(f"{name}: expected a pair ({lo_name}, {hi_name}), got "
                             f"{len(items)} value(s): {_short(value)}")
    lo, hi = as_real_scalar(f"{name}[0]", items[0]), as_real_scalar(f"{name}[1]", items[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        hint = f"; write ({hi:g}, {lo:g})" if np.isfinite(lo) and np.isfinite(hi) and hi < lo \
            else ""
        raise ModelError(f"{name}: expected finite {lo_name} < {hi_name}, got ({lo}, {hi})"
                         f"{hint}")
    return lo, hi


def check_names(name: str, values: Any, valid: Sequence[str]) -> tuple[str, ...]:
    """A collection of names, each one of ``valid``, as a tuple.

    A single string is refused (``detect="flip"`` would otherwise be read letter by letter),
    and so is a misspelt name: the message lists the valid ones.

    Examples
    --------
    >>> check_names("detect", ["fold"], ("fold", "flip"))
    ('fold',)
    >>> check_names("detect", ["flp"], ("fold", "flip"))
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: detect: unknown name(s) 'flp'; valid names: 'fold', 'flip'
    """
    listed = ", ".join(repr(v) for v in valid)
    if isinstance(values, str | bytes):
        raise ModelError(f"{name}: expected a collection of names, got the string {values!r}; "
                         f"write ({values!r},) (valid names: {listed})")
    try:
        items = tuple(values)
    except TypeError:
        raise ModelError(f"{name}: expected a collection of names, got "
                         f"{type(values).__name__} {values!r} (valid names: {listed})") from None
    unknown = [v for v in items if not isinstance(v, str) or v not in valid]
    if unknown:
        raise ModelError(f"{name}: unknown name(s) {', '.join(repr(v) for v in unknown)}; "
                         f"valid names: {listed}")
    return items


def check_t_span(t_span: Any, name: str = "t_span") -> tuple[float, float]:
    """A pair ``(t0, tf)`` of finite real times with ``tf > t0`` (:func:`as_interval`).

    A string is not a pair of times (``"01"`` would otherwise unpack to ``0.0, 1.0``), and
    neither are string or complex entries.

    Examples
    --------
    >>> check_t_span((0, 2))
    (0.0, 2.0)
    >>> check_t_span("01")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: t_span: expected a pair of numbers (t0, tf), got the string ...
    """
    return as_interval(name, t_span, labels=("t0", "tf"))


def named_record(dtype: np.dtype, **values: Any) -> np.ndarray:
    """A one-element structured array of ``dtype`` (all fields ``float64``) with every field
    set by name: the parameter record of a compiled kernel.

    Its ``.view(np.float64)`` is the flat array the compiled loops pass (their signatures
    take ``float64[::1]``); a kernel reads it back by name with ``p.view(dtype)[0]``.

    Raises
    ------
    ModelError
        A field of ``dtype`` not given, or a name that is not a field.

    Examples
    --------
    >>> dt = np.dtype([("kp", np.float64), ("kd", np.float64)])
    >>> rec = named_record(dt, kd=0.3, kp=2.0)
    >>> float(rec[0]["kp"]), rec.view(np.float64).tolist()
    (2.0, [2.0, 0.3])
    """
    names = tuple(dtype.names or ())
    if set(values) != set(names):
        raise ModelError(f"values: expected the fields {list(names)}, got {sorted(values)}")
    out = np.zeros(1, dtype)
    for key, value in values.items():
        out[key] = float(value)
    return out

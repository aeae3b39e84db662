"""Input checks used at every public boundary.

Each helper names the argument in its message, says what was expected and what was received,
so that a bad input is reported where the user wrote it, not deep inside a solver.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import DimensionError, ModelError

FloatArray = NDArray[np.float64]


def as_float_array(name: str, value: Any, *, ndim: int | None = None,
                   shape: Sequence[int | None] | None = None) -> FloatArray:
    """Convert ``value`` to a finite float64 array, checking its rank and shape.

    ``shape`` may contain ``None`` for a free dimension.

    Raises
    ------
    DimensionError
        Wrong rank or shape.
    ModelError
        NaN or infinite entries, or a value that is not numeric.
    """
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{name}: expected a real numeric array, got {type(value).__name__} "
                         f"({exc})") from None
    if ndim is not None and arr.ndim != ndim:
        raise DimensionError(f"{name}: expected a {ndim}-d array, got shape {arr.shape}")
    if shape is not None:
        if arr.ndim != len(shape) or any(s is not None and s != a
                                         for s, a in zip(shape, arr.shape, strict=True)):
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise DimensionError(f"{name}: expected shape {want}, got {arr.shape}")
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
    if not np.all(np.isfinite(arr)):
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


def check_positive(name: str, value: Any, *, allow_zero: bool = False) -> float:
    """A finite scalar that is > 0 (or >= 0 with ``allow_zero``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{name}: expected a real number, got {value!r}") from None
    if not np.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ModelError(f"{name}: expected a finite number {bound}, got {value!r}")
    return v


def check_in_interval(name: str, value: Any, lo: float, hi: float) -> float:
    """A finite scalar in the closed interval ``[lo, hi]``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{name}: expected a real number, got {value!r}") from None
    if not (np.isfinite(v) and lo <= v <= hi):
        raise ModelError(f"{name}: expected a value in [{lo}, {hi}], got {value!r}")
    return v


def check_t_span(t_span: Any) -> tuple[float, float]:
    """A pair ``(t0, tf)`` of finite times with ``tf > t0``."""
    try:
        t0, tf = (float(t) for t in t_span)
    except (TypeError, ValueError):
        raise DimensionError(f"t_span: expected a pair (t0, tf), got {t_span!r}") from None
    if not (np.isfinite(t0) and np.isfinite(tf)) or tf <= t0:
        raise ModelError(f"t_span: expected finite t0 < tf, got ({t0}, {tf})")
    return t0, tf

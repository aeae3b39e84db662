"""Chattering measures of a sampled or simulated sliding motion: the amplitude of ``s`` after
reaching, the switching frequency of ``u``, and the order fitted to either against ``h``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_vector
from ..errors import DimensionError, ModelError

__all__ = ["chattering_amplitude", "switching_frequency", "fitted_order", "OrderFit",
           "reaching_time"]


def _window(t: ArrayLike, values: ArrayLike, after: float | None, name: str
            ) -> tuple[FloatArray, FloatArray]:
    t = as_vector("t", t)
    v = np.asarray(values, dtype=float).reshape(t.shape[0], -1)[:, 0] \
        if np.size(values) == t.shape[0] else None
    if v is None:
        raise DimensionError(f"{name}: expected one value per time ({t.shape[0]}), got "
                             f"{np.size(values)}")
    keep = t >= (t[0] if after is None else float(after))
    if not np.any(keep):
        raise ModelError(f"after: no sample at or after t = {after} (the run ends at "
                         f"{t[-1]:.6g})")
    return t[keep], v[keep]


def chattering_amplitude(t: ArrayLike, s: ArrayLike, after: float | None = None) -> float:
    """``max |s|`` over the samples at or after ``after`` (the sliding variable's residual
    oscillation once the surface is reached).

    Parameters
    ----------
    t : array_like
        Sample times.
    s : array_like
        The sliding variable at those times.
    after : float, optional
        Start of the window (default: the first time).

    Examples
    --------
    >>> chattering_amplitude([0.0, 1.0, 2.0, 3.0], [1.0, 0.1, -0.2, 0.1], after=1.0)
    0.2
    """
    return float(np.max(np.abs(_window(t, s, after, "s")[1])))


def switching_frequency(t: ArrayLike, u: ArrayLike, after: float | None = None,
                        level: float = 0.0) -> float:
    """Sign changes of ``u - level`` per unit time over the window at or after ``after``.

    Parameters
    ----------
    t : array_like
        Sample times.
    u : array_like
        The input (or its switching part) at those times.
    after : float, optional
        Start of the window (default: the first time).
    level : float
        The value around which switching is counted (default 0).

    Examples
    --------
    >>> switching_frequency([0.0, 1.0, 2.0, 3.0, 4.0], [1.0, -1.0, 1.0, -1.0, 1.0])
    1.0
    """
    tw, uw = _window(t, u, after, "u")
    signs = np.sign(uw - level)
    signs = signs[signs != 0.0]
    span = float(tw[-1] - tw[0])
    if span <= 0.0:
        raise ModelError("t: the window holds a single time; widen it (after=)")
    return float(np.count_nonzero(np.diff(signs))) / span


def reaching_time(t: ArrayLike, s: ArrayLike, tol: float) -> float:
    """The first time from which ``|s| <= tol`` holds to the end of the run (NaN if never).

    Parameters
    ----------
    t : array_like
        Sample times.
    s : array_like
        The sliding variable.
    tol : float
        The band counted as reached.
    """
    tv, sv = _window(t, s, None, "s")
    outside = np.flatnonzero(np.abs(sv) > tol)
    if outside.size == 0:
        return float(tv[0])
    if outside[-1] == tv.shape[0] - 1:
        return float("nan")
    return float(tv[outside[-1] + 1])


class OrderFit(NamedTuple):
    """A least-squares fit ``log y = log C + p log h``.

    Parameters
    ----------
    order
        The slope ``p``.
    constant
        ``C``.
    residual
        Largest deviation of ``log y`` from the line (natural log).
    """

    order: float
    constant: float
    residual: float


def fitted_order(h: ArrayLike, values: ArrayLike) -> OrderFit:
    """The order ``p`` of ``values ≈ C h^p`` by least squares on the logarithms.

    Parameters
    ----------
    h : array_like
        Steps (at least two, positive).
    values : array_like
        The measured quantity at each step (positive).

    Examples
    --------
    >>> fit = fitted_order([1e-2, 1e-3], [3e-4, 3e-6])
    >>> round(fit.order, 12), round(fit.constant, 9)
    (2.0, 3.0)
    """
    hv = as_vector("h", h)
    y = as_vector("values", values, hv.shape[0])
    if hv.shape[0] < 2 or np.any(hv <= 0.0) or np.any(y <= 0.0):
        raise ModelError("h, values: expected at least two positive steps and positive "
                         f"values, got h = {hv.tolist()}, values = {y.tolist()}")
    X = np.column_stack([np.ones_like(hv), np.log(hv)])
    coef: Any = np.linalg.lstsq(X, np.log(y), rcond=None)[0]
    res = float(np.max(np.abs(X @ coef - np.log(y))))
    return OrderFit(float(coef[1]), float(np.exp(coef[0])), res)

"""Single-valued nondecreasing laws ``phi(z)_i = f(z)_i`` (saturation, smooth monotone maps)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._validation import FloatArray
from ..errors import DimensionError, ModelError
from ._roots import solve_increasing
from .base import SetValuedLaw, check_dim

__all__ = ["MonotoneFunction"]

_PROBE = np.linspace(-10.0, 10.0, 81)


@dataclass(frozen=True, eq=False)
class MonotoneFunction(SetValuedLaw):
    """A continuous nondecreasing function acting componentwise, as a (single-valued) law.

    Parameters
    ----------
    f
        Vectorised map ``R^dim -> R^dim`` whose component ``i`` depends on ``z_i`` only and is
        continuous and nondecreasing in it (e.g. ``np.tanh``, a saturation, ``z**3``).
    df
        Optional componentwise derivative ``f'(z)`` (speeds up the resolvent).
    dim
        Number of components.

    Notes
    -----
    The constructor samples ``f`` on ``[-10, 10]`` and refuses a function found decreasing
    there (a cheap check, not a proof). Resolvent: the root of ``z + gamma f(z) = x``, bracketed
    in ``[min(x, x - gamma f(x)), max(x, x - gamma f(x))]`` and found by safeguarded Newton to a
    few ulps. ``graph_residual`` is the vertical distance ``|v - f(z)|`` (an upper bound of the
    Euclidean distance, zero exactly on the graph). No complementarity form.
    """

    f: Callable[[FloatArray], Any]
    df: Callable[[FloatArray], Any] | None = None
    dim: int = 1
    monotone: ClassVar[bool] = True
    componentwise: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not callable(self.f) or (self.df is not None and not callable(self.df)):
            raise ModelError(f"f, df: expected callables, got {type(self.f).__name__} and "
                             f"{type(self.df).__name__}")
        object.__setattr__(self, "dim", check_dim(self.dim))
        values = np.array([self._f(np.full(self.dim, s)) for s in _PROBE])
        drops = np.diff(values, axis=0)
        if np.any(drops < -1e-12 * np.maximum(1.0, np.abs(values[:-1]))):
            s = _PROBE[int(np.argmax(np.min(drops, axis=1) < 0))]
            raise ModelError(f"f: expected a nondecreasing function, but it decreases near "
                             f"z = {s:.3g}; a non-monotone law needs a loop transformation "
                             "(see Stribeck)")

    def _f(self, z: FloatArray) -> FloatArray:
        out = np.asarray(self.f(z), dtype=np.float64)
        if out.shape != (self.dim,):
            raise DimensionError(f"f: expected an output of shape ({self.dim},), got {out.shape}")
        if not np.all(np.isfinite(out)):
            raise ModelError(f"f: returned non-finite values at z = {z}")
        return out

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        other = x - gamma * self._f(x)
        df = self.df
        dg = None if df is None else (lambda z: 1.0 + gamma * np.asarray(df(z), dtype=float))
        return solve_increasing(lambda z: z + gamma * self._f(z) - x, dg,
                                np.minimum(x, other), np.maximum(x, other))

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        return float(np.linalg.norm(v - self._f(z)))

    def _select(self, z: FloatArray) -> FloatArray:
        return self._f(z)

    def __repr__(self) -> str:
        return f"MonotoneFunction(f={getattr(self.f, '__name__', self.f)!r}, dim={self.dim})"

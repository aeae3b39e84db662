"""Vectorised safeguarded Newton for increasing scalar equations (one per component)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .._validation import FloatArray
from ..errors import SolverError

_MAX_ITER = 200


def solve_increasing(g: Callable[[FloatArray], FloatArray],
                     dg: Callable[[FloatArray], FloatArray] | None,
                     lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Roots of the strictly increasing ``g`` (componentwise), with ``g(lo) <= 0 <= g(hi)``.

    Newton steps are taken when they stay inside the current bracket and otherwise replaced by
    bisection, so convergence is guaranteed; iteration stops when the bracket is a few ulps wide
    or ``g`` vanishes. Components with ``lo == hi`` are returned as they are.
    """
    lo, hi = lo.astype(np.float64).copy(), hi.astype(np.float64).copy()
    x = 0.5 * (lo + hi)
    for _ in range(_MAX_ITER):
        gx = g(x)
        done = (gx == 0.0) | (hi - lo <= 4.0 * np.spacing(np.maximum(np.abs(lo), np.abs(hi))))
        if np.all(done):
            return x
        lo = np.where(gx < 0.0, x, lo)
        hi = np.where(gx > 0.0, x, hi)
        mid = 0.5 * (lo + hi)
        if dg is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = x - gx / dg(x)
            inside = np.isfinite(newton) & (newton > lo) & (newton < hi)
            step = np.where(inside, newton, mid)
        else:
            step = mid
        x = np.where(done, x, step)
    gx = g(x)
    if np.any(np.abs(gx) > 1e-9 * np.maximum(1.0, np.abs(x))):
        raise SolverError("resolvent: the scalar root search did not converge in "
                          f"{_MAX_ITER} iterations (max |g| = {np.max(np.abs(gx)):.3g}); check "
                          "that the law's function is continuous and nondecreasing",
                          status="max_iter")
    return x

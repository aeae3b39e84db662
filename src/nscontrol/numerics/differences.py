"""Central finite differences: gradients and Jacobians of functions given without them.

The step ``d_k = c (1 + |x_k|)`` is relative to the size of ``x_k``. A central difference
errs by ``O(d²)`` (truncation) plus ``O(u/d)`` (rounding, ``u`` the unit roundoff), balanced
near ``d ≈ u^{1/3} ≈ 6e-6``: the Jacobian's ``c = 1e-6`` is accurate to about ``1e-10``
relative for smooth functions of unit scale, the gradient's ``c = 1e-7`` to about ``2e-9``.
The Jacobian's fourth-order stencil (``order=4``) errs by ``O(d⁴) + O(u/d)``, balanced near
``d ≈ u^{1/5} ≈ 7e-4``: about ``5e-13`` relative, for twice the evaluations — what a
variational equation integrated at tight tolerances needs (a Jacobian's rounding noise enters
its right-hand side, and an error controller resolving ``1e-10`` would chase it).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .._validation import FloatArray
from ..errors import ModelError

__all__ = ["central_difference_gradient", "central_difference_jacobian"]


def central_difference_gradient(h: Callable[[FloatArray], float], x: FloatArray) -> FloatArray:
    """``∇h(x)`` of a scalar function by central differences (step ``1e-7 (1 + |x_k|)``).

    Parameters
    ----------
    h : callable ``R^n -> R``
        The scalar function.
    x : (n,) ndarray
        The point.

    Examples
    --------
    >>> g = central_difference_gradient(lambda x: x[0] ** 2 + 3 * x[1], np.array([1.0, 2.0]))
    >>> bool(np.allclose(g, [2.0, 3.0], rtol=1e-8))
    True
    """
    g = np.empty_like(x)
    for k in range(x.shape[0]):
        d = 1e-7 * (1.0 + abs(x[k]))
        e = np.zeros_like(x)
        e[k] = d
        g[k] = (h(x + e) - h(x - e)) / (2.0 * d)
    return g


def central_difference_jacobian(f: Callable[[FloatArray], FloatArray],
                                x: FloatArray, *, order: int = 2) -> FloatArray:
    """``∂f/∂x`` of a vector field ``R^n -> R^n`` by central differences (step
    ``1e-6 (1 + |x_k|)``; ``order=4``: the five-point stencil, step ``u^{1/5} (1 + |x_k|)``).

    Parameters
    ----------
    f : callable ``R^n -> R^n``
        The vector field.
    x : (n,) ndarray
        The point.
    order : {2, 4}
        Order of the stencil in the step (``2 n`` or ``4 n`` evaluations of ``f``).

    Examples
    --------
    >>> J = central_difference_jacobian(lambda x: np.array([x[1], -x[0] ** 3]),
    ...                                 np.array([1.0, 0.0]))
    >>> bool(np.allclose(J, [[0.0, 1.0], [-3.0, 0.0]], rtol=1e-8, atol=1e-10))
    True
    """
    if order not in (2, 4):
        raise ModelError(f"order: expected 2 or 4, got {order!r}")
    n = x.shape[0]
    J = np.empty((n, n))
    for k in range(n):
        d = (1e-6 if order == 2 else _FIFTH_ROOT_EPS) * (1.0 + abs(x[k]))
        e = np.zeros(n)
        e[k] = d
        if order == 2:
            J[:, k] = (f(x + e) - f(x - e)) / (2.0 * d)
        else:
            J[:, k] = (8.0 * (f(x + e) - f(x - e)) - (f(x + 2 * e) - f(x - 2 * e))) / (12.0 * d)
    return J


#: ``u^{1/5}``: the relative step of the fourth-order stencil.
_FIFTH_ROOT_EPS = float(np.finfo(float).eps) ** 0.2

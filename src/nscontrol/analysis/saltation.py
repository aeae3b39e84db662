"""Saltation matrices: how a perturbation of the state is carried through a discrete event.

A trajectory of a non-smooth system reaches a guard ``h(x, t) = 0`` at ``t_e``, where the
state jumps ``x+ = J(x-)`` (impact: ``J`` reverses the normal velocity; facet crossing,
sliding entry and exit, PWM switching: ``J = I``) and the vector field changes from ``f-`` to
``f+``. A perturbation ``δx-`` of the state just before the event shifts the event time by
``δt = -∇h·δx- / ḣ-`` (``ḣ- = ∇h·f- + ∂h/∂t``, the guard's rate of approach); to first order
the perturbation just after the event is ``δx+ = S δx-`` with the **saltation matrix**

    S = J' + (f+ - J' f-) ∇hᵀ / ḣ-,        J' = ∂J/∂x at x-.

This is the matrix analysis multiplies between the flows' transition matrices to get the
monodromy of an orbit through events. Special cases:

* **impact** with Newton restitution on one contact of a mechanical system
  (:func:`impact_jump_jacobian` gives ``J'``);
* **facet crossing** of a piecewise-affine system and **sliding entry** (``J' = I``; ``f+``
  the next mode's or the sliding vector field);
* **sliding exit**: the sliding field equals the leaving mode's field at the exit point, so
  ``f+ = f-`` and ``S = I``;
* a **switching instant fixed in time** (PWM edge at a given time, ``∇h = 0``): ``S = I``;
  a PWM edge whose instant depends on the sampled state ``x_k`` (``t_e = t_k + τ(x_k)``)
  adds ``(f- - f+) ∂τ/∂x_k`` to the transition from ``x_k``, which
  :func:`time_shift_term` returns (defined in :mod:`nscontrol.numerics.saltation`, where the
  PWM integrator finds it).

Grazing (``ḣ- = 0``) makes ``S`` unbounded: :func:`saltation_matrix` refuses it with
``SolverError``.

Examples
--------
The impact of a unit mass on a stop at ``q = d`` with restitution ``r = 0.5``, approaching
at ``v = 2`` with acceleration ``-1`` before and ``-1`` after:

>>> import numpy as np
>>> J = np.diag([1.0, -0.5])
>>> S = saltation_matrix(J, f_minus=[2.0, -1.0], f_plus=[-1.0, -1.0], guard_gradient=[1.0, 0.0])
>>> S.tolist()
[[-0.5, 0.0], [-0.75, -0.5]]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import FloatArray, as_matrix, as_vector
from ..errors import DimensionError, SolverError
from ..numerics.saltation import time_shift_term  # the simulate layer uses it too

__all__ = ["saltation_matrix", "impact_jump_jacobian", "time_shift_term"]


def saltation_matrix(jump_jacobian: Any, f_minus: Any, f_plus: Any, guard_gradient: Any, *,
                     guard_time_derivative: float = 0.0) -> FloatArray:
    """``S = J' + (f+ - J' f-) ∇hᵀ / (∇h·f- + ∂h/∂t)``.

    Parameters
    ----------
    jump_jacobian : (n, n) array_like
        ``J' = ∂x+/∂x-`` (the identity for a switch without jump).
    f_minus, f_plus : (n,) array_like
        Vector fields just before (at ``x-``) and just after (at ``x+``) the event.
    guard_gradient : (n,) array_like
        ``∇h`` at ``x-``.
    guard_time_derivative : float
        ``∂h/∂t`` for a time-dependent guard.

    Returns
    -------
    (n, n) ndarray

    Raises
    ------
    DimensionError
        Shapes that disagree.
    SolverError
        A grazing event (``ḣ- = 0`` to rounding): the saltation matrix does not exist.
    """
    fm = as_vector("f_minus", f_minus)
    n = fm.shape[0]
    fp = as_vector("f_plus", f_plus, n)
    dh = as_vector("guard_gradient", guard_gradient, n)
    J = as_matrix("jump_jacobian", jump_jacobian)
    if J.shape != (n, n):
        raise DimensionError(f"jump_jacobian: expected shape ({n}, {n}), got {J.shape}")
    rate = float(dh @ fm) + float(guard_time_derivative)
    # ḣ- below rounding of its own terms: the event is tangential (grazing)
    if abs(rate) <= 8 * np.finfo(float).eps * (float(np.abs(dh) @ np.abs(fm))
                                                + abs(guard_time_derivative)):
        raise SolverError(f"guard_gradient: the event is grazing (rate of approach {rate:.3g}"
                          f" is zero to rounding); no saltation matrix exists there")
    return J + np.outer(fp - J @ fm, dh) / rate


def impact_jump_jacobian(mass_matrix: Any, normal: Any, restitution: float) -> FloatArray:
    """``∂x+/∂x-`` of Newton's impact law on one contact of a mechanical system.

    With state ``x = (q, v)``, contact normal ``w`` (``ġ = wᵀv``) and mass matrix ``M``, the
    post-impact velocity is ``v+ = v- - (1 + e) M⁻¹w (wᵀv-) / (wᵀM⁻¹w)``; positions do not
    jump. Returns the ``(2n, 2n)`` block matrix ``diag(I, I - (1 + e) M⁻¹w wᵀ/(wᵀM⁻¹w))``.

    Parameters
    ----------
    mass_matrix : (n, n) array_like
        ``M``, symmetric positive definite.
    normal : (n,) array_like
        The contact normal ``w``.
    restitution : float
        Newton's coefficient ``e``.
    """
    M = as_matrix("mass_matrix", mass_matrix)
    n = M.shape[0]
    w = as_vector("normal", normal, n)
    Minv_w = np.linalg.solve(M, w)
    P = np.eye(n) - (1.0 + float(restitution)) * np.outer(Minv_w, w) / float(w @ Minv_w)
    out = np.eye(2 * n)
    out[n:, n:] = P
    return out

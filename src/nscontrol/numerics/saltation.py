"""Saltation matrices, the Jacobian of Newton's impact jump, and the transition term of a
switching instant set by a sampled state.

The theory (what a saltation matrix is, every event kind) is told in
:mod:`nscontrol.analysis.saltation`, which re-exports these functions. They live here, below
``simulate``, because the integrators apply them while they integrate the variational
equation (``simulate(..., sensitivity=True)``); matrices and callables of ``q`` in, matrices
out.

Newton's law on one contact with a mass matrix ``M(q)`` and a gap ``g(q)`` (normal
``w(q) = ∇g(q)``) is the jump ``(q, v) -> (q, v+(q, v))`` with

    v+ = v - (1 + e) M⁻¹w (wᵀv) / (wᵀM⁻¹w).

Its Jacobian is block lower triangular: ``∂q+/∂q = I``, ``∂q+/∂v = 0``,
``∂v+/∂v = I - (1 + e) M⁻¹w wᵀ/(wᵀM⁻¹w)`` (a projection scaled on the normal) and
``∂v+/∂q``, which is zero when ``M`` is constant and the gap affine, and otherwise carries the
rotation of the normal and the change of the inertia along the motion (taken by central
differences, see :func:`impact_jump_jacobian`).

A sampled controller (a PWM modulator) reads ``x_k = x(t_k)`` and switches the vector field
from ``f-`` to ``f+`` at ``t_e = t_k + τ(x_k)``. The instantaneous state is continuous there
(its own saltation matrix is the identity: the instant does not depend on the state at
``t_e``), but the instant moves with ``x_k``: delaying it by ``δt`` runs ``f-`` instead of
``f+`` for ``δt``, so the state just after ``t_e`` moves by ``(f- - f+) δt``. Hence the
transition from ``x_k`` gains, at ``t_e``,

    ∂x(t_e+)/∂x_k  +=  (f- - f+) ∂τ/∂x_kᵀ,

and the flows after ``t_e`` carry this term on like the rest of the transition.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import FloatArray, as_matrix, as_vector
from ..errors import DimensionError, ModelError, SolverError
from .differences import central_difference_jacobian

__all__ = ["saltation_matrix", "impact_jump_jacobian", "impact_velocity", "time_shift_term"]


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

    Examples
    --------
    >>> S = saltation_matrix(np.diag([1.0, -0.5]), [2.0, -1.0], [-1.0, -1.0], [1.0, 0.0])
    >>> S.tolist()
    [[-0.5, 0.0], [-0.75, -0.5]]
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


def impact_velocity(mass_matrix: Any, normal: Any, velocity: Any,
                    restitution: float) -> FloatArray:
    """Newton's law on one contact: ``v+ = v - (1 + e) M⁻¹w (wᵀv) / (wᵀM⁻¹w)``.

    Parameters
    ----------
    mass_matrix : (n, n) array_like
        ``M``, symmetric positive definite.
    normal : (n,) array_like
        The contact normal ``w`` (``ġ = wᵀv``).
    velocity : (n,) array_like
        ``v-``.
    restitution : float
        Newton's coefficient ``e``.

    Examples
    --------
    >>> impact_velocity([[2.0]], [-1.0], [3.0], 0.5).tolist()
    [-1.5]
    """
    M = as_matrix("mass_matrix", mass_matrix)
    n = M.shape[0]
    w = as_vector("normal", normal, n)
    v = as_vector("velocity", velocity, n)
    Minv_w = np.linalg.solve(M, w)
    return np.asarray(v - (1.0 + float(restitution)) * Minv_w * float(w @ v)
                      / float(w @ Minv_w), dtype=np.float64)


def impact_jump_jacobian(mass_matrix: Any, normal: Any, restitution: float, *,
                         state: Any = None) -> FloatArray:
    """``∂x+/∂x-`` of Newton's impact law on one contact of a mechanical system.

    With state ``x = (q, v)``, contact normal ``w`` and mass matrix ``M``, the post-impact
    velocity is :func:`impact_velocity`; positions do not jump. For a constant ``M`` and a
    constant normal (affine gap) the result is ``diag(I, I - (1 + e) M⁻¹w wᵀ/(wᵀM⁻¹w))``.
    When ``mass_matrix`` or ``normal`` is a callable of ``q`` (``M(q)``, a nonlinear gap's
    ``∇g(q)``), the block ``∂v+/∂q`` is added: central differences of ``q -> v+(q, v)`` at
    the pre-impact ``state`` (:func:`~nscontrol.numerics.differences.central_difference_jacobian`,
    step ``1e-6 (1 + |q_k|)``: about ``1e-10`` relative for an analytic ``∇g``; a ``∇g``
    itself differenced adds its own error divided by the step).

    Parameters
    ----------
    mass_matrix : (n, n) array_like or callable ``q -> M(q)``
        ``M``, symmetric positive definite.
    normal : (n,) array_like or callable ``q -> w(q)``
        The contact normal ``w`` (the gradient of the gap).
    restitution : float
        Newton's coefficient ``e``.
    state : (2 n,) array_like, optional
        The pre-impact state ``[q; v]``; required when ``mass_matrix`` or ``normal`` is a
        callable.

    Returns
    -------
    (2 n, 2 n) ndarray

    Raises
    ------
    ModelError
        A callable ``mass_matrix`` or ``normal`` without ``state``.

    Examples
    --------
    >>> impact_jump_jacobian([[2.0]], [-1.0], 0.8).tolist()
    [[1.0, 0.0], [0.0, -0.8]]

    A normal that turns with ``q`` (a gap ``1 - q0² - q1``, unit masses): ``∂v+/∂q`` appears.

    >>> J = impact_jump_jacobian(np.eye(2), lambda q: np.array([-2 * q[0], -1.0]), 1.0,
    ...                          state=[0.5, 0.75, 0.0, 1.0])
    >>> bool(np.abs(J[2:, :2]).max() > 0.1)
    True
    """
    varying = callable(mass_matrix) or callable(normal)
    if varying and state is None:
        raise ModelError("state: a configuration-dependent mass matrix or normal needs the "
                         "pre-impact state [q; v] to differentiate the jump in q")
    if not varying:
        return _constant_impact_jacobian(mass_matrix, normal, restitution)
    x = as_vector("state", state)
    if x.shape[0] % 2:
        raise DimensionError(f"state: expected [q; v] of even length, got {x.shape[0]}")
    n = x.shape[0] // 2
    q, v = x[:n], x[n:]

    def mass_at(qq: FloatArray) -> Any:
        return mass_matrix(qq) if callable(mass_matrix) else mass_matrix

    def normal_at(qq: FloatArray) -> Any:
        return normal(qq) if callable(normal) else normal

    out = _constant_impact_jacobian(mass_at(q), normal_at(q), restitution)
    out[n:, :n] = central_difference_jacobian(
        lambda qq: impact_velocity(mass_at(qq), normal_at(qq), v, restitution), q)
    return out


def _constant_impact_jacobian(mass_matrix: Any, normal: Any, restitution: float) -> FloatArray:
    """``diag(I, I - (1 + e) M⁻¹w wᵀ/(wᵀM⁻¹w))``: the jump's Jacobian at fixed ``M`` and ``w``."""
    M = as_matrix("mass_matrix", mass_matrix)
    n = M.shape[0]
    w = as_vector("normal", normal, n)
    Minv_w = np.linalg.solve(M, w)
    P = np.eye(n) - (1.0 + float(restitution)) * np.outer(Minv_w, w) / float(w @ Minv_w)
    out = np.eye(2 * n)
    out[n:, n:] = P
    return out


def time_shift_term(f_minus: Any, f_plus: Any, dtau_dx: Any) -> FloatArray:
    """``(f- - f+) ∂τ/∂xᵀ``: the part of the transition from a sampled state ``x_k`` due to a
    switching instant ``t_e = t_k + τ(x_k)`` (PWM edge set by the sampled state).

    Parameters
    ----------
    f_minus, f_plus : (n,) array_like
        The fields before and after the switching instant.
    dtau_dx : (n,) array_like
        ``∂τ/∂x``, the gradient of the switching delay.

    Examples
    --------
    A falling edge (field ``(1, 0)`` to ``(0, 1)``) delayed by half the first state's change:

    >>> time_shift_term([1.0, 0.0], [0.0, 1.0], [0.5, 0.25]).tolist()
    [[0.5, 0.25], [-0.5, -0.25]]
    """
    fm = as_vector("f_minus", f_minus)
    fp = as_vector("f_plus", f_plus, fm.shape[0])
    g = as_vector("dtau_dx", dtau_dx)
    return np.outer(fm - fp, g)

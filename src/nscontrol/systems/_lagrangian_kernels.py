"""Signatures of a compiled Lagrangian model (:class:`~nscontrol.systems.lagrangian.
CompiledModel`): its functions are compiled by ``numba.njit`` with these declared, so that the
compiled Moreau–Jean loop receives them as first-class functions and stays compiled once;
and the force of a model without one (:func:`no_force`, :func:`no_force_jacobian`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

_VEC = types.float64[::1]
_MAT = types.float64[:, ::1]
#: ``mass(q, params) -> M (n, n)``.
MASS_SIGNATURE = _MAT(_VEC, _VEC)
#: ``force(t, q, v, params) -> f (n,)``: the nonlinear force (``force`` of the system).
FORCE_SIGNATURE = _VEC(types.float64, _VEC, _VEC, _VEC)
#: ``force_jacobian(t, q, v, params) -> [∂f/∂q; ∂f/∂v] (2n, n)``.
FORCE_JACOBIAN_SIGNATURE = _MAT(types.float64, _VEC, _VEC, _VEC)
#: ``gaps(q, params) -> g (m,)``.
GAP_SIGNATURE = _VEC(_VEC, _VEC)
#: ``gap_jacobian(q, params) -> ∂g/∂q (m, n)``.
GAP_JACOBIAN_SIGNATURE = _MAT(_VEC, _VEC)
#: ``potential(q, params) -> V`` (optional: the energy signal's potential).
POTENTIAL_SIGNATURE = types.float64(_VEC, _VEC)


@njit(FORCE_SIGNATURE, cache=True)
def no_force(t, q, v, params):
    """The force of a model without a nonlinear force term: zeros."""
    return np.zeros(q.size)


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def no_force_jacobian(t, q, v, params):
    """The Jacobian of :func:`no_force`: zeros ``(2n, n)``."""
    return np.zeros((2 * q.size, q.size))


@njit(MASS_SIGNATURE, cache=True)
def constant_mass(q, params):
    """``M`` of an affine model: ``params = [n, m, M (n n), G (m n), g0 (m)]``."""
    n = q.size
    return params[2:2 + n * n].copy().reshape((n, n))


@njit(GAP_SIGNATURE, cache=True)
def affine_gaps(q, params):
    """``G q + g0`` of an affine model (layout of :func:`constant_mass`)."""
    n, m = q.size, int(params[1])
    off = 2 + n * n
    out = np.empty(m)
    for j in range(m):
        s = 0.0
        for i in range(n):
            s += params[off + j * n + i] * q[i]
        out[j] = s + params[off + m * n + j]
    return out


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def affine_gap_jacobian(q, params):
    """``G`` of an affine model (layout of :func:`constant_mass`)."""
    n, m = q.size, int(params[1])
    off = 2 + n * n
    return params[off:off + m * n].copy().reshape((m, n))

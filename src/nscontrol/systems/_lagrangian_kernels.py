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

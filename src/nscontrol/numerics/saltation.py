"""The transition term of a switching instant set by a sampled state.

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

from .._validation import FloatArray, as_vector

__all__ = ["time_shift_term"]


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

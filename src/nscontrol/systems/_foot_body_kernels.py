"""The foot + body model (:func:`~nscontrol.systems.foot_body.foot_body_model`), written once.

Every formula of the model lives here as a compiled function; the model's Python callables
(``mass``, ``coriolis_force``, ``gaps``, ...) call these same functions, and the compiled
model (:class:`~nscontrol.systems.lagrangian.CompiledModel`) is made of them: the force and
its Jacobian are composed from the Coriolis and potential terms as the Python model composes
them (``-C(q, v) v - ∇V(q)``).

Parameters: the named record :data:`FOOT_BODY`, passed as its flat ``float64`` view
(``named_record(FOOT_BODY, ...).view(np.float64)``) and read back by name.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._lagrangian_kernels import (
    FORCE_JACOBIAN_SIGNATURE,
    FORCE_SIGNATURE,
    GAP_JACOBIAN_SIGNATURE,
    GAP_SIGNATURE,
    MASS_SIGNATURE,
    POTENTIAL_SIGNATURE,
)

_F = np.float64
#: ``m = m_f + m_b`` (total mass), then the fields of
#: :class:`~nscontrol.systems.foot_body.FootBodyParameters` the model reads.
FOOT_BODY = np.dtype([("m", _F), ("m_b", _F), ("L", _F), ("I_f", _F), ("a", _F), ("b", _F),
                      ("d", _F), ("g", _F), ("I_b", _F)])


@njit(MASS_SIGNATURE, cache=True)
def mass(q, p):
    """``M(q)``."""
    c = p.view(FOOT_BODY)[0]
    mb, L = c.m_b, c.L
    co, si = mb * L * math.cos(q[3]), mb * L * math.sin(q[3])
    M = np.zeros((4, 4))
    M[0, 0], M[0, 3] = c.m, -co
    M[1, 1], M[1, 3] = c.m, -si
    M[2, 2] = c.I_f
    M[3, 0], M[3, 1], M[3, 3] = -co, -si, mb * L * L + c.I_b
    return M


@njit(cache=True)
def coriolis_force(q, v, p):
    """``C(q, v) v``."""
    c = p.view(FOOT_BODY)[0]
    w2 = v[3] * v[3]
    f = np.zeros(4)
    f[0] = c.m_b * c.L * math.sin(q[3]) * w2
    f[1] = -c.m_b * c.L * math.cos(q[3]) * w2
    return f


@njit(cache=True)
def coriolis_jacobians(q, v, p):
    """``(∂(Cv)/∂q, ∂(Cv)/∂v)``."""
    c = p.view(FOOT_BODY)[0]
    mb, L = c.m_b, c.L
    s, co, w = math.sin(q[3]), math.cos(q[3]), v[3]
    Jq, Jv = np.zeros((4, 4)), np.zeros((4, 4))
    Jq[0, 3], Jq[1, 3] = mb * L * co * w * w, mb * L * s * w * w
    Jv[0, 3], Jv[1, 3] = 2 * mb * L * s * w, -2 * mb * L * co * w
    return Jq, Jv


@njit(POTENTIAL_SIGNATURE, cache=True)
def potential(q, p):
    """``V(q) = m g y + m_b g L cos θ``."""
    c = p.view(FOOT_BODY)[0]
    return c.m * c.g * q[1] + c.m_b * c.g * c.L * math.cos(q[3])


@njit(cache=True)
def potential_gradient(q, p):
    """``∇V(q)``."""
    c = p.view(FOOT_BODY)[0]
    out = np.zeros(4)
    out[1] = c.m * c.g
    out[3] = -c.m_b * c.g * c.L * math.sin(q[3])
    return out


@njit(cache=True)
def potential_hessian(q, p):
    """``∇²V(q)``."""
    c = p.view(FOOT_BODY)[0]
    H = np.zeros((4, 4))
    H[3, 3] = -c.m_b * c.g * c.L * math.cos(q[3])
    return H


@njit(FORCE_SIGNATURE, cache=True)
def force(t, q, v, p):
    """``-C(q, v) v - ∇V(q)``."""
    return -coriolis_force(q, v, p) - potential_gradient(q, p)


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def force_jacobian(t, q, v, p):
    """``[∂f/∂q; ∂f/∂v]`` of :func:`force`."""
    Jq, Jv = coriolis_jacobians(q, v, p)
    J = np.empty((8, 4))
    J[:4] = -Jq - potential_hessian(q, p)
    J[4:] = -Jv
    return J


@njit(GAP_SIGNATURE, cache=True)
def gaps(q, p):
    """Heel and toe gaps."""
    c = p.view(FOOT_BODY)[0]
    s, co = math.sin(q[2]), math.cos(q[2])
    out = np.empty(2)
    out[0] = q[1] - c.a * s - c.d * co
    out[1] = q[1] + c.b * s - c.d * co
    return out


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def gap_jacobian(q, p):
    """``∂g/∂q``."""
    c = p.view(FOOT_BODY)[0]
    s, co = math.sin(q[2]), math.cos(q[2])
    G = np.zeros((2, 4))
    G[0, 1], G[0, 2] = 1.0, -c.a * co + c.d * s
    G[1, 1], G[1, 2] = 1.0, c.b * co + c.d * s
    return G


@njit(cache=True)
def gap_hessians(q, p):
    """``∇²g_α(q)`` stacked ``(2, 4, 4)``."""
    c = p.view(FOOT_BODY)[0]
    s, co = math.sin(q[2]), math.cos(q[2])
    H = np.zeros((2, 4, 4))
    H[0, 2, 2] = c.a * s + c.d * co
    H[1, 2, 2] = -c.b * s + c.d * co
    return H


@njit(cache=True)
def support_abscissae(q, p):
    """Horizontal positions of the heel and the toe."""
    c = p.view(FOOT_BODY)[0]
    s, co = math.sin(q[2]), math.cos(q[2])
    out = np.empty(2)
    out[0] = q[0] - c.a * co + c.d * s
    out[1] = q[0] + c.b * co + c.d * s
    return out

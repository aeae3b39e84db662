"""Compiled forms of the foot + body model (:func:`~nscontrol.systems.foot_body.
foot_body_model`), with the Python closures' operations in their order.

``params = [m, m_b, L, I_f, a, b, d, g, I_b]`` (``m = m_f + m_b``).
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


@njit(MASS_SIGNATURE, cache=True)
def mass(q, p):
    """``M(q)``."""
    m, mb, L, I_f = p[0], p[1], p[2], p[3]
    c, s = mb * L * math.cos(q[3]), mb * L * math.sin(q[3])
    M = np.zeros((4, 4))
    M[0, 0], M[0, 3] = m, -c
    M[1, 1], M[1, 3] = m, -s
    M[2, 2] = I_f
    M[3, 0], M[3, 1], M[3, 3] = -c, -s, mb * L * L + p[8]
    return M


@njit(FORCE_SIGNATURE, cache=True)
def force(t, q, v, p):
    """``-C(q, v) v - ∇V(q)``."""
    m, mb, L, g = p[0], p[1], p[2], p[7]
    w2 = v[3] * v[3]
    f = np.empty(4)
    f[0] = -(mb * L * math.sin(q[3]) * w2) - 0.0
    f[1] = -(-mb * L * math.cos(q[3]) * w2) - m * g
    f[2] = -0.0 - 0.0
    f[3] = -0.0 - (-mb * g * L * math.sin(q[3]))
    return f


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def force_jacobian(t, q, v, p):
    """``[∂f/∂q; ∂f/∂v]`` of :func:`force`."""
    mb, L, g = p[1], p[2], p[7]
    s, c, w = math.sin(q[3]), math.cos(q[3]), v[3]
    J = np.zeros((8, 4))
    J[0, 3] = -(mb * L * c * w * w)
    J[1, 3] = -(mb * L * s * w * w)
    J[3, 3] = -0.0 - (-mb * g * L * math.cos(q[3]))
    J[4, 3] = -(2 * mb * L * s * w)
    J[5, 3] = -(-2 * mb * L * c * w)
    return J


@njit(GAP_SIGNATURE, cache=True)
def gaps(q, p):
    """Heel and toe gaps."""
    a, b, d = p[4], p[5], p[6]
    s, c = math.sin(q[2]), math.cos(q[2])
    out = np.empty(2)
    out[0] = q[1] - a * s - d * c
    out[1] = q[1] + b * s - d * c
    return out


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def gap_jacobian(q, p):
    """``∂g/∂q``."""
    a, b, d = p[4], p[5], p[6]
    s, c = math.sin(q[2]), math.cos(q[2])
    G = np.zeros((2, 4))
    G[0, 1], G[0, 2] = 1.0, -a * c + d * s
    G[1, 1], G[1, 2] = 1.0, b * c + d * s
    return G


@njit(POTENTIAL_SIGNATURE, cache=True)
def potential(q, p):
    """``V(q) = m g y + m_b g L cos θ``."""
    m, mb, L, g = p[0], p[1], p[2], p[7]
    return m * g * q[1] + mb * g * L * math.cos(q[3])

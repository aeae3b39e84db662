"""Compiled forms of the two-link arm (:meth:`~nscontrol.systems.lagrangian.LagrangianSystem.
two_link_arm`), the Python functions' formulas in their order.

``params = [l1, l2, m1, m2, I1, I2, g]``.
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
    """``M(θ)``."""
    l1, l2, m1, m2, I1, I2 = p[0], p[1], p[2], p[3], p[4], p[5]
    c2 = math.cos(q[1])
    m11 = m1 * l1**2 / 4 + m2 * (l1**2 + l2**2 / 4 + l1 * l2 * c2) + I1 + I2
    m12 = m2 * l2**2 / 4 + m2 * l1 * l2 / 2 * c2 + I2
    M = np.empty((2, 2))
    M[0, 0], M[0, 1], M[1, 0], M[1, 1] = m11, m12, m12, m2 * l2**2 / 4 + I2
    return M


@njit(FORCE_SIGNATURE, cache=True)
def force(t, q, v, p):
    """``-C(θ, θ')θ' - G(θ)``."""
    l1, l2, m1, m2, g = p[0], p[1], p[2], p[3], p[6]
    h = m2 * l1 * l2 / 2 * math.sin(q[1])
    c00, c01, c10 = -h * v[1], -h * (v[0] + v[1]), h * v[0]
    c12 = math.cos(q[0] + q[1])
    g0 = g / 2 * (l1 * (m1 + 2 * m2) * math.cos(q[0]) + m2 * l2 * c12)
    g1 = m2 * g * l2 / 2 * c12
    f = np.empty(2)
    f[0] = -(c00 * v[0] + c01 * v[1]) - g0
    f[1] = -(c10 * v[0] + 0.0 * v[1]) - g1
    return f


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def force_jacobian(t, q, v, p):
    """``[∂f/∂θ; ∂f/∂θ']``."""
    l1, l2, m1, m2, g = p[0], p[1], p[2], p[3], p[6]
    c = m2 * l1 * l2 / 2
    s2, c2 = c * math.sin(q[1]), c * math.cos(q[1])
    s1, s12 = math.sin(q[0]), math.sin(q[0] + q[1])
    J = np.empty((4, 2))
    J[0, 0] = g / 2 * (l1 * (m1 + 2 * m2) * s1 + m2 * l2 * s12)
    J[0, 1] = g / 2 * m2 * l2 * s12 + c2 * (2 * v[0] * v[1] + v[1] ** 2)
    J[1, 0] = m2 * g * l2 / 2 * s12
    J[1, 1] = m2 * g * l2 / 2 * s12 - c2 * v[0] ** 2
    J[2, 0], J[2, 1] = 2 * s2 * v[1], 2 * s2 * (v[0] + v[1])
    J[3, 0], J[3, 1] = -2 * s2 * v[0], 0.0
    return J


@njit(GAP_SIGNATURE, cache=True)
def gaps(q, p):
    """End-effector height ``l1 sin θ1 + l2 sin(θ1 + θ2)``."""
    out = np.empty(1)
    out[0] = p[0] * math.sin(q[0]) + p[1] * math.sin(q[0] + q[1])
    return out


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def gap_jacobian(q, p):
    """``∂g/∂θ``."""
    c12 = p[1] * math.cos(q[0] + q[1])
    G = np.empty((1, 2))
    G[0, 0], G[0, 1] = p[0] * math.cos(q[0]) + c12, c12
    return G


@njit(POTENTIAL_SIGNATURE, cache=True)
def potential(q, p):
    """Gravity's potential."""
    l1, l2, m1, m2, g = p[0], p[1], p[2], p[3], p[6]
    return g * (m1 * l1 / 2 * math.sin(q[0])
                + m2 * (l1 * math.sin(q[0]) + l2 / 2 * math.sin(q[0] + q[1])))

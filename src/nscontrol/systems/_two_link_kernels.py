"""The one source of the two-link arm's formulas (:meth:`~nscontrol.systems.lagrangian.
LagrangianSystem.two_link_arm`, :class:`~nscontrol.systems.two_link.TwoLinkArm`): the
compiled model's functions, the joint-space terms and the task map the Python functions
call, and the task-space model the tracking controller's kernel calls (:func:`task_model`).

Each formula is written once, as a scalar helper inlined into every kernel that needs it
(:func:`_inertia`, :func:`_coriolis`, :func:`_gravity`, :func:`_jacobian`,
:func:`_jacobian_rate`). The Python functions (``two_link_arm_mass`` and the like,
``TwoLinkArm.position`` and the like) call the declared kernels below with the parameters'
array.

The parameters are the record :data:`ARM` (``l1, l2, m1, m2, I1, I2, g``); a compiled model's
flat ``params`` array is that record's bytes, read by name through ``record(params, ARM)``
(``nscontrol.systems._feedback_kernels.record``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._feedback_kernels import record
from ._lagrangian_kernels import (
    FORCE_JACOBIAN_SIGNATURE,
    FORCE_SIGNATURE,
    GAP_JACOBIAN_SIGNATURE,
    GAP_SIGNATURE,
    MASS_SIGNATURE,
    POTENTIAL_SIGNATURE,
)

_F = np.float64
#: The arm's parameters by name (geometry, inertia, gravity; see ``TwoLinkParams``).
ARM = np.dtype([("l1", _F), ("l2", _F), ("m1", _F), ("m2", _F), ("I1", _F), ("I2", _F),
                ("g", _F)])


def arm_array(l1: float, l2: float, m1: float, m2: float, I1: float, I2: float,
              g: float = 0.0) -> np.ndarray:
    """The flat ``float64`` array of the record :data:`ARM` (what the kernels take)."""
    return np.array([(l1, l2, m1, m2, I1, I2, g)], dtype=ARM).view(np.float64)


# -- the formulas, once ------------------------------------------------------------------
@njit(cache=True, inline="always")
def _inertia(c2, l1, l2, m1, m2, I1, I2):
    """``(M11, M12, M22)`` of ``M(θ)`` from ``cos θ2``."""
    m11 = m1 * l1**2 / 4 + m2 * (l1**2 + l2**2 / 4 + l1 * l2 * c2) + I1 + I2
    m12 = m2 * l2**2 / 4 + m2 * l1 * l2 / 2 * c2 + I2
    return m11, m12, m2 * l2**2 / 4 + I2


@njit(cache=True, inline="always")
def _coriolis(s2, w1, w2, l1, l2, m2):
    """``C(θ, θ')`` in Christoffel form, row-major, from ``sin θ2``."""
    h = m2 * l1 * l2 / 2 * s2
    return -h * w2, -h * (w1 + w2), h * w1, 0.0


@njit(cache=True, inline="always")
def _gravity(c1, c12, l1, l2, m1, m2, g):
    """``G(θ) = ∂P/∂θ`` from ``cos θ1`` and ``cos(θ1 + θ2)``."""
    return g / 2 * (l1 * (m1 + 2 * m2) * c1 + m2 * l2 * c12), m2 * g * l2 / 2 * c12


@njit(cache=True, inline="always")
def _jacobian(s1, c1, s12, c12, l1, l2):
    """``J = ∂(y, x)/∂θ``, row-major (``y`` first: ``J[0]`` is the gap's gradient)."""
    return l1 * c1 + l2 * c12, l2 * c12, -l1 * s1 - l2 * s12, -l2 * s12


@njit(cache=True, inline="always")
def _jacobian_rate(s1, c1, s12, c12, w1, w2, l1, l2):
    """``J̇ = d/dt J(θ(t))``, row-major."""
    w12 = w1 + w2
    return (-l1 * s1 * w1 - l2 * s12 * w12, -l2 * s12 * w12,
            -l1 * c1 * w1 - l2 * c12 * w12, -l2 * c12 * w12)


@njit(cache=True, inline="always")
def _mat(a, rows, cols):
    """A new ``(rows, cols)`` array from a row-major tuple."""
    out = np.empty((rows, cols))
    for k in range(rows * cols):
        out[k // cols, k % cols] = a[k]
    return out


# -- the compiled model (Moreau–Jean) ----------------------------------------------------
@njit(MASS_SIGNATURE, cache=True)
def mass(q, p):
    """``M(θ)``."""
    a = record(p, ARM)
    m11, m12, m22 = _inertia(math.cos(q[1]), a.l1, a.l2, a.m1, a.m2, a.I1, a.I2)
    return _mat((m11, m12, m12, m22), 2, 2)


@njit(FORCE_SIGNATURE, cache=True)
def force(t, q, v, p):
    """``-C(θ, θ')θ' - G(θ)``."""
    a = record(p, ARM)
    C = _coriolis(math.sin(q[1]), v[0], v[1], a.l1, a.l2, a.m2)
    G = _gravity(math.cos(q[0]), math.cos(q[0] + q[1]), a.l1, a.l2, a.m1, a.m2, a.g)
    f = np.empty(2)
    f[0] = -(C[0] * v[0] + C[1] * v[1]) - G[0]
    f[1] = -(C[2] * v[0] + C[3] * v[1]) - G[1]
    return f


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def force_jacobian(t, q, v, p):
    """``[∂f/∂θ; ∂f/∂θ']``; with ``c = m2 l1 l2 / 2``: ``-C θ' = c sin θ2 (2 θ1'θ2' + θ2'²,
    -θ1'²)``."""
    a = record(p, ARM)
    l1, l2, m1, m2, g = a.l1, a.l2, a.m1, a.m2, a.g
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
    a = record(p, ARM)
    out = np.empty(1)
    out[0] = a.l1 * math.sin(q[0]) + a.l2 * math.sin(q[0] + q[1])
    return out


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def gap_jacobian(q, p):
    """``∂g/∂θ``: the first row of :func:`jacobian`."""
    a = record(p, ARM)
    s12, c12 = math.sin(q[0] + q[1]), math.cos(q[0] + q[1])
    J = _jacobian(math.sin(q[0]), math.cos(q[0]), s12, c12, a.l1, a.l2)
    return _mat(J[:2], 1, 2)


@njit(POTENTIAL_SIGNATURE, cache=True)
def potential(q, p):
    """Gravity's potential."""
    a = record(p, ARM)
    l1, l2, m1, m2, g = a.l1, a.l2, a.m1, a.m2, a.g
    return g * (m1 * l1 / 2 * math.sin(q[0])
                + m2 * (l1 * math.sin(q[0]) + l2 / 2 * math.sin(q[0] + q[1])))


# -- joint-space terms and the task map, for the Python functions (compiled at first use,
# for the contiguous float64 arrays they are given) -----------------------------------------
@njit(cache=True)
def coriolis(q, v, p):
    """``C(θ, θ')``."""
    a = record(p, ARM)
    return _mat(_coriolis(math.sin(q[1]), v[0], v[1], a.l1, a.l2, a.m2), 2, 2)


@njit(cache=True)
def gravity(q, p):
    """``G(θ)``."""
    a = record(p, ARM)
    G = _gravity(math.cos(q[0]), math.cos(q[0] + q[1]), a.l1, a.l2, a.m1, a.m2, a.g)
    out = np.empty(2)
    out[0], out[1] = G[0], G[1]
    return out


@njit(cache=True)
def position(q, p):
    """End-effector task coordinates ``(y, x)``."""
    a = record(p, ARM)
    out = np.empty(2)
    out[0] = a.l1 * math.sin(q[0]) + a.l2 * math.sin(q[0] + q[1])
    out[1] = a.l1 * math.cos(q[0]) + a.l2 * math.cos(q[0] + q[1])
    return out


@njit(cache=True)
def jacobian(q, p):
    """``J = ∂(y, x)/∂θ``."""
    a = record(p, ARM)
    s12, c12 = math.sin(q[0] + q[1]), math.cos(q[0] + q[1])
    return _mat(_jacobian(math.sin(q[0]), math.cos(q[0]), s12, c12, a.l1, a.l2), 2, 2)


@njit(cache=True)
def jacobian_rate(q, v, p):
    """``J̇``."""
    a = record(p, ARM)
    s12, c12 = math.sin(q[0] + q[1]), math.cos(q[0] + q[1])
    return _mat(_jacobian_rate(math.sin(q[0]), math.cos(q[0]), s12, c12, v[0], v[1], a.l1,
                               a.l2), 2, 2)


# -- task space (the tracking controller) ------------------------------------------------
@njit(cache=True, inline="always")
def task_model(x, l1, l2, m1, m2, I1, I2, grav, q, dq, Mq, Cq, gq, J):
    """Task coordinates ``q = (y, x)``, velocities and ``(M_q, C_q, g_q, J)`` of the arm at
    ``x = [θ; θ']`` into the arrays (the :data:`ARM` fields as scalars: a record nested in
    another costs a copy in numba); closed form on floats (2x2 matrices as row-major
    4-tuples: no allocation)."""
    t1, t2, w1, w2 = x[0], x[1], x[2], x[3]
    s1, c1, s2, c2 = math.sin(t1), math.cos(t1), math.sin(t2), math.cos(t2)
    s12, c12 = math.sin(t1 + t2), math.cos(t1 + t2)
    Jt = _jacobian(s1, c1, s12, c12, l1, l2)
    det = Jt[0] * Jt[3] - Jt[1] * Jt[2]           # = l1 l2 sin θ2 (up to sign)
    Ji = (Jt[3] / det, -Jt[1] / det, -Jt[2] / det, Jt[0] / det)
    m11, m12, m22 = _inertia(c2, l1, l2, m1, m2, I1, I2)
    M = (m11, m12, m12, m22)
    C = _coriolis(s2, w1, w2, l1, l2, m2)
    Jd = _jacobian_rate(s1, c1, s12, c12, w1, w2, l1, l2)
    JiT = (Ji[0], Ji[2], Ji[1], Ji[3])
    Mq2 = _mm(_mm(JiT, M), Ji)
    MJiJd = _mm(_mm(M, Ji), Jd)
    Cq2 = _mm(_mm(JiT, (C[0] - MJiJd[0], C[1] - MJiJd[1], C[2] - MJiJd[2],
                        C[3] - MJiJd[3])), Ji)
    G1, G2 = _gravity(c1, c12, l1, l2, m1, m2, grav)
    gq[0] = JiT[0] * G1 + JiT[1] * G2
    gq[1] = JiT[2] * G1 + JiT[3] * G2
    off = 0.5 * (Mq2[1] + Mq2[2])                # symmetric to the last bit
    Mq[0, 0], Mq[0, 1], Mq[1, 0], Mq[1, 1] = Mq2[0], off, off, Mq2[3]
    Cq[0, 0], Cq[0, 1], Cq[1, 0], Cq[1, 1] = Cq2[0], Cq2[1], Cq2[2], Cq2[3]
    J[0, 0], J[0, 1], J[1, 0], J[1, 1] = Jt[0], Jt[1], Jt[2], Jt[3]
    # q = (y, x): the Jacobian's entries are the link sums
    q[0], q[1] = -Jt[2], Jt[0]
    dq[0] = Jt[0] * w1 + Jt[1] * w2
    dq[1] = Jt[2] * w1 + Jt[3] * w2


@njit(cache=True, inline="always")
def one_dof_task_model(x, m, g, q, dq, Mq, Cq, gq, J):
    """The same for the mass on a vertical line (identity task map): ``(m, 0, m g, 1)``."""
    q[0], dq[0] = x[0], x[1]
    Mq[0, 0], Cq[0, 0], gq[0], J[0, 0] = m, 0.0, m * g, 1.0


@njit(cache=True)
def task_model_of(x, p):
    """``(q, q', M_q, C_q, g_q, J)`` of the arm (``p``: the flat :data:`ARM` array) at
    ``x = [θ; θ']``, as new arrays (what ``TwoLinkArm.task_model`` returns)."""
    q, dq, gq = np.empty(2), np.empty(2), np.empty(2)
    Mq, Cq, J = np.empty((2, 2)), np.empty((2, 2)), np.empty((2, 2))
    a = record(p, ARM)
    task_model(x, a.l1, a.l2, a.m1, a.m2, a.I1, a.I2, a.g, q, dq, Mq, Cq, gq, J)
    return q, dq, Mq, Cq, gq, J


@njit(cache=True, inline="always")
def _mm(A, B):
    """Product of two 2x2 matrices stored row-major as 4-tuples."""
    return (A[0] * B[0] + A[1] * B[2], A[0] * B[1] + A[1] * B[3],
            A[2] * B[0] + A[3] * B[2], A[2] * B[1] + A[3] * B[3])

"""Compiled form of :class:`~nscontrol.design.complementarity_tracking.
SwitchingTrackingController` (``switching="designed"``, exact position and force
measurements), for the integrators' compiled loops.

The Python controller keeps its phase logic as object state and advances it inside
``output``; the compiled form keeps the same quantities in the block state ``xb`` and
``output`` advances them **in place** (the compiled loop passes the loop's own state array),
while ``update`` returns a zero derivative so that the loop's explicit Euler step leaves
``xb`` exactly as ``output`` left it. The loop logs ``xb`` at every step start: the phase,
cycle, per-cycle quantities and the logged ``V``, ``V1``, ``λ_d``, ``λ̂`` and ``q_d`` of
every step can be read back from that log.

Block-state layout (``X_*`` indices; ``K = detection_delay + 1`` ring slots at the end)::

    phase, cycle, contact_steps, liftoff_at, t_prev,
    tau0, V_tau0, V1_tau0, depth, q10, q2_star, t_first_impact, t_constrained, t_detach,
    t_star, u_star,                                  (the current cycle, 0 until fixed)
    V, V1, lam_d, lam_hat, qd[0], qd[1],             (this step's log row)
    seen_count, ring_t[K], ring_lam[K]               (the delayed contact detection)

Parameter layout: the ``P_*`` indices below (see ``SwitchingTrackingController.compiled``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..systems._feedback_kernels import BLOCK_SIGNATURE

# -- block state ------------------------------------------------------------------------
X_PHASE, X_CYCLE, X_CONTACT, X_LIFTOFF, X_TPREV = 0, 1, 2, 3, 4
X_TAU0, X_V_TAU0, X_V1_TAU0, X_DEPTH, X_Q10, X_Q2STAR = 5, 6, 7, 8, 9, 10
X_T_IMPACT, X_T_CONSTRAINED, X_T_DETACH, X_T_STAR, X_U_STAR = 11, 12, 13, 14, 15
X_V, X_V1, X_LAM_D, X_LAM_HAT, X_QD = 16, 17, 18, 19, 20      # X_QD: two slots
X_SEEN = 22
X_RING = 23
#: Cycle fields reset to NaN at every take-off.
CYCLE_FIELDS = (X_TAU0, X_U_STAR + 1)

# -- parameters -------------------------------------------------------------------------
P_N, P_TASK, P_TASK0 = 0, 1, 2          # task: 4 slots from P_TASK0
P_MODEL, P_MODEL0 = 6, 7                # model: 7 slots from P_MODEL0
P_G1, P_G2, P_KF = 14, 15, 16
P_DELTA, P_DDELTA, P_LAW, P_ALPHA, P_PHI, P_DMIN, P_DMAX, P_NCONS = range(17, 25)
P_LRATE, P_LSAT, P_TLIFT, P_SCALE, P_FFS, P_DELAY = range(25, 31)
N_PARAMS = 31
TASK_CIRCLE, TASK_HALF_SINE = 0.0, 1.0
MODEL_TWO_LINK, MODEL_ONE_DOF = 0.0, 1.0
FREE, APPROACH, IMPACTS, CONSTRAINED = 0.0, 1.0, 2.0, 3.0
_EPS_T = 1e-12                           # the Python logic's slack on planned instants
#: Stands for the Python logic's ``-inf`` ("no such instant yet"): the compiled loops reject
#: a block state that is not finite.
NEVER = -1e300


def state_size(delay: int) -> int:
    """Length of the block state for a detection delay of ``delay`` steps."""
    return X_RING + 2 * (delay + 1)


def initial_state(delay: int) -> np.ndarray:
    """The block state before a run: free motion of cycle 0, no take-off, no step yet
    (finite sentinels: the compiled loops reject a non-finite block state)."""
    xb = np.zeros(state_size(delay))
    xb[X_LIFTOFF] = xb[X_TPREV] = NEVER
    return xb


@njit(cache=True)
def _nominal(t, p, qd, dqd, ddqd):
    """The task's ``(q_d, q̇_d, q̈_d)`` at ``t`` into the three arrays."""
    if p[P_TASK] == TASK_CIRCLE:
        xc, r, P = p[P_TASK0], p[P_TASK0 + 1], p[P_TASK0 + 2]
        w = 2 * math.pi / P
        c, s = math.cos(w * t), math.sin(w * t)
        qd[0], qd[1] = r * s, xc + r * c
        dqd[0], dqd[1] = r * w * c, -r * w * s
        ddqd[0], ddqd[1] = -r * w * w * s, -r * w * w * c
    else:
        A, w = p[P_TASK0], p[P_TASK0 + 1]
        qd[0] = A * math.sin(w * t)
        dqd[0] = A * w * math.cos(w * t)
        ddqd[0] = -A * w * w * math.sin(w * t)


@njit(cache=True)
def _tau0(k, p):
    """Start of the transition design of cycle ``k``."""
    if p[P_TASK] == TASK_CIRCLE:
        r, P, y_thr = p[P_TASK0 + 1], p[P_TASK0 + 2], p[P_TASK0 + 3]
        return k * P + P / 2 - P * math.asin(y_thr / r) / (2 * math.pi)
    A, w, thr, P = p[P_TASK0], p[P_TASK0 + 1], p[P_TASK0 + 2], p[P_TASK0 + 3]
    return k * P + (math.pi - math.asin(thr / A)) / w


@njit(cache=True)
def _t_detach(k, p):
    """Planned take-off of cycle ``k``: the end of its period."""
    P = p[P_TASK0 + 2] if p[P_TASK] == TASK_CIRCLE else p[P_TASK0 + 3]
    return (k + 1) * P


@njit(cache=True)
def _task_model(x, p, q, dq, Mq, Cq, gq, J):
    """Task coordinates, velocities and ``(M_q, C_q, g_q, J)`` of the plant in ``x`` (the
    formulas of ``TwoLinkArm.task_dynamics`` / ``OneDofMass.task_dynamics``)."""
    if p[P_MODEL] == MODEL_ONE_DOF:
        m, g = p[P_MODEL0], p[P_MODEL0 + 1]
        q[0], dq[0] = x[0], x[1]
        Mq[0, 0], Cq[0, 0], gq[0], J[0, 0] = m, 0.0, m * g, 1.0
        return
    l1, l2, m1, m2 = p[P_MODEL0], p[P_MODEL0 + 1], p[P_MODEL0 + 2], p[P_MODEL0 + 3]
    I1, I2, grav = p[P_MODEL0 + 4], p[P_MODEL0 + 5], p[P_MODEL0 + 6]
    t1, t2, w1, w2 = x[0], x[1], x[2], x[3]
    s1, c1, s2, c2 = math.sin(t1), math.cos(t1), math.sin(t2), math.cos(t2)
    s12, c12 = math.sin(t1 + t2), math.cos(t1 + t2)
    # 2x2 matrices as row-major 4-tuples (the Python closed form's order; no allocation)
    Jt = (l1 * c1 + l2 * c12, l2 * c12, -l1 * s1 - l2 * s12, -l2 * s12)
    det = Jt[0] * Jt[3] - Jt[1] * Jt[2]
    Ji = (Jt[3] / det, -Jt[1] / det, -Jt[2] / det, Jt[0] / det)
    m11 = m1 * l1**2 / 4 + m2 * (l1**2 + l2**2 / 4 + l1 * l2 * c2) + I1 + I2
    m12 = m2 * l2**2 / 4 + m2 * l1 * l2 / 2 * c2 + I2
    M = (m11, m12, m12, m2 * l2**2 / 4 + I2)
    hh = m2 * l1 * l2 / 2 * s2
    C = (-hh * w2, -hh * (w1 + w2), hh * w1, 0.0)
    w12 = w1 + w2
    Jd = (-l1 * s1 * w1 - l2 * s12 * w12, -l2 * s12 * w12,
          -l1 * c1 * w1 - l2 * c12 * w12, -l2 * c12 * w12)
    JiT = (Ji[0], Ji[2], Ji[1], Ji[3])
    Mq2 = _mm(_mm(JiT, M), Ji)
    MJiJd = _mm(_mm(M, Ji), Jd)
    Cq2 = _mm(_mm(JiT, (C[0] - MJiJd[0], C[1] - MJiJd[1], C[2] - MJiJd[2],
                        C[3] - MJiJd[3])), Ji)
    G1 = grav / 2 * (l1 * (m1 + 2 * m2) * c1 + m2 * l2 * c12)
    G2 = m2 * grav * l2 / 2 * c12
    gq[0] = JiT[0] * G1 + JiT[1] * G2
    gq[1] = JiT[2] * G1 + JiT[3] * G2
    off = 0.5 * (Mq2[1] + Mq2[2])
    Mq[0, 0], Mq[0, 1], Mq[1, 0], Mq[1, 1] = Mq2[0], off, off, Mq2[3]
    Cq[0, 0], Cq[0, 1], Cq[1, 0], Cq[1, 1] = Cq2[0], Cq2[1], Cq2[2], Cq2[3]
    J[0, 0], J[0, 1], J[1, 0], J[1, 1] = Jt[0], Jt[1], Jt[2], Jt[3]
    q[0], q[1] = -Jt[2], Jt[0]
    dq[0] = Jt[0] * w1 + Jt[1] * w2
    dq[1] = Jt[2] * w1 + Jt[3] * w2


@njit(cache=True)
def _mm(A, B):
    """Product of two 2x2 matrices stored row-major as 4-tuples."""
    return (A[0] * B[0] + A[1] * B[2], A[0] * B[1] + A[1] * B[3],
            A[2] * B[0] + A[3] * B[2], A[2] * B[1] + A[3] * B[3])


@njit(cache=True)
def _lyapunov(Mq, q, dq, qd, dqd, p):
    """``(V, V1)`` with ``V1 = ½ sᵀ M s``, ``V = V1 + γ1 γ2 |q̃|²`` (scalar loops: no
    temporaries at every step)."""
    n = q.size
    g1, g2 = p[P_G1], p[P_G2]
    V1, ee = 0.0, 0.0
    for i in range(n):
        ei = q[i] - qd[i]
        si = dq[i] - dqd[i] + g2 * ei
        ee += ei * ei
        for j in range(n):
            sj = dq[j] - dqd[j] + g2 * (q[j] - qd[j])
            V1 += si * Mq[i, j] * sj
    V1 *= 0.5
    return V1 + g1 * g2 * ee, V1


@njit(cache=True)
def _depth(v1, p):
    """``d_k`` of ``TransitionDesign.depth``."""
    v = max(v1, 0.0)
    raw = p[P_ALPHA] * math.sqrt(v) if p[P_LAW] == 0.0 else p[P_PHI] * v
    return min(max(raw, p[P_DMIN]), p[P_DMAX])


@njit(cache=True)
def _dive(t, tau0, q10, depth, delta, Delta):
    """``virtual_dive`` for ``t >= τ0 + δ``: ``(q1*, q̇1*, q̈1*)``."""
    th = min((t - tau0 - delta) / Delta, 1.0)
    a = q10 + depth
    if th >= 1.0:
        return -depth, 0.0, 0.0
    return (q10 - 3 * a * th * th + 2 * a * th ** 3, (-6 * a * th + 6 * a * th * th) / Delta,
            (-6 * a + 12 * a * th) / Delta ** 2)


@njit(cache=True)
def _dive_crossing(xb, p):
    """``(t*, u*)``: where the dive crosses ``q1 = 0`` and its speed there (bisection)."""
    tau0, q10, depth = xb[X_TAU0], xb[X_Q10], xb[X_DEPTH]
    delta, Delta = p[P_DELTA], p[P_DDELTA]
    lo, hi = tau0 + delta, tau0 + delta + Delta
    if q10 <= 0.0:
        return lo, 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if mid >= tau0 + delta and _dive(mid, tau0, q10, depth, delta, Delta)[0] > 0.0:
            lo = mid
        else:
            hi = mid
    if hi < tau0 + delta:
        return hi, 0.0
    return hi, _dive(hi, tau0, q10, depth, delta, Delta)[1]


@njit(cache=True)
def _hermite(t, t0, t1, p0, v0, p1, v1):
    """Cubic Hermite from ``(p0, v0)`` at ``t0`` to ``(p1, v1)`` at ``t1`` (clamped)."""
    T = t1 - t0
    if T <= 0.0 or t >= t1:
        return p1, v1, 0.0
    s = max((t - t0) / T, 0.0)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, \
        s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, \
        3 * s**2 - 2 * s
    e00, e10, e01, e11 = 12 * s - 6, 6 * s - 4, -12 * s + 6, 6 * s - 2
    pos = h00 * p0 + h10 * T * v0 + h01 * p1 + h11 * T * v1
    vel = (d00 * p0 + d10 * T * v0 + d01 * p1 + d11 * T * v1) / T
    acc = (e00 * p0 + e10 * T * v0 + e01 * p1 + e11 * T * v1) / T**2
    return pos, vel, acc


@njit(cache=True)
def _reference(t, xb, p, qd, dqd, ddqd, q_star):
    """The current phase's ``(q_d, q̇_d, q̈_d)`` into the arrays; returns ``(has_q_star,
    λ_d)`` (``q_star`` filled when used)."""
    n = qd.size
    phase = xb[X_PHASE]
    if phase == FREE:
        _nominal(t, p, qd, dqd, ddqd)
        T = p[P_TLIFT]
        theta = (t - xb[X_LIFTOFF]) / T
        if theta < 1.0:          # y = σ y_nom: leaves the surface with zero velocity
            th = max(theta, 0.0)
            a = 10 * th ** 3 - 15 * th ** 4 + 6 * th ** 5
            b = 30 * th ** 2 - 60 * th ** 3 + 30 * th ** 4
            c = 60 * th - 180 * th ** 2 + 120 * th ** 3
            if a < 1.0:
                q0, v0, a0 = qd[0], dqd[0], ddqd[0]
                qd[0], dqd[0], ddqd[0] = (a * q0, b / T * q0 + a * v0,
                                          c / T**2 * q0 + 2 * b / T * v0 + a * a0)
        return False, 0.0
    if phase == APPROACH:
        tau0, delta = xb[X_TAU0], p[P_DELTA]
        if t >= tau0 + delta:
            dv = _dive(t, tau0, xb[X_Q10], xb[X_DEPTH], delta, p[P_DDELTA])
            qd[0], dqd[0], ddqd[0] = dv[0], dv[1], dv[2]
            for i in range(1, n):
                qd[i], dqd[i], ddqd[i] = xb[X_Q2STAR], 0.0, 0.0
            return False, 0.0
        s = t - tau0
        psi = tau0 + (s - delta) ** 2 * s / delta**2
        dpsi = (s - delta) * (3 * s - delta) / delta**2
        ddpsi = (6 * s - 4 * delta) / delta**2
        _nominal(psi, p, qd, dqd, ddqd)
        for i in range(n):
            v, a = dqd[i], ddqd[i]
            dqd[i] = v * dpsi
            ddqd[i] = a * dpsi**2 + v * ddpsi
        return False, 0.0
    if phase == IMPACTS:
        qd[0], q_star[0] = 0.0, -xb[X_DEPTH]
        dqd[0] = ddqd[0] = 0.0
        for i in range(1, n):
            qd[i] = q_star[i] = xb[X_Q2STAR]
            dqd[i] = ddqd[i] = 0.0
        return True, 0.0
    t_d = xb[X_T_DETACH]                  # constrained
    qd[0] = dqd[0] = ddqd[0] = 0.0
    if n > 1:             # the circle at t_d (q2 = x): where the slide must end
        xc, r, P = p[P_TASK0], p[P_TASK0 + 1], p[P_TASK0 + 2]
        wt = 2 * math.pi / P
        pn, vn = xc + r * math.cos(wt * t_d), -r * wt * math.sin(wt * t_d)
        qd[1], dqd[1], ddqd[1] = _hermite(t, xb[X_T_CONSTRAINED], t_d, xb[X_Q2STAR], 0.0,
                                          pn, vn)
    return False, p[P_LRATE] * max(t_d - t, 0.0)


@njit(cache=True)
def _detected(xb, p, lam_raw):
    """The impulse over ``h`` the phase logic sees, ``detection_delay`` steps old (0 before
    that many steps); returns ``(λ, step start it was seen at)``."""
    K = int(p[P_DELAY]) + 1
    count = int(xb[X_SEEN])
    slot = count % K
    xb[X_RING + slot], xb[X_RING + K + slot] = xb[X_TPREV], lam_raw
    xb[X_SEEN] = count + 1
    if count + 1 < K:
        return 0.0, NEVER
    oldest = (count + 1) % K
    return xb[X_RING + K + oldest], xb[X_RING + oldest]


@njit(cache=True)
def _take_off(xb, t):
    xb[X_LIFTOFF] = t
    xb[X_PHASE] = FREE
    xb[X_CYCLE] += 1.0
    for i in range(CYCLE_FIELDS[0], CYCLE_FIELDS[1]):
        xb[i] = 0.0


@njit(cache=True)
def _advance(t, xb, p, q, dq, Mq, lam, t_seen):
    """The phase logic of ``_advance_designed`` at the step start ``t``."""
    n = q.size
    phase = xb[X_PHASE]
    if phase == FREE and t >= _tau0(xb[X_CYCLE], p) - _EPS_T:
        qd, dqd, ddqd, qs = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        _reference(t, xb, p, qd, dqd, ddqd, qs)
        V, V1 = _lyapunov(Mq, q, dq, qd, dqd, p)
        _nominal(t, p, qd, dqd, ddqd)
        xb[X_TAU0], xb[X_V_TAU0], xb[X_V1_TAU0] = t, V, V1
        xb[X_DEPTH] = _depth(V1, p)
        xb[X_Q10] = qd[0]
        xb[X_Q2STAR] = qd[1] if n > 1 else 0.0
        xb[X_T_DETACH] = _t_detach(xb[X_CYCLE], p)
        xb[X_T_STAR], xb[X_U_STAR] = _dive_crossing(xb, p)
        xb[X_PHASE] = APPROACH
    elif phase == APPROACH and lam > 0.0:
        xb[X_T_IMPACT] = t_seen
        xb[X_PHASE], xb[X_CONTACT] = IMPACTS, 1.0
    elif phase == IMPACTS:
        xb[X_CONTACT] = xb[X_CONTACT] + 1.0 if lam > 0.0 else 0.0
        if xb[X_CONTACT] >= p[P_NCONS]:
            xb[X_T_CONSTRAINED] = t
            xb[X_PHASE] = CONSTRAINED
    if (xb[X_PHASE] == IMPACTS or xb[X_PHASE] == CONSTRAINED) \
            and t >= xb[X_T_DETACH] - _EPS_T:
        _take_off(xb, t)


@njit(cache=True)
def task_rows(x, p):
    """``[q, q']`` in task coordinates for every row of plant states ``x``."""
    n = int(p[P_N])
    out = np.empty((x.shape[0], 2 * n))
    q, dq, gq = np.empty(n), np.empty(n), np.empty(n)
    Mq, Cq, J = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    for k in range(x.shape[0]):
        _task_model(x[k], p, q, dq, Mq, Cq, gq, J)
        out[k, :n], out[k, n:] = q, dq
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def tracking_output(t, xb, y, x, xhat, lam, p):
    """Joint torques at the step start ``t``; advances the phase logic in ``xb`` (in place)
    and writes this step's log row into it."""
    n = int(p[P_N])
    lam_raw = lam[0] if lam.size else 0.0
    # one workspace for the step's vectors and matrices (views: no allocation each)
    w = np.empty(8 * n + 3 * n * n)
    q, dq, gq, qd = w[:n], w[n:2 * n], w[2 * n:3 * n], w[3 * n:4 * n]
    dqd, ddqd, qs, tau = w[4 * n:5 * n], w[5 * n:6 * n], w[6 * n:7 * n], w[7 * n:8 * n]
    mats = w[8 * n:].reshape((3, n, n))
    Mq, Cq, J = mats[0], mats[1], mats[2]
    _task_model(x, p, q, dq, Mq, Cq, gq, J)
    lam_det, t_seen = _detected(xb, p, lam_raw)
    _advance(t, xb, p, q, dq, Mq, lam_det, t_seen)
    has_star, lam_d = _reference(t, xb, p, qd, dqd, ddqd, qs)
    sc, g1, g2 = p[P_SCALE], p[P_G1], p[P_G2]
    for i in range(n):
        acc = 0.0
        for j in range(n):
            dqr_j = dqd[j] - g2 * (q[j] - qd[j])
            ddqr_j = ddqd[j] - g2 * (dq[j] - dqd[j])
            acc += sc * Mq[i, j] * ddqr_j + sc * Cq[i, j] * dqr_j
        s_bar = dq[i] - dqd[i] + g2 * (q[i] - qs[i]) if has_star \
            else dq[i] - (dqd[i] - g2 * (q[i] - qd[i]))
        tau[i] = acc + sc * gq[i] - g1 * s_bar
    lam_hat = min(lam_raw, p[P_LSAT])
    if xb[X_PHASE] == CONSTRAINED:
        tau[0] += -lam_d + p[P_FFS] * p[P_KF] * (lam_hat - lam_d)
    V, V1 = _lyapunov(Mq, q, dq, qd, dqd, p)
    xb[X_V], xb[X_V1], xb[X_LAM_D], xb[X_LAM_HAT] = V, V1, lam_d, lam_hat
    for i in range(2):
        xb[X_QD + i] = qd[i] if i < n else 0.0
    xb[X_TPREV] = t
    u = np.zeros(n)
    for i in range(n):
        for j in range(n):
            u[i] += J[j, i] * tau[j]
    return u


@njit(BLOCK_SIGNATURE, cache=True)
def tracking_update(t, xb, y, x, xhat, lam, p):
    """A zero derivative: ``output`` has already moved the state (see the module)."""
    return np.zeros(xb.size)

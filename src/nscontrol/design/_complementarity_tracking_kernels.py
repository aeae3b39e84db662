"""The one source of :class:`~nscontrol.design.complementarity_tracking.
SwitchingTrackingController`: its phase logic, references and law, compiled.

Both paths run these kernels. The compiled closed loop calls :func:`tracking_output` (a
:class:`~nscontrol.systems.feedback.CompiledBlock`); the Python methods call :func:`control`
with the measurement models that only Python has (noise drawn from NumPy's generators), and
the public helpers of the design module (``virtual_dive``, ``liftoff_blend``,
``slotine_li_force``, the tasks' ``nominal``/``tau0``, ``TransitionDesign.depth``) call the
scalar kernels below.

Parameters are the record :data:`PARAMS`: the compiled block's flat ``params`` array is its
bytes, read by name (``record(p, PARAMS).gamma1``). The phase logic keeps its quantities in
the block state, whose head is the record :data:`STATE` (read and written by name through
``record(xb, STATE)``); ``output`` advances them **in place** (the compiled loop
passes the loop's own state array), while ``update`` returns a zero derivative so that the
loop's explicit Euler step leaves ``xb`` exactly as ``output`` left it. The loop logs ``xb``
at every step start: the phase, cycle, per-cycle quantities and the logged ``V``, ``V1``,
``λ_d``, ``λ̂`` and ``q_d`` of every step can be read back from that log. After the record
come ``K = detection_delay + 1`` ring slots of step starts, then ``K`` of impulses (the
delayed contact detection).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..systems._feedback_kernels import BLOCK_SIGNATURE, record
from ..systems._two_link_kernels import ARM, one_dof_task_model
from ..systems._two_link_kernels import task_model as arm_task_model

# The helpers on the per-step path are inlined into their callers (``inline="always"``): a
# call between compiled functions that passes arrays costs their reference counting, which
# is most of a small helper's time.

_F = np.float64
#: The controller's parameters by name (``SwitchingTrackingController.compiled`` fills it).
PARAMS = np.dtype([
    ("n", _F), ("task", _F), ("model", _F), ("switching", _F),
    # the task: circle (centre, radius) or half sine (amplitude, omega); both have these two
    ("centre", _F), ("radius", _F), ("amplitude", _F), ("omega", _F), ("threshold", _F),
    ("period", _F),
    # the model: the arm's fields (those of ARM, flat: a nested record costs a copy in
    # numba), or the mass and gravity of the 1-DOF mass
    *((f"arm_{name}", _F) for name in ARM.names or ()), ("mass", _F), ("gravity", _F),
    ("gamma1", _F), ("gamma2", _F), ("Kf", _F),
    # transition design
    ("delta", _F), ("Delta", _F), ("depth_law", _F), ("alpha", _F), ("phi", _F),
    ("depth_min", _F), ("depth_max", _F), ("n_consecutive_contact", _F),
    # contact phase design
    ("lam_rate", _F), ("lam_sat", _F), ("liftoff_time", _F),
    ("model_scale", _F), ("force_feedback_scale", _F), ("force_scale", _F),
    ("force_bias", _F), ("detection_delay", _F), ("trigger_q2", _F), ("q2_end", _F)])
#: The phase logic's quantities by name (the head of the block state).
STATE = np.dtype([
    ("phase", _F), ("cycle", _F), ("contact_steps", _F), ("liftoff_at", _F), ("t_prev", _F),
    # the current cycle's record (NEVER until fixed)
    ("tau0", _F), ("V_tau0", _F), ("V1_tau0", _F), ("depth", _F), ("q10", _F),
    ("q2_star", _F), ("t_first_impact", _F), ("t_constrained", _F), ("t_detach", _F),
    ("t_star", _F), ("u_star", _F),
    # this step's log row
    ("V", _F), ("V1", _F), ("lam_d", _F), ("lam_hat", _F), ("qd1", _F), ("qd2", _F),
    ("seen", _F)])
N_STATE = STATE.itemsize // 8
#: The fields of the per-cycle record (``_Cycle`` of the design module).
CYCLE_FIELDS: tuple[str, ...] = (STATE.names or ())[5:16]
TASK_CIRCLE, TASK_HALF_SINE = 0.0, 1.0
MODEL_TWO_LINK, MODEL_ONE_DOF = 0.0, 1.0
DESIGNED, IMPACT_TRIGGERED = 0.0, 1.0
FREE, APPROACH, IMPACTS, CONSTRAINED = 0.0, 1.0, 2.0, 3.0
_EPS_T = 1e-12                           # slack on planned instants
#: "No such instant yet": finite (the compiled loops reject a block state that is not),
#: read back as NaN (a cycle's record) or ``-inf`` (no take-off, no step yet).
NEVER = -1e300


def state_size(delay: int) -> int:
    """Length of the block state for a detection delay of ``delay`` steps."""
    return N_STATE + 2 * (delay + 1)


def initial_state(delay: int) -> np.ndarray:
    """The block state before a run: free motion of cycle 0, no take-off, no step yet."""
    xb = np.zeros(state_size(delay))
    s = xb[:N_STATE].view(STATE)
    for name in ("liftoff_at", "t_prev", *CYCLE_FIELDS):
        s[name] = NEVER
    return xb


# -- tasks --------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def circle_nominal(t, xc, r, P, qd, dqd, ddqd):
    """The circle ``y = r sin(2πt/P)``, ``x = xc + r cos(2πt/P)`` and its derivatives."""
    w = 2 * math.pi / P
    c, s = math.cos(w * t), math.sin(w * t)
    qd[0], qd[1] = r * s, xc + r * c
    dqd[0], dqd[1] = r * w * c, -r * w * s
    ddqd[0], ddqd[1] = -r * w * w * s, -r * w * w * c


@njit(cache=True, inline="always")
def half_sine_nominal(t, A, w, qd, dqd, ddqd):
    """``A sin(ωt)`` and its derivatives."""
    qd[0] = A * math.sin(w * t)
    dqd[0] = A * w * math.cos(w * t)
    ddqd[0] = -A * w * w * math.sin(w * t)


@njit(cache=True, inline="always")
def circle_tau0(k, r, P, y_thr):
    """Where the descending ``y_d`` of cycle ``k`` falls to ``y_thr``."""
    return k * P + P / 2 - P * math.asin(y_thr / r) / (2 * math.pi)


@njit(cache=True, inline="always")
def half_sine_tau0(k, A, w, thr, P):
    """Where the descending ``A sin(ωt)`` of cycle ``k`` falls to ``thr``."""
    return k * P + (math.pi - math.asin(thr / A)) / w


@njit(cache=True, inline="always")
def _nominal(t, r, qd, dqd, ddqd):
    """The task's ``(q_d, q̇_d, q̈_d)`` at ``t`` into the three arrays."""
    if r.task == TASK_CIRCLE:
        circle_nominal(t, r.centre, r.radius, r.period, qd, dqd, ddqd)
    else:
        half_sine_nominal(t, r.amplitude, r.omega, qd, dqd, ddqd)


@njit(cache=True, inline="always")
def _tau0(k, r):
    """Start of the transition design of cycle ``k``."""
    if r.task == TASK_CIRCLE:
        return circle_tau0(k, r.radius, r.period, r.threshold)
    return half_sine_tau0(k, r.amplitude, r.omega, r.threshold, r.period)


@njit(cache=True, inline="always")
def _task_model(x, r, q, dq, Mq, Cq, gq, J):
    """Task coordinates, velocities and ``(M_q, C_q, g_q, J)`` of the plant in ``x``."""
    if r.model == MODEL_ONE_DOF:
        one_dof_task_model(x, r.mass, r.gravity, q, dq, Mq, Cq, gq, J)
    else:
        arm_task_model(x, r.arm_l1, r.arm_l2, r.arm_m1, r.arm_m2, r.arm_I1, r.arm_I2, r.arm_g,
                       q, dq, Mq, Cq, gq, J)


# -- the law's pieces ---------------------------------------------------------------------
@njit(cache=True, inline="always")
def lyapunov(Mq, q, dq, qd, dqd, g1, g2):
    """``(V, V1)`` with ``V1 = ½ sᵀ M s``, ``V = V1 + γ1 γ2 |q̃|²``."""
    n = q.size
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


@njit(cache=True, inline="always")
def slotine_li(Mq, Cq, gq, q, dq, qd, dqd, ddqd, g1, g2, scale, has_star, q_star, tau):
    """``τ = scale (M q̈_r + C q̇_r + g) - γ1 s̄`` into ``tau``; ``s̄ = q̇ + γ2 (q - q_star) -
    q̇_d`` when ``has_star``, else ``s``."""
    n = q.size
    for i in range(n):
        acc = 0.0
        for j in range(n):
            dqr_j = dqd[j] - g2 * (q[j] - qd[j])
            ddqr_j = ddqd[j] - g2 * (dq[j] - dqd[j])
            acc += scale * Mq[i, j] * ddqr_j + scale * Cq[i, j] * dqr_j
        s_bar = dq[i] - dqd[i] + g2 * (q[i] - q_star[i]) if has_star \
            else dq[i] - (dqd[i] - g2 * (q[i] - qd[i]))
        tau[i] = acc + scale * gq[i] - g1 * s_bar


@njit(cache=True)
def depth(v1, law, alpha, phi, dmin, dmax):
    """``d_k`` from ``V1(τ0)``: ``α √V1`` (``law == 0``) or ``φ V1``, clipped."""
    v = max(v1, 0.0)
    raw = alpha * math.sqrt(v) if law == 0.0 else phi * v
    return min(max(raw, dmin), dmax)


@njit(cache=True, inline="always")
def dive(t, tau0, q10, depth, delta, Delta):
    """The cubic dive for ``t >= τ0 + δ``: ``(q1*, q̇1*, q̈1*)``."""
    th = min((t - tau0 - delta) / Delta, 1.0)
    a = q10 + depth
    if th >= 1.0:
        return -depth, 0.0, 0.0
    return (q10 - 3 * a * th * th + 2 * a * th ** 3, (-6 * a * th + 6 * a * th * th) / Delta,
            (-6 * a + 12 * a * th) / Delta ** 2)


@njit(cache=True, inline="always")
def liftoff_blend(theta):
    """``σ(θ) = 10θ³ - 15θ⁴ + 6θ⁵`` and its two derivatives (``θ`` clipped to [0, 1])."""
    if theta >= 1.0:
        return 1.0, 0.0, 0.0
    th = max(theta, 0.0)
    return (10 * th ** 3 - 15 * th ** 4 + 6 * th ** 5, 30 * th ** 2 - 60 * th ** 3 + 30 * th ** 4,
            60 * th - 180 * th ** 2 + 120 * th ** 3)


@njit(cache=True)
def hermite(t, t0, t1, p0, v0, p1, v1):
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
def _dive_crossing(s, r):
    """``(t*, u*)``: where the dive crosses ``q1 = 0`` and its speed there (bisection on the
    monotone cubic)."""
    tau0, q10, d = s.tau0, s.q10, s.depth
    delta, Delta = r.delta, r.Delta
    lo, hi = tau0 + delta, tau0 + delta + Delta
    if q10 <= 0.0:
        return lo, 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if mid >= tau0 + delta and dive(mid, tau0, q10, d, delta, Delta)[0] > 0.0:
            lo = mid
        else:
            hi = mid
    if hi < tau0 + delta:
        return hi, 0.0
    return hi, dive(hi, tau0, q10, d, delta, Delta)[1]


# -- references ---------------------------------------------------------------------------
@njit(cache=True, inline="always")
def warp(t, tau0, delta, r, qd, dqd, ddqd):
    """The nominal path time-warped to rest at ``τ0 + δ``:
    ``ψ(t) = τ0 + (s - δ)² s / δ²``, ``s = t - τ0``."""
    s = t - tau0
    psi = tau0 + (s - delta) ** 2 * s / delta**2
    dpsi = (s - delta) * (3 * s - delta) / delta**2
    ddpsi = (6 * s - 4 * delta) / delta**2
    _nominal(psi, r, qd, dqd, ddqd)
    for i in range(qd.size):
        v, a = dqd[i], ddqd[i]
        dqd[i] = v * dpsi
        ddqd[i] = a * dpsi**2 + v * ddpsi


@njit(cache=True, inline="always")
def _reference_free(t, s, r, qd, dqd, ddqd):
    """Free motion: the nominal task; after a designed take-off, ``y = σ y_nom`` (leaves
    the surface with zero velocity)."""
    _nominal(t, r, qd, dqd, ddqd)
    if r.switching != DESIGNED:
        return
    T = r.liftoff_time
    a, b, c = liftoff_blend((t - s.liftoff_at) / T)
    if a < 1.0:
        q0, v0, a0 = qd[0], dqd[0], ddqd[0]
        qd[0], dqd[0], ddqd[0] = (a * q0, b / T * q0 + a * v0,
                                  c / T**2 * q0 + 2 * b / T * v0 + a * a0)


@njit(cache=True, inline="always")
def _reference_constrained(t, s, r, q, qd, dqd, ddqd):
    """Constrained motion: ``q1d = 0``; designed: the slide along a Hermite to where the
    circle leaves the ground at ``t_d``, ``λ_d = c_λ (t_d - t)``; impact-triggered: the
    nominal slide, ``λ_d = 0.5 (q2_end - q2)``. Returns ``λ_d``."""
    n = qd.size
    if r.switching == DESIGNED:
        t_d = s.t_detach
        qd[0] = dqd[0] = ddqd[0] = 0.0
        if n > 1:             # the circle at t_d (q2 = x): where the slide must end
            w = 2 * math.pi / r.period
            pn, vn = r.centre + r.radius * math.cos(w * t_d), \
                -r.radius * w * math.sin(w * t_d)
            qd[1], dqd[1], ddqd[1] = hermite(t, s.t_constrained, t_d, s.q2_star, 0.0, pn, vn)
        return r.lam_rate * max(t_d - t, 0.0)
    _nominal(t, r, qd, dqd, ddqd)
    qd[0] = dqd[0] = ddqd[0] = 0.0
    return 0.5 * max(r.q2_end - q[1], 0.0) if n > 1 else 0.0


@njit(cache=True, inline="always")
def reference(t, s, r, q, qd, dqd, ddqd, q_star):
    """The current phase's ``(q_d, q̇_d, q̈_d)`` into the arrays; returns ``(has_q_star,
    λ_d)`` (``q_star`` filled when used)."""
    n = qd.size
    phase = s.phase
    if phase == FREE:
        _reference_free(t, s, r, qd, dqd, ddqd)
        return False, 0.0
    if phase == APPROACH:
        if t >= s.tau0 + r.delta:
            q1, v1, a1 = dive(t, s.tau0, s.q10, s.depth, r.delta, r.Delta)
            qd[0], dqd[0], ddqd[0] = q1, v1, a1
            for i in range(1, n):
                qd[i], dqd[i], ddqd[i] = s.q2_star, 0.0, 0.0
        else:
            warp(t, s.tau0, r.delta, r, qd, dqd, ddqd)
        return False, 0.0
    if phase == IMPACTS:
        qd[0], q_star[0] = 0.0, -s.depth
        dqd[0] = ddqd[0] = 0.0
        for i in range(1, n):
            qd[i] = q_star[i] = s.q2_star
            dqd[i] = ddqd[i] = 0.0
        return True, 0.0
    return False, _reference_constrained(t, s, r, q, qd, dqd, ddqd)


# -- phase logic --------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _detected(xb, s, r, lam_raw):
    """The impulse over ``h`` the phase logic sees, ``detection_delay`` steps old (0 before
    that many steps); returns ``(λ, step start it was seen at)``."""
    K = int(r.detection_delay) + 1
    count = int(s.seen)
    slot = count % K
    xb[N_STATE + slot], xb[N_STATE + K + slot] = s.t_prev, lam_raw
    s.seen = count + 1
    if count + 1 < K:
        return 0.0, NEVER
    oldest = (count + 1) % K
    return xb[N_STATE + K + oldest], xb[N_STATE + oldest]


@njit(cache=True)
def _take_off(s, t):
    s.liftoff_at = t
    s.phase = FREE
    s.cycle += 1.0
    s.tau0 = s.V_tau0 = s.V1_tau0 = s.depth = s.q10 = s.q2_star = NEVER
    s.t_first_impact = s.t_constrained = s.t_detach = s.t_star = s.u_star = NEVER


@njit(cache=True)
def _transition(t, s, r, q, dq, Mq):
    """Start of the designed transition at ``τ0``: ``V(τ0)``, the depth, the dive."""
    n = q.size
    qd, dqd, ddqd = np.empty(n), np.empty(n), np.empty(n)
    _reference_free(t, s, r, qd, dqd, ddqd)
    V, V1 = lyapunov(Mq, q, dq, qd, dqd, r.gamma1, r.gamma2)
    _nominal(t, r, qd, dqd, ddqd)
    s.tau0, s.V_tau0, s.V1_tau0 = t, V, V1
    s.depth = depth(V1, r.depth_law, r.alpha, r.phi, r.depth_min, r.depth_max)
    s.q10 = qd[0]
    s.q2_star = qd[1] if n > 1 else 0.0
    s.t_detach = (s.cycle + 1) * r.period
    s.t_star, s.u_star = _dive_crossing(s, r)
    s.phase = APPROACH


@njit(cache=True, inline="always")
def _advance_designed(t, s, r, q, dq, Mq, lam, t_seen):
    """Transition at ``τ0ᵏ``; impacts at the first impulse; constrained after
    ``n_consecutive_contact`` steps with one; take-off at ``t_dᵏ``."""
    phase = s.phase
    if phase == FREE and t >= _tau0(s.cycle, r) - _EPS_T:
        _transition(t, s, r, q, dq, Mq)
    elif phase == APPROACH and lam > 0.0:
        s.t_first_impact = t_seen
        s.phase, s.contact_steps = IMPACTS, 1.0
    elif phase == IMPACTS:
        s.contact_steps = s.contact_steps + 1.0 if lam > 0.0 else 0.0
        if s.contact_steps >= r.n_consecutive_contact:
            s.t_constrained = t
            s.phase = CONSTRAINED
    if (s.phase == IMPACTS or s.phase == CONSTRAINED) and t >= s.t_detach - _EPS_T:
        _take_off(s, t)


@njit(cache=True, inline="always")
def _advance_triggered(t, s, r, q, dq, Mq, lam, t_seen):
    """The 2007 logic: transition at the first impulse with ``q2 < trigger_q2``,
    ``d = √(γ2 V/γ1)``; constrained once gap and normal velocity are below 1e-4; take-off
    when the force, once built up, falls below 1e-4 N, or at the period's end."""
    n = q.size
    phase = s.phase
    if phase == FREE and lam > 0.0 and q[1] < r.trigger_q2:
        qd, dqd, ddqd = np.empty(n), np.empty(n), np.empty(n)
        _reference_free(t, s, r, qd, dqd, ddqd)
        V, V1 = lyapunov(Mq, q, dq, qd, dqd, r.gamma1, r.gamma2)
        s.tau0 = s.t_first_impact = t_seen
        s.V_tau0, s.V1_tau0 = V, V1
        s.depth = math.sqrt(r.gamma2 * V / r.gamma1)
        s.q10, s.q2_star = 0.0, q[1]
        # the nominal sliding segment of this period ends at the period's end
        s.t_detach = (t // r.period + 1) * r.period
        s.phase = IMPACTS
    elif phase == IMPACTS and q[0] <= 1e-4 and abs(dq[0]) <= 1e-4:
        s.t_constrained = t
        s.phase, s.contact_steps = CONSTRAINED, 0.0
    elif phase == CONSTRAINED:
        # take-off once the contact force, after it has built up, falls below 1e-4 N
        # (a gap of up to 1e-4 m is accepted as contact: no force may follow at once)
        if lam >= 1e-4:
            s.contact_steps += 1.0
        elif s.contact_steps > 0.0:
            _take_off(s, t)
            return
        if t >= s.t_detach - _EPS_T:   # the nominal path leaves the ground
            _take_off(s, t)


# -- one step -----------------------------------------------------------------------------
@njit(cache=True, inline="always")
def control(t, xb, x, x_true, noisy, lam_raw, force_noise, p):
    """Joint torques at the step start ``t`` for the measured state ``x``; advances the
    phase logic in ``xb`` (in place) and writes this step's log row into it.

    ``lam_raw`` is the last step's impulse over ``h``: the contact switch reads it as it is,
    the force sensor as ``force_scale λ + force_bias + force_noise`` (``force_noise``: this
    step's draw), saturated at ``lam_sat``. With ``noisy``, ``x`` is a noisy measurement of
    ``x_true``: the log and ``V(τ0)`` are those of the true state.
    """
    r = record(p, PARAMS)
    s = record(xb, STATE)
    n = int(r.n)
    # one workspace for the step's vectors and matrices (views: no allocation each)
    w = np.empty(8 * n + 3 * n * n)
    q, dq, gq, qd = w[:n], w[n:2 * n], w[2 * n:3 * n], w[3 * n:4 * n]
    dqd, ddqd, qs, tau = w[4 * n:5 * n], w[5 * n:6 * n], w[6 * n:7 * n], w[7 * n:8 * n]
    mats = w[8 * n:].reshape((3, n, n))
    Mq, Cq, J = mats[0], mats[1], mats[2]
    _task_model(x, r, q, dq, Mq, Cq, gq, J)
    cycle, phase = s.cycle, s.phase
    lam_det, t_seen = _detected(xb, s, r, lam_raw)
    if r.switching == DESIGNED:
        _advance_designed(t, s, r, q, dq, Mq, lam_det, t_seen)
    else:
        _advance_triggered(t, s, r, q, dq, Mq, lam_det, t_seen)
    has_star, lam_d = reference(t, s, r, q, qd, dqd, ddqd, qs)
    slotine_li(Mq, Cq, gq, q, dq, qd, dqd, ddqd, r.gamma1, r.gamma2, r.model_scale,
               has_star, qs, tau)
    lam_hat = min(r.force_scale * lam_raw + r.force_bias + force_noise, r.lam_sat)
    if s.phase == CONSTRAINED:
        tau[0] += -lam_d + r.force_feedback_scale * r.Kf * (lam_hat - lam_d)
    u = np.zeros(n)
    for i in range(n):
        for j in range(n):
            u[i] += J[j, i] * tau[j]
    if noisy:             # log and judge the true state, not the measured one
        _task_model(x_true, r, q, dq, Mq, Cq, gq, J)
    V, V1 = lyapunov(Mq, q, dq, qd, dqd, r.gamma1, r.gamma2)
    if noisy and cycle == s.cycle and phase == FREE and s.phase == APPROACH:
        s.V_tau0, s.V1_tau0 = V, V1
    s.V, s.V1, s.lam_d, s.lam_hat = V, V1, lam_d, lam_hat
    s.qd1 = qd[0]
    s.qd2 = qd[1] if n > 1 else 0.0
    s.t_prev = t
    return u


@njit(cache=True)
def _model_and_reference(t, xb, x, p):
    """The task-space model at ``x`` and the reference of the phase in ``xb`` at ``t``
    (``xb`` unchanged): ``(γ1, γ2, M(q), q, q̇, q_d, q̇_d, q̈_d)`` (a record cannot be
    returned, so the gains are)."""
    r = record(p, PARAMS)
    s = record(xb, STATE)
    n = int(r.n)
    q, dq, gq = np.empty(n), np.empty(n), np.empty(n)
    qd, dqd, ddqd, qs = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    Mq, Cq, J = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    _task_model(x, r, q, dq, Mq, Cq, gq, J)
    reference(t, s, r, q, qd, dqd, ddqd, qs)
    return r.gamma1, r.gamma2, Mq, q, dq, qd, dqd, ddqd


@njit(cache=True)
def lyapunov_at(t, xb, x, p):
    """``(V, V1)`` at ``(t, x)`` with the reference of the phase in ``xb`` (unchanged)."""
    gamma1, gamma2, Mq, q, dq, qd, dqd, _ = _model_and_reference(t, xb, x, p)
    return lyapunov(Mq, q, dq, qd, dqd, gamma1, gamma2)


@njit(cache=True)
def reference_at(t, xb, x, p):
    """``(q_d, q̇_d, q̈_d)`` of the phase in ``xb`` at ``(t, x)`` (``xb`` unchanged)."""
    _, _, _, _, _, qd, dqd, ddqd = _model_and_reference(t, xb, x, p)
    return qd, dqd, ddqd


@njit(cache=True)
def task_rows(x, p):
    """``[q, q']`` in task coordinates for every row of plant states ``x``."""
    r = record(p, PARAMS)
    n = int(r.n)
    out = np.empty((x.shape[0], 2 * n))
    q, dq, gq, xk = np.empty(n), np.empty(n), np.empty(n), np.empty(2 * n)
    Mq, Cq, J = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    for k in range(x.shape[0]):
        for j in range(2 * n):          # element by element: no view made per row
            xk[j] = x[k, j]
        _task_model(xk, r, q, dq, Mq, Cq, gq, J)
        for j in range(n):
            out[k, j], out[k, n + j] = q[j], dq[j]
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def tracking_output(t, xb, y, x, xhat, lam, p):
    """Joint torques at the step start ``t`` (:func:`control` with exact measurements)."""
    lam_raw = lam[0] if lam.size else 0.0
    return control(t, xb, x, x, False, lam_raw, 0.0, p)


@njit(BLOCK_SIGNATURE, cache=True)
def tracking_update(t, xb, y, x, xhat, lam, p):
    """A zero derivative: ``output`` has already moved the state (see the module)."""
    return np.zeros(xb.size)

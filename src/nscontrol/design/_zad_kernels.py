"""Compiled kernels of the ZAD-controlled buck converter: the exact stroboscopic map and its
Jacobian in closed form.

Plant (normalised buck): ``x' = A x + B u`` with ``A = [[0, 1], [-1, -δ]]``, ``B = [0, 1]ᵀ``,
``u ∈ {u_off, u_on}``; a centred pulse ``on (d/2), off (T - d), on (d/2)`` per period. Every
mode is affine with the equilibrium ``(u, 0)``, so one piece is
``x(τ) = x_eq + E(τ)(x - x_eq)`` with ``E(τ) = e^{Aτ}`` in closed form (the 2×2 exponential
by ``A = μI + N``, ``N² = qI``). Mean values over a period need no quadrature:
``∫x dt = A⁻¹(x(T) - x(0) - B ∫u dt)``.

Parameters travel as one float array ``p`` (layout ``P_*`` below) so a kernel signature stays
short and one compilation serves every variant.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Layout of the parameter array: plant damping, controller-model damping, switch levels,
#: period, surface slope, reference, variant (0 PL-ZAD, 1 exact ZAD).
P_DELTA, P_DELTA_MODEL, P_U_OFF, P_U_ON, P_T, P_KS, P_XREF, P_VARIANT = range(8)
N_PARAMS = 8


@njit(cache=True)
def flow_coefficients(delta, t):
    """``e^{At}`` for ``A = [[0, 1], [-1, -delta]]`` as the tuple ``(E00, E01, E10, E11)``
    (closed form, any ``delta``; no allocation in the inner loops)."""
    mu = -0.5 * delta
    q = mu * mu - 1.0                      # N = A - μI satisfies N² = qI (det A = 1)
    qt2 = q * t * t
    if abs(qt2) < 1e-12:                   # critically damped: two-term series (error q²t⁴)
        c = 1.0 + 0.5 * qt2
        s = t * (1.0 + qt2 / 6.0)
    elif q < 0.0:
        w = math.sqrt(-q)
        c = math.cos(w * t)
        s = math.sin(w * t) / w
    else:
        w = math.sqrt(q)
        c = math.cosh(w * t)
        s = math.sinh(w * t) / w
    e = math.exp(mu * t)
    es = e * s
    return e * c - mu * es, es, -es, e * c + mu * es


@njit(cache=True)
def flow_matrix(delta, t):
    """``e^{At}`` as a 2×2 array."""
    e00, e01, e10, e11 = flow_coefficients(delta, t)
    E = np.empty((2, 2))
    E[0, 0], E[0, 1], E[1, 0], E[1, 1] = e00, e01, e10, e11
    return E


@njit(cache=True)
def piece(delta, u, x0, x1, tau):
    """State after ``tau`` in the mode of input ``u`` from ``(x0, x1)``."""
    e00, e01, e10, e11 = flow_coefficients(delta, tau)
    y0 = x0 - u
    return (u + e00 * y0 + e01 * x1, e10 * y0 + e11 * x1)


@njit(cache=True)
def pwm_period(delta, u_off, u_on, T, d, x0, x1):
    """The three states after the pieces of a centred pulse: ``x_a`` (first on), ``x_b``
    (off), ``x_c = P(x)`` (last on), as a (3, 2) array."""
    h = 0.5 * d
    out = np.empty((3, 2))
    a0, a1 = piece(delta, u_on, x0, x1, h)
    b0, b1 = piece(delta, u_off, a0, a1, T - d)
    c0, c1 = piece(delta, u_on, b0, b1, h)
    out[0, 0], out[0, 1] = a0, a1
    out[1, 0], out[1, 1] = b0, b1
    out[2, 0], out[2, 1] = c0, c1
    return out


@njit(cache=True)
def map_duty_derivative(delta, u_off, u_on, T, d, states):
    """``∂P/∂d`` at fixed ``x``: ``½F_on(x_c) + E(d/2)[-F_off(x_b) + E(T-d)·½F_on(x_a)]``."""
    a0, a1 = states[0, 0], states[0, 1]
    b0, b1 = states[1, 0], states[1, 1]
    c0, c1 = states[2, 0], states[2, 1]
    fa0, fa1 = 0.5 * a1, 0.5 * (-a0 - delta * a1 + u_on)
    E2 = flow_matrix(delta, T - d)
    v0 = E2[0, 0] * fa0 + E2[0, 1] * fa1 - b1
    v1 = E2[1, 0] * fa0 + E2[1, 1] * fa1 - (-b0 - delta * b1 + u_off)
    E1 = flow_matrix(delta, 0.5 * d)
    out = np.empty(2)
    out[0] = 0.5 * c1 + E1[0, 0] * v0 + E1[0, 1] * v1
    out[1] = 0.5 * (-c0 - delta * c1 + u_on) + E1[1, 0] * v0 + E1[1, 1] * v1
    return out


@njit(cache=True)
def pl_duty(p, x0, x1):
    """PL-ZAD duty before saturation, ``(2s + Tṡ_off)/(ṡ_off - ṡ_on)``: the one formula of
    the duty law (:func:`pl_duty_raw`, the controller that ``simulate`` runs) and of the
    map's period (:func:`pl_step`)."""
    ks, dm, T = p[P_KS], p[P_DELTA_MODEL], p[P_T]
    s = x0 - p[P_XREF] + ks * x1
    sdot_off = x1 + ks * (-x0 - dm * x1 + p[P_U_OFF])
    return (2.0 * s + T * sdot_off) / (-ks * (p[P_U_ON] - p[P_U_OFF]))   # ṡ_off - ṡ_on


@njit(cache=True)
def pl_duty_raw(p, x0, x1):
    """PL-ZAD duty before saturation (:func:`pl_duty`) and its gradient."""
    ks, dm, T = p[P_KS], p[P_DELTA_MODEL], p[P_T]
    den = -ks * (p[P_U_ON] - p[P_U_OFF])    # ṡ_off - ṡ_on = -k_s Δu
    grad = np.empty(2)
    grad[0] = (2.0 - T * ks) / den          # (2g + T gA)/den with gA = [-k_s, 1 - k_s δ]
    grad[1] = (2.0 * ks + T * (1.0 - ks * dm)) / den
    return pl_duty(p, x0, x1), grad


@njit(cache=True)
def zad_residual(p, d, x0, x1):
    """Exact ZAD residual ``∫s dt`` over the period for duty ``d`` (controller model) and its
    derivative in ``d``."""
    dm, u_off, u_on, T, ks = p[P_DELTA_MODEL], p[P_U_OFF], p[P_U_ON], p[P_T], p[P_KS]
    st = pwm_period(dm, u_off, u_on, T, d, x0, x1)
    y0 = st[2, 0] - x0
    y1 = st[2, 1] - x1 - (u_off * T + (u_on - u_off) * d)
    # ∫x = A⁻¹ y with A⁻¹ = [[-δ, -1], [1, 0]]; ∫s = ∫x1 - x_ref T + k_s ∫x2
    F = (-dm * y0 - y1) + ks * y0 - p[P_XREF] * T
    dP = map_duty_derivative(dm, u_off, u_on, T, d, st)
    dy1 = dP[1] - (u_on - u_off)
    dF = -dm * dP[0] - dy1 + ks * dP[0]
    return F, dF


@njit(cache=True)
def exact_duty(p, x0, x1):
    """Exact-ZAD duty: the root in ``[0, T]`` of :func:`zad_residual` (safeguarded Newton),
    ``0`` or ``T`` when there is none; returns ``(d, inside)``."""
    T = p[P_T]
    f_lo, _ = zad_residual(p, 0.0, x0, x1)
    f_hi, _ = zad_residual(p, T, x0, x1)
    if f_lo >= 0.0 and f_hi >= 0.0:
        return (0.0, False) if f_lo <= f_hi else (T, False)
    if f_lo <= 0.0 and f_hi <= 0.0:
        return (T, False) if f_lo <= f_hi else (0.0, False)
    lo, hi = 0.0, T
    increasing = f_hi > f_lo
    raw, _ = pl_duty_raw(p, x0, x1)
    d = min(max(raw, 0.0), T)
    for _ in range(100):
        F, dF = zad_residual(p, d, x0, x1)
        if (F > 0.0) == increasing:
            hi = d
        else:
            lo = d
        step = F / dF if dF != 0.0 else 0.0
        nxt = d - step
        if not (lo < nxt < hi) or dF == 0.0:
            nxt = 0.5 * (lo + hi)
        if abs(nxt - d) <= 1e-16 * T + 1e-15 * abs(d):
            return nxt, True
        d = nxt
    return d, True


@njit(cache=True)
def duty_and_gradient(p, x0, x1):
    """The saturated duty, whether it is inside ``(0, T)``, and ``∇d`` (zero when saturated)."""
    T = p[P_T]
    grad = np.zeros(2)
    if p[P_VARIANT] == 0.0:
        raw, g = pl_duty_raw(p, x0, x1)
        if 0.0 < raw < T:
            return raw, True, g
        return min(max(raw, 0.0), T), False, grad
    d, inside = exact_duty(p, x0, x1)
    if not inside:
        return d, False, grad
    # implicit function: ∇d = -(∂F/∂x)/(∂F/∂d), ∂F/∂x = g A⁻¹ (E(T) - I) (controller model)
    dm, ks = p[P_DELTA_MODEL], p[P_KS]
    _, dF = zad_residual(p, d, x0, x1)
    E = flow_matrix(dm, T)
    for j in range(2):
        y0 = E[0, j] - (1.0 if j == 0 else 0.0)
        y1 = E[1, j] - (1.0 if j == 1 else 0.0)
        grad[j] = -((-dm * y0 - y1) + ks * y0) / dF
    return d, True, grad


@njit(cache=True)
def pl_step(p, ET, x0, x1):
    """One period of the PL-ZAD loop without allocation (the diagrams' inner loop).

    ``ET = E(T)`` (a tuple, computed once per run); ``E(T - d) = E(T) E(d/2)⁻²`` saves one
    exponential per period (``E(d/2)`` is near the identity, so its inverse loses nothing:
    its condition number is ``e^{δ d/2}``-close to 1)."""
    T, u_off, u_on = p[P_T], p[P_U_OFF], p[P_U_ON]
    d = min(max(pl_duty(p, x0, x1), 0.0), T)
    h0, h1, h2, h3 = flow_coefficients(p[P_DELTA], 0.5 * d)    # both on-pieces last d/2
    g0 = h0 * h0 + h1 * h2                                     # E(d) = E(d/2)²
    g1 = h0 * h1 + h1 * h3
    g2 = h2 * h0 + h3 * h2
    g3 = h2 * h1 + h3 * h3
    det = g0 * g3 - g1 * g2
    i0, i1, i2, i3 = g3 / det, -g1 / det, -g2 / det, g0 / det
    f0 = ET[0] * i0 + ET[1] * i2                               # E(T - d) = E(T) E(d)⁻¹
    f1 = ET[0] * i1 + ET[1] * i3
    f2 = ET[2] * i0 + ET[3] * i2
    f3 = ET[2] * i1 + ET[3] * i3
    y0 = x0 - u_on
    a0 = u_on + h0 * y0 + h1 * x1
    a1 = h2 * y0 + h3 * x1
    y0 = a0 - u_off
    b0 = u_off + f0 * y0 + f1 * a1
    b1 = f2 * y0 + f3 * a1
    y0 = b0 - u_on
    return u_on + h0 * y0 + h1 * b1, h2 * y0 + h3 * b1, d


@njit(cache=True)
def step(p, x0, x1):
    """One period of the closed loop: ``(x0', x1', d)``."""
    if p[P_VARIANT] == 0.0:
        return pl_step(p, flow_coefficients(p[P_DELTA], p[P_T]), x0, x1)
    d, _, _ = duty_and_gradient(p, x0, x1)
    st = pwm_period(p[P_DELTA], p[P_U_OFF], p[P_U_ON], p[P_T], d, x0, x1)
    return st[2, 0], st[2, 1], d


@njit(cache=True)
def jacobian(p, x0, x1):
    """``DP(x) = E(T) + (∂P/∂d) ∇dᵀ`` (``E(T)`` alone in a saturated period)."""
    delta, T = p[P_DELTA], p[P_T]
    d, inside, grad = duty_and_gradient(p, x0, x1)
    J = flow_matrix(delta, T)
    if inside:
        st = pwm_period(delta, p[P_U_OFF], p[P_U_ON], T, d, x0, x1)
        dP = map_duty_derivative(delta, p[P_U_OFF], p[P_U_ON], T, d, st)
        for i in range(2):
            for j in range(2):
                J[i, j] += dP[i] * grad[j]
    return J


@njit(cache=True)
def iterate(p, x0, x1, n_transient, n_record):
    """``n_transient`` periods discarded, then ``n_record`` recorded: states ``x_k`` (rows),
    duties ``d_k`` and the mean of ``x1`` over each recorded period; and the final state."""
    if p[P_VARIANT] == 0.0:
        ET = flow_coefficients(p[P_DELTA], p[P_T])
        for _ in range(n_transient):
            x0, x1, _ = pl_step(p, ET, x0, x1)
    else:
        for _ in range(n_transient):
            x0, x1, _ = step(p, x0, x1)
    X = np.empty((n_record, 2))
    D = np.empty(n_record)
    M = np.empty(n_record)
    T, u_off, du = p[P_T], p[P_U_OFF], p[P_U_ON] - p[P_U_OFF]
    delta = p[P_DELTA]
    for k in range(n_record):
        X[k, 0], X[k, 1] = x0, x1
        y0, y1, d = step(p, x0, x1)
        D[k] = d
        # mean x1 = (A⁻¹ (x' - x - B ∫u))_1 / T = (-δ Δx1 - Δx2 + ∫u)/T
        M[k] = (-delta * (y0 - x0) - (y1 - x1) + u_off * T + du * d) / T
        x0, x1 = y0, y1
    last = np.empty(2)
    last[0], last[1] = x0, x1
    return X, D, M, last


#: The rounding floor of the residual ``P^k(x) - x`` per period, relative to ``1 + |x|``
#: (sum of the components): a period is about 60 operations on numbers of the size of ``x``
#: (three closed-form pieces, the duty), each within one rounding ``u = eps/2``, so the
#: residual of an exact orbit evaluates to at most ``~60 u (1 + |x|)`` per period; twice
#: that, ``64 eps``, is the floor. Measured on the ZAD loops: at most ``5 eps``.
RESIDUAL_FLOOR_EPS = 64.0 * np.finfo(np.float64).eps


@njit(cache=True)
def fixed_point(p, x0, x1, period, tol, max_iter):
    """Newton on ``P^period(x) - x`` with the closed-form Jacobian; returns
    ``(x, iterations, converged)``.

    Converged: the Newton step is below ``tol (1 + |x|)``, or the residual is at its
    rounding floor (``period`` times :data:`RESIDUAL_FLOOR_EPS` ``(1 + |x|)``). Near a flip
    ``DP^period - I`` is nearly singular (the 2T orbit just past it has a multiplier close
    to 1), so a residual of rounding size gives Newton steps of rounding size divided by
    that gap, which no ``tol`` bounds: ``x`` is then as accurate as the map's rounding
    allows, and a further step would only move it by that noise.
    """
    x = np.array([x0, x1])
    for it in range(1, max_iter + 1):
        y0, y1 = x[0], x[1]
        M = np.eye(2)
        for _ in range(period):
            J = jacobian(p, y0, y1)
            M = J @ M
            y0, y1, _ = step(p, y0, y1)
        r0, r1 = y0 - x[0], y1 - x[1]
        scale = 1.0 + abs(x[0]) + abs(x[1])
        if abs(r0) + abs(r1) <= period * RESIDUAL_FLOOR_EPS * scale:
            return x, it, True
        a, b = M[0, 0] - 1.0, M[0, 1]
        c, e = M[1, 0], M[1, 1] - 1.0
        det = a * e - b * c
        if det == 0.0:
            return x, it, False
        dx0 = (e * r0 - b * r1) / det
        dx1 = (-c * r0 + a * r1) / det
        x[0] -= dx0
        x[1] -= dx1
        if abs(dx0) + abs(dx1) <= tol * (1.0 + abs(x[0]) + abs(x[1])):
            return x, it, True
    return x, max_iter, False


@njit(cache=True)
def duties(p, X):
    """The saturated duty of each row of ``X`` (states)."""
    out = np.empty(X.shape[0])
    for k in range(X.shape[0]):
        out[k], _, _ = duty_and_gradient(p, X[k, 0], X[k, 1])
    return out

"""Compiled inner loops of the implicit Euler / θ-method for Lur'e systems.

The kernels advance ``x_{k+1} = Φ x_k + Γ ū_k + G_h w_{k+1}`` where ``w_{k+1}`` solves the
one-step inclusion ``w ∈ -φ(a + D_h w)``, ``a = H Φ x_k + H Γ ū_k + g_{k+1}``, for laws that act
componentwise and a step matrix ``D_h`` that is diagonal or lower triangular after a permutation
of the components (a plant and its observer). Component kinds:

* ``KIND_SOFT`` (relay ``c Sign``, Coulomb): ``z = sign(a) max(|a| - γ c, 0)``;
* ``KIND_CLIP`` (normal cone of ``[lo, hi]``, complementarity when ``[0, inf)``):
  ``z = clip(a, lo, hi)``;
* ``KIND_CURVE`` (monotone set-valued Stribeck ``Sign(z) f(|z|)``, the monotone part of a
  friction law after the loop transformation; ``curve[i] = (T_s, T_c, omega_s, delta, b)``
  with ``f(s) = T_c + (T_s - T_c) exp(-(s/omega_s)^delta) + b s`` nondecreasing): ``z = 0``
  when ``|a| <= d T_s``, else the root of ``s + d f(s) = |a|`` (safeguarded Newton).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._block_kernels import step_blocks

KIND_SOFT = 0
KIND_CLIP = 1
KIND_CURVE = 2
_CURVE_ITER = 200


@njit(cache=True)
def curve_root(target, d, ts, tc, ws, dl, b):
    """The root ``s in (0, target)`` of ``s + d f(s) = target`` (``f`` nondecreasing, so the
    left side increases strictly); Newton steps kept inside a shrinking bracket, else
    bisection, until the bracket is a few ulps wide."""
    lo = 0.0
    hi = target
    s = 0.5 * target
    for _ in range(_CURVE_ITER):
        x = s / ws
        e = np.exp(-x ** dl)
        g = s + d * (tc + (ts - tc) * e + b * s) - target
        if g == 0.0:
            return s
        if g < 0.0:
            lo = s
        else:
            hi = s
        if hi - lo <= 4.0 * np.spacing(hi):
            return 0.5 * (lo + hi)
        slope = 1.0 + d * (b - (ts - tc) / ws * dl * x ** (dl - 1.0) * e) if x > 0.0 else 1.0
        step = s - g / slope
        s = step if (slope > 0.0 and lo < step < hi) else 0.5 * (lo + hi)
    return s


@njit(cache=True)
def _affine_part(Phi, Gam, HPhi, HGam, x, ubar, gnext, q, a):
    n = Phi.shape[0]
    m = HPhi.shape[0]
    nu = Gam.shape[1]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += Phi[i, j] * x[j]
        for j in range(nu):
            s += Gam[i, j] * ubar[j]
        q[i] = s
    for i in range(m):
        s = gnext[i]
        for j in range(n):
            s += HPhi[i, j] * x[j]
        for j in range(nu):
            s += HGam[i, j] * ubar[j]
        a[i] = s


@njit(cache=True)
def triangular_steps(Phi, Gam, Gh, HPhi, HGam, Dh, order, coupled, kind, p1, p2, curve, H,
                     ucol, x0, ubar, gnext, X, Z, Wout):
    """Steps with a step matrix ``D_h`` that is lower triangular in the component order
    ``order`` (diagonal when ``coupled`` is False): closed-form resolvents, one component after
    the other, ``z_i = (1 + d_ii φ_i)⁻¹(a_i + Σ_{j before i} d_ij w_j)``.

    ``ubar[k]``, ``gnext[k]`` are the input mean and the shift used by step ``k``; outputs
    ``X[k]``, ``Z[k]``, ``Wout[k]`` are the state, law argument and multiplier after step
    ``k``. ``Z`` is the resolvent's value (a relay on its kink -- sticking, or sliding on
    ``z_i = 0`` -- has ``z_i == 0.0``), and a relay off its kink has ``w_i = -c_i sign(z_i)``
    exactly. When component ``i`` sits at a kink of its law (stuck, or
    clipped to a bound) and ``z_i = H[i, j] x_j + g_i`` involves one state only
    (``ucol[i] = j >= 0``), ``x_j`` is set to ``(z_i - g_i)/H[i, j]``: the active constraint
    holds exactly on the state instead of up to the round-off of ``Φx + G_h w``.
    """
    n = Phi.shape[0]
    m = Dh.shape[0]
    q = np.empty(n)
    a = np.empty(m)
    w = np.zeros(m)
    stuck = np.zeros(m, np.bool_)
    x = x0.copy()
    for k in range(ubar.shape[0]):
        triangular_step(Phi, Gam, Gh, HPhi, HGam, Dh, order, coupled, kind, p1, p2, curve, H,
                        ucol, x, ubar[k], gnext[k], q, a, w, stuck, Z[k], Wout[k])
        for i in range(n):
            X[k, i] = x[i]


@njit(cache=True)
def triangular_step(Phi, Gam, Gh, HPhi, HGam, Dh, order, coupled, kind, p1, p2, curve, H, ucol,
                    x, ubar, gnext, q, a, w, stuck, z_out, w_out):
    """One step of :func:`triangular_steps` from ``x`` (overwritten with the new state);
    ``q``, ``a``, ``w``, ``stuck`` are work arrays (``w`` zeros before the first step), the
    law argument and multiplier go to ``z_out``, ``w_out``."""
    n = Phi.shape[0]
    m = Dh.shape[0]
    _affine_part(Phi, Gam, HPhi, HGam, x, ubar, gnext, q, a)
    if coupled:
        for i in range(m):
            w[i] = 0.0
    for idx in range(m):
        i = order[idx]
        ai = a[i]
        if coupled:
            for j in range(m):
                if j != i:
                    ai += Dh[i, j] * w[j]
        d = Dh[i, i]
        kink = False
        if kind[i] == KIND_SOFT:
            thr = d * p1[i]
            if ai > thr:          # off the kink: the multiplier sits on its bound exactly
                zi = ai - thr
                wi = -p1[i]
            elif ai < -thr:
                zi = ai + thr
                wi = p1[i]
            else:                 # on the kink: z = 0 (sticking / sliding on z = 0)
                zi = 0.0
                wi = -ai / d
                kink = True
        elif kind[i] == KIND_CURVE:
            ts, tc, ws, dl, b = curve[i, 0], curve[i, 1], curve[i, 2], curve[i, 3], curve[i, 4]
            if abs(ai) <= d * ts:   # stick: z = 0, the multiplier inside [-T_s, T_s]
                zi = 0.0
                wi = -ai / d
                kink = True
            else:                   # slip in the direction of a
                sg = 1.0 if ai > 0.0 else -1.0
                v = curve_root(abs(ai), d, ts, tc, ws, dl, b)
                zi = sg * v
                wi = -sg * (tc + (ts - tc) * np.exp(-(v / ws) ** dl) + b * v)
        else:
            zi = min(max(ai, p1[i]), p2[i])
            if zi == ai:
                wi = 0.0
            else:
                wi = (zi - ai) / d
                kink = True
        w[i] = wi
        z_out[i] = zi
        w_out[i] = wi
        stuck[i] = kink
    for i in range(n):
        s = q[i]
        for j in range(m):
            s += Gh[i, j] * w[j]
        x[i] = s
    for i in range(m):
        if stuck[i] and ucol[i] >= 0:
            x[ucol[i]] = (z_out[i] - gnext[i]) / H[i, ucol[i]]


@njit(cache=True)
def controlled_steps(Phi, Gam, Gh, HPhi, HGam, Dh, order, coupled, kind, p1, p2, curve, H,
                     ucol, Cy, times, x0, gnext, X, Z, Wout, has_obs, obs_fns,
                     obs_params, obs_period, xo, xhat, has_ctrl, ctrl_fns,
                     ctrl_params, ctrl_period, xc, u, prev_y, prev_x, prev_xhat, prev_lam,
                     sched, XO, XC, U):
    """:func:`triangular_step` after each step start's compiled blocks, their input held
    over each step (zero-order hold): at ``times[k]`` the blocks read ``y = Cy x_k``
    (:func:`~nscontrol.simulate._block_kernels.step_blocks`), their states and ``u`` are
    logged in ``XO[k]``, ``XC[k]``, ``U[k]``, then the plant steps with ``ū = u``.

    Returns ``(k, status)``: the steps completed and the blocks' status (0: all done).
    """
    n = Phi.shape[0]
    p = Cy.shape[0]
    y = np.empty(p)
    lam = np.zeros(0)
    m = Dh.shape[0]
    q = np.empty(n)
    a = np.empty(m)
    w = np.zeros(m)
    stuck = np.zeros(m, np.bool_)
    x = x0.copy()
    for k in range(times.size - 1):
        for i in range(p):
            s = 0.0
            for j in range(n):
                s += Cy[i, j] * x[j]
            y[i] = s
        status = step_blocks(times[k], x, y, lam, has_obs, obs_fns, obs_params,
                             obs_period, xo, xhat, has_ctrl, ctrl_fns, ctrl_params,
                             ctrl_period, xc, u, prev_y, prev_x, prev_xhat, prev_lam, sched)
        if status != 0:
            return k, status
        XO[k, :] = xo
        XC[k, :] = xc
        U[k, :] = u
        triangular_step(Phi, Gam, Gh, HPhi, HGam, Dh, order, coupled, kind, p1, p2, curve, H,
                        ucol, x, u, gnext[k], q, a, w, stuck, Z[k], Wout[k])
        for i in range(n):
            X[k, i] = x[i]
    return times.size - 1, 0

"""Compiled Moreau–Jean loop for a Lagrangian system with a compiled model
(:class:`~nscontrol.systems.lagrangian.CompiledModel`: ``M(q)``, a nonlinear force, nonlinear
gaps), optionally closed by compiled blocks (:func:`~nscontrol.simulate._block_kernels.
step_blocks`).

Each step is the Python path's step of :mod:`nscontrol.simulate.moreau_jean` (implicit
linearised forces, ``M`` at ``q_k`` or at the predicted ``q_k + θ h v_k``, the active set
``g + γ h G v <= activation``, one contact in closed form, more by Lemke), operation for
operation except the small matrix products (plain loops here, BLAS there). With blocks, at
every step start they read ``y = C x``, ``λ̂ = P_{k-1} / h`` and their input ``u`` enters
as ``S u``; after a step whose impulse rises on an approaching contact they are reset.

Return codes: 0, the LCP kernel's status (1-3), ``MODEL_ERROR`` (``M(q)`` not positive
definite, a non-finite force or Jacobian: ``info = [t]``), ``SINGULAR`` (``rcond`` in
``info[1]``), ``BLOCKS + status`` (a block's status, :mod:`._block_kernels`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..numerics._lcp_kernels import lemke_kernel
from ._block_kernels import reset_blocks, step_blocks
from ._mj_linearised_kernel import mj_linearised_kernel

MODEL_ERROR = -2
SINGULAR = -3
BLOCKS = 100
_EPS = np.finfo(np.float64).eps


@njit(cache=True)
def _positive_definite(M):
    """Cholesky succeeds (``numpy.linalg.cholesky``'s test)."""
    n = M.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return True


@njit(cache=True)
def _finite(a):
    for x in a.ravel():
        if not np.isfinite(x):
            return False
    return True


@njit(cache=True)
def mj_model_steps(model, params, K, D, f0, S, e, h, theta, gamma, activation, predicted,
                   times, q0, v0, p_prev, fext, has_blocks, Cy, has_obs, obs_fns, obs_reset,
                   obs_params, obs_period, xo, xhat, has_ctrl, ctrl_fns, ctrl_reset,
                   ctrl_params, ctrl_period, xc, u, prev_y, prev_x, prev_xhat, prev_lam,
                   sched, XO, XC, U, q_out, v_out, p_out, info):
    """Steps from ``(q0, v0)`` at ``times`` (step starts); ``model = ((mass,), (force,),
    (force_jacobian,), (gaps,), (gap_jacobian,))`` first-class functions; ``fext`` rows
    ``S u(t_k)`` of an open-loop input (one row: held). Writes ``q_out``, ``v_out``,
    ``p_out`` (and the blocks' logs); ``p_prev`` holds the last impulses on return.
    Returns ``(steps done, code)``."""
    n = q0.size
    m = e.size
    nu = S.shape[1]
    p = Cy.shape[0]
    q = q0.copy()
    v = v0.copy()
    x = np.empty(2 * n)
    y = np.empty(p)
    lam = np.empty(m)
    f_in = np.empty(n)
    minv = np.empty((n, n))
    dv = np.empty(n)
    f = np.empty(n)
    Jq = np.empty((n, n))
    Jv = np.empty((n, n))
    qm = np.empty(n)
    v_free = np.empty(n)
    v_new = np.empty(n)
    un = np.empty(m)
    act = np.empty(m, np.int64)
    MinvGt_buf = np.empty((n, m))
    a = h * theta
    for k in range(times.size):
        t = times[k]
        row = k if k < fext.shape[0] else fext.shape[0] - 1
        for i in range(n):
            f_in[i] = fext[row, i]
        if has_blocks:
            for i in range(n):
                x[i] = q[i]
                x[n + i] = v[i]
            for i in range(p):
                s = 0.0
                for j in range(2 * n):
                    s += Cy[i, j] * x[j]
                y[i] = s
            for j in range(m):
                lam[j] = p_prev[j] / h
            status = step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo,
                                 xhat, has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                                 prev_y, prev_x, prev_xhat, prev_lam, sched)
            if status != 0:
                return k, BLOCKS + status
            XO[k, :] = xo
            XC[k, :] = xc
            U[k, :] = u
            for i in range(n):
                s = 0.0
                for j in range(nu):
                    s += S[i, j] * u[j]
                f_in[i] += s
        # -- the step (moreau_jean._PythonRunner._step) --
        for i in range(n):
            qm[i] = q[i] + a * v[i] if predicted else q[i]
        M = model[0][0](qm, params)
        if not _positive_definite(M):
            info[0] = t
            return k, MODEL_ERROR
        tm = t + a
        for i in range(n):
            f[i] = f0[i]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += K[i, j] * q[j]
            f[i] -= s
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += D[i, j] * v[j]
            f[i] -= s
        fn = model[1][0](tm, q, v, params)
        for i in range(n):
            f[i] += fn[i]
        J = model[2][0](tm, q, v, params)
        if not (_finite(f) and _finite(J)):
            info[0] = t
            return k, MODEL_ERROR
        for i in range(n):
            for j in range(n):
                Jq[i, j] = J[i, j] - K[i, j]
                Jv[i, j] = J[n + i, j] - D[i, j]
        rcond = mj_linearised_kernel(M, Jq, Jv, f, f_in, v, h, theta, minv, dv)
        if not rcond >= n * _EPS:
            info[0] = t
            info[1] = rcond
            return k, SINGULAR
        for i in range(n):
            v_free[i] = v[i] + dv[i]
        G = model[4][0](q, params)
        gq = model[3][0](q, params)
        na = 0
        for j in range(m):
            s = 0.0
            for i in range(n):
                s += G[j, i] * v[i]
            un[j] = s
            if gq[j] + gamma * h * s <= activation:
                act[na] = j
                na += 1
        for i in range(n):
            v_new[i] = v_free[i]
        for j in range(m):
            p_out[k, j] = 0.0
        if na > 0:
            MinvGt = MinvGt_buf[:, :na]
            for i in range(n):
                for c in range(na):
                    s = 0.0
                    for l2 in range(n):
                        s += minv[i, l2] * G[act[c], l2]
                    MinvGt[i, c] = s
            W = np.empty((na, na))
            qa = np.empty(na)
            for r in range(na):
                for c in range(na):
                    s = 0.0
                    for l2 in range(n):
                        s += G[act[r], l2] * MinvGt[l2, c]
                    W[r, c] = s
                s = 0.0
                for l2 in range(n):
                    s += G[act[r], l2] * v_free[l2]
                qa[r] = s + e[act[r]] * un[act[r]]
            z = np.empty(na)
            if na == 1:
                z[0] = max(-qa[0] / W[0, 0], 0.0)
            else:
                w = np.empty(na)
                code, _ = lemke_kernel(W, qa, z, w, 0)
                if code:
                    return k, code
            for i in range(n):
                s = 0.0
                for c in range(na):
                    s += MinvGt[i, c] * z[c]
                v_new[i] = v_free[i] + s
            for c in range(na):
                p_out[k, act[c]] = z[c]
        # -- an impact in this step resets the blocks (closed_loop's jump listener) --
        if has_blocks:
            approaching = False
            for j in range(m):
                if p_out[k, j] > 0.0 and p_prev[j] == 0.0 and un[j] < 0.0:
                    approaching = True
            if approaching:
                x_minus = np.concatenate((q, v))
                x_plus = np.concatenate((q + h * ((1 - theta) * v + theta * v_new), v_new))
                status = reset_blocks(t + h, x_minus, x_plus, p_out[k].copy(), has_obs,
                                      obs_reset, obs_params, xo, has_ctrl, ctrl_reset,
                                      ctrl_params, xc)
                if status != 0:
                    return k, BLOCKS + status
        for i in range(n):    # q + h((1 - θ) v + θ v_new), element by element
            q[i] = q[i] + h * ((1 - theta) * v[i] + theta * v_new[i])
            v[i] = v_new[i]
            q_out[k, i] = q[i]
            v_out[k, i] = v[i]
        for j in range(m):
            p_prev[j] = p_out[k, j]
    return times.size, 0


@njit(cache=True)
def gap_rows(gaps, params, q, m):
    """``g(q_k)`` for every row of ``q`` (``gaps = ((gaps,),)``)."""
    out = np.empty((q.shape[0], m))
    for k in range(q.shape[0]):
        out[k] = gaps[0][0](np.ascontiguousarray(q[k]), params)
    return out


@njit(cache=True)
def kinetic_energy_rows(mass, params, q, v):
    """``½ v_kᵀ M(q_k) v_k`` for every row (``mass = ((mass,),)``)."""
    n = q.shape[1]
    out = np.empty(q.shape[0])
    for k in range(q.shape[0]):
        M = mass[0][0](np.ascontiguousarray(q[k]), params)
        s = 0.0
        for i in range(n):
            r = 0.0
            for j in range(n):
                r += M[i, j] * v[k, j]
            s += v[k, i] * r
        out[k] = 0.5 * s
    return out


@njit(cache=True)
def potential_rows(potential, params, q):
    """``V(q_k)`` for every row (``potential = ((potential,),)``)."""
    out = np.empty(q.shape[0])
    for k in range(q.shape[0]):
        out[k] = potential[0][0](np.ascontiguousarray(q[k]), params)
    return out

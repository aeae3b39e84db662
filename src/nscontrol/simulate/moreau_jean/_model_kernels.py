"""Compiled Moreau–Jean loop for a Lagrangian system with a compiled model
(:class:`~nscontrol.systems.lagrangian.CompiledModel`: ``M(q)``, a nonlinear force, nonlinear
gaps), optionally closed by compiled blocks (:func:`~nscontrol.simulate._block_kernels.
step_blocks`).

Each step evaluates the model's functions and takes the one step of the Python path,
:func:`~nscontrol.simulate.moreau_jean._step_kernels.mj_step` (implicit linearised forces, ``M``
at ``q_k`` or at the predicted ``q_k + θ h v_k``, the active set ``g + γ h G v <=
activation``, one contact in closed form, more by Lemke). With blocks, at every step start
they read ``y = C x``, ``λ̂ = P_{k-1} / h`` and their input ``u`` enters as ``S u``; after a
step whose impulse rises on an approaching contact they are reset.

Return codes: 0, the LCP kernel's status (1-3), ``MODEL_ERROR`` (``M(q)`` not positive
definite, a non-finite force or Jacobian: ``info = [t]``), ``SINGULAR`` (``rcond`` in
``info[1]``), ``BLOCKS + status`` (a block's status, :mod:`._block_kernels`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._block_kernels import reset_blocks, step_blocks
from ._step_kernels import MODEL_ERROR, SINGULAR, mj_step, positive_definite

__all__ = ["BLOCKS", "MODEL_ERROR", "SINGULAR", "mj_model_steps"]

BLOCKS = 100


@njit(cache=True)
def _finite(a):
    for x in a.ravel():
        if not np.isfinite(x):
            return False
    return True


@njit(cache=True, inline="always")
def _model_forces(model, params, K, D, f0, t, q, v, f, Jq, Jv):
    """``f = f0 - K q - D v + force(t, q, v)`` and its Jacobians ``Jq``, ``Jv`` (the model's
    ``force_jacobian`` minus ``K``, ``D``); False when a value is not finite."""
    n = q.shape[0]
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
    fn = model[1][0](t, q, v, params)
    for i in range(n):
        f[i] += fn[i]
    J = model[2][0](t, q, v, params)
    if not (_finite(f) and _finite(J)):
        return False
    for i in range(n):
        for j in range(n):
            Jq[i, j] = J[i, j] - K[i, j]
            Jv[i, j] = J[n + i, j] - D[i, j]
    return True


@njit(cache=True)
def _blocks_input(k, t, q, v, h, p_prev, S, f_in, Cy, has_obs, obs_fns, obs_params,
                  obs_period, xo, xhat, has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                  prev_y, prev_x, prev_xhat, prev_lam, sched, XO, XC, U):
    """Step the blocks at ``t`` (they read ``y = C x`` and ``λ̂ = P_{k-1} / h``), log them
    in row ``k`` and add ``S u`` to ``f_in``; returns the blocks' status."""
    n = q.shape[0]
    x = np.concatenate((q, v))
    y = np.empty(Cy.shape[0])
    for i in range(Cy.shape[0]):
        s = 0.0
        for j in range(2 * n):
            s += Cy[i, j] * x[j]
        y[i] = s
    lam = p_prev / h
    status = step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo, xhat,
                         has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u, prev_y, prev_x,
                         prev_xhat, prev_lam, sched)
    if status != 0:
        return status
    XO[k, :] = xo
    XC[k, :] = xc
    U[k, :] = u
    for i in range(n):
        s = 0.0
        for j in range(S.shape[1]):
            s += S[i, j] * u[j]
        f_in[i] += s
    return 0


@njit(cache=True)
def _approaching(p_out, k, p_prev, un):
    """An impulse rises on an approaching contact in step ``k`` (closed_loop's jump listener
    fires)."""
    for j in range(p_prev.shape[0]):
        if p_out[k, j] > 0.0 and p_prev[j] == 0.0 and un[j] < 0.0:
            return True
    return False


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
    q = q0.copy()
    v = v0.copy()
    f_in = np.empty(n)
    minv = np.empty((n, n))
    f = np.empty(n)
    Jq = np.empty((n, n))
    Jv = np.empty((n, n))
    un = np.empty(m)
    act = np.empty(m, np.int64)
    qm = np.empty(n)
    dv = np.empty(n)
    mgt = np.empty((n, m))
    for k in range(times.size):
        t = times[k]
        row = k if k < fext.shape[0] else fext.shape[0] - 1
        for i in range(n):
            f_in[i] = fext[row, i]
        if has_blocks:
            status = _blocks_input(k, t, q, v, h, p_prev, S, f_in, Cy, has_obs, obs_fns,
                                   obs_params, obs_period, xo, xhat, has_ctrl, ctrl_fns,
                                   ctrl_params, ctrl_period, xc, u, prev_y, prev_x, prev_xhat,
                                   prev_lam, sched, XO, XC, U)
            if status != 0:
                return k, BLOCKS + status
        for i in range(n):
            qm[i] = q[i] + h * theta * v[i] if predicted else q[i]
        M = model[0][0](qm, params)
        info[0] = t
        if not positive_definite(M):
            return k, MODEL_ERROR
        if not _model_forces(model, params, K, D, f0, t + h * theta, q, v, f, Jq, Jv):
            return k, MODEL_ERROR
        code, rcond, _ = mj_step(M, f, Jq, Jv, f_in, model[4][0](q, params),
                                 model[3][0](q, params), q, v, e, h, theta, gamma, activation,
                                 minv, dv, un, act, mgt, p_out, q_out, v_out, k)
        if code:
            info[1] = rcond
            return k, code
        if has_blocks and _approaching(p_out, k, p_prev, un):   # reset the blocks
            status = reset_blocks(t + h, np.concatenate((q, v)),
                                  np.concatenate((q_out[k], v_out[k])), p_out[k].copy(),
                                  has_obs, obs_reset, obs_params, xo, has_ctrl, ctrl_reset,
                                  ctrl_params, xc)
            if status != 0:
                return k, BLOCKS + status
        for i in range(n):
            q[i] = q_out[k, i]
            v[i] = v_out[k, i]
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

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

What the system's structure makes constant is evaluated once per call, at its first step
(``structure = (constant_mass, with_force, affine_gaps)``, from the system): a constant
mass (evaluated and checked positive definite once), the gaps' Jacobian of affine gaps,
and, for a constant mass without a nonlinear force, ``M̂`` itself (inverted once). The
values are those every step would compute again: the run is the same to the last bit.

Return codes: 0, the LCP kernel's status (1-3), ``MODEL_ERROR`` (``M(q)`` not positive
definite, a non-finite force or Jacobian, a model value of the wrong size: ``info = [t]``),
``SINGULAR`` (``rcond`` in ``info[1]``), ``BLOCKS + status`` (a block's status,
:mod:`._block_kernels`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._block_kernels import reset_blocks, step_blocks
from ._step_kernels import MODEL_ERROR, SINGULAR, mj_step, positive_definite, step_workspace

__all__ = ["BLOCKS", "MODEL_ERROR", "SINGULAR", "mj_model_steps"]

BLOCKS = 100


@njit(cache=True)
def _finite(a):
    for x in a.ravel():
        if not np.isfinite(x):
            return False
    return True


@njit(cache=True, inline="always")
def _copy_into(out, value):
    """``out[...] = value`` when the shapes agree (False otherwise: a model function that
    raised returns an empty array, whose error the caller raises once the loop returns)."""
    if value.shape != out.shape:
        return False
    out[:, :] = value
    return True


@njit(cache=True, inline="always")
def _model_forces(model, params, K, D, f0, t, q, v, with_force, f, Jq, Jv):
    """``f = f0 - K q - D v + force(t, q, v)`` and, with a nonlinear force, its Jacobians
    ``Jq``, ``Jv`` (the model's ``force_jacobian`` minus ``K``, ``D``; without one they are
    ``-K``, ``-D``, set once by the caller); False when a value is not finite."""
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
    if not with_force:
        return _finite(f)
    fn = model[1][0](t, q, v, params)
    J = model[2][0](t, q, v, params)
    if fn.size != n or J.shape != (2 * n, n):
        return False
    for i in range(n):
        f[i] += fn[i]
    if not (_finite(f) and _finite(J)):
        return False
    for i in range(n):
        for j in range(n):
            Jq[i, j] = J[i, j] - K[i, j]
            Jv[i, j] = J[n + i, j] - D[i, j]
    return True


@njit(cache=True)
def _evaluate_model(model, params, K, D, f0, t, h, theta, q, v, predicted, structure, first,
                    M, G, f, Jq, Jv, qm, L):
    """The model's terms at the step start ``t``, into ``M`` (at ``q`` or at the predicted
    ``q + θ h v``), ``G``, ``f``, ``Jq`` and ``Jv``; what ``structure`` makes constant only
    at the ``first`` step. False when ``M`` is not positive definite or a value is not
    finite or of the wrong size."""
    constant_mass, with_force, affine_gaps = structure
    if first or not constant_mass:
        for i in range(q.shape[0]):
            qm[i] = q[i] + h * theta * v[i] if predicted else q[i]
        if not (_copy_into(M, model[0][0](qm, params)) and positive_definite(M, L)):
            return False
    if first or not affine_gaps:
        if not _copy_into(G, model[4][0](q, params)):
            return False
    if first and not with_force:       # linear forces: constant Jacobians
        for i in range(q.shape[0]):
            for j in range(q.shape[0]):
                Jq[i, j] = 0.0 - K[i, j]
                Jv[i, j] = 0.0 - D[i, j]
    return _model_forces(model, params, K, D, f0, t + h * theta, q, v, with_force, f, Jq, Jv)


@njit(cache=True)
def _blocks_input(k, t, q, v, h, p_prev, S, f_in, Cy, x, y, lam, has_obs, obs_fns,
                  obs_params, obs_period, xo, xhat, has_ctrl, ctrl_fns, ctrl_params,
                  ctrl_period, xc, u, prev_y, prev_x, prev_xhat, prev_lam, sched, XO, XC, U):
    """Step the blocks at ``t`` (they read ``y = C x`` and ``λ̂ = P_{k-1} / h``, formed in
    the workspaces ``x``, ``y``, ``lam``), log them in row ``k`` and add ``S u`` to
    ``f_in``; returns the blocks' status."""
    n = q.shape[0]
    for i in range(n):
        x[i] = q[i]
        x[n + i] = v[i]
    for i in range(Cy.shape[0]):
        s = 0.0
        for j in range(2 * n):
            s += Cy[i, j] * x[j]
        y[i] = s
    for j in range(p_prev.shape[0]):
        lam[j] = p_prev[j] / h
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
                   structure, times, q0, v0, p_prev, fext, has_blocks, Cy, has_obs, obs_fns,
                   obs_reset, obs_params, obs_period, xo, xhat, has_ctrl, ctrl_fns, ctrl_reset,
                   ctrl_params, ctrl_period, xc, u, prev_y, prev_x, prev_xhat, prev_lam,
                   sched, XO, XC, U, q_out, v_out, p_out, info):
    """Steps from ``(q0, v0)`` at ``times`` (step starts); ``model = ((mass,), (force,),
    (force_jacobian,), (gaps,), (gap_jacobian,))`` first-class functions, ``structure``
    (module docstring); ``fext`` rows ``S u(t_k)`` of an open-loop input (one row: held).
    Writes ``q_out``, ``v_out``, ``p_out`` (and the blocks' logs); ``p_prev`` holds the
    last impulses on return. Returns ``(steps done, code)``."""
    n, m = q0.size, e.size
    q, v = q0.copy(), v0.copy()
    f_in, f, qm, dv, x = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(2 * n)
    M, L, minv = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    Jq, Jv, G, mgt = np.empty((n, n)), np.empty((n, n)), np.empty((m, n)), np.empty((n, m))
    un, lam, act = np.empty(m), np.empty(m), np.empty(m, np.int64)
    y, work = np.empty(Cy.shape[0]), step_workspace(n, m)
    constant_hat = structure[0] and not structure[1]     # M̂ inverted once
    rcond = -1.0
    for k in range(times.size):
        t = times[k]
        row = k if k < fext.shape[0] else fext.shape[0] - 1
        for i in range(n):
            f_in[i] = fext[row, i]
        if has_blocks:
            status = _blocks_input(k, t, q, v, h, p_prev, S, f_in, Cy, x, y, lam, has_obs,
                                   obs_fns, obs_params, obs_period, xo, xhat, has_ctrl,
                                   ctrl_fns, ctrl_params, ctrl_period, xc, u, prev_y, prev_x,
                                   prev_xhat, prev_lam, sched, XO, XC, U)
            if status != 0:
                return k, BLOCKS + status
        info[0] = t
        if not _evaluate_model(model, params, K, D, f0, t, h, theta, q, v, predicted,
                               structure, k == 0, M, G, f, Jq, Jv, qm, L):
            return k, MODEL_ERROR
        code, rcond, _ = mj_step(M, f, Jq, Jv, f_in, G, model[3][0](q, params), q, v, e, h,
                                 theta, gamma, activation, minv,
                                 rcond if constant_hat and k > 0 else -1.0, dv, un, act, mgt,
                                 work, p_out, q_out, v_out, k)
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

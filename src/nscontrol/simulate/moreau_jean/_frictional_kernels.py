"""Compiled Moreau–Jean steps with Coulomb friction: diagonal ``M̂``, constant ``H = [G; T]``.

The contact problem of each step is solved by non-smooth Gauss–Seidel over the active
contacts without assembling the Delassus matrix: the velocity ``v = v_free + M̂⁻¹ Hᵀ r`` is
updated after every local solve, so a contact's local velocity is read from ``H_i v``
(``O(nnz(H_i))``) and its local problem is ``u_i = W_ii r_i + (u_i - W_ii r_i)`` with the
constant diagonal block ``W_ii = H_i M̂⁻¹ H_iᵀ``. The relative natural-map error of the whole
step is checked after every sweep.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...numerics._friction_kernels import contact_error2, local_1d, local_2d, local_3d


@njit(cache=True)
def _row_dot(Hp: np.ndarray, Hi: np.ndarray, Hx: np.ndarray, row: int, x: np.ndarray
             ) -> float:
    s = 0.0
    for p in range(Hp[row], Hp[row + 1]):
        s += Hx[p] * x[Hi[p]]
    return s


@njit(cache=True)
def _step_error(Hp: np.ndarray, Hi: np.ndarray, Hx: np.ndarray, vc: np.ndarray,
                r: np.ndarray, active: np.ndarray, un_k: np.ndarray, e: np.ndarray,
                mu: np.ndarray, dim: int, qnorm2: float) -> float:
    """Relative natural-map error of the step's contact problem (active contacts)."""
    x = np.empty(dim)
    p = np.empty(dim)
    u = np.empty(dim)
    err2, rn2, un2 = 0.0, 0.0, 0.0
    for j in range(active.shape[0]):
        if not active[j]:
            continue
        b = j * dim
        for k in range(dim):
            u[k] = _row_dot(Hp, Hi, Hx, b + k, vc)
        u[0] += e[j] * un_k[j]
        err2 += contact_error2(r, b, u, 0, mu[j], dim, x, p)
        for k in range(dim):
            rn2 += r[b + k] * r[b + k]
            un2 += u[k] * u[k]
    scale = np.sqrt(max(qnorm2, rn2, un2))
    return np.sqrt(err2) / scale if scale > 0.0 else np.sqrt(err2)


@njit(cache=True)
def _free_and_active(q, v, minv, kdiag, ddiag, f0, fe, Hp, Hi, Hx, g0, dim, h, theta, gamma,
                     act, r, vfree, vc, active, un_k, states):
    """``v_free`` (into ``vfree`` and ``vc``), the active set ``g + γ h u <= act`` with
    ``u_k = G v_k`` (into ``un_k``); the warm start ``r`` of inactive contacts zeroed, that of
    active ones added to ``vc``. Returns whether a contact is active."""
    n = q.shape[0]
    for i in range(n):
        f = f0[i] + fe[i] - kdiag[i] * (q[i] + h * theta * v[i]) - ddiag[i] * v[i]
        vfree[i] = v[i] + h * minv[i] * f
        vc[i] = vfree[i]
    any_active = False
    for j in range(active.shape[0]):
        b = j * dim
        gap = g0[j] + _row_dot(Hp, Hi, Hx, b, q)
        un_k[j] = _row_dot(Hp, Hi, Hx, b, v)
        active[j] = gap + gamma * h * un_k[j] <= act
        states[j] = 0
        if not active[j]:
            for c in range(dim):
                r[b + c] = 0.0
        else:
            any_active = True
            for c in range(dim):   # the warm start's contribution to v
                row = b + c
                for p in range(Hp[row], Hp[row + 1]):
                    vc[Hi[p]] += minv[Hi[p]] * Hx[p] * r[row]
    return any_active


@njit(cache=True)
def _sweep(minv, Hp, Hi, Hx, e, mu, blocks, inverses, dim, r, vc, active, un_k, states,
           qloc, rloc):
    """One non-smooth Gauss–Seidel sweep over the active contacts (``r``, ``vc`` updated)."""
    for j in range(active.shape[0]):
        if not active[j]:
            continue
        b = j * dim
        for c in range(dim):
            s = _row_dot(Hp, Hi, Hx, b + c, vc)
            for c2 in range(dim):
                s -= blocks[j, c, c2] * r[b + c2]
            qloc[c] = s
        qloc[0] += e[j] * un_k[j]
        for c in range(dim):   # the local fallback's start
            rloc[c] = r[b + c]
        if dim == 1:
            states[j] = local_1d(blocks[j, 0, 0], qloc[0], rloc)
        elif dim == 2:
            states[j] = local_2d(blocks[j], qloc, mu[j], rloc)
        else:
            states[j] = local_3d(blocks[j], inverses[j], qloc, mu[j], rloc)
        for c in range(dim):
            dr = rloc[c] - r[b + c]
            if dr != 0.0:
                row = b + c
                for p in range(Hp[row], Hp[row + 1]):
                    vc[Hi[p]] += minv[Hi[p]] * Hx[p] * dr
                r[row] = rloc[c]


@njit(cache=True)
def _free_norm2(Hp, Hi, Hx, vfree, e, un_k, active, dim):
    """``‖q‖²`` of the step's problem: the free local velocities of the active contacts."""
    qnorm2 = 0.0
    for j in range(active.shape[0]):
        if active[j]:
            for c in range(dim):
                w = _row_dot(Hp, Hi, Hx, j * dim + c, vfree)
                if c == 0:
                    w += e[j] * un_k[j]
                qnorm2 += w * w
    return qnorm2


@njit(cache=True)
def _add_work(Hp, Hi, Hx, v, vc, r, active, dim, work):
    """The work of the step's impulses, ``r · H (v_k + v_{k+1}) / 2``, normal and tangent."""
    for j in range(active.shape[0]):
        if active[j]:
            for c in range(dim):
                row = j * dim + c
                ubar = 0.5 * (_row_dot(Hp, Hi, Hx, row, v) + _row_dot(Hp, Hi, Hx, row, vc))
                work[0 if c == 0 else 1] += r[row] * ubar


@njit(cache=True)
def frictional_mj_kernel(q: np.ndarray, v: np.ndarray, minv: np.ndarray, kdiag: np.ndarray,
                         ddiag: np.ndarray, f0: np.ndarray, fext: np.ndarray, Hp: np.ndarray,
                         Hi: np.ndarray, Hx: np.ndarray, g0: np.ndarray, e: np.ndarray,
                         mu: np.ndarray, blocks: np.ndarray, inverses: np.ndarray, dim: int,
                         h: float, theta: float, gamma: float, act: float, tol: float,
                         max_sweeps: int, r: np.ndarray, work: np.ndarray,
                         q_out: np.ndarray, v_out: np.ndarray,
                         r_out: np.ndarray, st_out: np.ndarray, work_out: np.ndarray,
                         res_out: np.ndarray, sw_out: np.ndarray) -> tuple[int, int]:
    """Up to ``q_out.shape[0]`` steps from ``(q, v)`` (updated in place), ``r`` the previous
    step's impulses (the warm start, updated in place), ``work`` the cumulative normal and
    friction work (updated in place). Returns ``(done, code)``: code 0, or
    2 when a step's NSGS did not reach ``tol`` (that step not taken)."""
    n = q.shape[0]
    m = mu.shape[0]
    vfree = np.empty(n)
    vc = np.empty(n)
    active = np.zeros(m, np.bool_)
    un_k = np.zeros(m)
    qloc = np.empty(dim)
    rloc = np.empty(dim)
    states = np.zeros(m, np.int64)
    for k in range(q_out.shape[0]):
        fe = fext[min(k, fext.shape[0] - 1)]
        any_active = _free_and_active(q, v, minv, kdiag, ddiag, f0, fe, Hp, Hi, Hx, g0, dim,
                                      h, theta, gamma, act, r, vfree, vc, active, un_k, states)
        sweeps = 0
        err = 0.0
        if any_active:
            qnorm2 = _free_norm2(Hp, Hi, Hx, vfree, e, un_k, active, dim)
            converged = False
            while sweeps < max_sweeps:
                sweeps += 1
                _sweep(minv, Hp, Hi, Hx, e, mu, blocks, inverses, dim, r, vc, active, un_k,
                       states, qloc, rloc)
                err = _step_error(Hp, Hi, Hx, vc, r, active, un_k, e, mu, dim, qnorm2)
                if err <= tol:
                    converged = True
                    break
            if not converged:
                return k, 2
        _add_work(Hp, Hi, Hx, v, vc, r, active, dim, work)
        for i in range(n):
            q[i] = q[i] + h * ((1.0 - theta) * v[i] + theta * vc[i])
            v[i] = vc[i]
            q_out[k, i] = q[i]
            v_out[k, i] = v[i]
        for i in range(m * dim):
            r_out[k, i] = r[i]
        for j in range(m):
            st_out[k, j] = states[j] if r[j * dim] > 0.0 else 0
        work_out[k, 0] = work[0]
        work_out[k, 1] = work[1]
        res_out[k] = err
        sw_out[k] = sweeps
    return q_out.shape[0], 0

"""The one compiled Moreau–Jean step with Coulomb friction: constant ``M̂``, linear forces,
constant ``H = [G; T]``.

Every step of the frictional path is taken here, whatever ``M̂`` (diagonal or not), the step
(the shortened last one has its own :class:`FrictionalStep`) and the projection (the loop
stops after a step that leaves a gap negative, and the stepper projects it).

The contact problem of each step is solved by non-smooth Gauss–Seidel over the active
contacts without assembling the Delassus matrix: the velocity ``v = v_free + M̂⁻¹ Hᵀ r`` is
updated after every local solve (row ``i`` of ``B = H M̂⁻¹`` is the change of ``v`` per unit
of impulse ``r_i``), so a contact's local velocity is read from ``H_i v`` (``O(nnz(H_i))``)
and its local problem is ``u_i = W_ii r_i + (u_i - W_ii r_i)`` with the constant diagonal
block ``W_ii = H_i M̂⁻¹ H_iᵀ``. The relative natural-map error of the whole step is checked
after every sweep. The sweeps start from the previous step's impulses (a warm start) unless
told otherwise; a step whose impulses were found by another solver (the stepper's checked
fallback) is taken with them as given.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...numerics._friction_kernels import contact_error2, local_1d, local_2d, local_3d

#: Codes of :func:`frictional_mj_kernel`: every step taken; a step's sweeps did not reach
#: the tolerance (that step not taken); the last step taken left a gap negative (to project).
DONE, NOT_CONVERGED, PENETRATED = 0, 2, 3


class FrictionalStep(NamedTuple):
    """What is constant over the steps of one length ``h`` (a numba named tuple).

    Sparse matrices are CSR triples ``(indptr, indices, data)``: ``H`` (contact rows:
    normal, then tangents, per contact), ``B = H M̂⁻¹``, ``hMinv = h M̂⁻¹``, the stiffness
    ``K`` and the damping ``D`` (empty rows when absent).
    """

    Hp: np.ndarray
    Hi: np.ndarray
    Hx: np.ndarray
    Bp: np.ndarray
    Bi: np.ndarray
    Bx: np.ndarray
    Mp: np.ndarray
    Mi: np.ndarray
    Mx: np.ndarray
    Kp: np.ndarray
    Ki: np.ndarray
    Kx: np.ndarray
    Dp: np.ndarray
    Di: np.ndarray
    Dx: np.ndarray
    #: constant force ``f0`` (n,), gap offsets ``g0`` (m,), restitutions ``e`` (m,),
    #: friction coefficients ``μ`` (m,)
    f0: np.ndarray
    g0: np.ndarray
    e: np.ndarray
    mu: np.ndarray
    #: ``W_ii`` (m, dim, dim) and the inverses the spatial local solver uses
    blocks: np.ndarray
    inverses: np.ndarray
    dim: int
    h: float
    theta: float
    gamma: float
    #: threshold of the active-set test ``g + γ h u_N <= act``
    act: float


@njit(cache=True)
def _row_dot(Hp: np.ndarray, Hi: np.ndarray, Hx: np.ndarray, row: int, x: np.ndarray
             ) -> float:
    s = 0.0
    for p in range(Hp[row], Hp[row + 1]):
        s += Hx[p] * x[Hi[p]]
    return s


@njit(cache=True)
def _add_row(Bp: np.ndarray, Bi: np.ndarray, Bx: np.ndarray, row: int, dr: float,
             vc: np.ndarray) -> None:
    """``vc += B_rowᵀ dr``: the velocity change of impulse ``dr`` on contact row ``row``."""
    for p in range(Bp[row], Bp[row + 1]):
        vc[Bi[p]] += Bx[p] * dr


# The helpers below take the arrays they read, not the FrictionalStep: a named tuple of
# arrays passed to a compiled call costs a reference count per array and call.
@njit(cache=True)
def _step_error(Hp, Hi, Hx, vc, r, active, un_k, e, mu, dim, qnorm2):
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


@njit(cache=True, inline="always")
def _free_velocity(s, q, v, fe, x, f, vfree):
    """``v_free = v + h M̂⁻¹ f`` with ``f = f0 + fe - K (q + h θ v) - D v``."""
    n = q.shape[0]
    ht = s.h * s.theta
    for i in range(n):
        x[i] = q[i] + ht * v[i]
    Kp, Ki, Kx, Dp, Di, Dx = s.Kp, s.Ki, s.Kx, s.Dp, s.Di, s.Dx
    for i in range(n):
        f[i] = s.f0[i] + fe[i] - _row_dot(Kp, Ki, Kx, i, x) - _row_dot(Dp, Di, Dx, i, v)
    Mp, Mi, Mx = s.Mp, s.Mi, s.Mx
    for i in range(n):
        vfree[i] = v[i] + _row_dot(Mp, Mi, Mx, i, f)


@njit(cache=True, inline="always")
def _free_and_active(s, q, v, fe, r, cold, x, f, vfree, vc, active, un_k):
    """``v_free`` (into ``vfree`` and ``vc``), the active set ``g + γ h u <= act`` with
    ``u_k = G v_k`` (into ``un_k``); the start ``r`` of inactive contacts zeroed (of every
    contact when ``cold``), that of active ones added to ``vc``. Returns whether a contact is
    active."""
    _free_velocity(s, q, v, fe, x, f, vfree)
    for i in range(q.shape[0]):
        vc[i] = vfree[i]
    Hp, Hi, Hx, Bp, Bi, Bx, g0 = s.Hp, s.Hi, s.Hx, s.Bp, s.Bi, s.Bx, s.g0
    dim, lead, act = s.dim, s.gamma * s.h, s.act
    any_active = False
    for j in range(active.shape[0]):
        b = j * dim
        gap = g0[j] + _row_dot(Hp, Hi, Hx, b, q)
        un_k[j] = _row_dot(Hp, Hi, Hx, b, v)
        active[j] = gap + lead * un_k[j] <= act
        if cold or not active[j]:
            for c in range(dim):
                r[b + c] = 0.0
        if active[j]:
            any_active = True
            for c in range(dim):   # the start's contribution to v
                _add_row(Bp, Bi, Bx, b + c, r[b + c], vc)
    return any_active


@njit(cache=True)
def _sweep(Hp, Hi, Hx, Bp, Bi, Bx, e, mu, blocks, inverses, dim, r, vc, active, un_k, states,
           qloc, rloc):
    """One non-smooth Gauss–Seidel sweep over the active contacts (``r``, ``vc`` updated)."""
    for j in range(active.shape[0]):
        if not active[j]:
            continue
        b = j * dim
        for c in range(dim):
            t = _row_dot(Hp, Hi, Hx, b + c, vc)
            for c2 in range(dim):
                t -= blocks[j, c, c2] * r[b + c2]
            qloc[c] = t
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
                _add_row(Bp, Bi, Bx, b + c, dr, vc)
                r[b + c] = rloc[c]


@njit(cache=True)
def _free_local(Hp, Hi, Hx, vfree, e, un_k, active, dim, out):
    """The step problem's free local velocities ``H_A v_free + (e u_N,k, 0)`` into ``out``
    (rows of inactive contacts untouched); returns their squared norm ``‖q‖²``."""
    qnorm2 = 0.0
    for j in range(active.shape[0]):
        if active[j]:
            for c in range(dim):
                w = _row_dot(Hp, Hi, Hx, j * dim + c, vfree)
                if c == 0:
                    w += e[j] * un_k[j]
                out[j * dim + c] = w
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
def _penetrates(Hp, Hi, Hx, g0, dim, q):
    """Whether a gap ``g0 + G q`` is negative."""
    for j in range(g0.shape[0]):
        if g0[j] + _row_dot(Hp, Hi, Hx, j * dim, q) < 0.0:
            return True
    return False


@njit(cache=True)
def step_problem(s, q, v, fe, qfree, active):
    """The contact problem of the step from ``(q, v)`` under the input force ``fe``: the
    active set (into ``active``) and the free local velocities of its contacts (into their
    rows of ``qfree``). For the stepper's cold start and its checked fallback."""
    n, m = q.shape[0], active.shape[0]
    vfree = np.empty(n)
    un_k = np.empty(m)
    r = np.zeros(m * s.dim)
    _free_and_active(s, q, v, fe, r, True, np.empty(n), np.empty(n), vfree, np.empty(n),
                     active, un_k)
    _free_local(s.Hp, s.Hi, s.Hx, vfree, s.e, un_k, active, s.dim, qfree)


@njit(cache=True, inline="always")
def _solve(s, tol, max_sweeps, r, vc, active, un_k, states, qnorm2, qloc, rloc):
    """Sweeps until the step's error reaches ``tol``: ``(sweeps, error, converged)``."""
    Hp, Hi, Hx, Bp, Bi, Bx, e, mu = s.Hp, s.Hi, s.Hx, s.Bp, s.Bi, s.Bx, s.e, s.mu
    blocks, inverses, dim = s.blocks, s.inverses, s.dim
    sweeps, err = 0, 0.0
    while sweeps < max_sweeps:
        sweeps += 1
        _sweep(Hp, Hi, Hx, Bp, Bi, Bx, e, mu, blocks, inverses, dim, r, vc, active, un_k,
               states, qloc, rloc)
        err = _step_error(Hp, Hi, Hx, vc, r, active, un_k, e, mu, dim, qnorm2)
        if err <= tol:
            return sweeps, err, True
    return sweeps, err, False


@njit(cache=True)
def frictional_mj_kernel(s, q, v, fext, r, work, states, warm, given, project, tol,
                         max_sweeps, q_out, v_out, r_out, st_out, work_out, res_out, sw_out):
    """Up to ``q_out.shape[0]`` steps from ``(q, v)`` (updated in place).

    ``s`` is the :class:`FrictionalStep`, ``fext[k]`` the input force of step ``k`` (its last
    row repeated), ``r`` the previous step's impulses (the sweeps' start when ``warm``;
    updated in place), ``work`` the cumulative normal and friction work (updated in place),
    ``states`` the contact states. With ``given`` the first step's impulses are ``r`` and
    its states ``states`` as they are (no sweeps). With ``project`` the loop stops after a
    step that leaves a gap negative. Returns ``(done, code)``: :data:`DONE`,
    :data:`NOT_CONVERGED` (step ``done`` not taken, ``r`` spoiled) or :data:`PENETRATED`
    (step ``done - 1`` penetrates)."""
    n, m, dim, h, theta = q.shape[0], s.mu.shape[0], s.dim, s.h, s.theta
    Hp, Hi, Hx, e, mu, g0 = s.Hp, s.Hi, s.Hx, s.e, s.mu, s.g0
    x, f, vfree, vc = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    active = np.zeros(m, np.bool_)
    un_k = np.zeros(m)
    qfree = np.zeros(m * dim)
    qloc, rloc = np.empty(dim), np.empty(dim)
    for k in range(q_out.shape[0]):
        keep = given and k == 0
        any_active = _free_and_active(s, q, v, fext[min(k, fext.shape[0] - 1)], r,
                                      not (warm or keep), x, f, vfree, vc, active, un_k)
        sweeps, err = 0, 0.0
        if any_active:
            qnorm2 = _free_local(Hp, Hi, Hx, vfree, e, un_k, active, dim, qfree)
            if keep:
                err = _step_error(Hp, Hi, Hx, vc, r, active, un_k, e, mu, dim, qnorm2)
            else:
                sweeps, err, converged = _solve(s, tol, max_sweeps, r, vc, active, un_k,
                                                states, qnorm2, qloc, rloc)
                if not converged:
                    sw_out[k] = sweeps   # counted: the work spent on the step not taken
                    return k, NOT_CONVERGED
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
        if project and _penetrates(Hp, Hi, Hx, g0, dim, q):
            return k + 1, PENETRATED
    return q_out.shape[0], DONE

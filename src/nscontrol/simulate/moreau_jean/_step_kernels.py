"""numba kernels of the Moreau–Jean θ-method for constant-mass linear Lagrangian systems.

One step ``k -> k+1`` (Acary & Brogliato 2008, §10.1), with ``M̂ = M + hθD + h²θ²K``:

    v_free  = v_k + h M̂⁻¹ (f0 + F_k - K q_k - D v_k - hθ K v_k)
    A       = { j : g_j(q_k) + γ h u_j(v_k) <= 0 }                (position prediction)
    0 <= P_A ⟂ W_AA P_A + G_A v_free + e_A u_A(v_k) >= 0,   W = G M̂⁻¹ Gᵀ
    v_{k+1} = v_free + M̂⁻¹ G_Aᵀ P_A,   q_{k+1} = q_k + h((1-θ) v_k + θ v_{k+1})

Three kernels take this step:

* :func:`mj_pairwise_kernel` — diagonal ``M̂`` and contacts touching at most two coordinates
  whose Delassus matrix is tridiagonal (chains, stacks, cradles, the bouncing ball): O(n + m)
  per step, the LCP on the active contacts by the shared O(n) ``tridiagonal_lcp_kernel``.
* :func:`mj_dense_kernel` — any constant SPD ``M`` and affine gaps: ``M̂⁻¹`` and ``W`` are
  precomputed, the LCP on the active block by the shared ``lemke_kernel`` (closed form for a
  single active contact).
* :func:`mj_step` — one step of the general θ-method with linearised forces (module
  docstring of :mod:`nscontrol.simulate.moreau_jean`): ``M``, ``f``, ``∂f/∂q``, ``∂f/∂v``,
  ``G`` and ``g`` evaluated by the caller at the step's start. The one source of the step of
  both the Python path (user callables, one call a step) and the compiled-model loop
  (:func:`~nscontrol.simulate.moreau_jean._model_kernels.mj_model_steps`).

The first two write every step of a chunk into caller-provided arrays and return
``(steps_done, status_code)`` (status as the LCP kernels; 0 = all steps done). The active
sets are those of :func:`active_set` (dense rows) and :func:`pairwise_active_set`, which the
Python runners also call to tell a controller the contacts of a step.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...numerics._lcp_kernels import lemke_kernel, tridiagonal_lcp_kernel
from ._linearised_kernels import free_velocity, iteration_matrix

#: Status of a step stopped by the model (``M(q)`` not positive definite).
MODEL_ERROR = -2
#: Status of a step stopped by a singular iteration matrix ``M̂``.
SINGULAR = -3
_EPS = np.finfo(np.float64).eps


@njit(cache=True)
def pairwise_active_set(q, v, ia, ib, ca, cb, g0, gamma, h, activation, act):
    """Write the contacts with ``g + γ h u <= activation`` into ``act``; return how many
    (contacts touching one or two coordinates: ``g_j = g0_j + ca_j q_a (+ cb_j q_b)``)."""
    na = 0
    for j in range(g0.shape[0]):
        a = ia[j]
        b = ib[j]
        gap = g0[j] + ca[j] * q[a]
        un = ca[j] * v[a]
        if b >= 0:
            gap += cb[j] * q[b]
            un += cb[j] * v[b]
        if gap + gamma * h * un <= activation:
            act[na] = j
            na += 1
    return na


@njit(cache=True)
def _pairwise_lcp(act, na, ia, ib, ca, cb, minv, e, vfree, vold, lower, diag, upper, qlcp):
    """The tridiagonal LCP of the active contacts ``act[:na]``: ``W`` (shared coordinates of
    neighbouring contacts only) and ``q = G_A v_free + e G_A v_k``."""
    for p in range(na):
        j = act[p]
        a = ia[j]
        b = ib[j]
        d = ca[j] * ca[j] * minv[a]
        s = ca[j] * (vfree[a] + e[j] * vold[a])
        if b >= 0:
            d += cb[j] * cb[j] * minv[b]
            s += cb[j] * (vfree[b] + e[j] * vold[b])
        diag[p] = d
        qlcp[p] = s
        if p > 0:
            jp = act[p - 1]
            c = 0.0
            if jp == j - 1:
                # shared coordinates of neighbouring contacts
                if ia[jp] == a:
                    c += ca[jp] * ca[j] * minv[a]
                if ia[jp] == b and b >= 0:
                    c += ca[jp] * cb[j] * minv[b]
                if ib[jp] >= 0 and ib[jp] == a:
                    c += cb[jp] * ca[j] * minv[a]
                if ib[jp] >= 0 and ib[jp] == b and b >= 0:
                    c += cb[jp] * cb[j] * minv[b]
            lower[p - 1] = c
            upper[p - 1] = c


@njit(cache=True)
def mj_pairwise_kernel(q, v, minv, kdiag, ddiag, f0, fext, ia, ib, ca, cb, g0, e,
                       h, theta, gamma, activation, q_out, v_out, p_out):
    """Run ``q_out.shape[0]`` steps in place on ``q, v`` (diagonal ``M̂⁻¹ = minv``).

    ``fext`` has one row per step (or a single row used for all steps).
    """
    n = q.shape[0]
    m = g0.shape[0]
    vfree = np.empty(n)
    vold = np.empty(n)
    act = np.empty(m, dtype=np.int64)
    lower = np.empty(max(m - 1, 0))
    diag = np.empty(m)
    upper = np.empty(max(m - 1, 0))
    qlcp = np.empty(m)
    z = np.empty(m)
    w = np.empty(m)
    nf = fext.shape[0]
    for k in range(q_out.shape[0]):
        row = k if k < nf else nf - 1
        for i in range(n):
            f = f0[i] + fext[row, i] - kdiag[i] * (q[i] + h * theta * v[i]) - ddiag[i] * v[i]
            vold[i] = v[i]
            vfree[i] = v[i] + h * minv[i] * f
        na = pairwise_active_set(q, v, ia, ib, ca, cb, g0, gamma, h, activation, act)
        for j in range(m):
            p_out[k, j] = 0.0
        if na > 0:
            _pairwise_lcp(act, na, ia, ib, ca, cb, minv, e, vfree, vold, lower, diag, upper,
                          qlcp)
            if na == 1:
                z[0] = -qlcp[0] / diag[0] if qlcp[0] < 0.0 else 0.0
                status = 0
            else:
                status, _ = tridiagonal_lcp_kernel(lower[: na - 1], diag[:na], upper[: na - 1],
                                                   qlcp[:na], z[:na], w[:na], 0)
            if status != 0:
                return k, status
            for p in range(na):
                j = act[p]
                pj = z[p]
                p_out[k, j] = pj
                a = ia[j]
                vfree[a] += minv[a] * ca[j] * pj
                b = ib[j]
                if b >= 0:
                    vfree[b] += minv[b] * cb[j] * pj
        _advance(q, v, vold, vfree, h, theta, q_out, v_out, k)
    return q_out.shape[0], 0


@njit(cache=True)
def _advance(q, v, vold, vnew, h, theta, q_out, v_out, k):
    """``q += h((1-θ) v_k + θ v_{k+1})``, ``v = v_{k+1}``, both also written to row ``k``."""
    for i in range(q.shape[0]):
        v[i] = vnew[i]
        q[i] += h * ((1.0 - theta) * vold[i] + theta * vnew[i])
        q_out[k, i] = q[i]
        v_out[k, i] = v[i]


@njit(cache=True, inline="always")
def active_set(G, gq, v, gamma, h, activation, un, act):
    """Write ``u = G v`` into ``un`` and the contacts with ``g + γ h u <= activation`` into
    ``act``; return how many."""
    na = 0
    for j in range(gq.shape[0]):
        s = 0.0
        for i in range(v.shape[0]):
            s += G[j, i] * v[i]
        un[j] = s
        if gq[j] + gamma * h * s <= activation:
            act[na] = j
            na += 1
    return na


@njit(cache=True, inline="always")
def affine_gaps(G, g0, q, out):
    """``g0 + G q`` into ``out`` (each sum from ``g0_j``, in column order)."""
    for j in range(g0.shape[0]):
        s = g0[j]
        for i in range(q.shape[0]):
            s += G[j, i] * q[i]
        out[j] = s
    return out


@njit(cache=True)
def mj_dense_kernel(q, v, minv, K, D, f0, fext, G, g0, e, minv_gt, W,
                    h, theta, gamma, activation, q_out, v_out, p_out):
    """Run ``q_out.shape[0]`` steps in place on ``q, v`` with dense ``M̂⁻¹ = minv``.

    ``minv_gt = M̂⁻¹ Gᵀ`` (n, m) and ``W = G M̂⁻¹ Gᵀ`` (m, m) are precomputed by the caller.
    """
    n = q.shape[0]
    m = g0.shape[0]
    f = np.empty(n)
    vold = np.empty(n)
    vfree = np.empty(n)
    gq = np.empty(m)
    un = np.empty(m)
    act = np.empty(m, dtype=np.int64)
    nf = fext.shape[0]
    for k in range(q_out.shape[0]):
        row = k if k < nf else nf - 1
        for i in range(n):
            s = f0[i] + fext[row, i]
            for j in range(n):
                s -= K[i, j] * (q[j] + h * theta * v[j]) + D[i, j] * v[j]
            f[i] = s
            vold[i] = v[i]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += minv[i, j] * f[j]
            vfree[i] = v[i] + h * s
        na = active_set(G, affine_gaps(G, g0, q, gq), v, gamma, h, activation, un, act)
        for c in range(m):
            p_out[k, c] = 0.0
        if na > 0:
            Wa = np.empty((na, na))
            qa = np.empty(na)
            for p in range(na):
                c = act[p]
                s = e[c] * un[c]
                for i in range(n):
                    s += G[c, i] * vfree[i]
                qa[p] = s
                for r in range(na):
                    Wa[p, r] = W[c, act[r]]
            za = np.empty(na)
            status = _solve_active(Wa, qa, za)
            if status != 0:
                return k, status
            for p in range(na):
                c = act[p]
                p_out[k, c] = za[p]
                for i in range(n):
                    vfree[i] += minv_gt[i, c] * za[p]
        _advance(q, v, vold, vfree, h, theta, q_out, v_out, k)
    return q_out.shape[0], 0


@njit(cache=True, inline="always")
def _solve_active(W, qa, z):
    """The LCP ``0 <= z ⟂ W z + qa >= 0`` of the active contacts: one contact in closed form,
    more by Lemke. Returns Lemke's status (0: solved)."""
    if qa.shape[0] == 1:
        z[0] = -qa[0] / W[0, 0] if qa[0] < 0.0 else 0.0
        return 0
    w = np.empty(qa.shape[0])
    status, _ = lemke_kernel(W, qa, z, w, 0)
    return status


@njit(cache=True)
def positive_definite(M, L):
    """Cholesky succeeds (``numpy.linalg.cholesky``'s test); ``L``: an ``(n, n)``
    workspace."""
    n = M.shape[0]
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
def step_workspace(n, m):
    """The float workspace :func:`mj_step` takes for ``n`` coordinates and ``m`` contacts:
    ``h f̃`` (``n``), then the active contacts' ``W`` (up to ``m²``), ``q`` and ``z`` (``m``
    each)."""
    return np.empty(n + m * m + 2 * m)


@njit(cache=True, inline="always")
def mj_step(M, f, Jq, Jv, f_in, G, gq, q, v, e, h, theta, gamma, activation, minv, rcond,
            dv, un, act, mgt, work, p_out, q_out, v_out, k):
    """One step from ``(q, v)`` of the θ-method with linearised forces; returns
    ``(code, rcond, na)``.

    ``M`` the mass matrix (at ``q_k`` or the predicted configuration), ``f`` the smooth force
    and ``Jq, Jv`` its Jacobians (zeros: explicit forces), ``f_in`` the input's force
    ``S u_k``, ``G``, ``gq`` the gaps' Jacobian and values at ``q_k``. ``rcond``: ``M̂``'s
    when ``minv`` already holds ``M̂⁻¹`` (a constant ``M̂``, inverted once by the caller with
    :func:`~._linearised_kernels.iteration_matrix`), negative to assemble and invert it here.
    Writes the impulses, ``q_{k+1}`` and ``v_{k+1}`` into row ``k`` of ``p_out``, ``q_out``,
    ``v_out``; ``M̂⁻¹`` into ``minv``, ``M̂⁻¹ h f̃`` into ``dv``, ``G v_k`` into ``un``, the
    active contacts into ``act[:na]`` and ``M̂⁻¹ G_Aᵀ`` into ``mgt[:, :na]`` (``mgt`` of shape
    ``(n, m)``); ``work`` is :func:`step_workspace`'s. ``code``: 0, ``SINGULAR``
    (``rcond < n ε``, the rows not written) or the LCP's status.
    """
    n = q.shape[0]
    if rcond < 0.0:
        rcond = iteration_matrix(M, Jq, Jv, h, theta, minv)
    if not rcond >= n * _EPS:   # also catches NaN
        return SINGULAR, rcond, 0
    free_velocity(minv, Jq, f, f_in, v, h, theta, work[:n], dv)
    for i in range(n):
        v_out[k, i] = v[i] + dv[i]          # v_free = v_k + M̂⁻¹ h f̃
    na = active_set(G, gq, v, gamma, h, activation, un, act)
    for j in range(gq.shape[0]):
        p_out[k, j] = 0.0
    if na > 0:
        code = _contact_impulses(G, minv, e, un, act, na, mgt, work[n:], v_out, p_out, k)
        if code:
            return code, rcond, na
    for i in range(n):    # q + h((1 - θ) v + θ v_new), element by element
        q_out[k, i] = q[i] + h * ((1 - theta) * v[i] + theta * v_out[k, i])
    return 0, rcond, na


@njit(cache=True, inline="always")
def _contact_impulses(G, minv, e, un, act, na, MinvGt, work, v_out, p_out, k):
    """Newton's law on the active contacts ``act[:na]``: ``W = G_A M̂⁻¹ G_Aᵀ``,
    ``0 <= P ⟂ W P + G_A v_free + e u_A >= 0``; row ``k`` of ``v_out`` (``v_free`` on entry)
    becomes ``v_free + M̂⁻¹ G_Aᵀ P``, ``P`` goes to ``p_out[k, act]``. ``work`` holds ``W``,
    ``q`` and ``z`` (``na² + 2 na`` floats at least). Returns the LCP's status."""
    n = v_out.shape[1]
    for i in range(n):
        for c in range(na):
            s = 0.0
            for l2 in range(n):
                s += minv[i, l2] * G[act[c], l2]
            MinvGt[i, c] = s
    W = work[:na * na].reshape((na, na))
    qa = work[na * na:na * na + na]
    z = work[na * na + na:na * na + 2 * na]
    for r in range(na):
        for c in range(na):
            s = 0.0
            for l2 in range(n):
                s += G[act[r], l2] * MinvGt[l2, c]
            W[r, c] = s
        s = 0.0
        for l2 in range(n):
            s += G[act[r], l2] * v_out[k, l2]
        qa[r] = s + e[act[r]] * un[act[r]]
    code = _solve_active(W, qa, z)
    if code:
        return code
    for i in range(n):
        s = 0.0
        for c in range(na):
            s += MinvGt[i, c] * z[c]
        v_out[k, i] = v_out[k, i] + s
    for c in range(na):
        p_out[k, act[c]] = z[c]
    return 0

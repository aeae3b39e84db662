"""numba kernels of the Moreau–Jean θ-method for constant-mass linear Lagrangian systems.

One step ``k -> k+1`` (Acary & Brogliato 2008, §10.1), with ``M̂ = M + hθD + h²θ²K``:

    v_free  = v_k + h M̂⁻¹ (f0 + F_k - K q_k - D v_k - hθ K v_k)
    A       = { j : g_j(q_k) + γ h u_j(v_k) <= 0 }                (position prediction)
    0 <= P_A ⟂ W_AA P_A + G_A v_free + e_A u_A(v_k) >= 0,   W = G M̂⁻¹ Gᵀ
    v_{k+1} = v_free + M̂⁻¹ G_Aᵀ P_A,   q_{k+1} = q_k + h((1-θ) v_k + θ v_{k+1})

Two kernels share this step:

* :func:`mj_pairwise_kernel` — diagonal ``M̂`` and contacts touching at most two coordinates
  whose Delassus matrix is tridiagonal (chains, stacks, cradles, the bouncing ball): O(n + m)
  per step, the LCP on the active contacts by the shared O(n) ``tridiagonal_lcp_kernel``.
* :func:`mj_dense_kernel` — any constant SPD ``M`` and affine gaps: ``M̂⁻¹`` and ``W`` are
  precomputed, the LCP on the active block by the shared ``lemke_kernel`` (closed form for a
  single active contact).

Both write every step of a chunk into caller-provided arrays and return
``(steps_done, status_code)`` (status as the LCP kernels; 0 = all steps done).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..numerics._lcp_kernels import lemke_kernel, tridiagonal_lcp_kernel


@njit(cache=True)
def mj_pairwise_kernel(q, v, minv, kdiag, ddiag, f0, fext, ia, ib, ca, cb, g0, e,
                       h, theta, gamma, activation, q_out, v_out, p_out):
    """Run ``q_out.shape[0]`` steps in place on ``q, v`` (diagonal ``M̂⁻¹ = minv``).

    ``fext`` has one row per step (or a single row used for all steps).
    """
    n = q.shape[0]
    m = g0.shape[0]
    steps = q_out.shape[0]
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
    for k in range(steps):
        row = k if k < nf else nf - 1
        for i in range(n):
            f = f0[i] + fext[row, i] - kdiag[i] * (q[i] + h * theta * v[i]) - ddiag[i] * v[i]
            vold[i] = v[i]
            vfree[i] = v[i] + h * minv[i] * f
        na = 0
        for j in range(m):
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
        for j in range(m):
            p_out[k, j] = 0.0
        if na > 0:
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
        for i in range(n):
            v[i] = vfree[i]
            q[i] += h * ((1.0 - theta) * vold[i] + theta * vfree[i])
            q_out[k, i] = q[i]
            v_out[k, i] = v[i]
    return steps, 0


@njit(cache=True)
def mj_dense_kernel(q, v, minv, K, D, f0, fext, G, g0, e, minv_gt, W,
                    h, theta, gamma, activation, q_out, v_out, p_out):
    """Run ``q_out.shape[0]`` steps in place on ``q, v`` with dense ``M̂⁻¹ = minv``.

    ``minv_gt = M̂⁻¹ Gᵀ`` (n, m) and ``W = G M̂⁻¹ Gᵀ`` (m, m) are precomputed by the caller.
    """
    n = q.shape[0]
    m = g0.shape[0]
    steps = q_out.shape[0]
    f = np.empty(n)
    vold = np.empty(n)
    vfree = np.empty(n)
    un = np.empty(m)
    act = np.empty(m, dtype=np.int64)
    nf = fext.shape[0]
    for k in range(steps):
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
        na = 0
        for c in range(m):
            gap = g0[c]
            u = 0.0
            for i in range(n):
                gap += G[c, i] * q[i]
                u += G[c, i] * v[i]
            un[c] = u
            if gap + gamma * h * u <= activation:
                act[na] = c
                na += 1
        for c in range(m):
            p_out[k, c] = 0.0
        if na > 0:
            Wa = np.empty((na, na))
            qa = np.empty(na)
            za = np.empty(na)
            wa = np.empty(na)
            for p in range(na):
                c = act[p]
                s = e[c] * un[c]
                for i in range(n):
                    s += G[c, i] * vfree[i]
                qa[p] = s
                for r in range(na):
                    Wa[p, r] = W[c, act[r]]
            if na == 1:
                za[0] = -qa[0] / Wa[0, 0] if qa[0] < 0.0 else 0.0
                status = 0
            else:
                status, _ = lemke_kernel(Wa, qa, za, wa, 0)
            if status != 0:
                return k, status
            for p in range(na):
                c = act[p]
                p_out[k, c] = za[p]
                for i in range(n):
                    vfree[i] += minv_gt[i, c] * za[p]
        for i in range(n):
            v[i] = vfree[i]
            q[i] += h * ((1.0 - theta) * vold[i] + theta * vfree[i])
            q_out[k, i] = q[i]
            v_out[k, i] = v[i]
    return steps, 0

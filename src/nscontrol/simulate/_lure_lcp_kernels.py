"""Compiled inner loop of the θ-method for Lur'e systems whose step matrix is not diagonal:
one LCP per step through the shared Lemke kernel of :mod:`nscontrol.numerics._lcp_kernels`.
(Kept apart from :mod:`._lure_kernels` so that the closed-form path never loads the LCP code.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..numerics._lcp_kernels import lemke_kernel
from ._lure_kernels import _affine_part


@njit(cache=True)
def lcp_steps(Phi, Gam, Gh, HPhi, HGam, Dh, M, Qa, q0, T, s, x0, ubar, gnext, X, Z, Wout,
              max_iter):
    """Steps with a full step matrix: one LCP ``0 <= ζ ⟂ M ζ + Qa a + q0 >= 0`` per step,
    solved by the shared Lemke kernel, then ``w = T ζ + s``.

    Returns ``(k, status)``: the number of completed steps and the kernel status of the first
    failed step (0 when all succeeded).
    """
    n = Phi.shape[0]
    m = Dh.shape[0]
    nv = M.shape[0]
    qv = np.empty(n)
    a = np.empty(m)
    qlcp = np.empty(nv)
    zeta = np.empty(nv)
    wv = np.empty(nv)
    x = x0.copy()
    for k in range(ubar.shape[0]):
        _affine_part(Phi, Gam, HPhi, HGam, x, ubar[k], gnext[k], qv, a)
        for r in range(nv):
            acc = q0[r]
            for j in range(m):
                acc += Qa[r, j] * a[j]
            qlcp[r] = acc
        status, _ = lemke_kernel(M, qlcp, zeta, wv, max_iter)
        if status != 0:
            return k, status
        for i in range(m):
            acc = s[i]
            for r in range(nv):
                acc += T[i, r] * zeta[r]
            Wout[k, i] = acc
        for i in range(m):
            acc = a[i]
            for j in range(m):
                acc += Dh[i, j] * Wout[k, j]
            Z[k, i] = acc
        for i in range(n):
            acc = qv[i]
            for j in range(m):
                acc += Gh[i, j] * Wout[k, j]
            x[i] = acc
            X[k, i] = acc
    return ubar.shape[0], 0

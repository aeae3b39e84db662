"""Compiled inner loop of the θ-method for Lur'e systems whose step matrix is not diagonal:
one LCP per step and per diagonal block of ``D_h`` through the shared Lemke kernel of
:mod:`nscontrol.numerics._lcp_kernels`, each solution verified by its natural residual.
(Kept apart from :mod:`._lure_kernels` so that the closed-form path never loads the LCP code.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...numerics._lcp_kernels import NUMERICAL_FAILURE, lemke_kernel, verify_dense
from ._lure_kernels import _affine_part


@njit(cache=True)
def lcp_steps(Phi, Gam, Gh, HPhi, HGam, Dh, M3, Qa3, q03, T3, s3, comp, nv, mg, x0, ubar, gnext,
              X, Z, Wout, tol):
    """Steps with a full or block-triangular step matrix.

    Block ``g`` (in dependency order) holds the law components ``comp[g, :mg[g]]`` and the LCP
    ``0 <= ζ ⟂ M ζ + Qa a_g + q0 >= 0`` of size ``nv[g]`` (zero-padded in ``M3[g]``,
    ``Qa3[g]``, ``q03[g]``), with ``a_g = a + D_h w`` restricted to the block (the multipliers
    of the blocks solved before it enter, the others are still zero) and ``w = T ζ + s``.
    Every Lemke solution is accepted only if its natural residual passes the shared test
    of :func:`~nscontrol.numerics._lcp_kernels.certify` (``tol`` plus the round-off bound).

    Returns ``(k, status, residual)``: the number of completed steps, the status of the first
    failed step (0 when all succeeded; ``NUMERICAL_FAILURE`` for a rejected residual) and
    the worst accepted residual (or the rejected one).
    """
    n = Phi.shape[0]
    m = Dh.shape[0]
    nb = nv.shape[0]
    P = M3.shape[1]
    qv = np.empty(n)
    a = np.empty(m)
    w = np.zeros(m)
    ag = np.empty(m)
    qbuf = np.empty(P)
    zbuf = np.zeros(P)
    wbuf = np.empty(P)
    Ms = [np.ascontiguousarray(M3[g, :nv[g], :nv[g]]) for g in range(nb)]
    worst = 0.0
    x = x0.copy()
    for k in range(ubar.shape[0]):
        _affine_part(Phi, Gam, HPhi, HGam, x, ubar[k], gnext[k], qv, a)
        for i in range(m):
            w[i] = 0.0
        for g in range(nb):
            v = nv[g]
            kg = mg[g]
            for li in range(kg):
                i = comp[g, li]
                acc = a[i]
                for j in range(m):
                    acc += Dh[i, j] * w[j]
                ag[li] = acc
            zeta = zbuf[:v]
            if v > 0:
                M = Ms[g]
                qlcp = qbuf[:v]
                wv = wbuf[:v]
                for r in range(v):
                    acc = q03[g, r]
                    for li in range(kg):
                        acc += Qa3[g, r, li] * ag[li]
                    qlcp[r] = acc
                status, _ = lemke_kernel(M, qlcp, zeta, wv, 50 * (v + 1))
                if status != 0:
                    return k, status, np.inf
                res, _, certified = verify_dense(M, qlcp, zeta, wv, tol)
                if not certified:
                    return k, NUMERICAL_FAILURE, res
                worst = max(worst, res)
            for li in range(kg):
                acc = s3[g, li]
                for r in range(v):
                    acc += T3[g, li, r] * zeta[r]
                w[comp[g, li]] = acc
            for li in range(kg):
                i = comp[g, li]
                acc = ag[li]
                for lj in range(kg):
                    acc += Dh[i, comp[g, lj]] * w[comp[g, lj]]
                Z[k, i] = acc
        for i in range(m):
            Wout[k, i] = w[i]
        for i in range(n):
            acc = qv[i]
            for j in range(m):
                acc += Gh[i, j] * w[j]
            x[i] = acc
            X[k, i] = acc
    return ubar.shape[0], 0, worst

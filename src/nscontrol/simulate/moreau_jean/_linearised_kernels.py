"""numba kernel of the matrices of one linearised θ-step of Moreau–Jean's Python path.

The Python path (``M(q)``, nonlinear forces or gaps) assembles, at every step,

    M̂ = M - hθ J_v - h²θ² J_q,   h f̃ = h (f + f_ext + hθ J_q v),

inverts ``M̂`` (LU with partial pivoting), forms ``M̂⁻¹ h f̃`` and measures how singular
``M̂`` is against its terms. One compiled call replaces about fifteen small numpy calls
(each a few µs for the 1–10 coordinates of these models).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _norm1(A):
    n, m = A.shape
    best = 0.0
    for j in range(m):
        s = 0.0
        for i in range(n):
            s += abs(A[i, j])
        best = max(best, s)
    return best


@njit(cache=True)
def mj_linearised_kernel(M, Jq, Jv, f, fext, v, h, theta, minv_out, dv_out):
    """Write ``M̂⁻¹`` into ``minv_out`` and ``M̂⁻¹ h f̃`` into ``dv_out``; return ``rcond``.

    ``rcond = 1 / (scale ‖M̂⁻¹‖₁)`` with ``scale = ‖M‖₁ + hθ‖J_v‖₁ + h²θ²‖J_q‖₁`` (the
    terms of ``M̂``, so that cancellation between them counts); 0 when ``M̂`` is exactly
    singular or its inverse is not finite. Pass zero Jacobians for explicit forces.
    """
    n = M.shape[0]
    a = h * theta
    b = a * a
    Mhat = np.empty((n, n))
    hf = np.empty(n)
    for i in range(n):
        s = f[i] + fext[i]
        for j in range(n):
            Mhat[i, j] = M[i, j] - a * Jv[i, j] - b * Jq[i, j]
            s += a * Jq[i, j] * v[j]
        hf[i] = h * s
    scale = _norm1(M) + a * _norm1(Jv) + b * _norm1(Jq)
    for i in range(n):
        for j in range(n):
            if not np.isfinite(Mhat[i, j]):
                return 0.0
    # LU with partial pivoting; an exactly zero pivot is a singular M̂
    lu = Mhat.copy()
    piv = np.arange(n)
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(lu[i, k]) > abs(lu[p, k]):
                p = i
        if lu[p, k] == 0.0:
            return 0.0
        if p != k:
            for j in range(n):
                lu[k, j], lu[p, j] = lu[p, j], lu[k, j]
            piv[k], piv[p] = piv[p], piv[k]
        for i in range(k + 1, n):
            lu[i, k] /= lu[k, k]
            for j in range(k + 1, n):
                lu[i, j] -= lu[i, k] * lu[k, j]
    for c in range(n):  # column c of M̂⁻¹: solve M̂ x = e_c
        x = np.zeros(n)
        for i in range(n):
            x[i] = 1.0 if piv[i] == c else 0.0
            for j in range(i):
                x[i] -= lu[i, j] * x[j]
        for i in range(n - 1, -1, -1):
            for j in range(i + 1, n):
                x[i] -= lu[i, j] * x[j]
            x[i] /= lu[i, i]
        for i in range(n):
            minv_out[i, c] = x[i]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += minv_out[i, j] * hf[j]
        dv_out[i] = s
    ninv = _norm1(minv_out)
    if not np.isfinite(ninv):
        return 0.0
    return 1.0 / (scale * ninv)

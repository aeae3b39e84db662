"""numba kernels of the matrices of one linearised θ-step of Moreau–Jean.

A step with linearised forces (module docstring of :mod:`nscontrol.simulate.moreau_jean`)
needs

    M̂ = M - hθ J_v - h²θ² J_q,   h f̃ = h (f + f_ext + hθ J_q v),   M̂⁻¹ h f̃:

:func:`iteration_matrix` assembles and inverts ``M̂`` (LU with partial pivoting) and measures
how singular it is against its terms; :func:`free_velocity` forms ``M̂⁻¹ h f̃``. A step whose
``M``, ``J_q`` and ``J_v`` change calls both (:func:`mj_linearised_kernel`); a run whose
``M̂`` is constant (a constant mass, linear forces) inverts it once and calls the second
alone. One compiled call replaces about fifteen small numpy calls (each a few µs for the
1–10 coordinates of these models).
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
def iteration_matrix(M, Jq, Jv, h, theta, minv_out):
    """Write ``M̂⁻¹`` into ``minv_out``; return ``rcond``.

    ``rcond = 1 / (scale ‖M̂⁻¹‖₁)`` with ``scale = ‖M‖₁ + hθ‖J_v‖₁ + h²θ²‖J_q‖₁`` (the
    terms of ``M̂``, so that cancellation between them counts); 0 when ``M̂`` is exactly
    singular or its inverse is not finite. Pass zero Jacobians for explicit forces.
    """
    n = M.shape[0]
    a = h * theta
    b = a * a
    lu = np.empty((n, n))      # M̂, factored in place
    for i in range(n):
        for j in range(n):
            lu[i, j] = M[i, j] - a * Jv[i, j] - b * Jq[i, j]
    scale = _norm1(M) + a * _norm1(Jv) + b * _norm1(Jq)
    for i in range(n):
        for j in range(n):
            if not np.isfinite(lu[i, j]):
                return 0.0
    # LU with partial pivoting; an exactly zero pivot is a singular M̂
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
    for c in range(n):  # column c of M̂⁻¹: solve M̂ x = e_c, x in place in the column
        for i in range(n):
            x = 1.0 if piv[i] == c else 0.0
            for j in range(i):
                x -= lu[i, j] * minv_out[j, c]
            minv_out[i, c] = x
        for i in range(n - 1, -1, -1):
            x = minv_out[i, c]
            for j in range(i + 1, n):
                x -= lu[i, j] * minv_out[j, c]
            minv_out[i, c] = x / lu[i, i]
    ninv = _norm1(minv_out)
    if not np.isfinite(ninv):
        return 0.0
    return 1.0 / (scale * ninv)


@njit(cache=True, inline="always")
def free_velocity(minv, Jq, f, fext, v, h, theta, hf, dv_out):
    """Write ``M̂⁻¹ h f̃`` into ``dv_out`` (``hf``: a workspace of ``n`` that receives
    ``h f̃``)."""
    n = v.shape[0]
    a = h * theta
    for i in range(n):
        s = f[i] + fext[i]
        for j in range(n):
            s += a * Jq[i, j] * v[j]
        hf[i] = h * s
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += minv[i, j] * hf[j]
        dv_out[i] = s


@njit(cache=True)
def mj_linearised_kernel(M, Jq, Jv, f, fext, v, h, theta, minv_out, dv_out):
    """Write ``M̂⁻¹`` into ``minv_out`` and ``M̂⁻¹ h f̃`` into ``dv_out``; return ``rcond``
    (:func:`iteration_matrix`; ``dv_out`` is left as it is when ``rcond`` is 0)."""
    rcond = iteration_matrix(M, Jq, Jv, h, theta, minv_out)
    if rcond > 0.0:
        free_velocity(minv_out, Jq, f, fext, v, h, theta, np.empty(v.shape[0]), dv_out)
    return rcond

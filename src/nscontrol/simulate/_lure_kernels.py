"""Compiled inner loops of the implicit Euler / θ-method for Lur'e systems.

Both kernels advance ``x_{k+1} = Φ x_k + Γ ū_k + G_h w_{k+1}`` where ``w_{k+1}`` solves the
one-step inclusion ``w ∈ -φ(a + D_h w)``, ``a = H Φ x_k + H Γ ū_k + g_{k+1}``, for laws that act
componentwise. Component kinds:

* ``KIND_SOFT`` (relay ``c Sign``, Coulomb): ``z = sign(a) max(|a| - γ c, 0)``;
* ``KIND_CLIP`` (normal cone of ``[lo, hi]``, complementarity when ``[0, inf)``):
  ``z = clip(a, lo, hi)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

KIND_SOFT = 0
KIND_CLIP = 1


@njit(cache=True)
def _affine_part(Phi, Gam, HPhi, HGam, x, ubar, gnext, q, a):
    n = Phi.shape[0]
    m = HPhi.shape[0]
    nu = Gam.shape[1]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += Phi[i, j] * x[j]
        for j in range(nu):
            s += Gam[i, j] * ubar[j]
        q[i] = s
    for i in range(m):
        s = gnext[i]
        for j in range(n):
            s += HPhi[i, j] * x[j]
        for j in range(nu):
            s += HGam[i, j] * ubar[j]
        a[i] = s


@njit(cache=True)
def diagonal_steps(Phi, Gam, Gh, HPhi, HGam, dh, kind, p1, p2, x0, ubar, gnext,
                   X, Z, Wout):
    """Steps with a diagonal step matrix ``D_h = diag(dh)``: closed-form resolvents.

    ``ubar[k]``, ``gnext[k]`` are the input average and the shift used by step ``k``;
    outputs ``X[k]``, ``Z[k]``, ``Wout[k]`` are the state, law argument and multiplier after
    step ``k``.
    """
    n = Phi.shape[0]
    m = dh.shape[0]
    q = np.empty(n)
    a = np.empty(m)
    x = x0.copy()
    for k in range(ubar.shape[0]):
        _affine_part(Phi, Gam, HPhi, HGam, x, ubar[k], gnext[k], q, a)
        for i in range(m):
            ai = a[i]
            if kind[i] == KIND_SOFT:
                thr = dh[i] * p1[i]
                if ai > thr:
                    zi = ai - thr
                elif ai < -thr:
                    zi = ai + thr
                else:
                    zi = 0.0
            else:
                zi = min(max(ai, p1[i]), p2[i])
            Z[k, i] = zi
            Wout[k, i] = (zi - ai) / dh[i]
        for i in range(n):
            s = q[i]
            for j in range(m):
                s += Gh[i, j] * Wout[k, j]
            x[i] = s
            X[k, i] = s

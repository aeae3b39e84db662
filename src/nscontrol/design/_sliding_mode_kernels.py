"""Compiled one-step laws of the sampled sliding-mode blocks and the sampled-data loop.

The blocks of :mod:`nscontrol.design.sliding_mode` call the step functions below (one source
of truth); :func:`run_loop` runs the whole loop of a linear plant with a zero-order hold
(exact propagation matrices computed in Python) for the fast path of ``run_sampled``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Block kinds of :func:`run_loop`.
FIRST_ORDER, SUPER_TWISTING = 0, 1


@njit(cache=True)
def psi(s: float) -> float:
    """``|s|^{1/2} sign(s)``."""
    return math.copysign(math.sqrt(abs(s)), s) if s != 0.0 else 0.0


@njit(cache=True)
def st_resolvent(p: float, a: float, b: float) -> float:
    """``z`` with ``z + a |z|^{1/2} sign(z) + b Sign(z) ∋ p`` (``a, b >= 0``): a quadratic in
    ``r = |z|^{1/2}`` solved without cancellation."""
    c = abs(p) - b
    if c <= 0.0:
        return 0.0
    r = 2.0 * c / (a + math.sqrt(a * a + 4.0 * c))
    return math.copysign(r * r, p)


@njit(cache=True)
def first_order_switching(s: float, cG: float, alpha: float, implicit: bool) -> float:
    """The switching part ``u_s`` of first-order SMC from ``s_k`` (``cG = c Γ``).

    Implicit: ``u_s = -proj_[-α, α](s_k / cG)`` (the new sample ``s_k + cG u_s`` is zero
    whenever the projection is inactive). Explicit: ``-α sign(cG s_k)``.
    """
    if implicit:
        v = s / cG
        return -min(max(v, -alpha), alpha)
    if s == 0.0:
        return 0.0
    return -alpha if s * cG > 0.0 else alpha


@njit(cache=True)
def super_twisting_implicit(p: float, nu: float, cG: float, k1: float, k2: float,
                            h: float) -> tuple[float, float, float]:
    """Implicit super-twisting step: ``(u, nu_next, s_next)`` from the predicted drift ``p``.

    ``s_next + cG k1 ψ(s_next) + cG h k2 Sign(s_next) ∋ p`` (``p = c Φ x_k + cG ν_k``), then
    ``σ = (p - s_next - cG k1 ψ(s_next)) / (cG h k2)``, ``ν_{k+1} = ν_k - h k2 σ``,
    ``u = -k1 ψ(s_next) + ν_{k+1}``.
    """
    s1 = st_resolvent(p, cG * k1, cG * h * k2)
    ps = psi(s1)
    sigma = (p - s1 - cG * k1 * ps) / (cG * h * k2)
    sigma = min(max(sigma, -1.0), 1.0)      # rounding only: the resolvent puts it in [-1, 1]
    nu1 = nu - h * k2 * sigma
    return -k1 * ps + nu1, nu1, s1


@njit(cache=True)
def super_twisting_explicit(s: float, nu: float, k1: float, k2: float,
                            h: float) -> tuple[float, float]:
    """Explicit super-twisting step ``(u, nu_next)``: ``u = -k1 ψ(s_k) + ν_k``,
    ``ν_{k+1} = ν_k - h k2 sign(s_k)``."""
    sg = 0.0 if s == 0.0 else math.copysign(1.0, s)
    return -k1 * psi(s) + nu, nu - h * k2 * sg


@njit(cache=True)
def run_loop(kind: int, implicit: bool, Phi: np.ndarray, Gam: np.ndarray, X0: np.ndarray,
             n: int, c: np.ndarray, cPhi: np.ndarray, cPhiI: np.ndarray, cG: float,
             alpha: float, k1: float, k2: float, h: float, nu0: float, steps: int,
             estimate: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sampled loop ``X_{k+1} = Φ X_k + Γ u_k`` (``X = [x; w]``, plant state first).

    With ``estimate`` the implicit super-twisting law adds the one-step disturbance estimate
    ``d̂_k = d̂_{k-1} + (s_k - s̃_k) / cΓ`` (``s̃_k`` its own prediction of ``s_k``) to its
    prediction. Returns the states ``(steps + 1, N)``, the inputs ``u_k`` and the integral states
    ``ν_k`` (``steps + 1`` entries; the last input repeats the one before).
    """
    N = X0.shape[0]
    X = np.empty((steps + 1, N))
    U = np.zeros(steps + 1)
    NU = np.zeros(steps + 1)
    X[0] = X0
    nu = nu0
    s_pred, dhat = 0.0, 0.0
    for k in range(steps):
        x = X[k]
        s = 0.0
        for i in range(n):
            s += c[i] * x[i]
        NU[k] = nu
        if kind == FIRST_ORDER:
            drift = 0.0
            for i in range(n):
                drift += cPhiI[i] * x[i]
            u = -drift / cG + first_order_switching(s, cG, alpha, implicit)
        elif implicit:
            if estimate and k > 0:
                dhat += (s - s_pred) / cG
            p = cG * (nu + dhat)
            for i in range(n):
                p += cPhi[i] * x[i]
            u, nu, s_pred = super_twisting_implicit(p, nu, cG, k1, k2, h)
        else:
            u, nu = super_twisting_explicit(s, nu, k1, k2, h)
        U[k] = u
        for i in range(N):
            acc = Gam[i] * u
            for j in range(N):
                acc += Phi[i, j] * x[j]
            X[k + 1, i] = acc
    U[steps] = U[steps - 1] if steps > 0 else 0.0
    NU[steps] = nu
    return X, U, NU

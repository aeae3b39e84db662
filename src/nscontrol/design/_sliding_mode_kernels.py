"""Compiled one-step laws of the sampled sliding-mode blocks and their compiled forms.

The scalar laws (:func:`first_order_switching`, :func:`super_twisting_implicit`,
:func:`super_twisting_explicit`, :func:`st_resolvent`) are the one source of the blocks of
:mod:`nscontrol.design.sliding_mode`: their compiled forms (``output``/``update`` of the
:class:`~nscontrol.systems.feedback.CompiledBlock` signature, below) call them, and the
blocks' Python ``output``/``update`` call those compiled forms. The loop that runs a block on
its plant is ``simulate(..., method="sampled_zoh")``.

The parameter arrays (``params`` of the compiled forms) are laid out by the ``FO_*`` and
``ST_*`` indices below; the plant's rows ``c`` and ``c Φ`` (or ``c (Φ - I)``) follow the
scalars, ``n`` entries each.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..systems._feedback_kernels import BLOCK_SIGNATURE

#: ``FirstOrderSMC`` parameters: ``[n, implicit, alpha, cG, c (n), c (Φ - I) (n)]``.
FO_N, FO_IMPLICIT, FO_ALPHA, FO_CG, FO_ROWS = 0, 1, 2, 3, 4
#: ``SuperTwistingController`` parameters:
#: ``[n, implicit, estimate, k1, k2, h, cG, c (n), c Φ (n)]``.
ST_N, ST_IMPLICIT, ST_ESTIMATE, ST_K1, ST_K2, ST_H, ST_CG, ST_ROWS = 0, 1, 2, 3, 4, 5, 6, 7


@njit(cache=True, inline="always")
def psi(s: float) -> float:
    """``|s|^{1/2} sign(s)``."""
    return math.copysign(math.sqrt(abs(s)), s) if s != 0.0 else 0.0


@njit(cache=True, inline="always")
def st_resolvent(p: float, a: float, b: float) -> float:
    """``z`` with ``z + a |z|^{1/2} sign(z) + b Sign(z) ∋ p`` (``a, b >= 0``): a quadratic in
    ``r = |z|^{1/2}`` solved without cancellation."""
    c = abs(p) - b
    if c <= 0.0:
        return 0.0
    r = 2.0 * c / (a + math.sqrt(a * a + 4.0 * c))
    return math.copysign(r * r, p)


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def super_twisting_explicit(s: float, nu: float, k1: float, k2: float,
                            h: float) -> tuple[float, float]:
    """Explicit super-twisting step ``(u, nu_next)``: ``u = -k1 ψ(s_k) + ν_k``,
    ``ν_{k+1} = ν_k - h k2 sign(s_k)``."""
    sg = 0.0 if s == 0.0 else math.copysign(1.0, s)
    return -k1 * psi(s) + nu, nu - h * k2 * sg


@njit(BLOCK_SIGNATURE, cache=True)
def first_order_output(t, xb, y, x, xhat, lam, params):
    """``u_k = u_eq,k + u_s,k`` of ``FirstOrderSMC`` from the plant state ``x``:
    ``u_eq = -(cΓ)^{-1} c (Φ - I) x``, ``u_s`` by :func:`first_order_switching`."""
    n = int(params[FO_N])
    cG = params[FO_CG]
    s = 0.0
    for i in range(n):
        s += params[FO_ROWS + i] * x[i]
    drift = 0.0
    for i in range(n):
        drift += params[FO_ROWS + n + i] * x[i]
    out = np.empty(1)
    out[0] = -drift / cG + first_order_switching(s, cG, params[FO_ALPHA],
                                                 params[FO_IMPLICIT] != 0.0)
    return out


@njit(cache=True, inline="always")
def super_twisting_step(xb, x, params):
    """``(u_k, ν_{k+1}, s̃_{k+1}, d̂_k)`` of ``SuperTwistingController``: its output and the
    entries of its state at the next sample (scalars: the output does not build the state).

    Explicit: ``xb = [ν]`` (``s̃``, ``d̂`` unused, zero). Implicit: ``xb = [ν, s̃, d̂, started]``;
    with the estimate, the one-step disturbance estimate ``d̂_k = d̂_{k-1} + (s_k - s̃_k) / cΓ``
    (``s̃_k`` the law's own prediction of ``s_k``, from the second sample on) enters the
    prediction ``p = c Φ x_k + cΓ (ν_k + d̂_k)``.
    """
    n = int(params[ST_N])
    cG, k1, k2, h = params[ST_CG], params[ST_K1], params[ST_K2], params[ST_H]
    s = 0.0
    for i in range(n):
        s += params[ST_ROWS + i] * x[i]
    nu = xb[0]
    if params[ST_IMPLICIT] != 0.0:
        s_pred, dhat = xb[1], xb[2]
        if params[ST_ESTIMATE] != 0.0 and xb[3] > 0.0:
            dhat += (s - s_pred) / cG
        p = cG * (nu + dhat)
        for i in range(n):
            p += params[ST_ROWS + n + i] * x[i]
        u, nu1, s1 = super_twisting_implicit(p, nu, cG, k1, k2, h)
        return u, nu1, s1, dhat
    u, nu1 = super_twisting_explicit(s, nu, k1, k2, h)
    return u, nu1, 0.0, 0.0


@njit(BLOCK_SIGNATURE, cache=True)
def super_twisting_output(t, xb, y, x, xhat, lam, params):
    """The output ``[u_k]`` of ``SuperTwistingController`` (:func:`super_twisting_step`)."""
    out = np.empty(1)
    out[0] = super_twisting_step(xb, x, params)[0]
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def super_twisting_update(t, xb, y, x, xhat, lam, params):
    """The state of ``SuperTwistingController`` at the next sample
    (:func:`super_twisting_step`): ``[ν]`` (explicit) or ``[ν, s̃, d̂, 1]`` (implicit)."""
    _, nu1, s1, dhat = super_twisting_step(xb, x, params)
    if params[ST_IMPLICIT] != 0.0:
        nxt = np.empty(4)
        nxt[0], nxt[1], nxt[2], nxt[3] = nu1, s1, dhat, 1.0
        return nxt
    nxt = np.empty(1)
    nxt[0] = nu1
    return nxt

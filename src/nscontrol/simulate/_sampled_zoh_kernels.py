"""Compiled ticks of the sampled-data loop (method ``"sampled_zoh"``,
:mod:`nscontrol.simulate.sampled_zoh`).

:func:`tick` is the one step both paths take after the blocks have run at ``t_n``: keep the
sample (one in ``every``), propagate ``X_{n+1} = Φ X_n + Γ u_n`` (the exact zero-order-hold
step of the plant and of its disturbance generator), count the tick. :func:`run_chunk` runs
ticks ``k0 .. k1 - 1`` with the blocks in their compiled forms (stepped by the shared
:func:`~nscontrol.simulate._block_kernels.step_blocks`); the Python path calls :func:`tick`
after the Python block runner. The tick instants are ``t0 + n T`` from the integer count
``n``, never accumulated.

``count = [ticks done, rows kept]`` is written as the loop goes, so an exception (a failing
block, ``KeyboardInterrupt`` between chunks) finds the rows already computed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._block_kernels import step_blocks


@njit(cache=True)
def keep(k, every, force, t, X, u, xc, out_t, out_x, out_u, out_xc, count):
    """Keep the sample of tick ``k`` when ``k`` is a multiple of ``every`` (or ``force``):
    the time, the plant part of ``X``, the held input ``u`` and the controller state ``xc``
    at the tick (before its update)."""
    if not force and k % every != 0:
        return
    r = count[1]
    out_t[r] = t
    for i in range(out_x.shape[1]):
        out_x[r, i] = X[i]
    for i in range(u.size):
        out_u[r, i] = u[i]
    for i in range(xc.size):
        out_xc[r, i] = xc[i]
    count[1] = r + 1


@njit(cache=True)
def zoh_step(Phi, Gam, X, u, Xn):
    """``Xn = Γ u + Φ X``, summed in that order (``Γ`` of shape ``(N, m)``)."""
    N = X.shape[0]
    for i in range(N):
        acc = Gam[i, 0] * u[0] if u.size else 0.0
        for j in range(1, u.size):
            acc += Gam[i, j] * u[j]
        for j in range(N):
            acc += Phi[i, j] * X[j]
        Xn[i] = acc


@njit(cache=True)
def tick(k, t, every, Phi, Gam, X, Xn, u, xc, out_t, out_x, out_u, out_xc, count):
    """After the blocks ran at tick ``k`` (time ``t``): keep the sample, step ``X`` over one
    period with ``u`` held, count the tick."""
    keep(k, every, False, t, X, u, xc, out_t, out_x, out_u, out_xc, count)
    zoh_step(Phi, Gam, X, u, Xn)
    X[:] = Xn
    count[0] = k + 1


@njit(cache=True)
def run_chunk(k0, k1, t0, T, every, Phi, Gam, X, Xn, Cy, lam,
              has_obs, obs_fns, obs_params, obs_period, xo, xhat,
              has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
              prev_y, prev_x, prev_xhat, prev_lam, sched,
              out_t, out_x, out_u, out_xc, count):
    """Ticks ``k0 .. k1 - 1`` with compiled blocks; returns 0 or the blocks' status (the
    failing tick is ``count[0]``)."""
    n, p = Cy.shape[1], Cy.shape[0]
    x = np.empty(n)
    y = np.empty(p)
    xc_k = np.empty(xc.size)
    for k in range(k0, k1):
        t = t0 + k * T
        for i in range(n):
            x[i] = X[i]
        for i in range(p):
            acc = 0.0
            for j in range(n):
                acc += Cy[i, j] * x[j]
            y[i] = acc
        xc_k[:] = xc
        status = step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo,
                             xhat, has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                             prev_y, prev_x, prev_xhat, prev_lam, sched)
        if status != 0:
            return status
        tick(k, t, every, Phi, Gam, X, Xn, u, xc_k, out_t, out_x, out_u, out_xc, count)
    return 0

"""Compiled ticks of the sampled-data loop (method ``"sampled_zoh"``,
:mod:`nscontrol.simulate.sampled_zoh`).

:func:`tick` is the one step both paths take after the blocks have run at ``t_n``: keep the
sample (one in ``every``), propagate ``X_{n+1} = Φ X_n + Γ u_n`` (the exact zero-order-hold
step of the plant and of its disturbance generator), count the tick. :func:`run_chunk` runs
ticks ``k0 .. k1 - 1`` with the blocks in their compiled forms (stepped by the shared
:func:`~nscontrol.simulate._block_kernels.step_blocks`); the Python path calls :func:`tick`
after the Python block runner. The tick instants are ``t0 + n T`` from the integer count
``n``, never accumulated. A kept sample holds the time, the plant state, the sliding
variable ``s = c x`` (computed here, not afterwards in Python), the held input and the
controller's state at the tick.

The blocks' compiled functions reach :func:`run_chunk` as the addresses of their C wrappers
(an ``int64`` array, :func:`block_functions` makes them first-class functions again inside the
kernel): a tuple of first-class functions passed as an argument is unboxed by the interpreter
at every call (about 50 µs, a quarter of the fixed cost of a short run), an array of integers
is not. The functions are the same ones, called the same way (through their C wrappers, whose
errors :func:`~nscontrol.systems._feedback_kernels.calling_blocks` raises after the call).

``count = [ticks done, rows kept]`` is written as the loop goes, so an exception (a failing
block, ``KeyboardInterrupt`` between chunks) finds the rows already computed.

The per-tick kernels on arrays alone (:func:`keep`, :func:`zoh_step`, :func:`tick`) are
compiled without numba's reference counting (``_nrt=False``: they allocate nothing). Inlined
into the loop with it, each of their array arguments cost an ``NRT_incref`` and an
``NRT_decref`` per tick, which LLVM's reference-count pruning does not remove across their
branches: 20 calls, about 0.1 µs of a tick, for :func:`keep` alone.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.extending import intrinsic

from ...systems._feedback_kernels import BLOCK_SIGNATURE
from .._block_kernels import step_blocks

#: The numba type of a compiled block's ``output`` or ``update`` as the block stepper takes
#: it (the type :func:`~nscontrol.systems._feedback_kernels.compiled_entries` gives them).
with warnings.catch_warnings():   # numba: first-class functions "experimental"
    warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
    _BLOCK_FUNCTION = types.FunctionType(BLOCK_SIGNATURE)


@intrinsic
def _block_functions(typingctx, addresses, first):
    """``(output, update)``: the first-class functions whose C wrappers are at
    ``addresses[first]`` and ``addresses[first + 1]`` (``int64``), of the type the block
    stepper takes. Compiled code only."""
    if not (isinstance(addresses, types.Array) and addresses.dtype == types.int64
            and addresses.layout == "C" and isinstance(first, types.Integer)):
        return None
    pair = types.UniTuple(_BLOCK_FUNCTION, 2)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        start = context.cast(builder, args[1], signature.args[1], types.intp)
        null = context.get_constant_null(types.voidptr)
        items = []
        for i in range(2):
            at = builder.add(start, context.get_constant(types.intp, i))
            address = builder.load(builder.gep(ary.data, [at]))
            fn = cgutils.create_struct_proxy(_BLOCK_FUNCTION)(context, builder)
            fn.c_addr = builder.inttoptr(address, context.get_value_type(types.voidptr))
            fn.py_addr = null
            fn.jit_addr = null       # null: the call goes through the C wrapper (c_addr)
            items.append(fn._getvalue())
        return context.make_tuple(builder, pair, items)
    return pair(addresses, first), codegen


#: numba's option that compiles a kernel without reference counting (see the module docstring;
#: a private option of ``njit``, which its type stubs do not list).
NO_REFCOUNT: dict[str, Any] = {"_nrt": False}

#: ``block_functions(addresses, first)`` as kernels call it (numba passes the typing context).
block_functions: Any = _block_functions


@njit(cache=True, **NO_REFCOUNT)
def keep(k, every, force, t, X, c, u, xc, out_t, out_x, out_s, out_u, out_xc, count):
    """Keep the sample of tick ``k`` when ``k`` is a multiple of ``every`` (or ``force``):
    the time, the plant part of ``X``, its sliding variable ``c x``, the held input ``u`` and
    the controller state ``xc`` at the tick (before its update)."""
    if not force and k % every != 0:
        return
    r = count[1]
    out_t[r] = t
    s = 0.0
    for i in range(out_x.shape[1]):
        out_x[r, i] = X[i]
        s += c[i] * X[i]
    out_s[r] = s
    for i in range(u.size):
        out_u[r, i] = u[i]
    for i in range(xc.size):
        out_xc[r, i] = xc[i]
    count[1] = r + 1


@njit(cache=True, **NO_REFCOUNT)
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


@njit(cache=True, **NO_REFCOUNT)
def tick(k, t, every, Phi, Gam, X, Xn, c, u, xc, out_t, out_x, out_s, out_u, out_xc,
         count):
    """After the blocks ran at tick ``k`` (time ``t``): keep the sample, step ``X`` over one
    period with ``u`` held, count the tick."""
    keep(k, every, False, t, X, c, u, xc, out_t, out_x, out_s, out_u, out_xc, count)
    zoh_step(Phi, Gam, X, u, Xn)
    for i in range(X.size):
        X[i] = Xn[i]
    count[0] = k + 1


@njit(cache=True)
def run_chunk(k0, k1, last, t0, T, every, Phi, Gam, X, Xn, c, Cy, lam, addresses,
              has_obs, obs_params, obs_period, xo, xhat,
              has_ctrl, ctrl_params, ctrl_period, xc, u,
              prev_y, prev_x, prev_xhat, prev_lam, sched,
              out_t, out_x, out_s, out_u, out_xc, count):
    """Ticks ``k0 .. k1 - 1`` with compiled blocks (``addresses``: the C wrappers of the
    observer's and the controller's ``output`` and ``update``, :func:`block_functions`),
    then, if ``last``, the sample at tick ``k1`` (the input held before it); returns 0 or
    the blocks' status (the failing tick is ``count[0]``)."""
    obs_fns = block_functions(addresses, 0)
    ctrl_fns = block_functions(addresses, 2)
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
        for i in range(xc.size):
            xc_k[i] = xc[i]
        status = step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo,
                             xhat, has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                             prev_y, prev_x, prev_xhat, prev_lam, sched)
        if status != 0:
            return status
        tick(k, t, every, Phi, Gam, X, Xn, c, u, xc_k, out_t, out_x, out_s, out_u, out_xc,
             count)
    if last:
        keep(k1, every, True, t0 + k1 * T, X, c, u, xc, out_t, out_x, out_s, out_u, out_xc,
             count)
    return 0

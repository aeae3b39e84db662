"""Compiled forms of the ready-made blocks of :mod:`nscontrol.systems.feedback`.

Every function has the signature of :class:`~nscontrol.systems.feedback.CompiledBlock`:
``output/update(t, xb, y, x, xhat, lam, params)`` and ``reset(t, xb, x_minus, x_plus,
impulse, params)``. The parameter arrays start with the dimensions (as floats), then the
matrices row by row.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

_VEC = types.float64[::1]
#: The signature of a compiled block's ``output`` and ``update``
#: ``(t, xb, y, x, xhat, lam, params) -> array``.
BLOCK_SIGNATURE = _VEC(types.float64, _VEC, _VEC, _VEC, _VEC, _VEC, _VEC)
#: The signature of a compiled block's ``reset``
#: ``(t, xb, x_minus, x_plus, impulse, params) -> array``.
RESET_SIGNATURE = _VEC(types.float64, _VEC, _VEC, _VEC, _VEC, _VEC)


@intrinsic
def _record(typingctx: Any, arr: Any, dtype: Any) -> Any:
    """The record of type ``dtype`` (a NumPy structured dtype of ``float64`` fields) stored
    at the start of the contiguous ``float64`` array ``arr``, read and written by field name
    (a view: writes go to ``arr``). Compiled code only.

    A kernel's parameters (or the head of its state) are declared once as such a dtype;
    Python fills a one-element array of it by name and passes its flat ``float64`` view (the
    compiled loops' signatures take ``float64[::1]``); the kernel reads ``record(p,
    PARAMS).gamma1``. This is ``arr.view(dtype)[0]`` without that expression's cost in
    numba (a new array and its checks, about 0.1 µs a call): the record is the array's data
    pointer. ``arr`` must hold at least the record's bytes (a longer array is fine).
    """
    if not (isinstance(arr, types.Array) and arr.dtype == types.float64 and arr.layout == "C"
            and isinstance(dtype, types.DType) and isinstance(dtype.dtype, types.Record)):
        return None
    rec = dtype.dtype

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.bitcast(ary.data, context.get_value_type(rec))
    return rec(arr, dtype), codegen


#: ``record(arr, dtype)`` as kernels call it (numba passes the typing context itself).
record: Any = _record


@njit(RESET_SIGNATURE, cache=True)
def keep_state(t, xb, x_minus, x_plus, impulse, params):
    """Reset that leaves the block's state unchanged."""
    return xb.copy()


@njit(BLOCK_SIGNATURE, cache=True)
def static_update(t, xb, y, x, xhat, lam, params):
    """Update of a block without state dynamics: the state unchanged."""
    return xb.copy()


@njit(BLOCK_SIGNATURE, cache=True)
def empty_output(t, xb, y, x, xhat, lam, params):
    """Output of an absent block: nothing."""
    return np.zeros(0)


@njit(cache=True)
def _matvec(params, offset, rows, cols, v, out):
    """``out += M v`` with ``M`` stored row by row in ``params[offset:]``."""
    for i in range(rows):
        s = out[i]
        for j in range(cols):
            s += params[offset + i * cols + j] * v[j]
        out[i] = s
    return offset + rows * cols


@njit(BLOCK_SIGNATURE, cache=True)
def affine_output(t, xb, y, x, xhat, lam, params):
    """``u = K v + k`` with ``v = x`` or ``x̂``: ``params = [m, n, on_estimate, K, k]``."""
    m, n = int(params[0]), int(params[1])
    v = xhat if params[2] != 0.0 else x
    out = np.zeros(m)
    end = _matvec(params, 3, m, n, v, out)
    for i in range(m):
        out[i] += params[end + i]
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def linear_output(t, xb, y, x, xhat, lam, params):
    """``C xb + D y``: ``params = [r, p, m, A, B, C, D]``."""
    r, p, m = int(params[0]), int(params[1]), int(params[2])
    out = np.zeros(m)
    off = 3 + r * r + r * p
    off = _matvec(params, off, m, r, xb, out)
    _matvec(params, off, m, p, y, out)
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def linear_update(t, xb, y, x, xhat, lam, params):
    """``A xb + B y``: ``params = [r, p, m, A, B, C, D]``."""
    r, p = int(params[0]), int(params[1])
    out = np.zeros(r)
    off = _matvec(params, 3, r, r, xb, out)
    _matvec(params, off, r, p, y, out)
    return out

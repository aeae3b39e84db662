"""Compiled forms of the ready-made blocks of :mod:`nscontrol.systems.feedback`.

Every function has the signature of :class:`~nscontrol.systems.feedback.CompiledBlock`:
``output/update(t, xb, y, x, xhat, lam, params)`` and ``reset(t, xb, x_minus, x_plus,
impulse, params)``. The parameter arrays start with the dimensions (as floats), then the
matrices row by row.
"""

from __future__ import annotations

import sys
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from numba import njit, typeof, types
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.core.types import CompileResultWAP
from numba.extending import intrinsic, typeof_impl

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


class CompiledEntries(tuple):
    """Blocks' compiled functions as the compiled loops take them (a tuple of first-class
    functions), with their numba type found once: see :func:`compiled_entries`."""

    numba_type: Any


@typeof_impl.register(CompiledEntries)
def _typeof_entries(val: CompiledEntries, c: Any) -> Any:
    return val.numba_type


_ENTRIES: dict[tuple[Any, ...], CompiledEntries] = {}


def compiled_entries(*fns: Any) -> CompiledEntries:
    """The compiled entries of numba dispatchers of one declared signature each (the
    blocks' ``output``, ``update``, ``reset``), as the argument of a compiled loop. A tuple
    of dispatchers among ``fns`` becomes a nested tuple of entries (a compiled model's
    ``((mass,), (force,), ...)``).

    Passed as they are, a tuple of dispatchers is typed afresh at every call of the loop
    (numba asks each dispatcher for its compile result and inspects its Python signature,
    ~0.1 ms a function) and unboxed the same way. Here each dispatcher's compile result
    becomes a :class:`numba.core.types.CompileResultWAP` (the address of its C wrapper,
    which runs the same compiled code) and the tuple's type is found once: the loop's
    argument has the very type numba gives the dispatchers, so the cached loops are the
    same. The addresses belong to this process: the entries are made at first use in each
    process and kept here (never pickled with a block).
    """
    entries = _ENTRIES.get(fns)
    if entries is None:
        waps = tuple(compiled_entries(*fn) if isinstance(fn, tuple) else
                     CompileResultWAP(fn.get_compile_result(_signature(fn))) for fn in fns)
        entries = CompiledEntries(waps)
        with warnings.catch_warnings():   # numba: first-class functions "experimental"
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            entries.numba_type = typeof(waps)
        _ENTRIES[fns] = entries
    return entries


def _signature(fn: Any) -> Any:
    """The one signature ``fn`` was compiled for (declared: see ``CompiledBlock``)."""
    (args,) = fn.overloads
    return fn.overloads[args].signature


@contextmanager
def calling_blocks() -> Iterator[None]:
    """Around a compiled loop's call with :func:`compiled_entries`: an error a block raises
    is raised from the call, as from the blocks' dispatchers or Python methods.

    A compiled entry runs the block through its C wrapper, which cannot pass an exception
    on: it reports it to :data:`sys.unraisablehook` and returns an empty array (which the
    loop's checks of the block's values then flag). The first such report while the loop
    runs in this thread is kept and raised once the loop returns; the rest are its
    consequences. numba's warning that first-class functions are experimental is silenced.
    """
    caught: list[BaseException] = []
    thread, previous = threading.get_ident(), sys.unraisablehook

    def hook(report: Any) -> None:
        if (threading.get_ident() == thread and report.exc_value is not None
                and str(report.object).startswith(_NUMBA_WRAPPER)):
            caught.append(report.exc_value)
        else:
            previous(report)

    sys.unraisablehook = hook
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            yield
    finally:
        if sys.unraisablehook is hook:
            sys.unraisablehook = previous
        thread = -1                     # a hook left installed by a race forwards all
    if caught:
        raise caught[0]


# what numba's C wrappers report as the object of an unraisable error (its target context)
_NUMBA_WRAPPER = "<numba.core."

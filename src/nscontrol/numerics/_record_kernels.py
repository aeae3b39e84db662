"""Named records over flat ``float64`` arrays, for compiled kernels.

A kernel's parameters (or the head of its state) are declared once as a NumPy structured
dtype of ``float64`` fields; Python fills a one-element array of it by name and passes its
flat ``float64`` view (what the compiled loops' signatures take). Inside a kernel,
``record(arr, DTYPE)`` reads the same bytes as that record, by name, for reading and writing:
``record(p, PARAMS).gamma1``. It is ``arr.view(DTYPE)[0]`` without that expression's cost in
numba (a new array struct and its checks, about 0.1 µs a call, against nothing here: the
record is the array's data pointer).

The array must hold at least the record's bytes from its start (the callers build it from
the dtype); a longer array is fine (the record is its head).
"""

from __future__ import annotations

from typing import Any

from numba import types
from numba.extending import intrinsic

__all__ = ["record"]


@intrinsic
def record(typingctx: Any, arr: Any, dtype: Any) -> Any:
    """The record of type ``dtype`` stored at the start of the contiguous ``float64`` array
    ``arr`` (a view: writes go to ``arr``). Compiled code only."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.float64 and arr.layout == "C"
            and isinstance(dtype, types.DType) and isinstance(dtype.dtype, types.Record)):
        return None
    rec = dtype.dtype

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.bitcast(ary.data, context.get_value_type(rec))
    return rec(arr, dtype), codegen

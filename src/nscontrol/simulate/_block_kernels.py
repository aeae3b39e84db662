"""The one stepping of a loop's controller and observer, at the start of every plant step:
compiled inside the integrators' compiled loops (the blocks' compiled forms,
:class:`~nscontrol.systems.feedback.CompiledBlock`), and run by the interpreter for blocks
written in Python (:class:`~nscontrol.simulate._block_runner.BlockRunner`, through
:func:`python_form`).

:func:`step_blocks`, in this order:

* a continuous block (``period <= 0``) first advances its state by explicit Euler over the
  previous step, ``xb += h update(t - h, xb, m_prev)``, then outputs ``output(t, xb, m)``;
* a sampled block (period ``T``) at its instants ``t_first + k T`` (``t_first``: the first
  step start it sees; the first step start at or after each instant, to the rounding of
  the step times, see :func:`take_sample`) outputs ``output(t, xb, m)``, moves to
  ``update(t, xb, m)``, and holds the output until its next instant;
* the observer runs first; the controller reads its estimate;
* every value a block returns is checked (its length, finiteness) before it is used.

The instants are counted, never accumulated: ``t_first + k T`` is formed afresh from the
integer count ``k``, so its error stays a few ulps however long the run (adding ``T`` at
each tick drifts by one rounding per tick and, with a slack that is a fixed fraction of
``T``, skipped a sample after ~2·10⁴ ticks of a 1e-4 s loop). The scheduling state lives in
``sched = [t_prev, t_first_observer, k_observer, t_first_controller, k_controller]`` (NaN:
none yet), so a run cut into chunks takes the same samples. A non-zero return is a status
(``STATUS_*``): the caller raises the error for it (one message per status,
:func:`~nscontrol.simulate._block_runner.block_error`).

Why one source run two ways: a Python block cannot be called from compiled code, and a
compiled block is called ~10⁷ times a run, so the stepping has to exist as compiled code and
as code the interpreter runs. Rather than a Python twin, :func:`python_form` runs these
functions' own code (``py_func``) with Python callables of the compiled forms' signature in
place of the blocks' compiled functions; the kernels on arrays alone (:func:`take_sample`,
``_finite``) stay compiled in both (called from Python they cost less than interpreted).
The block runner then only adapts a Python block to that signature (the
:class:`~nscontrol.systems.feedback.Measurement` it reads, the refusal of non-numeric
values) and turns a status into its error.
"""

from __future__ import annotations

import functools
import math
import types
from typing import Any

import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]
from numba import njit
from numba import types as nbtypes
from numba.core import cgutils
from numba.extending import intrinsic

STATUS_OK = 0
STATUS_OBSERVER_SIZE = 1        # update returned a state of the wrong length
STATUS_OBSERVER_NONFINITE = 2
STATUS_CONTROLLER_SIZE = 3
STATUS_CONTROLLER_NONFINITE = 4
STATUS_OBSERVER_OUTPUT_SIZE = 5  # the estimate has the wrong length
STATUS_CONTROLLER_OUTPUT_SIZE = 6  # u has the wrong length
# The step starts are ``t0 + j h`` and the instants ``t_first + k T``, each formed from an
# integer count: one rounding of the product, one of the sum, and the relative rounding
# (u = eps/2) of h and T themselves times ``j h`` / ``k T`` (each <= |t| + |t_first|). Their
# difference, where the exact values coincide, is at most ~12 u max(|t|, |t_first|); the
# slack is 32 u = 16 eps of that scale (a factor ~2.5 over the bound), independent of the
# run's length, and far below one step (16 eps |t| < h while |t| / h < 2.8e14).
_SAMPLE_SLACK_EPS = 16.0 * np.finfo(np.float64).eps
SCHED_SIZE = 5                  # [t_prev, t_first_obs, k_obs, t_first_ctrl, k_ctrl]
SLOT_OBSERVER = 1
SLOT_CONTROLLER = 3


#: numba's option that compiles a kernel without reference counting: the stepping below
#: takes ~20 arrays, and with counting each one cost an atomic increment and decrement per
#: call (about half of a sampled loop's tick: 0.8 -> 0.4 µs); a private option of ``njit``.
NO_REFCOUNT: dict[str, Any] = {"_nrt": False}


@intrinsic
def _release_intrinsic(typingctx, a):
    """Give back the memory of the array ``a`` a block's compiled function returned:
    ``NRT_MemInfo_release`` (which numba's runtime exports to compiled code) of its
    meminfo, if any. A kernel compiled without reference counting owns those arrays and
    frees each one this way once it has read it; in Python (:func:`python_form`) nothing."""
    if not isinstance(a, nbtypes.Array):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [cgutils.voidptr_t]),
            "NRT_MemInfo_release")
        meminfo = builder.bitcast(ary.meminfo, cgutils.voidptr_t)
        with builder.if_then(cgutils.is_not_null(builder, meminfo), likely=True):
            builder.call(fn, [meminfo])
        return context.get_dummy_value()
    return nbtypes.none(a), codegen


@intrinsic
def _empty_of_intrinsic(typingctx, a):
    """An empty array of ``a``'s type on no memory of its own (nothing to count)."""
    if not (isinstance(a, nbtypes.Array) and a.ndim == 1):
        return None

    def codegen(context, builder, signature, args):
        src = context.make_array(signature.args[0])(context, builder, args[0])
        out = context.make_array(signature.return_type)(context, builder)
        zero = context.get_constant(nbtypes.intp, 0)
        context.populate_array(out, data=src.data, shape=[zero],
                               strides=cgutils.unpack_tuple(builder, src.strides, 1),
                               itemsize=src.itemsize, meminfo=None)
        return out._getvalue()
    return a(a), codegen


#: The intrinsics as kernels call them (numba passes the typing context itself).
_release: Any = _release_intrinsic
_empty_of: Any = _empty_of_intrinsic


@njit(cache=True, inline="always")
def _copy(src, dst):
    """``dst[:] = src`` (same length), without a view (nothing to count)."""
    for i in range(dst.size):
        dst[i] = src[i]


@njit(cache=True, inline="always")
def _finite(a):
    for i in range(a.size):
        if not np.isfinite(a[i]):
            return False
    return True


@njit(cache=True, inline="always")
def take_sample(sched, slot, t, period):
    """Whether a sampled block of period ``period`` samples at the step start ``t``.

    ``sched[slot]`` is the block's first instant ``t_first`` (NaN: none yet, then ``t``
    becomes it and is sampled), ``sched[slot + 1]`` the count ``k`` of instants already
    served. The step start serves the instant ``t_first + k period`` when ``t`` is at or
    after it up to the rounding of the step times (``_SAMPLE_SLACK_EPS``); it also serves
    every later instant it is at or after (a step longer than the period), and ``k``
    moves past them. Updates ``sched`` in place.
    """
    t_first = sched[slot]
    if np.isnan(t_first):
        sched[slot] = t
        sched[slot + 1] = 1.0
        return True
    k = sched[slot + 1]
    slack = _SAMPLE_SLACK_EPS * max(abs(t), abs(t_first))
    if t < t_first + k * period - slack:
        return False
    k += 1.0
    while t >= t_first + k * period - slack:
        k += 1.0
    sched[slot + 1] = k
    return True


@njit(cache=True, inline="always")
def _held(value, into, bad_size, bad_value):
    """Check a block's returned ``value`` (its length against ``into``'s, finiteness), copy
    it into ``into`` if it passes, give its memory back; returns a status."""
    status = STATUS_OK
    if value.size != into.size:
        status = bad_size
    elif not _finite(value):
        status = bad_value
    else:
        _copy(value, into)
    _release(value)
    return status


@njit(cache=True, inline="always")
def _advance(fns, params, period, xb, held, sched, slot, t, h, y, x, xhat, lam,
             prev_y, prev_x, prev_xhat, prev_lam, bad_size, bad_value, bad_out):
    """One block at the step start ``t``; writes its (held) output into ``held``."""
    if period <= 0.0:                      # continuous: explicit Euler over the last step
        if h > 0.0:
            d = fns[1](t - h, xb, prev_y, prev_x, prev_xhat, prev_lam, params)
            status = STATUS_OK
            if d.size != xb.size:
                status = bad_size
            elif not _finite(d):
                status = bad_value
            else:
                for i in range(xb.size):
                    xb[i] = xb[i] + h * d[i]
            _release(d)
            if status != STATUS_OK:
                return status
            if not _finite(xb):
                return bad_value
        return _held(fns[0](t, xb, y, x, xhat, lam, params), held, bad_out, bad_value)
    if take_sample(sched, slot, t, period):
        # the output held before the update: it may be a view of xb
        status = _held(fns[0](t, xb, y, x, xhat, lam, params), held, bad_out, bad_value)
        if status != STATUS_OK:
            return status
        return _held(fns[1](t, xb, y, x, xhat, lam, params), xb, bad_size, bad_value)
    return STATUS_OK


@njit(cache=True, **NO_REFCOUNT)
def step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo, xhat,
                has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                prev_y, prev_x, prev_xhat, prev_lam, sched):
    """The observer, then the controller (``*_fns = (output, update)``, first-class
    functions of ``BLOCK_SIGNATURE``), at the step start ``t`` with the plant in ``x``
    (``y = C x``, ``lam``: the last step's multipliers, empty if none). Updates ``xo``,
    ``xc`` in place, writes the estimate into ``xhat`` and the input into ``u`` (zeros
    without a controller), keeps this step's measurement in ``prev_*``; returns a status.

    Compiled without reference counting (:data:`NO_REFCOUNT`): the arrays the blocks
    return are given back by :func:`_release`."""
    h = 0.0 if math.isnan(sched[0]) else t - sched[0]
    sched[0] = t
    none = _empty_of(xhat)
    if has_obs:
        status = _advance(obs_fns, obs_params, obs_period, xo, xhat, sched, SLOT_OBSERVER,
                          t, h, y, x, none, lam, prev_y, prev_x, none, prev_lam,
                          STATUS_OBSERVER_SIZE, STATUS_OBSERVER_NONFINITE,
                          STATUS_OBSERVER_OUTPUT_SIZE)
        if status != STATUS_OK:
            return status
    if has_ctrl:
        status = _advance(ctrl_fns, ctrl_params, ctrl_period, xc, u, sched, SLOT_CONTROLLER, t,
                          h, y, x, xhat, lam, prev_y, prev_x, prev_xhat, prev_lam,
                          STATUS_CONTROLLER_SIZE, STATUS_CONTROLLER_NONFINITE,
                          STATUS_CONTROLLER_OUTPUT_SIZE)
        if status != STATUS_OK:
            return status
    if (has_obs and obs_period <= 0.0) or (has_ctrl and ctrl_period <= 0.0):
        _copy(y, prev_y)         # what a continuous block's next Euler step reads
        _copy(x, prev_x)
        _copy(xhat, prev_xhat)
        _copy(lam, prev_lam)
    return STATUS_OK


@njit(cache=True, **NO_REFCOUNT)
def reset_blocks(t, x_minus, x_plus, impulse, has_obs, obs_reset, obs_params, xo,
                 has_ctrl, ctrl_reset, ctrl_params, xc):
    """The blocks' states after a plant jump (``*_reset = (reset,)``); returns a status
    (compiled without reference counting, as :func:`step_blocks`)."""
    if has_obs:
        status = _held(obs_reset[0](t, xo, x_minus, x_plus, impulse, obs_params), xo,
                       STATUS_OBSERVER_SIZE, STATUS_OBSERVER_NONFINITE)
        if status != STATUS_OK:
            return status
    if has_ctrl:
        return _held(ctrl_reset[0](t, xc, x_minus, x_plus, impulse, ctrl_params), xc,
                     STATUS_CONTROLLER_SIZE, STATUS_CONTROLLER_NONFINITE)
    return STATUS_OK


#: The kernels above that call a block's functions: run as Python with Python blocks
#: (:func:`python_form`). The others take arrays alone and stay compiled.
_CALL_BLOCKS = ("_held", "_advance", "step_blocks", "reset_blocks")


#: What the intrinsics are in :func:`python_form` (the interpreter counts references).
_PYTHON_INTRINSICS: dict[str, Any] = {"_release": lambda a: None,
                                      "_empty_of": lambda a: a[:0]}


@functools.cache
def python_form(name: str) -> Any:
    """The kernel ``name``'s own code, run by the interpreter, so that it can call Python
    functions in place of the blocks' compiled ones: the kernels of ``_CALL_BLOCKS`` it
    calls run as Python too, those on arrays alone stay compiled.

    Parameters
    ----------
    name : str
        ``"step_blocks"`` or ``"reset_blocks"``.

    Returns
    -------
    function
        The same function, same arguments, interpreted.
    """
    scope = dict(globals(), **_PYTHON_INTRINSICS)
    for kernel in _CALL_BLOCKS:
        py = globals()[kernel].py_func
        scope[kernel] = types.FunctionType(py.__code__, scope, py.__name__, py.__defaults__,
                                           py.__closure__)
    return scope[name]

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
from numba import njit

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
def _advance(fns, params, period, xb, held, sched, slot, t, h, y, x, xhat, lam,
             prev_y, prev_x, prev_xhat, prev_lam, bad_size, bad_value, bad_out):
    """One block at the step start ``t``; writes its (held) output into ``held``."""
    if period <= 0.0:                      # continuous: explicit Euler over the last step
        if h > 0.0:
            d = fns[1](t - h, xb, prev_y, prev_x, prev_xhat, prev_lam, params)
            if d.size != xb.size:
                return bad_size
            if not _finite(d):
                return bad_value
            for i in range(xb.size):
                xb[i] = xb[i] + h * d[i]
            if not _finite(xb):
                return bad_value
        out = fns[0](t, xb, y, x, xhat, lam, params)
        if out.size != held.size:
            return bad_out
        if not _finite(out):
            return bad_value
        held[:] = out
        return STATUS_OK
    if take_sample(sched, slot, t, period):
        out = fns[0](t, xb, y, x, xhat, lam, params)
        if out.size != held.size:
            return bad_out
        if not _finite(out):
            return bad_value
        held[:] = out                      # before the update: ``out`` may be a view of xb
        new = fns[1](t, xb, y, x, xhat, lam, params)
        if new.size != xb.size:
            return bad_size
        if not _finite(new):
            return bad_value
        xb[:] = new
    return STATUS_OK


@njit(cache=True, inline="always")
def step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo, xhat,
                has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                prev_y, prev_x, prev_xhat, prev_lam, sched):
    """The observer, then the controller (``*_fns = (output, update)``, first-class
    functions of ``BLOCK_SIGNATURE``), at the step start ``t`` with the plant in ``x``
    (``y = C x``, ``lam``: the last step's multipliers, empty if none). Updates ``xo``,
    ``xc`` in place, writes the estimate into ``xhat`` and the input into ``u`` (zeros
    without a controller), keeps this step's measurement in ``prev_*``; returns a status."""
    h = 0.0 if math.isnan(sched[0]) else t - sched[0]
    sched[0] = t
    none = xhat[:0]
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
        prev_y[:] = y            # what a continuous block's next Euler step reads
        prev_x[:] = x
        prev_xhat[:] = xhat
        prev_lam[:] = lam
    return STATUS_OK


@njit(cache=True, inline="always")
def reset_blocks(t, x_minus, x_plus, impulse, has_obs, obs_reset, obs_params, xo,
                 has_ctrl, ctrl_reset, ctrl_params, xc):
    """The blocks' states after a plant jump (``*_reset = (reset,)``); returns a status."""
    if has_obs:
        new = obs_reset[0](t, xo, x_minus, x_plus, impulse, obs_params)
        if new.size != xo.size:
            return STATUS_OBSERVER_SIZE
        if not _finite(new):
            return STATUS_OBSERVER_NONFINITE
        xo[:] = new
    if has_ctrl:
        new = ctrl_reset[0](t, xc, x_minus, x_plus, impulse, ctrl_params)
        if new.size != xc.size:
            return STATUS_CONTROLLER_SIZE
        if not _finite(new):
            return STATUS_CONTROLLER_NONFINITE
        xc[:] = new
    return STATUS_OK


#: The kernels above that call a block's functions: run as Python with Python blocks
#: (:func:`python_form`). The others take arrays alone and stay compiled.
_CALL_BLOCKS = ("_advance", "step_blocks", "reset_blocks")


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
    scope = dict(globals())
    for kernel in _CALL_BLOCKS:
        py = globals()[kernel].py_func
        scope[kernel] = types.FunctionType(py.__code__, scope, py.__name__, py.__defaults__,
                                           py.__closure__)
    return scope[name]

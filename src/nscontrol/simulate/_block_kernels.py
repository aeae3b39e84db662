"""Compiled stepping of a loop's controller and observer (their compiled forms,
:class:`~nscontrol.systems.feedback.CompiledBlock`), called at the start of every plant step
by the integrators' compiled loops.

:func:`step_blocks` does what ``closed_loop``'s Python block runner does, in the same order:

* a continuous block (``period <= 0``) first advances its state by explicit Euler over the
  previous step, ``xb += h update(t - h, xb, m_prev)``, then outputs ``output(t, xb, m)``;
* a sampled block (period ``T``) at its instants (the first step start at or after each,
  within ``1e-9 T``) outputs ``output(t, xb, m)``, moves to ``update(t, xb, m)``, and holds
  the output until its next instant;
* the observer runs first; the controller reads its estimate.

The scheduling state lives in ``sched = [t_prev, due_observer, due_controller]`` (NaN:
none yet), so a run can be cut into chunks. A non-zero return is a status (``STATUS_*``):
the integrator raises the error the Python path would raise.
"""

from __future__ import annotations

import numpy as np
from numba import njit

STATUS_OK = 0
STATUS_OBSERVER_SIZE = 1        # update returned a state of the wrong length
STATUS_OBSERVER_NONFINITE = 2
STATUS_CONTROLLER_SIZE = 3
STATUS_CONTROLLER_NONFINITE = 4
STATUS_OBSERVER_OUTPUT_SIZE = 5  # the estimate has the wrong length
STATUS_CONTROLLER_OUTPUT_SIZE = 6  # u has the wrong length
_SAMPLE_SLACK = 1e-9


@njit(cache=True)
def _finite(a):
    for i in range(a.size):
        if not np.isfinite(a[i]):
            return False
    return True


@njit(cache=True)
def _advance(fns, params, period, xb, held, sched, slot, t, h, y, x, xhat, lam,
             prev_y, prev_x, prev_xhat, prev_lam, bad_size, bad_value, bad_out):
    """One block at the step start ``t``; writes its (held) output into ``held``."""
    due = sched[slot]
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
    if np.isnan(due) or t >= due - _SAMPLE_SLACK * period:
        out = fns[0](t, xb, y, x, xhat, lam, params)
        if out.size != held.size:
            return bad_out
        if not _finite(out):
            return bad_value
        new = fns[1](t, xb, y, x, xhat, lam, params)
        if new.size != xb.size:
            return bad_size
        if not _finite(new):
            return bad_value
        xb[:] = new
        held[:] = out
        sched[slot] = (t if np.isnan(due) else due) + period
    return STATUS_OK


@njit(cache=True)
def step_blocks(t, x, y, lam, has_obs, obs_fns, obs_params, obs_period, xo, xhat,
                has_ctrl, ctrl_fns, ctrl_params, ctrl_period, xc, u,
                prev_y, prev_x, prev_xhat, prev_lam, sched):
    """The observer, then the controller (``*_fns = (output, update)``, first-class
    functions of ``BLOCK_SIGNATURE``), at the step start ``t`` with the plant in ``x``
    (``y = C x``, ``lam``: the last step's multipliers, empty if none). Updates ``xo``,
    ``xc`` in place, writes the estimate into ``xhat`` and the input into ``u`` (zeros
    without a controller), keeps this step's measurement in ``prev_*``; returns a status."""
    h = 0.0 if np.isnan(sched[0]) else t - sched[0]
    sched[0] = t
    none = xhat[:0]
    if has_obs:
        status = _advance(obs_fns, obs_params, obs_period, xo, xhat, sched, 1, t, h,
                          y, x, none, lam, prev_y, prev_x, none, prev_lam,
                          STATUS_OBSERVER_SIZE, STATUS_OBSERVER_NONFINITE,
                          STATUS_OBSERVER_OUTPUT_SIZE)
        if status != STATUS_OK:
            return status
    if has_ctrl:
        status = _advance(ctrl_fns, ctrl_params, ctrl_period, xc, u, sched, 2, t,
                          h, y, x, xhat, lam, prev_y, prev_x, prev_xhat, prev_lam,
                          STATUS_CONTROLLER_SIZE, STATUS_CONTROLLER_NONFINITE,
                          STATUS_CONTROLLER_OUTPUT_SIZE)
        if status != STATUS_OK:
            return status
    prev_y[:] = y
    prev_x[:] = x
    prev_xhat[:] = xhat
    prev_lam[:] = lam
    return STATUS_OK


@njit(cache=True)
def reset_blocks(t, x_minus, x_plus, impulse, has_obs, obs_reset, obs_params, xo,
                 has_ctrl, ctrl_reset, ctrl_params, xc):
    """The blocks' states after a plant jump (``*_reset = (reset,)``); returns a status."""
    if has_obs:
        new = obs_reset[0](t, xo, x_minus, x_plus, impulse, obs_params)
        if new.size != xo.size:
            return STATUS_OBSERVER_SIZE
        xo[:] = new
    if has_ctrl:
        new = ctrl_reset[0](t, xc, x_minus, x_plus, impulse, ctrl_params)
        if new.size != xc.size:
            return STATUS_CONTROLLER_SIZE
        xc[:] = new
    return STATUS_OK

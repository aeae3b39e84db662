"""One flow prepared for the compiled event loop, and the regular sample grid."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import SolverError
from ...numerics.lti import LTIFlow
from ._options import _Options
from ._zeno import _Zeno


class _Flight:
    """One flow (mode) prepared for the compiled event loop: guards, and the linear jump
    ``x+ = J_i x`` of each guard that has one (``jump_ok``); others are handed back.

    :meth:`run` flows from ``(t, x)``, settles the simple events in compiled code (see
    :mod:`nscontrol.simulate._event_kernels`), passes their samples and events to the
    callbacks and returns ``(t, x, event)`` at ``tf`` (``event`` None) or at the first event
    Python must handle.
    """

    SAMPLES, EVENTS = 4096, 512

    def __init__(self, flow: LTIFlow, G: FloatArray, g0: FloatArray, J: FloatArray | None,
                 jump_ok: np.ndarray, slots: np.ndarray) -> None:
        from ...numerics.lti import TAYLOR_DEGREE

        self.flow = flow
        self.ctx = ctx = flow.guard_context()
        n, p = flow.n, len(g0)
        self.G, self.g0 = np.ascontiguousarray(G, dtype=float).reshape(p, n), np.asarray(g0,
                                                                                    float)
        if p:
            self.W, self.row_norm = ctx.guard_data(self.G)
        else:
            self.W, self.row_norm = np.zeros((TAYLOR_DEGREE + 1, 0, n)), np.zeros(0)
        self.J = np.zeros((max(p, 1), n, n)) if J is None else np.ascontiguousarray(J, float)
        self.jump_ok = np.asarray(jump_ok, dtype=np.bool_).reshape(p)
        self.slots = np.asarray(slots, dtype=np.int64).reshape(p)

    def run(self, x: FloatArray, t: float, tf: float, zeno: _Zeno, geometric: bool,
            opts: _Options, *, sample_pre: bool, on_samples: Callable[..., None],
            on_events: Callable[..., None]) -> tuple[float, FloatArray, Any]:
        from ...numerics.lti import _REMAINDER, GuardEvent
        from .._event_kernels import DONE, FULL, HANDOFF, INADMISSIBLE, run_linear_jumps

        ctx, n, p = self.ctx, self.flow.n, len(self.g0)
        x = np.array(x, dtype=float)
        s_t, s_x = np.empty(self.SAMPLES), np.empty((self.SAMPLES, n))
        e_t, e_i = np.empty(self.EVENTS), np.empty(self.EVENTS, dtype=np.int64)
        e_pre, e_post = np.empty((self.EVENTS, n)), np.empty((self.EVENTS, n))
        hit, graze = np.zeros(max(p, 1), dtype=np.int8), np.zeros(max(p, 1), dtype=np.int8)
        while True:
            budget = opts.max_events - zeno.n_events
            code, t, n_s, n_e = run_linear_jumps(
                self.W, self.g0, self.row_norm, 1e-12, 1e-12, _REMAINDER, ctx.phi, ctx.bern,
                ctx.kind, ctx.lam, ctx.V, ctx.Vinv, ctx.taylor, ctx.d, ctx.h,
                self.J, self.jump_ok, self.slots, zeno.hist, zeno.count, zeno.first, geometric,
                opts.ratio_tol, opts.horizon, opts.rel, opts.min_interval, budget,
                x, t, tf, opts.dt, opts.t0, sample_pre,
                s_t, s_x, e_t, e_i, e_pre, e_post, hit, graze)
            zeno.n_events += n_e
            if n_s:
                on_samples(s_t[:n_s].copy(), s_x[:n_s].copy())
            if n_e:  # views: the callbacks copy what they keep
                on_events(e_t[:n_e], e_i[:n_e], e_pre[:n_e], e_post[:n_e])
            if code == FULL:
                continue
            if code == DONE:
                return t, x, None
            if code == INADMISSIBLE:
                from ...errors import InadmissibleStateError

                g = self.G @ x + self.g0
                raise InadmissibleStateError(
                    f"event_driven: guard {int(np.argmin(g))} is negative at t = {t:.12g} "
                    f"(g = {g.min():.3g}); the state left the admissible set")
            if code != HANDOFF:
                raise SolverError(f"event_driven: unexpected event-loop status {code}")
            idx = tuple(int(i) for i in np.flatnonzero(hit[:p]))
            return t, x, GuardEvent(0.0, idx, bool(graze[list(idx)].all()))


def _sample_times(t: float, t_next: float, dt: float, t0: float) -> FloatArray:
    """Regular grid points strictly inside ``(t, t_next)``."""
    k0 = int(np.floor((t - t0) / dt)) + 1
    k1 = int(np.ceil((t_next - t0) / dt))
    grid = t0 + dt * np.arange(k0, k1)
    return grid[(grid > t) & (grid < t_next)]

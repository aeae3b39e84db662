"""One flow prepared for the compiled event loop, the arrays a run lends to it, and the
regular sample grid."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..._validation import FloatArray
from ...errors import InadmissibleStateError, SolverError
from ...numerics.lti import TAYLOR_DEGREE, TAYLOR_REMAINDER, LTIFlow
from .._event_kernels import DONE, FULL, HANDOFF, INADMISSIBLE, run_linear_jumps
from ._options import _Options
from ._recording import _Samples
from ._zeno import _Zeno


class _Flight:
    """One flow (mode) prepared for the compiled event loop: guards, and the linear jump
    ``x+ = J_i x`` of each guard that has one (``jump_ok``); others are handed back.

    :meth:`run` flows from ``(t, x)``, settles the simple events in compiled code (see
    :mod:`nscontrol.simulate._event_kernels`), and returns ``(t, x, event)`` at ``tf``
    (``event`` None) or at the first event Python must handle.
    """

    def __init__(self, flow: LTIFlow, G: FloatArray, g0: FloatArray, J: FloatArray | None,
                 jump_ok: np.ndarray, slots: np.ndarray, n_free: int | None = None) -> None:
        self.flow = flow
        # the entries a restart's round-off projection may move (the plant's state, not the
        # constant and input generator of an augmented one)
        self.n_free = flow.n if n_free is None else n_free
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
            opts: _Options, samples: _Samples, ws: _Workspace, *, sample_pre: bool,
            on_events: Callable[..., None], restart: bool = True
            ) -> tuple[float, FloatArray, _Handoff | None]:
        """Flow from ``(t, x)`` to ``tf`` or to the first event Python must handle; samples
        go into ``samples``, settled events (in time order) to ``on_events(t, i, pre,
        post)`` (views of ``ws``: the callback copies what it keeps).

        ``restart``: ``x`` is a state the run computed (after an event Python handled, at a
        chunk's restart), whose guards negative at round-off level are projected
        (:func:`nscontrol.numerics.lti.project_restart`, counted in ``ws.proj``); False for
        the user's ``x0``, which must be admissible as given."""
        ctx = self.ctx
        x = np.array(x, dtype=float)
        while True:
            s_t, s_x = samples.free()
            user = not restart  # x is the caller's: a negative guard is its state's fault
            code, t, n_s, n_e = run_linear_jumps(
                self.W, self.g0, self.row_norm, 1e-12, 1e-12, TAYLOR_REMAINDER, ctx.phi,
                ctx.bern, ctx.kind, ctx.lam, ctx.V, ctx.Vinv, ctx.taylor, ctx.d, ctx.h,
                ctx.kappa, self.n_free, self.J, self.jump_ok, self.slots, zeno.hist,
                zeno.count, zeno.first, geometric, opts.ratio_tol, opts.horizon, opts.rel,
                opts.min_interval, opts.max_events - zeno.n_events, x, t, tf, opts.dt,
                opts.t0, sample_pre, restart, ws.proj, ws.clock, s_t, s_x, ws.e_t, ws.e_i,
                ws.e_pre, ws.e_post, ws.hit, ws.graze)
            zeno.n_events += n_e
            samples.wrote(n_s)
            if n_e:
                on_events(ws.e_t[:n_e], ws.e_i[:n_e], ws.e_pre[:n_e], ws.e_post[:n_e])
            restart = True  # the next call goes on from the state this one computed
            if code == FULL:
                samples.flush()
                continue
            if code == DONE:
                return t, x, None
            if code == HANDOFF:
                return t, x, self._handoff(ws)
            if code == INADMISSIBLE:
                raise self._inadmissible(x, t, ws.proj, user)
            raise SolverError(f"event_driven: unexpected event-loop status {code}")

    def _inadmissible(self, x: FloatArray, t: float, proj: FloatArray, user: bool
                      ) -> InadmissibleStateError:
        g = self.G @ x + self.g0
        i = int(np.argmin(g))
        if proj[4] > 0.0:   # a restart beyond the round-off tolerance
            return InadmissibleStateError(
                f"event_driven: guard {i} is negative at t = {t:.12g} (g = {proj[3]:.3g}), "
                f"beyond the integrator's round-off tolerance {proj[4]:.3g} at a state it "
                f"computed: the state left the admissible set (a jump map that does not "
                f"restore it?); check the model's jumps and guards")
        name = "x0" if user else "event_driven"
        return InadmissibleStateError(
            f"{name}: guard {i} is negative at t = {t:.12g} (g = {g[i]:.3g} < 0); the state "
            f"is outside the admissible set — start from a state with every guard >= 0")

    def _handoff(self, ws: _Workspace) -> _Handoff:
        p = len(self.g0)
        hit = ws.hit[:p].tolist()
        idx = [i for i in range(p) if hit[i]]
        graze = ws.graze[:p].tolist()
        return _Handoff(idx, all(graze[i] for i in idx))


class _Handoff(NamedTuple):
    """The event the compiled loop hands back: the guards at zero (ascending) and whether
    they all only touch zero."""

    indices: list[int]
    grazing: bool


class _Workspace:
    """The arrays a run writes into: samples, the events the compiled loop settles (read
    after each call), the guards of the event it hands back, contact flags, impulses and the
    Zeno history. Allocating them costs more than a short run's Python otherwise does, so a
    system's runs share them: :meth:`lend` takes a free one from a pool (a new one when all
    are in use, e.g. by a run started from a listener) and :meth:`give_back` returns it."""

    SAMPLES, EVENTS = _Samples.CAPACITY, 512

    def __init__(self, n: int, p: int, n_slots: int) -> None:
        self.s_t = np.empty(self.SAMPLES)
        self.s_x = np.empty((self.SAMPLES, n))
        self.e_t = np.empty(self.EVENTS)
        self.e_i = np.empty(self.EVENTS, dtype=np.int64)
        self.e_pre = np.empty((self.EVENTS, n))
        self.e_post = np.empty((self.EVENTS, n))
        self.hit = np.zeros(max(p, 1), dtype=np.int8)
        self.graze = np.zeros(max(p, 1), dtype=np.int8)
        self.closed = np.empty(max(n_slots, 1), dtype=np.int64)
        self.still = np.empty(max(n_slots, 1), dtype=np.bool_)
        self.contacts = np.empty(self.EVENTS, dtype=np.int64)
        self.impulses = np.empty((self.EVENTS, max(n_slots, 1)))
        self.zeno = (np.zeros((max(n_slots, 1), 6)), np.zeros(max(n_slots, 1), dtype=np.int64),
                     np.zeros(max(n_slots, 1)))
        # round-off projections at restarts: count, largest |g|, largest |g|/tol, and the
        # guard value and tolerance of a violation beyond it
        self.proj = np.zeros(5)
        # the time label the loop returned and the rounding it could not hold
        # (_lti_kernels.clock_advance): NaN, no label yet
        self.clock = np.array([np.nan, 0.0])
        self.shape = (n, p, n_slots)

    @classmethod
    def lend(cls, pool: list[_Workspace], n: int, p: int, n_slots: int) -> _Workspace:
        try:
            ws = pool.pop()
        except IndexError:
            return cls(n, p, n_slots)
        ws.zeno[1][:] = 0  # an empty history (rows are read up to their count)
        ws.proj[:] = 0.0
        ws.clock[:] = np.nan, 0.0
        return ws

    def give_back(self, pool: list[_Workspace]) -> None:
        if len(pool) < 4:
            pool.append(self)


def projection_stats(proj: FloatArray) -> dict[str, float | int]:
    """The run's round-off projections at restarts, for ``traj.stats``: how many
    (``projections``), the largest guard value moved to zero (``largest_projection``) and
    its share of the tolerance (``largest_projection_ratio``, below 1)."""
    return {"projections": int(proj[0]), "largest_projection": float(proj[1]),
            "largest_projection_ratio": float(proj[2])}


def _sample_times(t: float, t_next: float, dt: float, t0: float) -> FloatArray:
    """Regular grid points strictly inside ``(t, t_next)``."""
    k0 = int(np.floor((t - t0) / dt)) + 1
    k1 = int(np.ceil((t_next - t0) / dt))
    grid = t0 + dt * np.arange(k0, k1, dtype=np.float64)
    return np.asarray(grid[(grid > t) & (grid < t_next)], dtype=np.float64)

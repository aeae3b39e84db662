"""What a run records: one buffer of samples in front of the run's record (the loop's
:class:`~nscontrol.simulate.trajectory.Recorder`), the signals derived as it is handed over,
the errors that end a run (the loop attaches the partial trajectory), and the reordering of
states for another convention."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, NoReturn

import numpy as np

from ..._validation import FloatArray
from ...errors import BudgetExceededError, ZenoError
from ..loop import Recording, drive
from ..trajectory import Event, Recorder, Trajectory
from ._options import _Options


def recording(opts: _Options, n: int, offered: Sequence[str], state_names: Sequence[str]
              ) -> Recording:
    """What an event-driven run records: ``n`` states, the ``offered`` signals, as the
    options ask."""
    return Recording(n, every=opts.every, signals=opts.signals, offered=tuple(offered),
                     state_names=tuple(state_names))


class _Samples:
    """One buffer in front of the run's :class:`Recorder` (``record_every``, selected
    signals).

    The compiled loop writes its samples straight into the free part of the buffer
    (:meth:`free`, :meth:`wrote`); Python adds samples with :meth:`add` and :meth:`extend`.
    The buffer goes to the recorder in one block when it is full and at the end
    (:meth:`flush`): the recorder sees the same rows in the same order as sample by sample,
    so ``record_every`` thins them alike, while a run pays one recorder call instead of one
    per flight. The buffer may hold more columns than are recorded (the augmented state of
    the mechanics: the first ``n`` are kept). The last sample offered is kept whatever
    ``record_every`` drops.

    The signals of these integrators are functions of the state (outputs, gaps, energy):
    ``derive(X) -> {name: values}`` computes them per flushed block, so the recorder builds
    the trajectory with its signals at once.
    """

    CAPACITY = 4096

    def __init__(self, rec: Recorder, derive: Callable[[FloatArray], dict[str, FloatArray]],
                 buffer: tuple[FloatArray, FloatArray] | None = None) -> None:
        self.rec = rec
        n = rec.n_states
        self.wanted = [k for k in rec.offered or () if rec.wants(k)]
        self.derive = derive
        self.n = n
        self.t, self.x = ((np.empty(self.CAPACITY), np.empty((self.CAPACITY, n)))
                          if buffer is None else buffer)
        self.size = 0
        self.last: tuple[float, FloatArray] | None = None

    def free(self) -> tuple[FloatArray, FloatArray]:
        """The unused rows of the buffer (views for the compiled loop to write into)."""
        return self.t[self.size:], self.x[self.size:]

    def wrote(self, k: int) -> None:
        """``k`` rows were written into :meth:`free`'s views."""
        self.size += k

    def add(self, t: float, x: FloatArray) -> None:
        """One sample (a buffer row; ``x`` may be longer than the recorded state)."""
        if self.size == self.CAPACITY:
            self.flush()
        self.t[self.size] = t
        self.x[self.size] = x[: self.x.shape[1]]
        self.size += 1

    def extend(self, times: FloatArray, X: FloatArray) -> None:
        """A block of samples (after the buffered ones)."""
        k = len(times)
        if self.size + k > self.CAPACITY:
            self.flush()
            if k > self.CAPACITY:
                self._record(np.asarray(times, dtype=float), np.asarray(X, dtype=float))
                return
        self.t[self.size:self.size + k] = times
        self.x[self.size:self.size + k] = X
        self.size += k

    def flush(self) -> None:
        """Hand the buffered rows to the recorder."""
        if self.size:
            self._record(self.t[:self.size], self.x[:self.size, :self.n])
            self.size = 0

    def _record(self, times: FloatArray, X: FloatArray) -> None:
        self.rec.extend(times, X, **self._signals(X))
        self.last = (float(times[-1]), X[-1].copy())

    def _signals(self, X: FloatArray) -> dict[str, FloatArray]:
        if not self.wanted:
            return {}
        signals = self.derive(X)
        return {k: signals[k] for k in self.wanted}

    def settle(self) -> None:
        """Hand the buffered rows to the recorder, the last one kept whatever
        ``record_every`` drops."""
        self.flush()
        if self.last is not None and self.rec.last_time < self.last[0]:
            t, x = self.last
            self.rec.sample(t, x, force=True,
                            **{k: v[0] for k, v in self._signals(x[None]).items()})


def append_events(rec: Recorder, times: FloatArray, kind: str, indices: np.ndarray,
                  pre: FloatArray, post: FloatArray) -> None:
    """Record a block of events (``pre``/``post`` copied once for the block).

    The same :class:`Event` objects as ``Event(t, kind, i, a, b)``, built without the frozen
    dataclass's ``__init__`` (seven ``object.__setattr__`` calls, half the cost of a
    bouncing ball's run in Python): the attributes go into the instance dictionary at once.
    """
    pre = np.array(pre, dtype=np.float64)
    post = np.array(post, dtype=np.float64)
    block = [object.__new__(Event) for _ in range(len(pre))]
    for ev, t, i, a, b in zip(block, np.asarray(times, dtype=np.float64).tolist(),
                              np.asarray(indices, dtype=np.int64).tolist(), pre, post,
                              strict=True):
        ev.__dict__.update({"time": t, "kind": kind, "index": i, "pre": a, "post": b,
                            "mode_from": -1, "mode_to": -1})
    rec.events.extend(block)


def reorder_listeners(listeners: Sequence[Callable[..., None]], order: np.ndarray
                      ) -> list[Callable[..., None]]:
    """Listeners that receive ``x_minus, x_plus`` permuted by ``order`` (the caller's state
    convention, e.g. ``[x_a; x_b]`` of :class:`ImpactingBodies`)."""
    def wrap(fn: Callable[..., None]) -> Callable[..., None]:
        def call(t: float, x_minus: FloatArray, x_plus: FloatArray, *rest: Any) -> None:
            fn(t, x_minus[order], x_plus[order], *rest)
        return call
    return [wrap(fn) for fn in listeners]


def reorder_states(traj: Trajectory, order: np.ndarray, names: Sequence[str]) -> Trajectory:
    """The same trajectory with its state columns (and event states) permuted by ``order``."""
    events = tuple(Event(e.time, e.kind, e.index,
                         e.pre[order] if e.pre.size == order.size else e.pre,
                         e.post[order] if e.post.size == order.size else e.post,
                         e.mode_from, e.mode_to) for e in traj.events)
    return replace(traj, x=traj.x[:, order], events=events, state_names=tuple(names))


def _fail_zeno(message: str, t: float) -> NoReturn:
    """An accumulation the run cannot resolve (the loop attaches the part computed)."""
    raise ZenoError(message + "; pass on_failure='return' (or 'warn') to keep the partial "
                    "trajectory, or use method='moreau_jean' which passes through "
                    "accumulations", time=t)


def _fail_budget(opts: _Options, t: float, used: int) -> NoReturn:
    """The run spent its event budget ``max_events`` (the loop attaches the part
    computed)."""
    raise BudgetExceededError(
        f"max_events: the run spent its budget of {opts.max_events} events by t = {t:.12g} "
        f"({used} events); raise max_events for a long run (one event per impact or "
        f"switching), or look for an accumulation of events (Zeno). The computed part is in "
        f"err.trajectory (on_failure='return' returns it)", budget="max_events",
        limit=opts.max_events, used=used)


def _guarded(run: Any) -> Trajectory:
    """Drive the run's stepper (:func:`~nscontrol.simulate.loop.drive`: the run's record,
    its progress bar, one flight and its event per step, the part computed attached to any
    exception that ends it)."""
    return drive(run, (run.t0, run.tf), desc="event_driven", progress=run.opts.progress)

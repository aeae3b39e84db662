"""What a run records: samples thinned by ``record_every``, the signals derived at the end,
the partial trajectory of a failed run, and the reordering of states for another convention."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import NscontrolError, ZenoError, ZenoWarning
from ..trajectory import Recorder, Trajectory
from ._options import _Options


class _Samples:
    """The run's :class:`Recorder` (``record_every``, selected signals) and the last sample
    offered, so that the final state is kept whatever ``record_every`` drops.

    The signals of these integrators are functions of the state (outputs, gaps, energy):
    ``derive(X) -> {name: values}`` computes them once, on the recorded samples, at the end.
    """

    def __init__(self, n: int, opts: _Options, offered: Sequence[str],
                 derive: Callable[[FloatArray], dict[str, FloatArray]]) -> None:
        self.rec = Recorder(n, every=opts.every, signals=opts.signals, offered=offered)
        self.derive = derive
        self.last: tuple[float, FloatArray] | None = None

    def extend(self, times: FloatArray, X: FloatArray) -> None:
        self.rec.extend(times, X)
        self.last = (float(times[-1]), X[-1])

    def finish(self, **kw: Any) -> Trajectory:
        from dataclasses import replace

        if self.last is not None and self.rec.last_time < self.last[0]:
            self.rec.sample(*self.last, force=True)
        traj = self.rec.finish(**kw)
        wanted = [k for k in self.rec.offered or () if self.rec.wants(k)]
        if not wanted:
            return traj
        signals = self.derive(traj.x)
        return replace(traj, signals={k: signals[k] for k in wanted})


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
    from dataclasses import replace

    from ..trajectory import Event

    events = tuple(Event(e.time, e.kind, e.index,
                         e.pre[order] if e.pre.size == order.size else e.pre,
                         e.post[order] if e.post.size == order.size else e.post,
                         e.mode_from, e.mode_to) for e in traj.events)
    return replace(traj, x=traj.x[:, order], events=events, state_names=tuple(names))


def _caller_level() -> int:
    """``stacklevel`` pointing at the first frame outside nscontrol (the user's call)."""
    import sys

    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_globals.get("__name__", "").startswith("nscontrol"):
        frame, level = frame.f_back, level + 1
    return level


def _fail_zeno(opts: _Options, rec: _Samples, message: str, t: float, **finish: Any
               ) -> Trajectory:
    traj = rec.finish(status=-1, message=message, **finish)
    if opts.on_zeno == "warn":
        warnings.warn(message, ZenoWarning, stacklevel=_caller_level())
        return traj
    raise ZenoError(message + "; pass on_zeno='warn' to keep the partial trajectory, or use "
                    "method='moreau_jean' which passes through accumulations", time=t,
                    trajectory=traj)


def _guarded(run: Any) -> Trajectory:
    """Run; an error raised mid-run carries the trajectory computed so far."""
    try:
        return run.run()
    except NscontrolError as err:
        if err.trajectory is None:
            err.trajectory = run.samples.finish(status=-1, message=str(err),
                                                method="event_driven",
                                                state_names=run.s.state_names)
        raise

"""Event-driven run of a :class:`~nscontrol.systems.hybrid.LinearHybridSystem`: exact flow,
compiled events for matrix jumps, Python for callable jumps and grazing."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...numerics.lti import LTIFlow
from ..loop import END, Stop
from ..trajectory import Recorder
from ._flight import _Flight, _Workspace, projection_stats
from ._options import _Options
from ._recording import _fail_budget, _fail_zeno, _Samples, append_events, recording
from ._zeno import _Zeno


class HybridRun:
    """Exact simulation of a :class:`~nscontrol.systems.hybrid.LinearHybridSystem` (a
    :class:`~nscontrol.simulate.loop.Stepper`)."""

    samples: _Samples
    rec: Recorder

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float,
                 opts: _Options) -> None:
        self.s, self.x, self.t0, self.tf, self.opts = system, x0.copy(), t0, tf, opts
        self.flow = LTIFlow.shared(system.A)
        p = system.n_guards
        J = system.jump_matrices
        self.flight = _Flight(self.flow, system.G, system.g0, J,
                              np.full(p, J is not None), np.arange(p))
        self.ws = _Workspace(system.n_states, p, p)
        self.recording = recording(opts, system.n_states, tuple(system.outputs),
                                   system.state_names)
        self.zeno = _Zeno(opts, p, self.ws.zeno)
        self.t = t0
        self.restart = False  # the first flight starts from the user's x0
        self.ended = False

    def start(self, rec: Recorder) -> None:
        """The first sample into ``rec``, the run's record (behind the sample buffer)."""
        outputs, ws = self.s.outputs, self.ws
        self.rec = rec
        self.samples = _Samples(rec, lambda X: {k: X @ C.T for k, C in outputs.items()},
                                buffer=(ws.s_t, ws.s_x))
        self.samples.add(self.t0, self.x)

    def _jumped(self, times: FloatArray, idx: np.ndarray, pre: FloatArray,
                post: FloatArray) -> None:
        append_events(self.rec, times, "jump", idx, pre, post)
        for t, i, xm, xp in zip(times, idx, pre, post, strict=True) if self.opts.listeners \
                else ():
            for listener in self.opts.listeners:
                listener(float(t), xm.copy(), xp.copy(), np.array([i]), None)

    def advance(self) -> float | Stop:
        """One flight (the matrix jumps the compiled loop settles included) and the event it
        hands back; a :class:`Stop` once ``tf`` is reached."""
        if self.ended or self.t >= self.tf:
            return END
        s, opts = self.s, self.opts
        t, x, ev = self.flight.run(self.x, self.t, self.tf, self.zeno, False, opts,
                                   self.samples, self.ws, sample_pre=True,
                                   on_events=self._jumped, restart=self.restart)
        self.restart = True
        self.t, self.x = t, x
        if ev is None:
            self.ended = True
            return t
        self.zeno.n_events += 1   # every event spends the budget, a touch too
        if self.zeno.n_events > opts.max_events:
            _fail_budget(opts, t, self.zeno.n_events)
        if ev.grazing:
            for i in ev.indices:
                self.rec.event(t, "grazing", i, x, x)
            return t
        idx = np.asarray(ev.indices, dtype=np.int64)
        if any(self.zeno.too_close(int(i), t) for i in idx):
            _fail_zeno(f"event_driven: accumulation of events of guards {idx.tolist()} near "
                       f"t = {t:.12g}", t)
        for i in idx:
            self.zeno.push(int(i), t)
        x_plus = np.asarray(s.apply_jump(t, x, idx), float)
        for i in idx:
            self.rec.event(t, "jump", int(i), x, x_plus)
        for listener in opts.listeners:
            listener(t, x.copy(), x_plus.copy(), idx, None)
        self.x = x_plus
        self.samples.add(t, x_plus)
        return t

    def settle(self) -> None:
        """The buffered samples to the record."""
        self.samples.settle()

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics."""
        return {"events": self.zeno.n_events, **projection_stats(self.ws.proj)}

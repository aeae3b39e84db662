"""A run of implicit Euler as the stepper :func:`~nscontrol.simulate.loop.drive` advances: the
initial sample into the run's record (:meth:`Run.start`), then one chunk of steps per
:meth:`Run.advance` (appended at once), then the statistics at :meth:`Run.end`.

A chunk is ``2**16`` steps of the plant alone (a few milliseconds of compiled work) and
``2**13`` with a closed loop's blocks (a block call per step), so an interrupt is seen well
within 0.2 s. A solver failure ends the run with its verified steps recorded (a
:class:`~nscontrol.simulate.loop.Stop` with ``status = -1``); any other error (the input
``u(t)`` or a block raising, ``KeyboardInterrupt``) goes on with the chunk's finished steps
recorded (:meth:`~nscontrol.simulate.trajectory.Recorder.chunk`).
"""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import SolverError
from .._block_runner import CompiledBlocks
from ..loop import END, Recording, Stop
from ..trajectory import Recorder
from ._inclusion import initial_multiplier
from ._law_data import law_parts
from ._options import SIGNALS, ImplicitEulerOptions
from ._plan import Setup
from ._recording import record_block, record_finished, warn_degenerate
from ._steps import Rows, Steps

__all__ = ["Run"]

_CHUNK = 1 << 16
_BLOCK_CHUNK = 1 << 13


class Run:
    """One run: the chunk solver, the loop's blocks, the optional sensitivity (a
    :class:`~nscontrol.simulate.loop.Stepper`: the loop holds its record).

    Parameters
    ----------
    system : LureSystem
        The plant (its input already replaced by the ``u`` option).
    setup : Setup
        Its step matrices and plan for the step.
    opts : ImplicitEulerOptions
        The checked options.
    n_steps : int
        The number of steps of the span.
    x0 : ndarray
        The initial state (recorded first, with its multiplier).
    t0 : float
        The initial time.
    """

    rec: Recorder

    def __init__(self, system: Any, setup: Setup, opts: ImplicitEulerOptions, n_steps: int,
                 x0: FloatArray, t0: float) -> None:
        self.system, self.opts, self.n_steps, self.t0 = system, opts, n_steps, t0
        self.plan, self.h = setup.plan, setup.mats.h
        self.recording = Recording(
            system.n_states, every=opts.record_every, signals=opts.signals, offered=SIGNALS,
            capacity=Recorder.capacity_for(n_steps + 2, opts.record_every),
            state_names=system.state_names)
        self.steps = Steps(system, setup)
        # the loop's blocks: compiled in the closed form's loop when they can be
        self.runner, self.compiled = opts.blocks, None
        if self.runner is not None and self.plan.solver == "closed_form":
            self.compiled = CompiledBlocks.of(self.runner)
        self.chunk_size = _CHUNK if self.runner is None else _BLOCK_CHUNK
        self.jac = None
        if opts.sensitivity:
            from ._lure_sensitivity import StepJacobians

            self.jac = StepJacobians(system, setup.mats, self.plan.D, law_parts(system.law))
        self.x, self.done = x0, 0

    def start(self, rec: Recorder) -> None:
        """Record the initial state with its multiplier into ``rec``, the run's record."""
        self.rec, system, x0 = rec, self.system, self.x
        z0, w0 = initial_multiplier(system, x0, self.t0)
        rec.sample(self.t0, x0, force=True, z=z0, w=w0, y=system.C @ x0)

    def advance(self) -> float | Stop:
        """Run and record the next chunk of steps; the time reached, or a :class:`Stop`."""
        if self.done >= self.n_steps:
            return END
        k1 = min(self.n_steps, self.done + self.chunk_size)
        times = np.asarray(self.t0 + self.h * np.arange(self.done, k1 + 1), dtype=float)
        with self.rec.chunk(partial(record_finished, rec=self.rec, system=self.system,
                                    times=times)) as self.steps.progress:
            try:
                X, Z, W = self._chunk(self.x, times)
            except SolverError as exc:
                rows = getattr(exc, "partial", None)
                if rows is None:
                    raise
                self.steps.progress.done = 0       # recorded here, not by the chunk
                return self._failed(exc, times, rows)
        self._record(times[1:], (X, Z, W), last=k1 == self.n_steps)
        self.x, self.done = X[-1], k1
        return float(times[-1])

    def _chunk(self, x: FloatArray, times: FloatArray) -> Rows:
        """The steps over ``times`` by the path chosen for the run."""
        if self.compiled is not None:
            return self.steps.run_with_blocks(x, times, self.compiled)
        if self.runner is not None:
            return self.steps.run_with_runner(x, times, self.runner)
        return self.steps.run(x, times)

    def _record(self, t: FloatArray, rows: Rows, *, last: bool) -> None:
        X, Z, W = rows
        record_block(self.rec, self.system, t, X, Z, W, last=last)
        if self.jac is not None:   # the transition up to the last recorded step
            self.jac.extend(t, Z, W, self.steps.worst)

    def _failed(self, exc: SolverError, times: FloatArray, rows: Rows) -> Stop:
        """Record the verified steps before a solver failure; the failure's :class:`Stop`."""
        k = rows[0].shape[0]
        self._record(times[1:1 + k], rows, last=True)
        self.done += k
        return Stop(status=-1, message=str(exc), error_status=exc.status)

    def settle(self) -> None:
        """Nothing is held back: each chunk is recorded as it ends, its last step kept."""

    def end(self, stop: Stop) -> dict[str, Any]:
        """The statistics of the run that ended with ``stop`` (and the warning about steps at
        a corner of the law's graph)."""
        if stop.status >= 0 and self.jac is not None and self.jac.degenerate_steps:
            warn_degenerate(self.jac)
        return self.stats()

    def stats(self) -> dict[str, Any]:
        """``traj.stats`` of the run so far (see :func:`~.integrate`)."""
        plan, jac = self.plan, self.jac
        out = {"steps": int(self.done), "h": float(self.h), "theta": float(self.opts.theta),
               "solver": plan.solver, "structure": plan.structure,
               "blocks": max(1, len(plan.blocks)),
               "input": "controller" if self.runner is not None else self.steps.input_mode}
        if self.runner is not None:
            out["controller"] = "compiled" if self.compiled is not None else "python"
        if plan.solver != "closed_form":
            out["max_residual"] = self.steps.worst
        if jac is not None:
            out["state_transition"] = jac.transition.copy()
            out["degenerate_steps"] = jac.degenerate_steps
            out["first_degenerate_time"] = jac.first_degenerate_time
        return out

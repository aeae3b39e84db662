"""Sampled-data loops with exact zero-order-hold propagation: ``method="sampled_zoh"``.

Integrates a closed loop (:func:`nscontrol.closed_loop`) of a
:class:`~nscontrol.systems.SlidingModePlant` ``x' = A x + B (u + d(t))`` and a sampled
controller of period ``T`` (a :class:`~nscontrol.systems.feedback.Controller` with
``period = T``), the loop itself (no lowering): at each tick ``t_n = t0 + n T`` (``n`` an
integer count, the instant formed afresh, never accumulated) the controller reads the plant
(``output``, then ``update``) and its output is held over ``[t_n, t_{n+1})``, over which the
plant and its disturbance generator ``X = [x; w]`` move by their exact zero-order-hold step
``X_{n+1} = Φ X_n + Γ u_n`` (``Φ = e^{A_aug T}``, ``Γ = ∫_0^T e^{A_aug τ} dτ B_aug``): no
integration error, the samples are those of the continuous-time plant.

The ticks run compiled, in chunks of :data:`CHUNK` ticks, when the controller has a compiled
form (``compiled()``, :class:`~nscontrol.systems.feedback.CompiledBlock`) and the loop was
built with ``compiled=True`` (the default); otherwise the block's Python methods run in
:class:`~nscontrol.simulate._block_runner.BlockRunner`, the same tick after it
(``stats["controller"]`` says which ran). Between chunks the progress bar moves and a
``KeyboardInterrupt`` is seen; any exception that ends the run keeps every sample computed
before it (``err.trajectory``).

The run takes ``floor((tf - t0) / T)`` ticks (to a relative ``1e-12``, so a span that is a
multiple of ``T`` in decimal is one in binary too): the last sample is the one at or before
``tf``. Samples: the plant state ``x_n``; signals ``"s"`` (the sliding variable ``c x_n``),
``"u"`` (the input held over ``[t_n, t_{n+1})``; the last sample repeats the one before) and
``"xc"`` (the controller's state at ``t_n``, before its update; absent for a block without
state).

Options: the common ones (``record_every``, ``signals``, ``progress``, ``on_failure``,
``t_eval`` by interpolation); no method option.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..._progress import TimeProgress
from ..._validation import FloatArray, as_vector, check_bool, check_integer
from ...errors import DimensionError, ModelError
from .._block_runner import BlockRunner, CompiledBlocks
from ..trajectory import Recorder, Trajectory, _signal_names

__all__ = ["integrate", "SampledZOHOptions", "CHUNK", "SIGNALS"]

#: Ticks a compiled chunk runs between two looks from Python (progress, Ctrl-C): a few
#: milliseconds at the loop's speed, so an interrupt is seen well within 0.2 s.
CHUNK = 1 << 13
#: The signals the method records.
SIGNALS = ("s", "u", "xc")
#: The refused span: more ticks than this would run for hours and fill the memory.
MAX_TICKS = 10**9


@dataclass(frozen=True)
class SampledZOHOptions:
    """The options of a ``sampled_zoh`` run, checked (the common ones the driver hands on).

    Attributes
    ----------
    record_every : int
        Keep every ``record_every``-th tick (and the last).
    signals : tuple of str or None
        The signals to record (``None``: all of :data:`SIGNALS`).
    progress : bool or None
        The progress bar (``None``: shown after 2 s).
    """

    record_every: int = 1
    signals: tuple[str, ...] | None = None
    progress: bool | None = None

    @classmethod
    def checked(cls, record_every: Any = 1, signals: Any = None,
                progress: Any = None) -> SampledZOHOptions:
        """The options from the user's values; :class:`~nscontrol.errors.ModelError` for a
        bad one (a signal name outside :data:`SIGNALS`, a bare string for ``signals``)."""
        return cls(check_integer("record_every", record_every, minimum=1),
                   None if signals is None else tuple(sorted(_signal_names(signals, SIGNALS))),
                   check_bool("progress", progress, allow_none=True))


def integrate(system: Any, x0: ArrayLike, t_span: tuple[float, float], *,
              record_every: int = 1, signals: Any = None,
              progress: bool | None = None) -> Trajectory:
    """The sampled loop ``system`` from the plant state ``x0`` over ``t_span`` (see the
    module docstring).

    Parameters
    ----------
    system : ClosedLoop
        ``closed_loop(plant, controller)``: a ``SlidingModePlant`` and a sampled controller.
    x0 : array_like
        The plant's initial state (the controller starts from its own ``x0``, if any).
    t_span : (float, float)
        ``(t0, tf)``, at least one period long.
    record_every : int
        Keep every ``record_every``-th tick (the last one always).
    signals : sequence of str, optional
        Signals to record among ``"s"``, ``"u"``, ``"xc"`` (default all).
    progress : bool, optional
        Progress bar (default: shown after 2 s).

    Returns
    -------
    Trajectory

    Raises
    ------
    ModelError
        A loop this method does not run (no controller, a continuous-time one, an observer,
        an exosystem), a block that returns a non-finite or wrong-length value.
    DimensionError
        ``x0`` of the wrong length, a span shorter than one period.
    """
    opts = SampledZOHOptions.checked(record_every, signals, progress)
    run = _Run(_check_loop(system), x0, t_span, opts)
    with TimeProgress(run.t0, t_span[1], desc="sampled_zoh", enable=opts.progress) as bar:
        k = 0
        while k < run.n_ticks:
            k1 = min(run.n_ticks, k + CHUNK)
            run.guarded(run.chunk, k, k1)
            k = k1
            bar.update(run.t0 + k * run.T)
    run.guarded(run.keep_last)
    return run.finish()


def _check_loop(loop: Any) -> Any:
    """The loop, refused with a message saying what runs when its parts do not fit."""
    ctrl = loop.controller
    if ctrl is None or getattr(ctrl, "period", None) is None:
        raise ModelError("controller: sampled_zoh runs a sampled controller (period T > 0) on "
                         "the plant, got " + ("none" if ctrl is None else
                                              f"a continuous-time {type(ctrl).__name__}") +
                         "; give the block a period (its continuous-time loop is "
                         "plant.first_order_loop / super_twisting_loop, method='switching')")
    for name in ("observer", "exosystem", "input_matrix"):
        if getattr(loop, name) is not None:
            raise ModelError(f"{name}: sampled_zoh runs a plant and a sampled controller "
                             f"only (the disturbance is the plant's own, u enters through "
                             f"its B); build the loop without {name}=")
    return loop


class _Run:
    """One run: the exact step, the blocks (compiled or Python), the kept rows."""

    def __init__(self, loop: Any, x0: ArrayLike, t_span: tuple[float, float],
                 opts: SampledZOHOptions) -> None:
        from ...numerics.lti import discretize

        plant, ctrl = loop.plant, loop.controller
        self.plant, self.n, self.every = plant, int(plant.n_states), opts.record_every
        self.t0, self.T = float(t_span[0]), float(ctrl.period)
        self.n_ticks = _ticks(self.t0, float(t_span[1]), self.T)
        A_aug, B_aug, w0 = plant.augmented()
        Phi, Gam = discretize(A_aug, B_aug, self.T)
        self.Phi, self.Gam = np.ascontiguousarray(Phi), np.ascontiguousarray(Gam)
        w = plant.disturbance.w(self.t0) if plant.disturbance is not None else w0
        self.X = np.concatenate([as_vector("x0", x0, self.n), np.asarray(w, dtype=float)])
        self.Xn = np.empty_like(self.X)
        self.runner = BlockRunner(loop)
        self.blocks = CompiledBlocks.of(self.runner)
        rows = min(CHUNK, self.n_ticks) // self.every + 2     # the kept rows of one chunk
        n_xc = int(ctrl.n_states)
        self.out = (np.empty(rows), np.empty((rows, self.n)),
                    np.empty((rows, self.runner.n_inputs)), np.empty((rows, n_xc)))
        self.count = np.zeros(2, dtype=np.int64)  # [ticks done, rows kept in this chunk]
        offered = SIGNALS if n_xc else SIGNALS[:2]
        self.rec = Recorder(self.n, signals=opts.signals, offered=offered,
                            capacity=Recorder.capacity_for(self.n_ticks + 1, self.every))

    def guarded(self, work: Any, *args: Any) -> None:
        """Run ``work`` (ticks into the chunk's buffers), then record the rows it kept; any
        exception that ends it (a block's error, ``KeyboardInterrupt``) has them recorded
        first, once: the recorder's length changes in one assignment, at the end of
        :meth:`Recorder.extend`, so it tells whether they were."""
        n0 = len(self.rec)
        self.count[1] = 0
        try:
            work(*args)
            self.record()
        except BaseException:
            if len(self.rec) == n0:
                self.record()
            raise

    def chunk(self, k0: int, k1: int) -> None:
        """Ticks ``k0 .. k1 - 1``."""
        from ...systems._feedback_kernels import calling_blocks
        from .. import _sampled_zoh_kernels as zk

        if self.blocks is None:
            self._python_chunk(k0, k1)
            return
        b = self.blocks
        with calling_blocks():      # a block's error raised from the call
            status = zk.run_chunk(  # type: ignore[call-arg]  # numba's stub
                k0, k1, self.t0, self.T, self.every, self.Phi, self.Gam, self.X, self.Xn,
                b.Cy, np.zeros(0), *b.kernel_state(), *self.out, self.count)
        if status:
            b.raise_status(int(status), self.t0 + int(self.count[0]) * self.T)

    def _python_chunk(self, k0: int, k1: int) -> None:
        from .. import _sampled_zoh_kernels as zk

        runner, m = self.runner, self.runner.n_inputs
        for k in range(k0, k1):
            t = self.t0 + k * self.T
            xc = runner.xc
            u = runner.step_state(t, self.X[:self.n].copy())
            if u.size != m:
                raise ModelError(f"controller: expected a finite input of length {m} at "
                                 f"t = {t:.6g}, got {u.size} values")
            zk.tick(k, t, self.every, self.Phi, self.Gam, self.X, self.Xn, u, xc, *self.out,
                    self.count)
        runner.log.clear()          # the runner's own log is not used here

    def keep_last(self) -> None:
        """The sample at the last tick: the input held before, the controller's state."""
        from .. import _sampled_zoh_kernels as zk

        if self.blocks is not None:
            xc, u = self.blocks.ctrl_parts[6], self.blocks.ctrl_parts[7]
        else:
            xc, u = self.runner.xc, self.runner.held["controller_out"]
        zk.keep(self.n_ticks, self.every, True, self.t0 + self.n_ticks * self.T, self.X,
                np.asarray(u, dtype=float), np.asarray(xc, dtype=float), *self.out,
                self.count)

    def record(self) -> None:
        """Hand the rows the chunk kept to the recorder."""
        r = int(self.count[1])
        if r == 0:
            return
        t, x, u, xc = (a[:r] for a in self.out)
        signals: dict[str, FloatArray] = {"u": u}
        if self.rec.wants("s"):
            signals["s"] = self.plant.sliding_variable(x)
        if xc.shape[1]:
            signals["xc"] = xc
        self.rec.extend(t, x, **signals)

    def finish(self) -> Trajectory:
        stats = {"steps": self.n_ticks, "period": self.T,
                 "controller": "python" if self.blocks is None else "compiled"}
        return self.rec.finish(status=0, method="sampled_zoh", stats=stats,
                               state_names=self.plant.state_names)


def _ticks(t0: float, tf: float, T: float) -> int:
    """The number of periods in ``[t0, tf]`` (the last tick at or before ``tf``)."""
    ticks = math.floor((tf - t0) / T * (1.0 + 1e-12))
    if ticks < 1:
        raise DimensionError(f"t_span: the span {tf - t0:.6g} is shorter than the "
                             f"controller's period {T:.6g}; run at least one period")
    if ticks > MAX_TICKS:
        raise ModelError(f"t_span: {ticks:.3g} periods of {T:.3g} (more than "
                         f"{MAX_TICKS:.0e}); run a shorter span")
    return ticks

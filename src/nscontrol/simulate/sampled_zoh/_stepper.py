"""The run of ``method="sampled_zoh"`` as a stepper of :func:`~nscontrol.simulate.loop.drive`:
each :meth:`ZOHStepper.advance` runs and records a chunk of ticks (see the package
docstring).

What a run sets up once per plant and period is kept, weakly, per plant
(:func:`zoh_setup`): the augmented plant ``[x; w]`` and its zero-order-hold matrices, and the
disturbance generator's state at the last start times. A plant is a frozen dataclass: its
matrices are taken as fixed once it is built.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import FloatArray, as_vector
from ...errors import DimensionError, ModelError
from .._block_runner import BlockRunner, CompiledBlocks
from ..loop import END, Recording, Stop, tick_count
from ..trajectory import Recorder

__all__ = ["ZOHStepper", "check_blocks", "zoh_setup", "CHUNK", "SIGNALS", "MAX_TICKS"]

#: Ticks a compiled chunk runs between two looks from Python (progress, Ctrl-C): a few
#: milliseconds at the loop's speed, so an interrupt is seen well within 0.2 s.
CHUNK = 1 << 13
#: The signals the method records.
SIGNALS = ("s", "u", "xc")
#: The refused span: more ticks than this would run for hours and fill the memory.
MAX_TICKS = 10**9
_EMPTY = np.zeros(0)


def check_blocks(plant: Any, blocks: Any) -> BlockRunner:
    """The blocks a lowering handed the method (the ``blocks=`` of
    :mod:`nscontrol.simulate.lowering.python_blocks`), refused with a message saying what
    runs when the loop's parts do not fit."""
    from ...systems.sliding_mode import SlidingModePlant

    if not isinstance(plant, SlidingModePlant):
        raise ModelError(f"sampled_zoh: integrates a SlidingModePlant with its sampled "
                         f"controller, got {type(plant).__name__}")
    if blocks is None:
        raise ModelError("controller: sampled_zoh runs a sampled controller on the plant, got "
                         "none; write simulate(closed_loop(plant, controller), ...)")
    if not isinstance(blocks, BlockRunner):
        raise ModelError(f"blocks: expected the BlockRunner of a closed loop (set by "
                         f"simulate(closed_loop(plant, block), ...)), got "
                         f"{type(blocks).__name__}")
    ctrl, loop = blocks.ctrl, blocks.loop
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
    return blocks


class _PlantSetup:
    """The zero-order-hold matrices per period and the generator's state per start time."""

    def __init__(self, plant: Any) -> None:
        self.plant_ref = weakref.ref(plant)
        self.A_aug, self.B_aug, self.w0 = plant.augmented()
        self.steps: dict[float, tuple[FloatArray, FloatArray]] = {}
        self.starts: dict[float, FloatArray] = {}

    def step(self, T: float) -> tuple[FloatArray, FloatArray]:
        from ...numerics.lti import discretize

        found = self.steps.get(T)
        if found is None:
            Phi, Gam = discretize(self.A_aug, self.B_aug, T)
            found = (np.ascontiguousarray(Phi), np.ascontiguousarray(Gam))
            if len(self.steps) >= _KEEP:
                self.steps.pop(next(iter(self.steps)))
            self.steps[T] = found
        return found

    def w(self, plant: Any, t0: float) -> FloatArray:
        found = self.starts.get(t0)
        if found is None:
            found = (self.w0 if plant.disturbance is None
                     else np.asarray(plant.disturbance.w(t0), dtype=float))
            if len(self.starts) >= _KEEP:
                self.starts.pop(next(iter(self.starts)))
            self.starts[t0] = found
        return found


_KEEP = 16                     # periods and start times kept per plant
_SETUPS: weakref.WeakKeyDictionary[Any, _PlantSetup] = weakref.WeakKeyDictionary()


def zoh_setup(plant: Any, T: float, t0: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(Φ, Γ, w(t0))`` of ``plant``'s augmented state ``[x; w]`` over a period ``T``
    (kept per plant: the read-only arrays are shared by its runs)."""
    setup = _SETUPS.get(plant)
    if setup is None:
        setup = _SETUPS[plant] = _PlantSetup(plant)
    Phi, Gam = setup.step(T)
    return Phi, Gam, setup.w(plant, t0)


def _ticks(t0: float, tf: float, T: float) -> int:
    """The number of periods in ``[t0, tf]`` (the last tick at or before ``tf``)."""
    ticks = tick_count(t0, tf, T)
    if ticks < 1:
        raise DimensionError(f"t_span: the span {tf - t0:.6g} is shorter than the "
                             f"controller's period {T:.6g}; run at least one period")
    if ticks > MAX_TICKS:
        raise ModelError(f"t_span: {ticks:.3g} periods of {T:.3g} (more than "
                         f"{MAX_TICKS:.0e}); run a shorter span")
    return ticks


class ZOHStepper:
    """One run: the exact step, the blocks (compiled or Python), the kept rows; a chunk of
    ticks per :meth:`advance`, appended to the run's record (a
    :class:`~nscontrol.simulate.loop.Stepper`)."""

    rec: Recorder

    def __init__(self, plant: Any, runner: BlockRunner, x0: ArrayLike,
                 t_span: tuple[float, float], every: int,
                 signals: tuple[str, ...] | None) -> None:
        ctrl = runner.ctrl
        self.plant, self.n, self.every = plant, int(plant.n_states), every
        self.t0, self.T = float(t_span[0]), float(ctrl.period)
        self.n_ticks = _ticks(self.t0, float(t_span[1]), self.T)
        self.k = 0
        self.Phi, self.Gam, w = zoh_setup(plant, self.T, self.t0)
        self.X = np.concatenate([as_vector("x0", x0, self.n), w])
        self.Xn = np.empty_like(self.X)
        self.c = plant.c
        self.runner = runner
        self.blocks = CompiledBlocks.of(self.runner)
        rows = min(CHUNK, self.n_ticks) // self.every + 2     # the kept rows of one chunk
        n_xc = int(ctrl.n_states)
        self.out = (np.empty(rows), np.empty((rows, self.n)), np.empty(rows),
                    np.empty((rows, self.runner.n_inputs)), np.empty((rows, n_xc)))
        self.count = np.zeros(2, dtype=np.int64)  # [ticks done, rows kept in this chunk]
        self.recording = Recording(   # every=1: the kernel keeps one tick in ``every``
            self.n, signals=signals, offered=SIGNALS if n_xc else SIGNALS[:2],
            capacity=Recorder.capacity_for(self.n_ticks + 1, every),
            state_names=tuple(plant.state_names))
        if self.blocks is not None:
            ks = self.blocks.kernel_state()
            self.addresses = np.array([f.__wrapper_address__() for f in (*ks[1], *ks[7])],
                                      dtype=np.int64)

    def start(self, rec: Recorder) -> None:
        """Keep the run's record (the first tick is the first chunk's first row)."""
        self.rec = rec

    def advance(self) -> float | Stop:
        """The next chunk of ticks, recorded (the last chunk adds the sample at the last
        tick); the time reached, or :data:`~nscontrol.simulate.loop.END`."""
        k0 = self.k
        if k0 >= self.n_ticks:
            return END
        k1 = min(self.n_ticks, k0 + CHUNK)
        self._guarded(k0, k1, k1 == self.n_ticks)
        self.k = k1
        return self.t0 + k1 * self.T

    def _guarded(self, k0: int, k1: int, last: bool) -> None:
        """Ticks ``k0 .. k1 - 1`` into the chunk's buffers, then record the rows kept; any
        exception that ends them (a block's error, ``KeyboardInterrupt``) has them recorded
        first, once: the recorder's length changes in one assignment, at the end of
        :meth:`Recorder.extend`, so it tells whether they were."""
        n0 = len(self.rec)
        self.count[1] = 0
        try:
            if self.blocks is None:
                self._python_chunk(k0, k1, last)
            else:
                self._compiled_chunk(k0, k1, last)
            self._record()
        except BaseException:
            if len(self.rec) == n0:
                self._record()
            raise

    def _compiled_chunk(self, k0: int, k1: int, last: bool) -> None:
        from ...systems._feedback_kernels import calling_blocks
        from ._zoh_kernels import run_chunk

        b = self.blocks
        assert b is not None
        ks = b.kernel_state()     # the runner's arrays, stepped in place chunk after chunk
        with calling_blocks():     # a block's error raised from the call
            status = run_chunk(  # type: ignore[call-arg]  # numba's stub
                k0, k1, last, self.t0, self.T, self.every, self.Phi, self.Gam, self.X,
                self.Xn, self.c, b.Cy, _EMPTY, self.addresses, ks[0], *ks[2:7], *ks[8:],
                *self.out, self.count)
        if status:
            b.raise_status(int(status), self.t0 + int(self.count[0]) * self.T)

    def _python_chunk(self, k0: int, k1: int, last: bool) -> None:
        from ._zoh_kernels import keep, tick

        runner, m, n = self.runner, self.runner.n_inputs, self.n
        try:
            for k in range(k0, k1):
                t = self.t0 + k * self.T
                xc = runner.xc
                u = runner.step_state(t, self.X[:n].copy())
                if u.size != m:
                    raise ModelError(f"controller: expected a finite input of length {m} at "
                                     f"t = {t:.6g}, got {u.size} values")
                tick(k, t, self.every, self.Phi, self.Gam, self.X, self.Xn, self.c, u, xc,
                     *self.out, self.count)
        finally:    # the runner's own log is not used here (the ticks record u and xc)
            runner.log.clear()
        if last:                    # the input held before the last tick, the block's state
            keep(k1, self.every, True, self.t0 + k1 * self.T, self.X, self.c,
                    runner.held["controller_out"], runner.xc, *self.out, self.count)

    def _record(self) -> None:
        """Hand the rows the chunk kept to the recorder."""
        r = int(self.count[1])
        if r == 0:
            return
        t, x, s, u, xc = (a[:r] for a in self.out)
        if xc.shape[1]:
            self.rec.extend(t, x, s=s, u=u, xc=xc)
        else:
            self.rec.extend(t, x, s=s, u=u)

    def settle(self) -> None:
        """Nothing is held back: each chunk's rows are recorded as it ends."""

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics (``stop``: the end of the span)."""
        return {"steps": self.n_ticks, "period": self.T,
                "controller": "python" if self.blocks is None else "compiled"}

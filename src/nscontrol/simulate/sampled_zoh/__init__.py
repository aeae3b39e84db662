"""Sampled-data loops with exact zero-order-hold propagation: ``method="sampled_zoh"``.

Integrates a :class:`~nscontrol.systems.SlidingModePlant` ``x' = A x + B (u + d(t))`` with
the sampled controller of period ``T`` (a :class:`~nscontrol.systems.feedback.Controller`
with ``period = T``) of a closed loop (:func:`nscontrol.closed_loop`). The loop reaches the
method as every loop of blocks reaches its integrator: :func:`nscontrol.simulate` lowers it
(:mod:`nscontrol.simulate.lowering.python_blocks`) to the plant and the loop's
:class:`~nscontrol.simulate._block_runner.BlockRunner`, the internal option ``blocks=``;
this module never sees the closed loop itself. At each tick ``t_n = t0 + n T`` (``n`` an
integer count, the instant formed afresh, never accumulated) the controller reads the plant
(``output``, then ``update``) and its output is held over ``[t_n, t_{n+1})``, over which the
plant and its disturbance generator ``X = [x; w]`` move by their exact zero-order-hold step
``X_{n+1} = Φ X_n + Γ u_n`` (``Φ = e^{A_aug T}``, ``Γ = ∫_0^T e^{A_aug τ} dτ B_aug``): no
integration error, the samples are those of the continuous-time plant.

The run is a stepper of :func:`~nscontrol.simulate.loop.drive` (the one loop every method's
run goes through: progress bar, end of the run, partial trajectory on any failure). Each
:meth:`~._stepper.ZOHStepper.advance` runs a chunk of :data:`CHUNK` ticks, compiled when the
controller has a compiled form (``compiled()``,
:class:`~nscontrol.systems.feedback.CompiledBlock`) and the loop was built with
``compiled=True`` (the default); otherwise the block's Python methods run in
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
``t_eval`` by interpolation); ``blocks`` (internal, set by the lowering); no other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from numpy.typing import ArrayLike

from ..._validation import check_bool, check_integer
from ..loop import drive
from ..trajectory import Trajectory, _signal_names
from ._stepper import CHUNK, MAX_TICKS, SIGNALS, ZOHStepper, check_blocks

__all__ = ["integrate", "SampledZOHOptions", "CHUNK", "SIGNALS", "MAX_TICKS"]


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
        if type(record_every) is int and record_every == 1 and signals is None \
                and progress is None:
            return _DEFAULTS          # the usual call: nothing to check
        return cls(check_integer("record_every", record_every, minimum=1),
                   None if signals is None else tuple(sorted(_signal_names(signals, SIGNALS))),
                   check_bool("progress", progress, allow_none=True))


_DEFAULTS = SampledZOHOptions()


def integrate(system: Any, x0: ArrayLike, t_span: tuple[float, float], *,
              blocks: Any = None, record_every: int = 1, signals: Any = None,
              progress: bool | None = None) -> Trajectory:
    """The plant ``system`` with its sampled controller (``blocks``) from the plant state
    ``x0`` over ``t_span`` (see the module docstring).

    Parameters
    ----------
    system : SlidingModePlant
        The plant of ``closed_loop(plant, controller)``.
    x0 : array_like
        The plant's initial state (the controller starts from its own ``x0``, if any).
    t_span : (float, float)
        ``(t0, tf)``, at least one period long.
    blocks : BlockRunner
        The loop's blocks, set by :func:`nscontrol.simulate` when it lowers the closed loop
        (internal: write ``simulate(closed_loop(plant, controller), ...)``).
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
    runner = check_blocks(system, blocks)
    stepper = ZOHStepper(system, runner, x0, t_span, opts.record_every, opts.signals)
    return drive(stepper, (stepper.t0, float(t_span[1])), desc="sampled_zoh",
                 progress=opts.progress)

"""The user callbacks the integrators call during a run, as structural types.

Any function with the right positional parameters fits (names are free: the protocols'
parameters are positional-only).

Examples
--------
>>> import numpy as np
>>> import nscontrol as nsc
>>> from nscontrol.systems.lagrangian import LagrangianSystem
>>> times: list[float] = []
>>> def record(t, x_minus, x_plus, indices, impulse):   # a Listener
...     times.append(t)
>>> traj = nsc.simulate(LagrangianSystem.bouncing_ball(0.5), [1.0, 0.0], (0.0, 1.0),
...                     listeners=[record])
>>> bool(np.allclose(times, traj.event_times("impact")))
True
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import FloatArray

__all__ = ["Listener", "StepController"]


class Listener(Protocol):
    """Called at every jump: ``(t, x_minus, x_plus, indices, impulse) -> None``.

    ``indices`` are the contacts (impacts) or the guard (hybrid jumps) involved, ``impulse``
    the contact impulses when the method computes them (``None`` otherwise, e.g. when the
    driver replays the event table after the run).
    """

    def __call__(self, t: float, x_minus: FloatArray, x_plus: FloatArray,
                 indices: NDArray[np.intp], impulse: FloatArray | None, /) -> None:
        ...


class StepController(Protocol):
    """State feedback ``(t, q, v) -> u`` evaluated by a time-stepping method (zero-order
    hold over each step); it may also accept the keywords ``lam_hat`` and ``active``."""

    def __call__(self, t: float, q: FloatArray, v: FloatArray, /) -> ArrayLike:
        ...

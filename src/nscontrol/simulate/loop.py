"""The one loop every method's run goes through: the method advances, the loop drives.

SciPy's ``solve_ivp`` owns ``while status is None: solver.step()``; here a method gives a
*stepper* whose :meth:`Stepper.advance` runs the next piece of the run (a chunk of fixed steps,
a flight up to the next event and its jump, a chunk of controller ticks), records it and says
the time reached — or returns a :class:`Stop`. :func:`drive` owns what is the same for every
method:

* the progress bar (one :class:`~nscontrol._progress.TimeProgress`, updated after each piece);
* the end of the run: the stepper's :meth:`Stepper.finish` freezes its record at a
  :class:`Stop`; a stop with ``status < 0`` is a failure, raised as
  :class:`~nscontrol.errors.SolverError` carrying the trajectory (the driver turns it into a
  returned or warned partial run under ``on_failure=``);
* the partial run on any exception (a user callback's error, ``KeyboardInterrupt``): the
  stepper's recorder is registered with the run in progress, so the driver attaches every
  sample recorded so far. A stepper keeps a piece short enough (a few milliseconds of
  compiled work) that an interrupt is seen well within 0.2 s.

The schedule of sampled blocks is integer: tick ``k`` falls at :func:`tick_time` ``(t0, k, T)``
``= t0 + k T`` and :func:`tick_count` counts the ticks of a span — never a time accumulated by
``t += T`` (round-off would skip or double a tick after ~10^4 ticks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from .._progress import TimeProgress
from ..errors import SolverError
from .trajectory import Trajectory

__all__ = ["Stop", "Stepper", "drive", "tick_time", "tick_count"]


@dataclass(frozen=True)
class Stop:
    """How a run ended.

    Attributes
    ----------
    status
        ``0`` at the end of the span, ``1`` on a terminal event, ``-1`` on a failure.
    message
        Why it stopped (a failure's message), or ``None``.
    error_status
        The :class:`~nscontrol.errors.SolverError` status of a failure (e.g. the LCP
        solver's), or ``None``.
    """

    status: int = 0
    message: str | None = None
    error_status: str | None = None


#: The end of the span, reached normally.
END = Stop()


class Stepper(Protocol):
    """What a method gives :func:`drive`."""

    def advance(self) -> float | Stop:
        """Run and record the next piece of the run; the simulated time reached, or a
        :class:`Stop` when the run is over (nothing more to record)."""
        ...

    def finish(self, stop: Stop) -> Trajectory:
        """The trajectory of the run that ended with ``stop`` (its final sample kept)."""
        ...


def drive(stepper: Stepper, t_span: tuple[float, float], *, desc: str,
          progress: bool | None) -> Trajectory:
    """Advance ``stepper`` until it stops, with the progress bar, and return its trajectory.

    Parameters
    ----------
    stepper : Stepper
        The method's run in progress.
    t_span : (float, float)
        The span, for the progress bar.
    desc : str
        The bar's label (the method's name).
    progress : bool or None
        ``True``/``False`` show or hide the bar, ``None`` shows it after 2 s.

    Returns
    -------
    Trajectory
        The stepper's trajectory (status 0 or 1).

    Raises
    ------
    SolverError
        The run stopped with a failure (``status < 0``); ``err.trajectory`` holds the run up
        to it.
    """
    with TimeProgress(t_span[0], t_span[1], desc=desc, enable=progress) as bar:
        while True:
            reached = stepper.advance()
            if isinstance(reached, Stop):
                break
            bar.update(reached)
    traj = stepper.finish(reached)
    if reached.status < 0:
        raise SolverError(str(reached.message), status=reached.error_status,
                          trajectory=traj)
    return traj


def tick_time(t0: float, k: int, period: float) -> float:
    """The instant of tick ``k``: ``t0 + k period`` (exact in ``k``, never accumulated).

    Examples
    --------
    >>> tick_time(0.0, 21_441, 1e-4) == 21_441 * 1e-4
    True
    """
    return t0 + k * period


def tick_count(t0: float, tf: float, period: float) -> int:
    """The number of ticks after ``t0`` in ``(t0, tf]`` (a tick within ``1e-12`` relative of
    ``tf`` counts: ``tf`` is often itself computed as ``t0 + n period``).

    Examples
    --------
    >>> tick_count(0.0, 1.0, 0.1)
    10
    """
    return max(0, math.floor((tf - t0) / period * (1.0 + 1e-12)))


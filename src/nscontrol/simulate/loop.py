"""The one loop every method's run goes through: the method advances, the loop drives and
records.

SciPy's ``solve_ivp`` owns ``while status is None: solver.step()``; here a method gives a
*stepper* whose :meth:`Stepper.advance` runs the next piece of the run (a chunk of fixed steps,
a flight up to the next event and its jump, a chunk of controller ticks), appends it to the
run's record and says the time reached — or returns a :class:`Stop`. :func:`drive` owns what
is the same for every method:

* the record: the stepper declares what it records (a :class:`Recording`: state size,
  ``record_every``, the signals asked and offered, a first capacity, the state names);
  :func:`drive` builds the one :class:`~nscontrol.simulate.trajectory.Recorder` of the run,
  hands it to :meth:`Stepper.start` (which records the first sample) and freezes it into the
  trajectory at the end, with the stepper's :meth:`Stepper.end` statistics;
* the progress bar (one :class:`~nscontrol._progress.TimeProgress`, updated after each piece);
* the end of the run: a stop with ``status < 0`` is a failure, raised as
  :class:`~nscontrol.errors.SolverError` carrying the trajectory (the driver turns it into a
  returned or warned partial run under ``on_failure=``);
* the partial run on any exception (a library error, a user callback's own error,
  ``KeyboardInterrupt``): :func:`drive` has the stepper hand over what it holds back
  (:meth:`Stepper.settle`) and attaches every sample recorded so far as ``err.trajectory``.
  A stepper appends each piece it finished before the exception leaves it (see
  :meth:`~nscontrol.simulate.trajectory.Recorder.chunk`), and keeps a piece short enough (a
  few milliseconds of compiled work) that an interrupt is seen well within 0.2 s.

The schedule of sampled blocks is integer: tick ``k`` falls at :func:`tick_time` ``(t0, k, T)``
``= t0 + k T`` and :func:`tick_count` counts the ticks of a span — never a time accumulated by
``t += T`` (round-off would skip or double a tick after ~10^4 ticks).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from .._progress import TimeProgress
from ..errors import NscontrolError, SolverError
from ._run_context import attach_partial
from .trajectory import Recorder, Trajectory

__all__ = ["Stop", "Recording", "Stepper", "drive", "tick_time",
           "tick_count"]


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


@dataclass(frozen=True)
class Recording:
    """What a run records, as a stepper declares it: :func:`drive` builds the run's
    :class:`~nscontrol.simulate.trajectory.Recorder` from it.

    Attributes
    ----------
    n_states
        The length of a recorded state.
    every
        Keep every ``every``-th sample (the user's ``record_every``, checked there).
    signals
        The signals asked for (``None``: every offered one).
    offered
        The signals the method can record (a name outside them is refused at once), or
        ``None`` (a requested signal never recorded is refused at the end).
    capacity
        The first length of the buffers (:meth:`Recorder.capacity_for` of the expected
        sample count); they grow as needed.
    state_names
        The names of the state's entries, for the trajectory.
    """

    n_states: int
    every: int = 1
    signals: Iterable[str] | None = None
    offered: Iterable[str] | None = None
    capacity: int = 1024
    state_names: Sequence[str] = ()

    def recorder(self) -> Recorder:
        """A fresh recorder for one run (its checks of ``every`` and ``signals`` raise
        :class:`~nscontrol.errors.ModelError` before the run starts)."""
        return Recorder(self.n_states, every=self.every, signals=self.signals,
                        capacity=self.capacity, offered=self.offered)


class Stepper(Protocol):
    """What a method gives :func:`drive`: the recording it declares and four calls, in this
    order: :meth:`start` once, :meth:`advance` until it stops, then :meth:`settle` and
    :meth:`end` (also when an exception ends the run: :meth:`end` then gets a stop with
    status -1 and its statistics go with the partial trajectory)."""

    recording: Recording

    def start(self, rec: Recorder) -> None:
        """Record the first sample(s) into ``rec``, the run's record, and keep it: every
        later piece is appended to it (a stepper may hold the first sample back to write it
        with its first piece; :meth:`settle` then hands it over if no piece did)."""
        ...

    def advance(self) -> float | Stop:
        """Run the next piece of the run and append it to the record; the simulated time
        reached, or a :class:`Stop` when the run is over (nothing more to record)."""
        ...

    def settle(self) -> None:
        """Hand the record whatever the stepper still holds back (rows buffered in front of
        it, the last state when ``record_every`` dropped it): called before the record is
        frozen, at the end of the run and when an exception ends it."""
        ...

    def end(self, stop: Stop) -> Mapping[str, Any]:
        """The run ended with ``stop``: its statistics (``traj.stats``); release what the
        run borrowed. After an exception (``stop.status == -1``) it may be called mid-piece:
        if it cannot say, it raises and the partial trajectory has no statistics."""
        ...


def drive(stepper: Stepper, t_span: tuple[float, float], *, desc: str,
          progress: bool | None) -> Trajectory:
    """Record and advance ``stepper`` until it stops, with the progress bar, and return its
    trajectory.

    Parameters
    ----------
    stepper : Stepper
        The method's run in progress.
    t_span : (float, float)
        The span, for the progress bar.
    desc : str
        The bar's label and the trajectory's ``method`` (the method's name).
    progress : bool or None
        ``True``/``False`` show or hide the bar, ``None`` shows it after 2 s.

    Returns
    -------
    Trajectory
        The run's trajectory (status 0 or 1).

    Raises
    ------
    SolverError
        The run stopped with a failure (``status < 0``); ``err.trajectory`` holds the run up
        to it.
    BaseException
        Whatever ends the run (a library error, a user callback's error,
        ``KeyboardInterrupt``), with ``err.trajectory`` holding every sample recorded
        before it (unless the error carries a trajectory of its own).
    """
    traj, reached = _recorded_run(stepper, stepper.recording, t_span, desc, progress)
    if reached.status < 0:
        raise SolverError(str(reached.message), status=reached.error_status,
                          trajectory=traj)
    return traj


def _advance_all(stepper: Stepper, t_span: tuple[float, float], desc: str,
                 progress: bool | None) -> Stop:
    """Advance ``stepper`` piece by piece under the progress bar; the :class:`Stop`."""
    with TimeProgress(t_span[0], t_span[1], desc=desc, enable=progress) as bar:
        while True:
            reached = stepper.advance()
            if isinstance(reached, Stop):
                return reached
            bar.update(reached)


def _recorded_run(stepper: Any, recording: Recording, t_span: tuple[float, float],
                  desc: str, progress: bool | None) -> tuple[Trajectory, Stop]:
    """The run of a :class:`Stepper` into the record built here; any exception leaves with
    the samples recorded before it."""
    rec = recording.recorder()
    try:
        stepper.start(rec)
        reached = _advance_all(stepper, t_span, desc, progress)
        stepper.settle()
        stats = stepper.end(reached)
    except BaseException as err:
        _keep_partial(err, stepper, rec, recording, desc)
        raise
    traj = rec.finish(status=reached.status, message=reached.message, method=desc,
                      stats=stats, state_names=recording.state_names)
    return traj, reached


def _keep_partial(err: BaseException, stepper: Any, rec: Recorder, recording: Recording,
                  desc: str) -> None:
    """Attach to ``err`` the trajectory recorded before it (status -1), unless it carries
    one or nothing was recorded."""
    if getattr(err, "trajectory", None) is not None:
        return
    try:
        stepper.settle()
    except Exception:  # noqa: BLE001 - the error being raised is the one to report
        pass
    if not len(rec):
        return
    library = isinstance(err, NscontrolError)
    message = str(err) if library else f"interrupted by {type(err).__name__}: {err}"
    try:        # the statistics of the part run (steps spent, events...), when it can say
        stats = dict(stepper.end(Stop(-1, message)))
    except Exception:  # noqa: BLE001 - a stepper stopped mid-piece may hold no statistics
        stats = {}
    traj = rec.snapshot(status=-1, message=message, method=desc,  # the run is over
                        state_names=recording.state_names, stats=stats, last=True)
    attach_partial(err, traj, note=not library)


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


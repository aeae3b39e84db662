"""Integrators for non-smooth dynamics, behind one verb: :func:`simulate`.

The integrators form a family (:class:`~nscontrol.simulate.driver.Integrator` subclasses;
:data:`METHODS` maps the built-in names to them, :mod:`nscontrol.simulate.methods` lists what
each integrates and can do) behind one driver (:mod:`nscontrol.simulate.driver`) that owns
what is common to all: option checks, sampling (``t_eval``, ``record_every``, ``signals``),
the failure policy (``on_failure``), ``listeners``, the progress bar, composite systems
(closed loops, lowered by the registered lowerings of :mod:`nscontrol.simulate.lowering`;
``register_lowering`` adds one) and the partial trajectory of a run that fails, whatever the
exception.
"""

from __future__ import annotations

from typing import Any, Literal

from numpy.typing import ArrayLike

from .._validation import check_t_span
from ..systems.protocols import SimulableSystem
from . import driver
from .driver import METHODS, Integrator, register_method
from .lowering import Lowered, Lowering, register_lowering
from .trajectory import STATUS_MESSAGES, Event, Recorder, Trajectory

__all__ = ["simulate", "Trajectory", "Event", "Recorder", "METHODS", "STATUS_MESSAGES",
           "Integrator", "register_method", "Lowering", "Lowered", "register_lowering"]

#: The built-in method names (``register_method`` adds more, so ``simulate`` takes any str).
Method = Literal["event_driven", "moreau_jean", "implicit_euler", "switching", "sampled_zoh"]


def simulate(system: SimulableSystem, x0: ArrayLike, t_span: tuple[float, float], *,
             method: Method | str | type[Integrator] | None = None,
             **options: Any) -> Trajectory:
    """Simulate a non-smooth system (or a closed loop) from ``x0`` over ``t_span``.

    Parameters
    ----------
    system
        A model from :mod:`nscontrol.systems`, or a closed loop
        (:func:`nscontrol.closed_loop`, or one built by a design object).
    x0 : array_like
        Initial state (admissible: no penetration, no approaching velocity at contact).
    t_span : (float, float)
        Start and end times, ``t0 < tf``.
    method : str or Integrator subclass, optional
        The integrator: ``"event_driven"``, ``"moreau_jean"``, ``"implicit_euler"``,
        ``"switching"``, ``"sampled_zoh"``, or a class (your own :class:`Integrator`
        subclass too). Default: the system's ``default_method``.
    **options
        The method's own options (``h``, ``theta``, ``rtol``, ``u`` ...: see
        :mod:`nscontrol.simulate.methods`) and the common ones every method takes:

        ``t_eval`` : array_like
            Sample times (methods that cannot stop there are interpolated afterwards).
        ``record_every`` : int
            Keep every k-th sample (events and the final state are always kept).
        ``signals`` : sequence of str
            The named signals to record (default: all the method offers).
        ``on_failure`` : {"raise", "return", "warn"}
            A run that cannot continue (:class:`~nscontrol.errors.SolverError`,
            :class:`~nscontrol.errors.ZenoError`) raises with ``err.trajectory``, or returns
            that partial trajectory with ``status = -1`` (``"warn"``: with a warning).
        ``listeners`` : sequence of callables ``(t, x_minus, x_plus, indices, impulse)``
            Called at every jump (during the run for methods that can, else from the event
            table once it ends).
        ``progress`` : bool
            Progress bar on stderr (default: shown after 2 s).
        ``sensitivity`` : bool
            Also compute ``stats["state_transition"]`` (methods with that capability).

    Returns
    -------
    Trajectory
        Samples, named signals, the event table and solver statistics.

    Raises
    ------
    ModelError
        Unknown method or option (the message lists the accepted ones), or a system the
        method does not integrate.
    InadmissibleStateError
        ``x0`` violates a constraint.
    ZenoError, SolverError
        The run could not continue (a spent budget, such as ``max_events``, is the
        ``SolverError`` :class:`~nscontrol.errors.BudgetExceededError`). Every exception
        raised during the run — these, a user callback's own, ``KeyboardInterrupt`` —
        carries the part computed so far in ``err.trajectory``.
    """
    t0, tf = check_t_span(t_span)
    return driver.run(system, x0, (t0, tf), method, dict(options))

"""Integrators for non-smooth dynamics, behind one verb: :func:`simulate`.

Every method lives in its own module of this package and exposes a function
``integrate(system, x0, t_span, **options) -> Trajectory``. The contract each one keeps:

1. It accepts the system types listed in its module docstring and raises
   :class:`~nscontrol.errors.ModelError` naming the supported types otherwise.
2. It validates its own options (step ``h > 0``, tolerances) and the initial state (an
   inadmissible one raises :class:`~nscontrol.errors.InadmissibleStateError`).
3. It writes samples and events into a :class:`Recorder` and returns
   :meth:`Recorder.finish` — status 0 at the end of the span, 1 on a terminal event.
4. On a failure it raises the specific error with ``trajectory=`` the part computed so far
   (or, with ``on_failure="return"``, returns it with ``status = -1``).
5. It shows a progress bar on stderr when a run lasts more than a couple of seconds.
"""

from __future__ import annotations

import importlib
from typing import Any, Literal

from .._validation import check_t_span
from .trajectory import STATUS_MESSAGES, Event, Recorder, Trajectory

__all__ = ["simulate", "Trajectory", "Event", "Recorder", "METHODS", "STATUS_MESSAGES"]

Method = Literal["event_driven", "moreau_jean", "implicit_euler", "switching"]

#: Method name -> module implementing ``integrate``.
METHODS: dict[str, str] = {
    "event_driven": "nscontrol.simulate.event_driven",
    "moreau_jean": "nscontrol.simulate.moreau_jean",
    "implicit_euler": "nscontrol.simulate.implicit_euler",
    "switching": "nscontrol.simulate.switching",
}


def simulate(system: Any, x0: Any, t_span: tuple[float, float], *,
             method: Method | None = None, **options: Any) -> Trajectory:
    """Simulate a non-smooth system (or a closed loop) from ``x0`` over ``t_span``.

    Parameters
    ----------
    system
        A model from :mod:`nscontrol.systems`, or a closed loop built by a design object.
    x0 : array_like
        Initial state (admissible: no penetration, no approaching velocity at contact).
    t_span : (float, float)
        Start and end times, ``t0 < tf``.
    method : {"event_driven", "moreau_jean", "implicit_euler", "switching"}, optional
        The integrator. Default: the system's ``default_method``.
    **options
        Options of the chosen method (``h``, ``theta``, ``rtol``, ``atol``,
        ``record_every``, ``signals``, ``progress``, ``on_failure`` ...); each method documents
        its own and rejects unknown ones.

    Returns
    -------
    Trajectory
        Samples, named signals, the event table and solver statistics.

    Raises
    ------
    ModelError
        Unknown method, or a system the method does not integrate.
    InadmissibleStateError
        ``x0`` violates a constraint.
    ZenoError, SolverError
        The run could not continue; ``err.trajectory`` holds what was computed.
    """
    t0, tf = check_t_span(t_span)
    if method is None:
        method = getattr(system, "default_method", None)
        if method is None:
            from ..errors import ModelError

            raise ModelError(f"simulate: {type(system).__name__} has no default_method; pass "
                             f"method= one of {sorted(METHODS)}")
    if method not in METHODS:
        from ..errors import ModelError

        raise ModelError(f"method: expected one of {sorted(METHODS)}, got {method!r}")
    module = importlib.import_module(METHODS[method])
    return module.integrate(system, x0, (t0, tf), **options)

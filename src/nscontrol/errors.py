"""The exception and warning family of nscontrol.

Every error derives from :class:`NscontrolError` *and* from the obvious built-in, so
``except ValueError`` keeps working around bad input and ``except RuntimeError`` around a
solver that gave up. Messages name the offending argument, what was expected and what was
received, and say what to do about it.

Errors raised while a simulation runs carry the part of the trajectory computed so far in
their ``trajectory`` attribute: a failed long run never loses its work.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "NscontrolError",
    "ModelError",
    "DimensionError",
    "InadmissibleStateError",
    "InfeasibleDesignError",
    "SolverError",
    "NonFiniteStateError",
    "BudgetExceededError",
    "ZenoError",
    "SlidingError",
    "NscontrolWarning",
    "ZenoWarning",
    "ChatteringWarning",
    "InaccurateCertificateWarning",
]


class NscontrolError(Exception):
    """Root of every error raised by nscontrol.

    Parameters
    ----------
    message
        What is wrong, what was expected, and what to do.
    trajectory
        The partial :class:`~nscontrol.simulate.Trajectory` computed before the failure,
        when the error interrupted a simulation; ``None`` otherwise.
    """

    def __init__(self, message: str, *, trajectory: Any = None) -> None:
        super().__init__(message)
        self.trajectory = trajectory


class ModelError(NscontrolError, ValueError):
    """A model is ill-posed: wrong sign, non-symmetric mass matrix, non-monotone law, overlapping
    regions, a discontinuous field declared continuous."""


class DimensionError(NscontrolError, ValueError):
    """An array has the wrong shape, or shapes of several arguments disagree."""


class InadmissibleStateError(NscontrolError, ValueError):
    """A state violates a constraint (penetration, approaching velocity at contact)."""


class InfeasibleDesignError(NscontrolError, RuntimeError):
    """A design problem has no solution; ``status`` holds the solver's or checker's diagnosis."""

    def __init__(self, message: str, *, status: str | None = None, trajectory: Any = None):
        super().__init__(message, trajectory=trajectory)
        self.status = status


class SolverError(NscontrolError, RuntimeError):
    """A numerical solver failed (LCP ray termination, no convergence, singular system)."""

    def __init__(self, message: str, *, status: str | None = None, trajectory: Any = None):
        super().__init__(message, trajectory=trajectory)
        self.status = status


class NonFiniteStateError(SolverError):
    """The state became infinite or NaN during a run (an unstable model, a force or input that
    returned NaN). ``time`` and ``state`` say where; ``err.trajectory`` holds every sample
    before it."""

    def __init__(self, message: str, *, time: float | None = None, state: str | None = None,
                 trajectory: Any = None):
        super().__init__(message, status="non_finite", trajectory=trajectory)
        self.time = time
        self.state = state


class BudgetExceededError(SolverError):
    """An adaptive or iterative loop spent its budget (steps, iterations, events, a smallest
    step relative to the time scale) before it finished: no loop of nscontrol runs unbounded.

    ``budget`` names the option that set the limit (``"max_steps"``, ``"max_iter"``,
    ``"min_step"``...), so the message and the attribute say which one to raise; ``limit`` is
    its value and ``used`` what was spent. A simulation's part computed so far is in
    ``trajectory``; any other loop's last iterate or partial result (a branch of a
    continuation, a Newton iterate) is in ``partial``.
    """

    def __init__(self, message: str, *, budget: str, limit: Any = None, used: Any = None,
                 trajectory: Any = None, partial: Any = None):
        super().__init__(message, status="budget", trajectory=trajectory)
        self.budget = budget
        self.limit = limit
        self.used = used
        self.partial = partial


class ZenoError(NscontrolError, RuntimeError):
    """An accumulation of events (impacts or switchings) that the integrator cannot resolve."""

    def __init__(self, message: str, *, time: float | None = None, trajectory: Any = None):
        super().__init__(message, trajectory=trajectory)
        self.time = time


class SlidingError(ModelError):
    """A switching run reached a facet where no region's field points inward: the solution
    would slide along the facet (or stop being unique), which a piecewise-affine model with
    crossings only cannot continue. ``time`` and ``state`` say where."""

    def __init__(self, message: str, *, time: float | None = None, state: Any = None,
                 trajectory: Any = None):
        super().__init__(message, trajectory=trajectory)
        self.time = time
        self.state = state


class NscontrolWarning(UserWarning):
    """Root of nscontrol's warnings."""


class ZenoWarning(NscontrolWarning):
    """An accumulation of events was detected and handled (or tolerated by option)."""


class ChatteringWarning(NscontrolWarning):
    """A time-stepping run switched mode at (almost) every step: the step is too large, or the
    law should be treated implicitly."""


class InaccurateCertificateWarning(NscontrolWarning):
    """A design certificate passed its numerical re-check only with a thin margin."""

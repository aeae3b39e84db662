"""What a model must provide to be simulated and checked, and the user signals it reads.

These are structural types (:class:`typing.Protocol`): a class need not inherit from them,
it only needs the attributes. Every model of :mod:`nscontrol.systems` satisfies
:class:`SimulableSystem` and :class:`StateChecked`; your own model does when it declares

* ``n_states`` (int) — the length of the state ``x``;
* ``default_method`` (str) — the integrator :func:`nscontrol.simulate` uses when none is
  named (a key of :data:`nscontrol.simulate.METHODS`);
* ``state_names`` (sequence of str, possibly empty) — names for plots and saved files;

and, for :class:`StateChecked`, ``check_state(x0)``, which returns ``x0`` as a float vector
or raises :class:`~nscontrol.errors.DimensionError` (wrong length) or
:class:`~nscontrol.errors.InadmissibleStateError` (a violated constraint).
:func:`nscontrol.testing.check_system` measures exactly these declarations.

Input signals (the ``u=`` of a model or of ``simulate``) are an :data:`InputSignal`: ``None``,
a constant vector, a function of time, or an exosystem (anything with a method ``u(t)``).

Examples
--------
>>> from nscontrol.systems.lagrangian import LagrangianSystem
>>> ball = LagrangianSystem.bouncing_ball()
>>> isinstance(ball, SimulableSystem), isinstance(ball, StateChecked)
(True, True)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, TypeAlias, runtime_checkable

from numpy.typing import ArrayLike

from .._validation import FloatArray

__all__ = ["SimulableSystem", "StateChecked", "InputFunction", "Exogenous", "InputSignal"]


@runtime_checkable
class SimulableSystem(Protocol):
    """A model :func:`nscontrol.simulate` can integrate (with a method that supports it)."""

    @property
    def n_states(self) -> int:
        """Length of the state vector."""
        ...

    @property
    def default_method(self) -> str:
        """The integrator used when ``simulate`` is given no ``method``."""
        ...

    @property
    def state_names(self) -> Sequence[str]:
        """One name per state, or empty."""
        ...


@runtime_checkable
class StateChecked(SimulableSystem, Protocol):
    """A model that validates an initial state itself."""

    def check_state(self, x0: ArrayLike) -> FloatArray:
        """``x0`` as a float vector of length ``n_states``, or an error saying what is wrong."""
        ...


class InputFunction(Protocol):
    """An input given as a function of time: ``t -> u(t)`` (length of the model's input)."""

    def __call__(self, t: float, /) -> ArrayLike:
        ...


class Exogenous(Protocol):
    """An exosystem: anything with a method ``u(t)``.

    :class:`~nscontrol.numerics.lti.Exosystem` is one.
    """

    def u(self, t: float, /) -> ArrayLike:
        ...


#: What an input argument ``u=`` accepts: none, a constant vector, ``t -> u``, an exosystem.
InputSignal: TypeAlias = "InputFunction | Exogenous | ArrayLike | None"

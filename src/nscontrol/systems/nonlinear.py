"""Smooth nonlinear flows ``x' = f(t, x)`` or ``x' = f(t, x, u(t))``.

:class:`NonlinearSystem` is the smooth member of the switched family: a Filippov system with
no switching surface. ``simulate(..., method="switching")`` integrates it by the same DOP853
pieces, and with ``sensitivity=True`` returns the state transition ``∂x(tf)/∂x(t0)`` from the
variational equation ``Φ' = (∂f/∂x) Φ`` — what shooting for periodic orbits
(:func:`nscontrol.analysis.orbits.find_cycle`, :func:`~nscontrol.analysis.orbits.find_orbit`)
needs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validation import FloatArray, check_integer
from ..errors import DimensionError, ModelError
from ..numerics.differences import central_difference_jacobian
from .lure import as_input_function
from .switched import _probe_state, _require_finite

if TYPE_CHECKING:
    from .protocols import InputSignal

__all__ = ["NonlinearSystem"]


@dataclass(frozen=True, eq=False)
class NonlinearSystem:
    """A smooth vector field ``x' = f(t, x)`` (or ``f(t, x, u)`` with an input).

    Parameters
    ----------
    n_states : int
        State dimension.
    field : callable
        ``field(t, x) -> (n,) array``; with ``n_inputs > 0``, ``field(t, x, u)`` where ``u``
        is the input's value at ``t`` (shape ``(n_inputs,)``). It must be smooth (at least
        twice continuously differentiable) where the motion goes.
    jacobian : callable, optional
        ``∂field/∂x`` with the field's signature, shape ``(n, n)``; used with
        ``sensitivity=True`` (default: central differences of ``field``, relative error
        ``~ε^{2/3}``).
    n_inputs : int
        Number of inputs (0: an autonomous or explicitly time-dependent field).
    u : Exosystem or callable or array_like, optional
        The default input ``u(t)`` (``simulate(..., u=...)`` overrides it); zero when not
        given.
    state_names : tuple of str, optional
        Names of the state components.

    Raises
    ------
    DimensionError
        ``n_states`` or ``n_inputs`` not an integer of the right range, a field or a
        Jacobian of the wrong shape, or ``state_names`` of the wrong length.
    ModelError
        ``field`` or ``jacobian`` not callable, non-finite values at a probe state, or an
        input ``u`` without ``n_inputs``.

    Examples
    --------
    Van der Pol's oscillator ``x'' - ε(1 - x²)x' + x = 0`` and its state transition:

    >>> from nscontrol import simulate
    >>> eps = 0.1
    >>> vdp = NonlinearSystem(2, lambda t, x: np.array([x[1], -x[0] + eps * (1 - x[0]**2) * x[1]]),
    ...                       state_names=("x", "v"))
    >>> tr = simulate(vdp, [2.0, 0.0], (0.0, 1.0), sensitivity=True)
    >>> tr.stats["state_transition"].shape
    (2, 2)
    """

    n_states: int
    field: Callable[..., Any]
    jacobian: Callable[..., Any] | None = None
    n_inputs: int = 0
    u: Any = None
    state_names: tuple[str, ...] = ()

    default_method = "switching"

    if TYPE_CHECKING:
        def __init__(self, n_states: int, field: Callable[..., Any],
                     jacobian: Callable[..., Any] | None = None, n_inputs: int = 0,
                     u: InputSignal = None, state_names: tuple[str, ...] = ()) -> None: ...

    def __post_init__(self) -> None:
        n = check_integer("n_states", self.n_states, minimum=1, error=DimensionError)
        m = check_integer("n_inputs", self.n_inputs, minimum=0, error=DimensionError)
        object.__setattr__(self, "n_states", n)
        object.__setattr__(self, "n_inputs", m)
        if not callable(self.field):
            raise ModelError(f"field: expected a callable field(t, x{', u' if m else ''}) -> "
                             f"({n},) array, got {type(self.field).__name__}")
        if self.jacobian is not None and not callable(self.jacobian):
            raise ModelError(f"jacobian: expected a callable jacobian(t, x{', u' if m else ''})"
                             f" -> ({n}, {n}) array, got {type(self.jacobian).__name__}")
        if self.u is not None and m == 0:
            raise ModelError("u: an input was given but n_inputs = 0; set n_inputs to its "
                             "length and make field take (t, x, u)")
        object.__setattr__(self, "_u_fn", as_input_function("u", self.u, m) if m else None)
        object.__setattr__(self, "state_names", tuple(self.state_names))
        if self.state_names and len(self.state_names) != n:
            raise DimensionError(f"state_names: expected {n} names, got "
                                 f"{len(self.state_names)}")
        self._probe()

    def _probe(self) -> None:
        """Evaluate the field (and the Jacobian) once at a generic state: wrong shapes and
        non-finite values are refused here rather than deep inside a run."""
        x = _probe_state(self.n_states)
        u = self.input_at(0.0)
        where = f"at t = 0, x = {np.array2string(x, precision=4)}"
        f = self.rhs(0.0, x, u)
        if f.shape != (self.n_states,):
            raise DimensionError(f"field: expected field(t, x) of shape ({self.n_states},), "
                                 f"got {f.shape}")
        _require_finite("field", f, where)
        if self.jacobian is not None:
            J = np.asarray(self._call(self.jacobian, 0.0, x, u), float)
            if J.shape != (self.n_states, self.n_states):
                raise DimensionError(f"jacobian: expected shape ({self.n_states}, "
                                     f"{self.n_states}), got {J.shape}")
            _require_finite("jacobian", J, where)

    def _call(self, fn: Callable[..., Any], t: float, x: FloatArray, u: FloatArray | None
              ) -> Any:
        return fn(t, x) if self.n_inputs == 0 else fn(t, x, u)

    def input_function(self, u: Any = None) -> Callable[[float], FloatArray | None]:
        """The input as a function of time, ``t -> u(t)``.

        Parameters
        ----------
        u : InputSignal, optional
            An input overriding the system's ``u``.

        Returns
        -------
        callable ``t -> ndarray (n_inputs,) or None``
            ``None`` at every ``t`` without inputs; zeros when no input signal is given.

        Raises
        ------
        ModelError
            ``u`` given for a system without inputs.
        """
        m = self.n_inputs
        if m == 0:
            if u is not None:
                raise ModelError("u: an input was given but the system has n_inputs = 0")
            return lambda t: None
        fn = self.__dict__["_u_fn"] if u is None else as_input_function("u", u, m)
        if fn is None:
            zero = np.zeros(m)
            return lambda t: zero
        return lambda t: np.asarray(fn(t), float).reshape(m)

    def input_at(self, t: float) -> FloatArray | None:
        """The system's input at ``t`` (``None`` without inputs, zeros when not given).

        Parameters
        ----------
        t : float
            Time.
        """
        return self.input_function()(t)

    def rhs(self, t: float, x: FloatArray, u: FloatArray | None = None) -> FloatArray:
        """The field ``f(t, x[, u])`` as a float array.

        Parameters
        ----------
        t : float
            Time.
        x : (n,) array_like
            State.
        u : (n_inputs,) array_like, optional
            The input's value (ignored without inputs).

        Returns
        -------
        ndarray, shape (n,)
        """
        return np.asarray(self._call(self.field, t, x, u), float)

    def jac(self, t: float, x: FloatArray, u: FloatArray | None = None) -> FloatArray:
        """``∂f/∂x``: the user's ``jacobian``, or central differences of the field.

        Parameters
        ----------
        t : float
            Time.
        x : (n,) array_like
            State.
        u : (n_inputs,) array_like, optional
            The input's value (ignored without inputs).

        Returns
        -------
        ndarray, shape (n, n)
        """
        if self.jacobian is not None:
            return np.asarray(self._call(self.jacobian, t, x, u), float)
        return central_difference_jacobian(lambda xx: self.rhs(t, xx, u),
                                           np.asarray(x, float))

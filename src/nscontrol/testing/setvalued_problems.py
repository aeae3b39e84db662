"""Canonical set-valued and switched problems with known answers.

Each builder returns a frozen :class:`SetValuedProblem`: the model(s), the initial state and
span, and the exact facts a correct integrator must reproduce (reaching time, equivalent
control, closed-form solution pieces).

* :func:`relay_scalar` — ``x' = -sign(x) + d(t)``, ``d = a sin t`` (``|a| < 1``): reaching
  time root of ``x0 - t + a(1 - cos t) = 0``, then sliding ``x ≡ 0`` with equivalent control
  ``w_eq = -d(t)``.
* :func:`relay_feedback` — the Siconos relay example ``x' = Ax + Gw``, ``w ∈ -Sign(x1 + x2)``,
  ``A = [[0, 1], [0, 0]]``: reaching at ``√3 - 1`` from ``(1, 0)``, then ``x1 = x1* e^{-(t -
  t*)}``, ``x2 = -x1`` and ``w_eq = x1``.
* :func:`bimodal_oscillator` — one-sided spring under harmonic forcing (ch11 example A), a
  continuous PWA system.
* :func:`diode_circuit` — RLC circuit with an ideal diode (ch08 §5.4) discharging from
  ``v_C = 1``: linear until ``v_C`` reaches 0, then clamped with diode current ``λ = i_L``
  and ``i_L' = -(R2/L1) i_L``.
* :func:`coulomb_oscillator` — forced mass–spring with Coulomb friction (ch08 §5.2): stick–slip,
  as a Lur'e system and as the equivalent Filippov system.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from ..errors import ModelError

__all__ = ["SetValuedProblem", "relay_scalar", "relay_feedback", "bimodal_oscillator",
           "diode_circuit", "coulomb_oscillator"]


@dataclass(frozen=True, eq=False)
class SetValuedProblem:
    """A model with known answers.

    Attributes
    ----------
    name
        Short identifier.
    system
        The model for its default integrator (``LureSystem`` or ``PiecewiseAffineSystem``).
    x0, t_span
        Initial state and time span.
    switched
        The same dynamics as a switched model for ``method="switching"`` (or ``None``).
    facts
        Known values: ``reaching_time``, ``exact`` (callable ``t -> x``), ``equivalent_control``
        (callable ``t -> w``), ... depending on the problem.
    """

    name: str
    system: Any
    x0: np.ndarray
    t_span: tuple[float, float]
    switched: Any = None
    facts: dict[str, Any] = field(default_factory=dict)


def relay_scalar(amplitude: float = 0.5, x0: float = 1.0, T: float = 4.0,
                 input: Literal["exosystem", "function"] = "exosystem") -> SetValuedProblem:
    """``x' = w + d(t)``, ``w ∈ -Sign(x)``, ``d = amplitude·sin t``.

    Parameters
    ----------
    amplitude : float, optional
        ``|amplitude| < 1``, so that the relay dominates and the motion slides on ``x = 0``.
    x0 : float, optional
        Initial state.
    T : float, optional
        End of the span.
    input : {"exosystem", "function"}, optional
        How ``d`` is given to the Lur'e system: as an
        :class:`~nscontrol.numerics.lti.Exosystem` (implicit Euler then uses its exact mean
        over each step) or as a plain function of time (sampled at the step ends).

    Returns
    -------
    SetValuedProblem
        ``system`` (LureSystem), ``switched`` (FilippovSystem) and the facts
        ``reaching_time``, ``exact`` (``t -> x``), ``equivalent_control`` (``t -> -d(t)``)
        and ``disturbance_mean`` (``(t0, t1) -> (1/(t1-t0)) ∫ d``).

    Raises
    ------
    ModelError
        ``|amplitude| >= 1`` (no sliding), or an unknown ``input``.

    Examples
    --------
    >>> p = relay_scalar()
    >>> round(p.facts["reaching_time"], 6)
    1.429672
    """
    from scipy.optimize import brentq

    from ..laws.relay import Relay
    from ..numerics.lti import Exosystem
    from ..systems.lure import LureSystem
    from ..systems.switched import FilippovSystem

    if not abs(amplitude) < 1.0:
        raise ModelError(f"amplitude: expected |amplitude| < 1 for sliding, got {amplitude}")
    if input not in ("exosystem", "function"):
        raise ModelError(f"input: expected 'exosystem' or 'function', got {input!r}")
    d = _Sine(amplitude)
    u = Exosystem.sinusoid(amplitude, 1.0) if input == "exosystem" else d.column
    lure = LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0), B=[[1.0]], u=u)
    fil = FilippovSystem.two_sided(lambda t, x: np.array([1.0 + d(t)]),
                                   lambda t, x: np.array([-1.0 + d(t)]),
                                   lambda x: float(x[0]), 1, gradient=lambda x: np.ones(1))
    s = np.sign(x0)
    t_r = brentq(lambda t: x0 - s * t + amplitude * (1.0 - np.cos(t)), 1e-9,
                 abs(x0) / (1.0 - abs(amplitude)) + 1.0, xtol=1e-15)

    def exact(t: Any) -> np.ndarray:
        t = np.asarray(t, float)
        return np.where(t < t_r, x0 - s * t + amplitude * (1.0 - np.cos(t)), 0.0)

    def disturbance_mean(t0: Any, t1: Any) -> np.ndarray:
        t0, t1 = np.asarray(t0, float), np.asarray(t1, float)
        return amplitude * (np.cos(t0) - np.cos(t1)) / (t1 - t0)

    return SetValuedProblem("relay-scalar", lure, np.array([x0]), (0.0, T), fil,
                            {"reaching_time": t_r, "exact": exact,
                             "equivalent_control": lambda t: -d(np.asarray(t, float)),
                             "disturbance_mean": disturbance_mean})


class _Sine:
    """``d(t) = a sin t`` as a picklable callable (``column``: shape ``(len(t), 1)``)."""

    def __init__(self, amplitude: float) -> None:
        self.amplitude = float(amplitude)

    def __call__(self, t: Any) -> Any:
        return self.amplitude * np.sin(t)

    def column(self, t: Any) -> np.ndarray:
        return np.reshape(self(np.asarray(t, float)), (-1, 1))


def relay_feedback(T: float = 10.0) -> SetValuedProblem:
    """Siconos' relay Lur'e example: reaching at ``√3 - 1``, sliding on ``x1 + x2 = 0``.

    Parameters
    ----------
    T : float, optional
        End of the span.

    Returns
    -------
    SetValuedProblem
        ``system`` (LureSystem ``x' = Ax + Gw``, ``w ∈ -Sign(x1 + x2)``), ``switched``
        (FilippovSystem given as data, which ``method="switching"`` runs in its compiled
        loop) and the facts ``reaching_time``, ``exact`` and ``equivalent_control``
        (``w_eq = x1`` in sliding).

    Examples
    --------
    >>> p = relay_feedback()
    >>> bool(abs(p.facts["reaching_time"] - (np.sqrt(3) - 1)) < 1e-15), p.x0.tolist()
    (True, [1.0, 0.0])
    """
    from ..laws.relay import Relay
    from ..systems.lure import LureSystem
    from ..systems.switched import FilippovSystem

    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    c = np.array([1.0, 1.0])
    lure = LureSystem(A, G, c[None, :], Relay(1.0), C=c[None, :], state_names=("x1", "x2"))
    # as data (a relay on a linear plant): method="switching" runs it in its compiled loop
    fil = FilippovSystem.two_sided((A, G[:, 0]), (A, -G[:, 0]), c, 2, state_names=("x1", "x2"))
    t_r = np.sqrt(3.0) - 1.0
    x1r = 1.0 - t_r**2 / 2.0

    def exact(t: Any) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        before = np.column_stack([1.0 - t**2 / 2.0, -t])
        x1 = x1r * np.exp(-(t - t_r))
        after = np.column_stack([x1, -x1])
        return np.where((t < t_r)[:, None], before, after)

    return SetValuedProblem("relay-feedback", lure, np.array([1.0, 0.0]), (0.0, T), fil,
                            {"reaching_time": t_r, "exact": exact,
                             "equivalent_control": lambda t: exact(t)[:, 0]})


def bimodal_oscillator(c: float = 0.1, k: float = 1.0, ks: float = 5.0, amplitude: float = 1.0,
                       omega: float = 2.9) -> SetValuedProblem:
    """One-sided spring (stiffness ``ks`` engaged for ``q < 0``) under ``a sin(ωt)``: ch11 A.

    Parameters
    ----------
    c, k, ks : float, optional
        Damping, stiffness of the free side, extra stiffness of the one-sided spring.
    amplitude, omega : float, optional
        Forcing ``amplitude · sin(omega t)`` (an Exosystem input: exact propagation).

    Returns
    -------
    SetValuedProblem
        ``system`` (a continuous bimodal PiecewiseAffineSystem) over 20 forcing periods and
        the facts ``rhs`` (the field for an ODE reference), ``period`` and ``omega``.

    Examples
    --------
    >>> p = bimodal_oscillator()
    >>> p.system.n_regions, p.system.continuous
    (2, True)
    """
    from ..numerics.lti import Exosystem
    from ..systems.pwa import PiecewiseAffineSystem

    A_free = np.array([[0.0, 1.0], [-k, -c]])
    A_spring = np.array([[0.0, 1.0], [-(k + ks), -c]])
    pwa = PiecewiseAffineSystem.bimodal(A_spring, A_free, [1.0, 0.0], E=[[0.0], [1.0]],
                                        u=Exosystem.sinusoid(amplitude, omega),
                                        state_names=("q", "v"))

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        A = A_spring if x[0] < 0.0 else A_free
        return A @ x + np.array([0.0, amplitude * np.sin(omega * t)])

    return SetValuedProblem("bimodal-oscillator", pwa, np.array([0.5, 0.0]),
                            (0.0, 40.0 * np.pi / omega), None,
                            {"rhs": rhs, "period": 2 * np.pi / omega, "omega": omega})


def diode_circuit(R1: float = 1.0, C1: float = 1.0, L1: float = 1.0, R2: float = 0.5,
                  T: float = 6.0) -> SetValuedProblem:
    """RLC circuit with an ideal diode clamping ``v_C >= 0`` (ch08 §5.4), source off.

    From ``(v_C, i_L) = (1, 0)`` the circuit rings linearly until ``v_C`` reaches 0 at
    ``t*``; from then on ``v_C ≡ 0``, ``i_L = i_L(t*) e^{-(R2/L1)(t - t*)}`` and the diode
    current is ``λ = i_L``.

    Parameters
    ----------
    R1, C1, L1, R2 : float, optional
        Circuit parameters (ch08 §5.4).
    T : float, optional
        End of the span; ``v_C`` must reach 0 before it.

    Returns
    -------
    SetValuedProblem
        ``system`` (LureSystem with a ``Complementarity`` law) and the facts ``clamp_time``,
        ``exact`` and ``diode_current``.

    Raises
    ------
    ModelError
        ``v_C`` does not reach 0 within ``T``.

    Examples
    --------
    >>> p = diode_circuit()
    >>> bool(0.0 < p.facts["clamp_time"] < p.t_span[1])
    True
    """
    from ..laws.normal_cone import Complementarity
    from ..numerics.lti import LTIFlow, first_event
    from ..systems.lure import LureSystem

    A = np.array([[-1.0 / (R1 * C1), -1.0 / C1], [1.0 / L1, -R2 / L1]])
    G = np.array([[1.0 / C1], [0.0]])
    H = np.array([[1.0, 0.0]])
    lure = LureSystem(A, G, H, Complementarity(1), state_names=("v_C", "i_L"))
    x0 = np.array([1.0, 0.0])
    flow = LTIFlow(A)
    ev = first_event(flow, x0, H, [0.0], T)
    if ev is None:
        raise ModelError(f"T: v_C does not reach 0 within T = {T:g}; increase T")
    t_c = float(ev.t)
    i_c = float(np.asarray(flow.propagate(x0, t_c)).reshape(-1)[1])

    def exact(t: Any) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        free = np.asarray(flow.propagate(x0, np.minimum(t, t_c))).reshape(t.size, 2)
        clamped = np.column_stack([np.zeros_like(t), i_c * np.exp(-(R2 / L1) * (t - t_c))])
        return np.where((t < t_c)[:, None], free, clamped)

    def diode_current(t: Any) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        return np.where(t < t_c, 0.0, exact(t)[:, 1])

    return SetValuedProblem("diode-circuit", lure, x0, (0.0, T), None,
                            {"clamp_time": t_c, "exact": exact, "diode_current": diode_current})


def coulomb_oscillator(friction: float = 1.0, amplitude: float = 2.0, T: float = 12.0
                       ) -> SetValuedProblem:
    """``q'' + q = u(t) - T_f``, ``T_f ∈ F_c Sign(q')``, ``u = a sin t`` (ch08 §5.2, ``c = 0``).

    Sticking (``q' = 0``) lasts while ``|u - q| <= F_c``; the Filippov form slides on ``q' = 0``
    exactly then.

    Parameters
    ----------
    friction : float, optional
        Coulomb level ``F_c``.
    amplitude : float, optional
        Forcing amplitude ``a``.
    T : float, optional
        End of the span.

    Returns
    -------
    SetValuedProblem
        ``system`` (LureSystem with a ``Coulomb`` law), ``switched`` (FilippovSystem sliding on
        ``q' = 0``) and the fact ``friction``.

    Examples
    --------
    >>> p = coulomb_oscillator()
    >>> p.system.n_states, p.switched.n_surfaces
    (2, 1)
    """
    from ..laws.friction import Coulomb
    from ..systems.lure import LureSystem
    from ..systems.switched import FilippovSystem

    A = np.array([[0.0, 1.0], [-1.0, 0.0]])
    e2 = np.array([0.0, 1.0])
    u = _Sine(amplitude)
    lure = LureSystem(A, e2[:, None], e2[None, :], Coulomb(friction, 1.0), B=e2[:, None],
                      u=u.column, state_names=("q", "v"))
    fil = FilippovSystem.two_sided(lambda t, x: A @ x + e2 * (u(t) + friction),
                                   lambda t, x: A @ x + e2 * (u(t) - friction),
                                   lambda x: float(x[1]), 2, gradient=lambda x: e2,
                                   state_names=("q", "v"))
    return SetValuedProblem("coulomb-oscillator", lure, np.array([1.0, 0.0]), (0.0, T), fil,
                            {"friction": friction})


PROBLEMS: dict[str, Callable[..., SetValuedProblem]] = {
    "relay-scalar": relay_scalar, "relay-feedback": relay_feedback,
    "bimodal-oscillator": bimodal_oscillator, "diode-circuit": diode_circuit,
    "coulomb-oscillator": coulomb_oscillator,
}

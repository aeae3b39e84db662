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
from typing import Any

import numpy as np

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


def relay_scalar(amplitude: float = 0.5, x0: float = 1.0, T: float = 4.0) -> SetValuedProblem:
    """``x' = w + d(t)``, ``w ∈ -Sign(x)``, ``d = amplitude·sin t``."""
    from scipy.optimize import brentq

    from ..laws.relay import Relay
    from ..systems.lure import LureSystem
    from ..systems.switched import FilippovSystem

    if not abs(amplitude) < 1.0:
        raise ValueError(f"amplitude: expected |amplitude| < 1 for sliding, got {amplitude}")
    d = lambda t: amplitude * np.sin(t)  # noqa: E731
    lure = LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0), B=[[1.0]],
                      u=lambda t: np.reshape(d(np.asarray(t, float)), (-1, 1)))
    fil = FilippovSystem.two_sided(lambda t, x: np.array([1.0 + d(t)]),
                                   lambda t, x: np.array([-1.0 + d(t)]),
                                   lambda x: float(x[0]), 1, gradient=lambda x: np.ones(1))
    s = np.sign(x0)
    t_r = brentq(lambda t: x0 - s * t + amplitude * (1.0 - np.cos(t)), 1e-9,
                 abs(x0) / (1.0 - abs(amplitude)) + 1.0, xtol=1e-15)

    def exact(t: Any) -> np.ndarray:
        t = np.asarray(t, float)
        return np.where(t < t_r, x0 - s * t + amplitude * (1.0 - np.cos(t)), 0.0)

    return SetValuedProblem("relay-scalar", lure, np.array([x0]), (0.0, T), fil,
                            {"reaching_time": t_r, "exact": exact,
                             "equivalent_control": lambda t: -d(np.asarray(t, float))})


def relay_feedback(T: float = 10.0) -> SetValuedProblem:
    """Siconos' relay Lur'e example: reaching at ``√3 - 1``, sliding on ``x1 + x2 = 0``."""
    from ..laws.relay import Relay
    from ..systems.lure import LureSystem
    from ..systems.switched import FilippovSystem

    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    c = np.array([1.0, 1.0])
    lure = LureSystem(A, G, c[None, :], Relay(1.0), C=c[None, :], state_names=("x1", "x2"))
    fil = FilippovSystem.two_sided(lambda t, x: A @ x + G[:, 0], lambda t, x: A @ x - G[:, 0],
                                   lambda x: float(c @ x), 2, gradient=lambda x: c,
                                   state_names=("x1", "x2"))
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
    """One-sided spring (stiffness ``ks`` engaged for ``q < 0``) under ``a sin(ωt)``: ch11 A."""
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
        raise ValueError("diode_circuit: v_C does not reach 0 within T; increase T")
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
    """
    from ..laws.friction import Coulomb
    from ..systems.lure import LureSystem
    from ..systems.switched import FilippovSystem

    A = np.array([[0.0, 1.0], [-1.0, 0.0]])
    e2 = np.array([0.0, 1.0])
    u = lambda t: amplitude * np.sin(t)  # noqa: E731
    lure = LureSystem(A, e2[:, None], e2[None, :], Coulomb(friction, 1.0), B=e2[:, None],
                      u=lambda t: np.reshape(u(np.asarray(t, float)), (-1, 1)),
                      state_names=("q", "v"))
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

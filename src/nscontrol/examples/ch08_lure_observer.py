"""Chapter 8: passivity-based observers for Lur'e systems with maximal monotone maps.

Scenarios of spec ``ch08-lure-observer`` §5 (5.1 is public Siconos code, the others are our
constructions), the observer designs, implicit Euler simulations of plant + observer as one
system, the §6 acceptance checks and the figures.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import Example

__all__ = ["Scenario", "siconos_observer_lcs", "coulomb_oscillator", "not_passifiable",
           "diode_circuit", "relay_relative_degree_one", "relay_relative_degree_three",
           "rotor_standin", "EXAMPLES"]


@dataclass(frozen=True, eq=False)
class Scenario:
    """One example plant: matrices, law, input and initial states.

    ``law`` is a zero-argument factory (laws are imported lazily); ``u`` and ``g`` are
    functions of time (scalar or array), or ``None``.
    """

    name: str
    A: np.ndarray
    G: np.ndarray
    H: np.ndarray
    C: np.ndarray
    law: Callable[[], Any]
    B: np.ndarray | None = None
    D: np.ndarray | None = None
    u: Callable[[Any], Any] | None = None
    g: Callable[[Any], Any] | None = None
    x0: np.ndarray = field(default_factory=lambda: np.zeros(0))
    xhat0: np.ndarray = field(default_factory=lambda: np.zeros(0))
    T: float = 1.0
    state_names: tuple[str, ...] = ()

    def plant(self) -> Any:
        """The plant as a :class:`~nscontrol.systems.lure.LureSystem`."""
        from ..systems.lure import LureSystem

        return LureSystem(self.A, self.G, self.H, self.law(), B=self.B, C=self.C, D=self.D,
                          u=self.u, g=self.g, state_names=self.state_names)

    @property
    def matrices(self) -> dict[str, Any]:
        """``A, G, H, C, D`` as keyword arguments of the LMI functions."""
        return {"A": self.A, "G": self.G, "H": self.H, "C": self.C, "D": self.D}


def _col(*v: float) -> np.ndarray:
    return np.array(v, dtype=float).reshape(-1, 1)


def _row(*v: float) -> np.ndarray:
    return np.array(v, dtype=float).reshape(1, -1)


def _complementarity() -> Any:
    from ..laws.set_valued import Complementarity

    return Complementarity(1)


def _relay(c: float = 1.0) -> Callable[[], Any]:
    def make() -> Any:
        from ..laws.set_valued import Relay

        return Relay(c)
    return make


def siconos_observer_lcs() -> Scenario:
    """5.1: the Siconos ObserverLCS complementarity system (``P = I``, ``L = [1, 1]ᵀ``)."""
    def u(t: Any) -> Any:
        return 30.0 * np.sin(50.0 * np.asarray(t, dtype=float))

    return Scenario(
        name="5.1 Siconos ObserverLCS", A=np.array([[1.0, 1.0], [3.0, 1.0]]), G=_col(-1, 1),
        H=_row(-1, 1), C=_row(2, 2), law=_complementarity, B=_col(1, 2), D=np.eye(1), u=u,
        g=u, x0=np.array([10.0, 0.0]), xhat0=np.zeros(2), T=2.0, state_names=("x1", "x2"))


#: Certificate of 5.1 given with the public example.
SICONOS_L = _col(1, 1)


def coulomb_oscillator(c: float = 0.0) -> Scenario:
    """5.2: mass–spring with Coulomb friction ``F_c Sign(q')``, position measured."""
    m, k, fc = 1.0, 1.0, 1.0

    def u(t: Any) -> Any:
        return 2.0 * np.sin(np.asarray(t, dtype=float))

    return Scenario(
        name=f"5.2 Coulomb oscillator (c = {c:g})", A=np.array([[0.0, 1.0], [-k / m, -c / m]]),
        G=_col(0, 1 / m), H=_row(0, 1), C=_row(1, 0), law=_relay(fc), B=_col(0, 1 / m), u=u,
        x0=np.array([1.0, 0.0]), xhat0=np.array([-1.0, 2.0]), T=12.0, state_names=("q", "v"))


def not_passifiable() -> Scenario:
    """5.3: ``C G = 0`` and ``H G = -1 < 0``: no observer of this class exists."""
    return Scenario(name="5.3 not passifiable", A=np.array([[0.0, 1.0], [0.0, 0.0]]),
                    G=_col(0, 1), H=_row(0, -1), C=_row(1, 0), law=_relay())


def diode_circuit() -> Scenario:
    """5.4: RC–RL circuit with an ideal diode; inductor current measured (``u = sin t``)."""
    R1 = C1 = L1 = 1.0
    R2 = 0.5

    def u(t: Any) -> Any:
        return np.sin(np.asarray(t, dtype=float))

    return Scenario(
        name="5.4 diode circuit",
        A=np.array([[-1 / (R1 * C1), -1 / C1], [1 / L1, -R2 / L1]]), G=_col(1 / C1, 0),
        H=_row(1, 0), C=_row(0, 1), law=_complementarity, B=_col(1 / (R1 * C1), 0), u=u,
        x0=np.array([0.5, 0.0]), xhat0=np.array([2.0, -1.0]), T=10.0,
        state_names=("v_C", "i_L"))


def relay_relative_degree_one(measure: str = "z") -> Scenario:
    """5.5: relay feedback, transfer ``(s+2)/((s+1)(s+3))``; ``measure="z"``: ``C = H``."""
    if measure not in ("z", "x1"):
        raise ValueError(f"measure: expected 'z' or 'x1', got {measure!r}")
    H = _row(2, 1)

    def u(t: Any) -> Any:
        return 3.0 * np.sin(2.0 * np.asarray(t, dtype=float))

    return Scenario(
        name=f"5.5 relay feedback (y = {'z' if measure == 'z' else 'x1'})",
        A=np.array([[0.0, 1.0], [-3.0, -4.0]]), G=_col(0, 1), H=H,
        C=H.copy() if measure == "z" else _row(1, 0), law=_relay(), B=_col(0, 1), u=u,
        x0=np.array([1.0, -1.0]), xhat0=np.array([-1.0, 1.0]), T=5.0)


def relay_relative_degree_three() -> Scenario:
    """5.5 (end): relative degree three, ``H G = 0``: infeasible."""
    return Scenario(name="5.5 relative degree three",
                    A=np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -3.0, -3.0]]),
                    G=_col(0, 0, 1), H=_row(1, 0, 0), C=_row(1, 0, 0), law=_relay())


#: Parameters of the two-inertia rotor stand-in (spec 5.7).
ROTOR = {"J_u": 0.5, "J_l": 0.05, "k_theta": 0.08, "b_u": 2.0, "T_s": 0.3, "T_c": 0.1,
         "omega_s": 1.0, "delta": 2.0, "b": 0.01, "sigma": 0.161553}


def rotor_standin(output: str = "alpha") -> Scenario:
    """5.7: two-inertia rotor, Stribeck friction on the lower disc, loop-transformed.

    ``A`` is the loop-transformed matrix of the spec (``σ/J_l`` in the last diagonal entry);
    the law is the monotone part ``friction + σ id`` (see :func:`rotor_law`).
    ``output``: ``"alpha"`` (twist), ``"omega_u"`` or ``"both"``.
    """
    p = ROTOR
    C = {"alpha": _row(1, 0, 0), "omega_u": _row(0, 1, 0),
         "both": np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])}[output]
    A = np.array([[0.0, 1.0, -1.0],
                  [-p["k_theta"] / p["J_u"], -p["b_u"] / p["J_u"], 0.0],
                  [p["k_theta"] / p["J_l"], 0.0, p["sigma"] / p["J_l"]]])

    def u(t: Any) -> Any:  # motor torque on the upper disc (our choice)
        return 1.0 + 0.5 * np.sin(0.5 * np.asarray(t, dtype=float))

    return Scenario(name=f"5.7 rotor stand-in (y = {output})", A=A, G=_col(0, 0, 1 / p["J_l"]),
                    H=_row(0, 0, 1), C=C, law=rotor_law, B=_col(0, 1 / p["J_u"], 0), u=u,
                    x0=np.array([0.0, 0.0, 0.0]), xhat0=np.array([0.5, 0.5, -0.5]), T=30.0,
                    state_names=("alpha", "omega_u", "omega_l"))


def rotor_law() -> Any:
    """Monotone part ``φ_m = Stribeck + σ id`` of the lower-disc friction (spec 5.7)."""
    from ..laws.set_valued import Stribeck

    p = ROTOR
    law = Stribeck(static=p["T_s"], coulomb=p["T_c"], stribeck_velocity=p["omega_s"],
                   delta=p["delta"], viscous=p["b"])
    return law.loop_transformation(p["sigma"]).monotone_part


EXAMPLES: list[Example] = []

"""User code the typed public surface must accept (checked by mypy in tests/test_typing.py).

Matrices as nested lists, inputs as plain functions, listeners and controllers as plain
functions and classes without any nscontrol base class: the protocols are structural.
"""

from __future__ import annotations

import numpy as np

import nscontrol as nsc
from nscontrol.design.lure_observer import design_lure_observer
from nscontrol.laws.relay import Relay
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems.feedback import Jump, Measurement, StateFeedback
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.protocols import SimulableSystem


def on_impact(t: float, x_minus: np.ndarray, x_plus: np.ndarray, indices: np.ndarray,
              impulse: np.ndarray | None) -> None:
    print(t, x_minus, x_plus, indices, impulse)


def push(t: float) -> list[float]:
    return [np.sin(t)]


class Integral:
    """A user's sampled controller: no base class, only the attributes of the protocol."""

    n_states, n_outputs = 1, 1

    def __init__(self, period: float) -> None:
        self.period = period

    def output(self, t: float, xc: np.ndarray, m: Measurement) -> np.ndarray:
        return -xc

    def update(self, t: float, xc: np.ndarray, m: Measurement) -> np.ndarray:
        return xc + self.period * m.x[:1]

    def reset(self, t: float, xc: np.ndarray, jump: Jump) -> np.ndarray:
        return xc


def tour() -> None:
    osc = LagrangianSystem(np.eye(1), stiffness=[[1.0]], gap_matrix=[[-1.0]],
                           gap_offset=[0.3], restitution=0.8, actuation=[[1.0]])
    system: SimulableSystem = osc
    nsc.simulate(system, [0.0, 0.0], (0.0, 1.0), u=Exosystem.sinusoid(0.9, 1.7),
                 listeners=[on_impact])
    nsc.simulate(osc, [0.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3, u=push)
    nsc.closed_loop(osc, StateFeedback([[-4.0, -1.0]], k=[5.0]))
    nsc.closed_loop(osc, Integral(0.01))
    plant = LureSystem([[0.0, 1.0], [-1.0, -0.5]], [[0.0], [1.0]], [[0.0, 1.0]], Relay(1.0),
                       C=[[1.0, 0.0]])
    design_lure_observer(plant)

"""User mistakes the typed public surface must reject (tests/test_typing.py counts them).

Each line marked ``# error`` is one mistake mypy must report on that line.
"""

from __future__ import annotations

import nscontrol as nsc
from nscontrol.systems.lagrangian import LagrangianSystem


def mistakes() -> None:
    ball = LagrangianSystem.bouncing_ball()
    nsc.simulate("ball", [1.0, 0.0], (0.0, 1.0))  # error
    nsc.simulate(ball, [1.0, 0.0], (0.0, 1.0), method=3)  # error
    nsc.closed_loop(ball, controller=[[1.0, 2.0]])  # error
    LagrangianSystem(mass=[[1.0]], gap=[[1.0]])  # error

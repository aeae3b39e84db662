"""Optimal control of complementarity systems: trajectory optimisation through contact and
friction, with the plan replayable by the library's own integrator.

A :class:`ContactProblem` transcribes a :class:`~nscontrol.systems.LagrangianSystem` with
unilateral contacts and planar Coulomb friction by the Moreau–Jean step of
``simulate(..., method="moreau_jean")`` (the same θ-method, the same velocity-level contact
law, the same step ``h``), handles the complementarity constraints by a Scholtes relaxation
homotopy solved by IPOPT through CasADi, and returns a :class:`ContactPlan` whose inputs,
replayed through ``simulate`` at the same ``h``, give back its states (``docs/optimal.md``).
A :class:`FesdProblem` plans a piecewise-smooth (Filippov) system in Stewart's form, several
and nonlinear switching surfaces, by finite elements with switch detection
(:class:`SwitchingProblem` and :func:`pwa_problem` are fronts over it).

Needs the ``optimal`` extra (``pip install 'nscontrol[optimal]'``): importing this package
without CasADi raises an ``ImportError`` saying so.
"""

from __future__ import annotations

from ._casadi import require_casadi

require_casadi()

from .cartpole import CartPole  # noqa: E402
from .contact import ContactProblem, Relaxation  # noqa: E402
from .fesd import SwitchingPlan, SwitchingProblem  # noqa: E402
from .lure import LurePlan, LureProblem  # noqa: E402
from .mpc import ContactMPC  # noqa: E402
from .periodic import JugglerPlan, JugglerProblem, VibratingTable  # noqa: E402
from .plan import ContactPlan, ZeroOrderHold  # noqa: E402
from .problems import PushedBlock, SimpleCar, SpeedUp  # noqa: E402
from .pwa import pwa_problem, stewart_form  # noqa: E402
from .stewart import FesdPlan, FesdProblem, HeldInput, StewartSystem  # noqa: E402

__all__ = ["ContactProblem", "Relaxation", "ContactPlan", "ZeroOrderHold", "PushedBlock",
           "SwitchingProblem", "SwitchingPlan", "SpeedUp", "ContactMPC", "CartPole",
           "VibratingTable", "JugglerProblem", "JugglerPlan", "LureProblem", "LurePlan",
           "StewartSystem", "FesdProblem", "FesdPlan", "HeldInput", "stewart_form",
           "pwa_problem", "SimpleCar"]

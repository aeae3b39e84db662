"""Blocks written in Python, stepped beside the plant's integrator.

A :class:`~nscontrol.systems.closed_loop.ClosedLoop` of composition ``"blocks"`` runs its
controller and observer as code at the start of every step (zero-order hold over the step):

* around a :class:`LagrangianSystem` or :class:`ImpactingBodies`: Moreau–Jean on the plant,
  the blocks fed the contact multipliers ``λ̂`` and reset at impacts (a listener);
* around a :class:`LureSystem`: implicit Euler on the plant, its set-valued law solved every
  step (chapter 7's digital friction compensation);
* around a :class:`SlidingModePlant`: ``sampled_zoh``, the plant stepped exactly between the
  sampled controller's ticks.

Each integrator is given the loop's
:class:`~nscontrol.simulate._block_runner.BlockRunner` as its internal option ``blocks=``;
it runs the blocks' compiled forms inside its compiled loop when every block has one
(``CompiledBlocks.of(runner)``), else the runner's Python methods.

Blocks that all offer a compiled form run inside the integrator's compiled loop.
:meth:`PythonBlocks.invert` adds the blocks' signals (``u``, ``xo``, ``xc``, ``xhat``) to the
trajectory.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ...errors import ModelError
from ...systems.closed_loop import ClosedLoop
from .._block_runner import BlockRunner
from .base import Lowered, Lowering, merge_options

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["PythonBlocks"]


class PythonBlocks(Lowering):
    """A ``"blocks"`` closed loop as its plant, its blocks stepped by the plant's
    integrator."""

    name = "run Python blocks"

    def accepts(self, system: Any, method: Any) -> bool:
        return isinstance(system, ClosedLoop) and system.composition == "blocks"

    def apply(self, system: Any, method: Any, x0: Any, options: Mapping[str, Any]
              ) -> Lowered:
        from ...systems.lure import LureSystem
        from ...systems.sliding_mode import SlidingModePlant

        lure = isinstance(system.plant, LureSystem)
        runner, own = (_zoh_options if isinstance(system.plant, SlidingModePlant) else
                       _lure_options if lure else _event_driven_options
                       if method.name == "event_driven" else _mechanical_options)(system, method)
        return Lowered(system.plant, x0, merge_options(options, own), runner)

    def invert(self, traj: Trajectory, lowered: Lowered) -> Trajectory:
        return lowered.data.finish(traj)


def _mechanical_options(loop: ClosedLoop, method: Any) -> tuple[BlockRunner, dict[str, Any]]:
    """Moreau–Jean with the loop's blocks (``blocks=``, stepped before each step; the
    integrator runs their compiled form when it can) and a listener that resets them at
    impacts."""
    if method.name != "moreau_jean":
        raise ModelError(f"{method.name}: this loop's blocks run as Python code stepped with "
                         f"the plant; use method='moreau_jean' (or give the blocks as "
                         f"matrices: StateFeedback, LinearController, LinearObserver)")
    runner = BlockRunner(loop)
    options: dict[str, Any] = {"blocks": runner, "listeners": [runner.on_jump]}
    if loop.exosystem is not None:
        options["u"] = loop.exosystem
    return runner, options


def _event_driven_options(loop: ClosedLoop, method: Any
                          ) -> tuple[BlockRunner, dict[str, Any]]:
    """Event-driven with ``blocks=``: a continuous law without state (a ``StaticLaw``),
    evaluated along the flow."""
    ctrl = loop.controller
    if loop.observer is not None or ctrl is None or int(ctrl.n_states) != 0 or \
            getattr(ctrl, "period", None) is not None:
        raise ModelError("event_driven: runs a closed loop whose controller is a continuous "
                         "law without state (a StaticLaw with period None, no observer), "
                         "evaluated along the flow; use method='moreau_jean' for sampled or "
                         "dynamic blocks and observers")
    runner = BlockRunner(loop)
    options: dict[str, Any] = {"blocks": runner}
    if loop.exosystem is not None:
        options["u"] = loop.exosystem
    return runner, options


def _lure_options(loop: ClosedLoop, method: Any) -> tuple[BlockRunner, dict[str, Any]]:
    """Implicit Euler with the loop's block runner (``blocks=``; zero-order hold)."""
    if method.name != "implicit_euler":
        raise ModelError(f"{method.name}: this loop's blocks run as Python code stepped with "
                         f"a LureSystem plant; use method='implicit_euler'")
    if loop.exosystem is not None:
        raise ModelError("exosystem: a Lur'e plant with Python blocks takes its reference "
                         "through the blocks themselves (the plant's input is the controller's "
                         "output)")
    runner = BlockRunner(loop)
    return runner, {"blocks": runner}


def _zoh_options(loop: ClosedLoop, method: Any) -> tuple[BlockRunner, dict[str, Any]]:
    """``sampled_zoh`` with the loop's block runner (``blocks=``: the method checks that it
    holds one sampled controller)."""
    if method.name != "sampled_zoh":
        raise ModelError(f"{method.name}: a {type(loop.plant).__name__} plant runs with its "
                         f"sampled controller by method='sampled_zoh'")
    runner = BlockRunner(loop)
    return runner, {"blocks": runner}

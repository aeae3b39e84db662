"""Static state feedback on a Lagrangian plant, folded into the plant's linear forces.

``u = K [q; v] + k`` entering through ``S`` is a linear force: stiffness ``- S K_q``, damping
``- S K_v``, constant force ``+ S k``. The plant's own model then runs the loop: the exact
event-driven flow of a linear plant (DOP853 for a nonlinear one, the same as the plant alone),
Moreau–Jean's compiled loop, with the feedback implicit in its θ-method — no block is stepped
beside it. A nonlinear plant (``M(q)``, a nonlinear force or gaps, a compiled model) keeps its
own terms: the linear ones are added to them. The loop's exosystem (a reference or a
disturbance entering through the actuation as well) is the folded plant's input ``u``. The
signal ``u`` (the feedback) is added back by :meth:`FoldStateFeedback.invert`.

Impacting bodies reach this lowering through their Lagrangian form
(:class:`~nscontrol.simulate.lowering.impacting_bodies.FeedbackOnLagrangianForm`, which
permutes the gain into the ``[q; v]`` order).
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ...systems.closed_loop import ClosedLoop
from ...systems.lagrangian import LagrangianSystem
from ._signals import Maps, add_loop_signals
from .base import Lowered, Lowering, merge_options

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["FoldStateFeedback", "folded_plant"]

#: One fold per loop (a loop is immutable).
_FOLDS: weakref.WeakKeyDictionary[ClosedLoop, tuple[Any, Maps]] = weakref.WeakKeyDictionary()


class FoldStateFeedback(Lowering):
    """A ``"folded"`` closed loop on a Lagrangian plant as that plant with the feedback
    inside."""

    name = "fold state feedback"

    def accepts(self, system: Any, method: Any) -> bool:
        return isinstance(system, ClosedLoop) and system.composition == "folded" and \
            isinstance(system.plant, LagrangianSystem)

    def apply(self, system: Any, method: Any, x0: Any, options: Mapping[str, Any]
              ) -> Lowered:
        model, maps = folded_plant(system)
        own = {"u": system.exosystem} if system.exosystem is not None else {}
        return Lowered(model, x0, merge_options(options, own), (system, maps))

    def invert(self, traj: Trajectory, lowered: Lowered) -> Trajectory:
        loop, maps = lowered.data
        return add_loop_signals(traj, maps, loop.plant)


def folded_plant(loop: ClosedLoop) -> tuple[Any, Maps]:
    """The plant with the loop's state feedback folded into its forces, and the map of ``u``.

    Parameters
    ----------
    loop : ClosedLoop
        A loop of composition ``"folded"`` (its gain's shape checked at construction). Around
        impacting bodies, the fold is that of their Lagrangian form: its state is ``[q; v]``
        (:meth:`~nscontrol.systems.ImpactingBodies.lagrangian_permutation`).

    Returns
    -------
    LagrangianSystem, dict
    """
    if loop not in _FOLDS:
        if not isinstance(loop.plant, LagrangianSystem):   # impacting bodies
            from .impacting_bodies import lagrangian_loop

            _FOLDS[loop] = folded_plant(lagrangian_loop(loop))
        else:
            _FOLDS[loop] = _fold(loop)
    return _FOLDS[loop]


def _fold(loop: ClosedLoop) -> tuple[Any, Maps]:
    plant, ctrl = loop.plant, loop.controller
    n = plant.n_dof
    S = loop.force_input_matrix()
    Kq, Kv = ctrl.K[:, :n], ctrl.K[:, n:]
    zero = np.zeros((n, n))
    K = (plant.stiffness if plant.stiffness is not None else zero) - S @ Kq
    D = (plant.damping if plant.damping is not None else zero) - S @ Kv
    f0 = (plant.constant_force if plant.constant_force is not None else np.zeros(n)) \
        + S @ ctrl.k
    return (replace(plant, stiffness=K, damping=D, constant_force=f0),
            {"u": (ctrl.K, ctrl.k)})

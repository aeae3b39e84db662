"""Lowerings: how :func:`nscontrol.simulate` runs a system its method does not integrate as
given (a closed loop, impacting bodies), and how a user adds one.

Each lowering has ``accepts(system, method)``, ``apply(system, method, x0, options)`` →
:class:`Lowered` and ``invert(traj, lowered)`` (:mod:`.base`). The built-in ones, tried in
this order, one module each:

=============================================  ===============================================
lowering (module)                              what it does
=============================================  ===============================================
``stack linear blocks`` (:mod:`.stack`)        a loop of linear blocks around a linear plant
                                               as ONE model of the plant's family
``fold state feedback`` (:mod:`.fold`)         continuous state feedback folded into a
                                               Lagrangian plant's linear forces
``run Python blocks`` (:mod:`.python_blocks`)  blocks stepped as code beside the plant's
                                               integrator (the loop's block runner, given
                                               as ``blocks=``)
``Lagrangian form of impacting bodies``        :class:`ImpactingBodies` in the ``[q; v]``
(:mod:`.impacting_bodies`)                     order of their Lagrangian form, and back
``state feedback on impacting bodies``         a state-feedback loop around impacting bodies
(:mod:`.impacting_bodies`)                     as the loop around their Lagrangian form (the
                                               gain permuted), for the fold
=============================================  ===============================================

Lowerings chain: a loop of Python blocks around impacting bodies is first the bodies with the
loop's block runner (``blocks=``), then their Lagrangian form. A closed loop is always
lowered (:func:`needs_lowering`): no integrator is handed one, whatever its ``supports``
says.
"""

from __future__ import annotations

from .base import (
    Lowered,
    Lowering,
    invert_all,
    lower,
    lowerings,
    lowers,
    merge_options,
    needs_lowering,
    register_lowering,
)
from .stack import stacked_model

__all__ = ["Lowering", "Lowered", "register_lowering", "lowerings", "lower", "lowers",
           "needs_lowering", "invert_all", "merge_options", "stacked_model"]

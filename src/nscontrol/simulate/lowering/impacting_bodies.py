"""Impacting bodies through their Lagrangian form, for every method that integrates it.

:class:`~nscontrol.systems.ImpactingBodies` keep the chapter's state order ``[x_a; x_b]``
(positions and velocities of body a, then of body b); their Lagrangian form
(:meth:`~nscontrol.systems.ImpactingBodies.lagrangian`) has ``[q; v]``. The lowering permutes
``x0`` and the states the listeners receive into the Lagrangian order,
and :meth:`LagrangianForm.invert` puts the trajectory (states, names, events) back — a
partial one too, when the run fails.

:class:`FeedbackOnLagrangianForm` does the same for a ``"folded"`` closed loop around the
bodies (continuous :class:`~nscontrol.systems.StateFeedback` ``u = K x + k`` on
``[x_a; x_b]``): the loop becomes the same loop around their Lagrangian form, its gain's
columns permuted into the ``[q; v]`` order, which :mod:`.fold` then folds into the forces.
"""


from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..._validation import check_bool
from ...errors import ModelError
from ...systems.closed_loop import ClosedLoop, closed_loop
from ...systems.feedback import StateFeedback
from ...systems.impacting_bodies import ImpactingBodies
from .base import Lowered, Lowering, lowers

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["LagrangianForm", "FeedbackOnLagrangianForm", "lagrangian_loop"]


class LagrangianForm(Lowering):
    """:class:`ImpactingBodies` as the :class:`LagrangianSystem` they are, for any method
    that integrates that."""

    name = "Lagrangian form of impacting bodies"

    def __init__(self) -> None:
        self._last: tuple[Any, Any] | None = None   # (bodies, their Lagrangian form)

    def _bodies(self, system: Any) -> ImpactingBodies:
        """The impacting bodies whose state order ``system`` has."""
        return system

    def _build(self, system: Any) -> Any:
        """What ``system`` is on the bodies' Lagrangian form."""
        return system.lagrangian()

    def _form(self, system: Any) -> Any:
        if self._last is None or self._last[0] is not system:
            self._last = (system, self._build(system))
        return self._last[1]

    def accepts(self, system: Any, method: Any) -> bool:
        return isinstance(system, ImpactingBodies) and method.supports(self._form(system))

    def apply(self, system: Any, method: Any, x0: Any, options: Mapping[str, Any]
              ) -> Lowered:
        if "sensitivity" in method.capabilities and options.get("sensitivity") is not None \
                and check_bool("sensitivity", options["sensitivity"]):   # in [q; v] order
            raise ModelError(f"sensitivity: {method.name} computes the state transition of a "
                             f"LagrangianSystem, got ImpactingBodies; for an ImpactingBodies "
                             f"pass its .lagrangian() form")
        from ..event_driven import reorder_listeners

        bodies = self._bodies(system)
        perm = bodies.lagrangian_permutation()
        back = np.argsort(perm)
        opts = dict(options)
        listeners = opts.get("listeners", ())
        if _callables(listeners):   # others are refused by the driver as given
            opts["listeners"] = reorder_listeners(listeners, back)
        return Lowered(self._form(system), bodies.check_state(x0)[perm], opts,
                       (back, bodies.state_names))

    def invert(self, traj: Trajectory, lowered: Lowered) -> Trajectory:
        from ..event_driven import reorder_states

        back, names = lowered.data
        return reorder_states(traj, back, names)


class FeedbackOnLagrangianForm(LagrangianForm):
    """A ``"folded"`` closed loop around :class:`ImpactingBodies` as the same loop around
    their Lagrangian form (gain permuted to ``[q; v]``; the state order, listeners and
    trajectory handled as :class:`LagrangianForm` does), for :mod:`.fold` to fold."""

    name = "state feedback on impacting bodies"

    def _bodies(self, system: Any) -> ImpactingBodies:
        return system.plant

    def _build(self, system: Any) -> Any:
        return lagrangian_loop(system)

    def accepts(self, system: Any, method: Any) -> bool:
        return isinstance(system, ClosedLoop) and system.composition == "folded" and \
            isinstance(system.plant, ImpactingBodies) and lowers(self._form(system), method)


def lagrangian_loop(loop: ClosedLoop) -> ClosedLoop:
    """A ``"folded"`` loop around impacting bodies as the same loop around their
    Lagrangian form.

    Parameters
    ----------
    loop : ClosedLoop
        Continuous :class:`StateFeedback` ``u = K x + k`` on the bodies' ``[x_a; x_b]``.

    Returns
    -------
    ClosedLoop
        ``u = K P x_L + k`` on the Lagrangian state ``x_L = [q; v]`` (``P`` the permutation
        :meth:`~nscontrol.systems.ImpactingBodies.lagrangian_permutation`), the same
        exosystem, input matrix and ``compiled``.
    """
    bodies, ctrl = loop.plant, loop.controller
    gain = StateFeedback(ctrl.K[:, bodies.lagrangian_permutation()], ctrl.k)
    return closed_loop(bodies.lagrangian(), gain, exosystem=loop.exosystem,
                       input_matrix=loop.input_matrix, compiled=loop.compiled)


def _callables(listeners: Any) -> bool:
    """Whether ``listeners`` is a sequence of callables (what the driver accepts)."""
    if callable(listeners) or isinstance(listeners, str | bytes):
        return False
    try:
        return all(callable(fn) for fn in listeners)
    except TypeError:   # not iterable
        return False

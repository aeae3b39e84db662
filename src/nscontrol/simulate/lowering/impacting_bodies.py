"""Impacting bodies through their Lagrangian form, for every method that integrates it.

:class:`~nscontrol.systems.ImpactingBodies` keep the chapter's state order ``[x_a; x_b]``
(positions and velocities of body a, then of body b); their Lagrangian form
(:meth:`~nscontrol.systems.ImpactingBodies.lagrangian`) has ``[q; v]``. The lowering permutes
``x0`` and the states the listeners receive into the Lagrangian order,
and :meth:`LagrangianForm.invert` puts the trajectory (states, names, events) back — a
partial one too, when the run fails.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..._validation import check_bool
from ...errors import ModelError
from ...systems.impacting_bodies import ImpactingBodies
from .base import Lowered, Lowering

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["LagrangianForm"]


class LagrangianForm(Lowering):
    """:class:`ImpactingBodies` as the :class:`LagrangianSystem` they are, for any method
    that integrates that."""

    name = "Lagrangian form of impacting bodies"

    def __init__(self) -> None:
        self._last: tuple[Any, Any] | None = None   # (bodies, their Lagrangian form)

    def _form(self, bodies: ImpactingBodies) -> Any:
        if self._last is None or self._last[0] is not bodies:
            self._last = (bodies, bodies.lagrangian())
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

        perm = system.lagrangian_permutation()
        back = np.argsort(perm)
        opts = dict(options)
        listeners = opts.get("listeners", ())
        if _callables(listeners):   # others are refused by the driver as given
            opts["listeners"] = reorder_listeners(listeners, back)
        return Lowered(self._form(system), system.check_state(x0)[perm], opts,
                       (back, system.state_names))

    def invert(self, traj: Trajectory, lowered: Lowered) -> Trajectory:
        from ..event_driven import reorder_states

        back, names = lowered.data
        return reorder_states(traj, back, names)


def _callables(listeners: Any) -> bool:
    """Whether ``listeners`` is a sequence of callables (what the driver accepts)."""
    if callable(listeners) or isinstance(listeners, str | bytes):
        return False
    try:
        return all(callable(fn) for fn in listeners)
    except TypeError:   # not iterable
        return False

"""Lowerings: what turns a system no method integrates as given into one a method does.

A lowering (CVXPY's reductions have the same shape) is three methods:

* :meth:`Lowering.accepts` ``(system, method)``: whether it applies;
* :meth:`Lowering.apply` ``(system, method, x0, options)`` → :class:`Lowered`: the system the
  method integrates next, its initial state, the options of the run (the user's, with what
  the lowering adds or changes) and the data its inverse needs;
* :meth:`Lowering.invert` ``(traj, lowered)``: the method's trajectory back in the terms of
  the original system (its state order and names, its named signals).

:func:`lower` is what :func:`nscontrol.simulate` does before it runs: while the method does
not integrate the system (``method.supports(system)`` is false), the first registered
lowering that accepts it is applied, and the next one to its result, and so on. A closed loop
is always lowered, whatever the method's ``supports`` says (:func:`needs_lowering`): feedback
reaches an integrator one way, as a model (the stack and fold lowerings) and, for blocks run
as code, the loop's block runner in the internal option ``blocks=``. The registry is consulted
in order; :func:`register_lowering` adds a user's lowering (at the end, or with
``first=True`` before the built-in ones).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ...errors import ModelError

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["Lowering", "Lowered", "register_lowering", "lowerings", "lower", "lowers",
           "needs_lowering", "invert_all", "merge_options"]

#: Lowerings applied in a row to one system before the method can run it, at most (a chain
#: longer than this is a pair of lowerings undoing each other).
MAX_CHAIN = 8


@dataclass(frozen=True)
class Lowered:
    """What a system becomes for one method: the result of :meth:`Lowering.apply`.

    Attributes
    ----------
    system
        The system the method integrates (or the next lowering takes).
    x0
        The initial state of ``system``.
    options : mapping
        The run's options: the user's, with what the lowering adds or changes (a
        ``blocks=``, listeners in another state order ...).
    data
        What :meth:`Lowering.invert` needs to map the trajectory back.
    """

    system: Any
    x0: Any
    options: Mapping[str, Any] = field(default_factory=dict)
    data: Any = None


class Lowering:
    """Base class of a lowering (see the module docstring).

    A subclass sets ``name`` and implements :meth:`accepts`, :meth:`apply` and, when the
    trajectory of the lowered system is not already the original's, :meth:`invert`.
    """

    name: str = ""

    def accepts(self, system: Any, method: Any) -> bool:  # pragma: no cover - abstract
        """Whether this lowering applies to ``system`` run by ``method`` (an
        :class:`~nscontrol.simulate.driver.Integrator` subclass)."""
        raise NotImplementedError

    def apply(self, system: Any, method: Any, x0: Any, options: Mapping[str, Any]
              ) -> Lowered:  # pragma: no cover - abstract
        """The lowered system, its ``x0``, the run's options and the inverse's data."""
        raise NotImplementedError

    def invert(self, traj: Trajectory, lowered: Lowered) -> Trajectory:
        """The trajectory of ``lowered.system`` as one of the original system (default: as
        it is)."""
        return traj


class _Registry:
    """The lowerings in the order :func:`lower` tries them; the built-in ones are named by
    ``module:Class`` and imported on first use (``import nscontrol`` stays light)."""

    def __init__(self, builtin: list[str]) -> None:
        self._entries: list[str | Lowering] = list(builtin)

    def resolved(self) -> list[Lowering]:
        for i, entry in enumerate(self._entries):
            if isinstance(entry, str):
                module, _, attr = entry.partition(":")
                self._entries[i] = getattr(importlib.import_module(module), attr)()
        return [entry for entry in self._entries if isinstance(entry, Lowering)]

    def add(self, lowering: Lowering, first: bool) -> None:
        if first:
            self._entries.insert(0, lowering)
        else:
            self._entries.append(lowering)


_REGISTRY = _Registry([
    "nscontrol.simulate.lowering.stack:StackLinearBlocks",
    "nscontrol.simulate.lowering.fold:FoldStateFeedback",
    "nscontrol.simulate.lowering.python_blocks:PythonBlocks",
    "nscontrol.simulate.lowering.impacting_bodies:LagrangianForm",
    "nscontrol.simulate.lowering.impacting_bodies:FeedbackOnLagrangianForm",
])


def register_lowering(lowering: Lowering, *, first: bool = False) -> Lowering:
    """Register a lowering: :func:`nscontrol.simulate` tries it for the systems its method
    does not integrate as given.

    Parameters
    ----------
    lowering : Lowering
        An instance of a :class:`Lowering` subclass.
    first : bool
        Try it before the lowerings registered so far (the built-in ones included) instead
        of after them.

    Returns
    -------
    Lowering
        ``lowering``, registered.

    Raises
    ------
    ModelError
        ``lowering`` is not a :class:`Lowering` instance (a class given for an instance
        too), or has no ``name``.
    """
    from ..._validation import check_bool

    if not isinstance(lowering, Lowering):
        raise ModelError(f"lowering: expected an instance of a Lowering subclass, got "
                         f"{lowering!r}; write register_lowering(MyLowering())")
    if not lowering.name:
        raise ModelError(f"lowering: {type(lowering).__name__}.name is empty; set "
                         f"name = '...'")
    _REGISTRY.add(lowering, check_bool("first", first))
    return lowering


def lowerings() -> tuple[Lowering, ...]:
    """The registered lowerings, in the order :func:`lower` tries them.

    Returns
    -------
    tuple of Lowering
    """
    return tuple(_REGISTRY.resolved())


def _accepting(system: Any, method: Any) -> Lowering | None:
    for lowering in _REGISTRY.resolved():
        if lowering.accepts(system, method):
            return lowering
    return None


def needs_lowering(system: Any, method: Any) -> bool:
    """Whether :func:`nscontrol.simulate` lowers ``system`` before ``method`` runs it: a
    closed loop always (no integrator is handed one), any other system when the method
    does not integrate it as given.

    Parameters
    ----------
    system
        The model.
    method : Integrator subclass
        The method.

    Returns
    -------
    bool
    """
    from ...systems.closed_loop import ClosedLoop

    return isinstance(system, ClosedLoop) or not method.supports(system)


def lowers(system: Any, method: Any) -> bool:
    """Whether ``method`` runs ``system``, as given or through a lowering.

    Parameters
    ----------
    system
        The model.
    method : Integrator subclass
        The method.

    Returns
    -------
    bool
    """
    return not needs_lowering(system, method) or _accepting(system, method) is not None


def lower(system: Any, method: Any, x0: Any, options: Mapping[str, Any]
          ) -> tuple[Any, Any, dict[str, Any], list[tuple[Lowering, Lowered]]]:
    """Lower ``system`` until ``method`` integrates it.

    Parameters
    ----------
    system
        The model given to :func:`nscontrol.simulate`.
    method : Integrator subclass
        The method that will run.
    x0
        The initial state given.
    options : mapping
        The options given (common and the method's own).

    Returns
    -------
    system, x0, options, applied
        What the method runs, and the lowerings applied with their results, in order (the
        trajectory goes back through them in reverse: :func:`invert_all`).

    Raises
    ------
    ModelError
        No lowering accepts the system (or what an earlier lowering made of it).
    """
    applied: list[tuple[Lowering, Lowered]] = []
    opts = dict(options)
    while needs_lowering(system, method):
        lowering = _accepting(system, method)
        if lowering is None or len(applied) >= MAX_CHAIN:
            raise ModelError(_refusal(system, method, applied))
        lowered = lowering.apply(system, method, x0, opts)
        applied.append((lowering, lowered))
        system, x0, opts = lowered.system, lowered.x0, dict(lowered.options)
    return system, x0, opts, applied


def invert_all(traj: Trajectory, applied: list[tuple[Lowering, Lowered]]) -> Trajectory:
    """The method's trajectory back through the lowerings applied (last first).

    Parameters
    ----------
    traj : Trajectory
        The trajectory of the system the method ran.
    applied : list
        The lowerings and their results, as :func:`lower` returns them.

    Returns
    -------
    Trajectory
    """
    for lowering, lowered in reversed(applied):
        traj = lowering.invert(traj, lowered)
    return traj


def _refusal(system: Any, method: Any, applied: list[tuple[Lowering, Lowered]]) -> str:
    if len(applied) >= MAX_CHAIN:
        chain = " -> ".join(lowering.name for lowering, _ in applied)
        return (f"{method.name}: the lowerings {chain} did not reach a system "
                f"{method.name} integrates; check the registered lowerings' accepts")
    if not applied:
        return (f"{method.name}: integrates {method.systems()}, got {type(system).__name__}, "
                f"and no registered lowering turns it into one (see "
                f"nscontrol.simulate.lowering)")
    what = " then ".join(lowering.name for lowering, _ in applied)
    use = getattr(system, "default_method", None)
    hint = f"; use method={use!r}" if use else ""
    return (f"{method.name}: lowered by {what}, this system is a {type(system).__name__}, "
            f"which {method.name} does not integrate{hint}")


def merge_options(user: Mapping[str, Any], own: Mapping[str, Any]) -> dict[str, Any]:
    """The user's options with a lowering's own: a name both set is refused, except
    ``listeners`` (the lowering's first).

    Parameters
    ----------
    user : mapping
        The options given to :func:`nscontrol.simulate`.
    own : mapping
        The options the lowering sets.

    Returns
    -------
    dict

    Raises
    ------
    ModelError
        An option set by both.
    """
    clash = sorted(set(own) & set(user) - {"listeners"})
    if clash:
        raise ModelError(f"{clash[0]}: set by the closed loop's parts; do not pass it to "
                         "simulate as well")
    merged = {**user, **own}
    if "listeners" in user and "listeners" in own:
        merged["listeners"] = [*own["listeners"], *user["listeners"]]
    return merged

"""What the stacked and folded lowerings share: the loop's signals read off the stacked
state (``u``, ``xhat``, ``error``) and the loop's input matrix. A module of its own, so that
``stack``, ``fold`` and ``_pwa_stack`` import it and not each other."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ..._validation import FloatArray, as_matrix
from ...errors import ModelError
from ...systems.closed_loop import ClosedLoop

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["Maps", "add_loop_signals", "input_matrix"]

#: ``name -> (M, offset)``: a loop signal is ``x @ M.T + offset`` of the stacked state.
Maps = dict[str, tuple[FloatArray, FloatArray]]


def add_loop_signals(traj: Trajectory, maps: Maps, plant: Any) -> Trajectory:
    """Adds the loop's signals (``u``, ``xhat``, the estimation error ``e``, also kept as
    ``error``) computed from the stacked state; a plant input already named ``u`` (an
    exosystem's) is kept as ``u_exo``, and a map named ``y`` (the plant's measured output)
    replaces the stacked model's own output.

    Parameters
    ----------
    traj : Trajectory
        The stacked model's trajectory.
    maps : dict
        ``name -> (M, offset)``: the signal is ``x @ M.T + offset``.
    plant
        The loop's plant (a Lagrangian plant's ``energy`` is its own, not the folded
        model's).

    Returns
    -------
    Trajectory
    """
    from ...systems.lagrangian import LagrangianSystem

    signals = dict(traj.signals)
    if "u" in maps and "u" in signals:
        signals["u_exo"] = signals.pop("u")
    for name, (M, offset) in maps.items():
        if name not in signals or name == "y":   # "y": the plant's, not the stacked model's
            signals[name] = traj.x @ M.T + offset
    if "error" in signals:      # the estimation error x - x̂, named e beside x and xhat
        signals["e"] = signals["error"]
    if isinstance(plant, LagrangianSystem) and "energy" in signals:
        signals["energy"] = plant.energy(traj.x)
    return replace(traj, signals=signals)


def input_matrix(loop: ClosedLoop, default: Any, n: int) -> FloatArray:
    """The loop's ``input_matrix`` (``u`` enters ``x'`` through it), or the plant's."""
    B = loop.input_matrix if loop.input_matrix is not None else default
    if B is None:
        raise ModelError(f"input_matrix: the plant does not say how u enters x'; pass "
                         f"closed_loop(..., input_matrix=B) with B of shape ({n}, m)")
    return as_matrix("input_matrix", B, rows=n)

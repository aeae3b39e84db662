"""The options of Moreau–Jean time-stepping, typed and checked once.

:func:`nscontrol.simulate.moreau_jean.integrate` turns its keyword arguments into a
:class:`MoreauJeanOptions` (the scheme's and the run's settings) and a :class:`Feedback`
(what reaches the plant between steps: the block runner of a closed loop and the jump
listeners); every path (the compiled loops, the Python runner, the frictional
loop) reads these records, never the raw keywords.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..._validation import FloatArray, check_bool, check_in_interval, check_positive
from ...errors import DimensionError, ModelError

__all__ = ["Feedback", "MoreauJeanOptions"]


@dataclass(frozen=True)
class MoreauJeanOptions:
    """Checked settings of one Moreau–Jean run (see
    :func:`nscontrol.simulate.moreau_jean.integrate` for their meaning).

    Attributes
    ----------
    h : float
        Step, ``> 0``.
    theta : float
        θ of the θ-method, in ``[1/2, 1]``.
    gamma : float
        Position-prediction weight of the active set, in ``[0, 1]``.
    activation : float
        Threshold (``>= 0``) of the active-set test ``g + γ h u <= activation``.
    u : Exosystem, callable or None
        Open-loop input.
    forces : {"implicit", "explicit"}
        Smooth forces of the Python path.
    mass_at : {"start", "predicted"}
        Where a configuration-dependent ``M(q)`` is evaluated.
    projection : bool
        Project ``q`` on the admissible set after each step.
    contact_tol : float
        Tolerance of each step's frictional contact problem, ``> 0``.
    record_every : int
        Keep every k-th step (checked by the recorder).
    signals : sequence of str or None
        Signals to record (checked by the recorder against those offered).
    progress : bool or None
        Progress bar (``None``: shown after 2 s).
    """

    h: float
    theta: float
    gamma: float
    activation: float
    u: Any = None
    forces: str = "implicit"
    mass_at: str = "start"
    projection: bool = False
    contact_tol: float = 1e-12
    record_every: int = 1
    signals: Sequence[str] | None = None
    progress: bool | None = None

    @classmethod
    def checked(cls, system: Any, x0: FloatArray, *, h: Any, theta: Any, gamma: Any,
                activation: Any, u: Any, forces: Any, mass_at: Any, projection: Any,
                contact_tol: Any, record_every: Any, signals: Any, progress: Any
                ) -> MoreauJeanOptions:
        """The options for ``system`` from ``x0`` (its checked initial state), each checked
        here once; ``activation=None`` becomes ``1e-12 (1 + max|q0|)``."""
        h = check_positive("h", h)
        theta = check_in_interval("theta", theta, 0.5, 1.0)
        gamma = check_in_interval("gamma", gamma, 0.0, 1.0)
        if forces not in ("implicit", "explicit"):
            raise ModelError(f"forces: expected 'implicit' or 'explicit', got {forces!r}")
        if mass_at not in ("start", "predicted"):
            raise ModelError(f"mass_at: expected 'start' or 'predicted', got {mass_at!r}")
        check_input(system, u)
        if activation is None:
            activation = 1e-12 * (1.0 + float(np.abs(x0[: system.n_dof]).max(initial=0.0)))
        return cls(h=h, theta=theta, gamma=gamma,
                   activation=check_positive("activation", activation, allow_zero=True),
                   u=u, forces=forces, mass_at=mass_at,
                   projection=check_bool("projection", projection),
                   contact_tol=check_positive("contact_tol", contact_tol),
                   record_every=record_every, signals=signals,
                   progress=check_bool("progress", progress, allow_none=True))

    def with_step(self, h: float) -> MoreauJeanOptions:
        """The same options with the step ``h`` (the shortened last step of a run)."""
        return replace(self, h=h)


@dataclass(frozen=True)
class Feedback:
    """What acts between steps: the ``blocks`` of a closed loop and the jump ``listeners``.

    Attributes
    ----------
    blocks : BlockRunner or None
        The loop's blocks (set by the ``python_blocks`` lowering of
        :func:`nscontrol.closed_loop`): stepped at every step start, they read the plant's
        state, the last step's impulses over ``h`` and its active set; their output is
        added to the input. The run takes their compiled form when it can.
    listeners : tuple of callables
        ``(t, x_minus, x_plus, contacts, impulse)``, called for every step with an impact
        (the blocks' reset among them).
    """

    blocks: Any = None
    listeners: tuple[Callable[..., None], ...] = ()

    @classmethod
    def checked(cls, blocks: Any, listeners: Sequence[Any]) -> Feedback:
        """The feedback of a run, its parts checked."""
        if blocks is not None and not _is_block_runner(blocks):
            raise ModelError(f"blocks: expected the BlockRunner of a closed loop (set by "
                             f"simulate for closed_loop(plant, controller)), got "
                             f"{type(blocks).__name__}; close the loop with "
                             f"nscontrol.closed_loop instead")
        for i, fn in enumerate(listeners):
            if not callable(fn):
                raise ModelError(f"listeners[{i}]: expected a callable (t, x_minus, x_plus, "
                                 f"contacts, impulse), got {type(fn).__name__}")
        return cls(blocks, tuple(listeners))


def _is_block_runner(blocks: Any) -> bool:
    from .._block_runner import BlockRunner

    return isinstance(blocks, BlockRunner)


def check_input(system: Any, u: Any) -> None:
    """An :class:`Exosystem` input must have one output per actuator column."""
    if u is None:
        return
    from ...numerics.lti import Exosystem

    if callable(u) and not isinstance(u, Exosystem):
        return
    if not isinstance(u, Exosystem):
        raise ModelError(f"u: expected an Exosystem or a callable t -> u, got "
                         f"{type(u).__name__}")
    m = system.n_dof if system.actuation is None else system.actuation.shape[1]
    if u.n_inputs != m:
        raise DimensionError(f"u: expected an Exosystem with {m} input(s) (the actuation's "
                             f"columns), got {u.n_inputs}")


def input_matrix(system: Any, with_input: bool) -> FloatArray | None:
    """The actuation ``S`` (identity when the system has none) when an input acts."""
    if not with_input:
        return None
    return (np.eye(system.n_dof) if system.actuation is None
            else np.asarray(system.actuation, float))

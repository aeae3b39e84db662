"""Event-driven integration: flow until the next event, apply the jump, repeat.

Integrates

* :class:`~nscontrol.systems.hybrid.LinearHybridSystem` — exact: ``e^{At}`` between events,
  events located on the exact solution by :func:`nscontrol.numerics.lti.first_event`;
* :class:`~nscontrol.systems.LagrangianSystem` that is linear between events (constant ``M``,
  linear forces, affine gaps), optionally driven by an exosystem input — exact as well: the
  state is augmented by ``[1; w]`` so that constant forces (gravity) and the input are part
  of one linear flow. Contacts in *persistent contact* change the flow (the constrained
  acceleration is again linear in the state) and are left when their contact force, also
  linear in the state, reaches zero;
* :class:`~nscontrol.systems.ImpactingBodies` through its Lagrangian form (state order
  ``[x_a; x_b]`` kept), which :func:`nscontrol.simulate` hands over
  (:mod:`nscontrol.simulate.lowering.impacting_bodies`);
* a linear :class:`~nscontrol.systems.LagrangianSystem` resting on one planar frictional
  contact (Coulomb friction, the contact closed throughout) — exact: the modes stick,
  slip forward and slip backward are linear flows, switched where the slip velocity or the
  friction needed to stick reaches its bound (:mod:`.frictional_contact`);
* any other :class:`~nscontrol.systems.LagrangianSystem` (``M(q)``, nonlinear forces or gaps)
  with scipy's DOP853 and event location (no persistent contact: an accumulation of impacts
  there is reported as Zeno).

With ``sensitivity=True`` (a :class:`LagrangianSystem`) the run is DOP853's with the
variational equation integrated along and the saltation matrix of Newton's law applied at each
impact: ``stats["state_transition"]`` is ``∂x(tf)/∂x0`` (:mod:`._variational`).

Impacts go through Newton's multi-contact law (:class:`nscontrol.laws.NewtonImpactLaw`, one
LCP on the Delassus matrix of the closed contacts), so simultaneous impacts are resolved
together. After an impact the contacts that stay closed with zero normal velocity enter
persistent contact when the contact-force LCP gives them a positive force.

Accumulations (Zeno): when the impact intervals of a contact shrink geometrically (three
successive ratios equal to ``zeno_ratio_tol``) and the remaining time ``Δ r / (1 - r)`` is
below ``zeno_horizon``, the accumulation point ``t∞ = t_k + Δ_k r / (1 - r)`` is computed, the
contact is closed plastically at ``t_k`` and the run continues in persistent contact; the
event ``"accumulation"`` is recorded at ``t∞`` (our choice: the samples in ``[t_k, t∞]``
follow the constrained flow, an error of the order of the remaining bounce heights). An
accumulation that cannot be resolved that way (no geometric pattern, a contact force that
would be negative) raises :class:`ZenoError` with the trajectory computed so far
(``simulate(..., on_failure="warn")`` warns and returns it); more than ``max_events`` events
(every event counts, touches too) raise :class:`~nscontrol.errors.BudgetExceededError`
(``budget="max_events"``), with it too.

Long runs: a flight ends at its event's own offset ``τ`` (the time labels carry their
rounding separately), and a restart whose guard is negative at round-off level is
projected by the one shared kernel :func:`nscontrol.numerics.lti.project_restart`
(``stats["projections"]``); see ``docs/lti.md``.

Speed: the flow between events, the event search and every event of a single guard with a
linear jump (a free contact bouncing with nothing else closed; a :class:`LinearHybridSystem`
whose ``jump`` is given as matrices, such as the chapter-2 plant with its observer) run in one
compiled loop (:mod:`nscontrol.simulate._event_kernels`); any other event — simultaneous,
grazing, a contact coming to rest, an accumulation — is handed back to the Python code below,
unchanged. Listeners are called for the compiled events too, in time order, once the loop
returns (they observe, they cannot alter the run).

Event kinds: ``"impact"``, ``"grazing"``, ``"accumulation"``, ``"contact_start"``,
``"contact_end"`` (mechanics), ``"stick"``, ``"slip"``, ``"slip_reversal"`` (friction),
``"jump"`` and ``"grazing"`` (linear hybrid systems).

Options
-------
u : Exosystem, optional
    Input of a Lagrangian system or of :class:`ImpactingBodies` (through its actuation),
    ``u(t) = Cu w(t)`` with ``w(0) = w0`` (absolute time, as in every integrator); its
    state is propagated exactly with the plant.
blocks : BlockRunner, optional
    Internal: a closed loop's continuous static law (``closed_loop(plant, law)`` with a
    :class:`~nscontrol.systems.feedback.StaticLaw` written in Python) evaluated along the
    flow, ``u = law(t, x)``
    added through the actuation; set by the lowering
    :mod:`~nscontrol.simulate.lowering.python_blocks`, not by a user. Such a law makes the
    flow nonlinear: the run uses DOP853 with event location (no persistent contact there).
    A continuous :class:`~nscontrol.systems.feedback.StateFeedback` on a Lagrangian plant or
    on impacting bodies is folded into the model instead
    (:mod:`~nscontrol.simulate.lowering.fold`): a linear plant's loop stays exact.
dt : float, optional
    Spacing of the regular samples between events (default ``(tf - t0) / 1000``); every
    event adds its pre- and post-event samples.
max_events : int
    Event budget: more events than this raises
    :class:`~nscontrol.errors.BudgetExceededError` (``budget="max_events"``) with the
    computed part (a long run needs one event per impact).
min_interval : float
    Two events of the same guard closer than this (without a geometric pattern) is Zeno.
zeno_ratio_tol : float
    Tolerance on successive interval ratios to call the shrinking geometric.
zeno_horizon : float, optional
    Accumulate once the predicted remaining time is below this many seconds. Default:
    relative, see ``zeno_rel``.
zeno_rel : float
    Without ``zeno_horizon``, accumulate once the predicted remaining time is below
    ``zeno_rel`` times the duration of the bouncing sequence (from its first impact to
    the accumulation point): the same bounces are resolved whatever ``t_span``.
listeners : sequence of callables ``(t, x_minus, x_plus, contacts, impulse)``
    Called after every jump / impact with the event's states, the indices of the guards
    or contacts involved and the contact impulses (``None`` for hybrid jumps). The same
    signature as :mod:`~nscontrol.simulate.moreau_jean`'s.
rtol, atol : float
    Tolerances of DOP853 (nonlinear systems only).
record_every : int
    Keep every ``record_every``-th sample (events, and the final state, are always kept).
signals : sequence of str, optional
    Signals to record (default all: the system's outputs for a hybrid system, ``gap`` and
    ``energy`` for mechanics); an empty sequence records states only.
progress : bool, optional
    Progress bar (default: shown after 2 s).
sensitivity : bool
    Also compute the state transition ``∂x(tf)/∂x0`` (:class:`LagrangianSystem` only):
    the variational equation is integrated with the state by DOP853 (a linear system
    too: the exact runner has no variational equation, and persistent contact is then
    refused as Zeno) and each impact multiplies it by the saltation matrix of Newton's
    law with ``M(q)`` and ``g(q)``; see :mod:`._variational`.

References: Acary & Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Springer
2008, ch. 8 (event-driven schemes); D5.3 chapter 2, section 5.

The package: :func:`integrate` here chooses the runner — :mod:`.hybrid_run`,
:mod:`.linear_mechanics`, :mod:`.frictional_contact` or :mod:`.nonlinear_mechanics` —
which share the options
(``_options``), the recording (``_recording``: one sample buffer in front of the
:class:`~nscontrol.simulate.trajectory.Recorder`), the Zeno history (``_zeno``) and the
compiled flights with the arrays a run writes into (``_flight``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import check_bool
from ...errors import ModelError
from ...systems.hybrid import LinearHybridSystem
from ...systems.lagrangian import LagrangianSystem
from ...systems.protocols import InputSignal
from ..callbacks import Listener
from ..trajectory import Trajectory
from ._options import _check_input, _Options
from ._recording import _guarded, reorder_listeners, reorder_states
from .frictional_contact import FrictionalContactRun, check_frictional_system
from .hybrid_run import HybridRun
from .linear_mechanics import LinearMechanicsRun, checked_state
from .nonlinear_mechanics import NonlinearMechanicsRun

if TYPE_CHECKING:
    from .._block_runner import BlockRunner

__all__ = ["integrate", "reorder_listeners", "reorder_states"]


def integrate(system: LagrangianSystem | LinearHybridSystem, x0: ArrayLike,
              t_span: tuple[float, float], *, u: InputSignal = None,
              blocks: BlockRunner | None = None, dt: float | None = None,
              max_events: int = 100_000,
              min_interval: float = 1e-12, zeno_ratio_tol: float = 1e-3,
              zeno_horizon: float | None = None, zeno_rel: float = 1e-3,
              listeners: Sequence[Listener] = (),
              rtol: float = 1e-10, atol: float = 1e-12, record_every: int = 1,
              signals: Sequence[str] | None = None, progress: bool | None = None,
              sensitivity: bool = False) -> Trajectory:
    """Event-driven simulation from ``x0`` over ``t_span`` (see the module docstring).

    Parameters
    ----------
    system : LinearHybridSystem, LagrangianSystem or ImpactingBodies
    x0 : array_like
        Admissible initial state (``[q; v]``, ``[x_a; x_b]`` or the hybrid state).
    t_span : (float, float)
    u, blocks, dt, max_events, min_interval, zeno_ratio_tol, zeno_horizon, zeno_rel, \
listeners, rtol, atol, record_every, signals, progress, sensitivity
        The options: see "Options" in the module docstring.

    Returns
    -------
    Trajectory
        ``signals``: the system's outputs (hybrid), ``gap`` and ``energy`` (mechanics);
        ``stats["impulses"]`` (mechanics): one row of contact impulses per ``"impact"``
        event, in the order of ``traj.events_of("impact")``. With friction (one planar
        contact held closed) also ``contact_state`` (1 stick, 2 slip), ``friction`` and
        ``normal_force`` (the contact forces). With ``sensitivity=True``:
        ``stats["state_transition"]`` and ``stats["saltation_matrices"]`` (one per impact).

    Raises
    ------
    ModelError
        Unsupported system or option; with friction, anything but one planar contact held
        closed (impacts, several contacts, the normal force reaching zero).
    InadmissibleStateError
        ``x0`` violates a constraint.
    BudgetExceededError
        More than ``max_events`` events (``err.budget == "max_events"``), with
        ``err.trajectory``.
    ZenoError
        Unresolvable accumulation of events; ``err.trajectory`` holds the run so far (every
        error raised during the run carries it).

    Examples
    --------
    >>> import nscontrol as nsc
    >>> from nscontrol.testing.mechanics_problems import BouncingBall
    >>> ball = BouncingBall(restitution=0.9)
    >>> traj = nsc.simulate(ball.system(), ball.x0, (0.0, 10.0))
    >>> bool(abs(traj.event_times("accumulation")[0] - ball.accumulation_time) < 1e-9)
    True
    """
    t0, tf = (float(t) for t in t_span)
    opts = _Options.checked(
        t0, tf, dt=dt, max_events=max_events, min_interval=min_interval,
        zeno_ratio_tol=zeno_ratio_tol, zeno_horizon=zeno_horizon, zeno_rel=zeno_rel,
        listeners=listeners, rtol=rtol, atol=atol, record_every=record_every,
        signals=signals, progress=progress)
    sensitivity = _check_sensitivity(system, sensitivity)
    if isinstance(system, LinearHybridSystem):
        return _run_hybrid(system, x0, t0, tf, u, blocks, opts)
    if isinstance(system, LagrangianSystem):
        return _with_law_signal(blocks, lambda: _run_lagrangian(
            system, x0, t0, tf, u, blocks, opts, sensitivity))
    raise ModelError(f"event_driven: integrates LinearHybridSystem and LagrangianSystem (and "
                     f"ImpactingBodies through nscontrol.simulate), got "
                     f"{type(system).__name__}")


def _check_sensitivity(system: Any, sensitivity: Any) -> bool:
    """The ``sensitivity`` option: a bool, true only for a :class:`LagrangianSystem`."""
    sensitivity = check_bool("sensitivity", sensitivity)
    if sensitivity and not isinstance(system, LagrangianSystem):
        raise ModelError(f"sensitivity: event_driven computes the state transition of a "
                         f"LagrangianSystem, got {type(system).__name__}")
    return bool(sensitivity)


def _run_hybrid(system: LinearHybridSystem, x0: ArrayLike, t0: float, tf: float, u: Any,
                blocks: Any, opts: _Options) -> Trajectory:
    """A linear hybrid system: its input and controller are in its state, never options."""
    for name, value in (("u", u), ("blocks", blocks)):
        if value is not None:
            raise ModelError(f"{name}: a LinearHybridSystem carries its input generator "
                             "and controller in its state; stack them into A instead")
    return _guarded(HybridRun(system, system.check_state(x0), t0, tf, opts))


def _run_lagrangian(system: LagrangianSystem, x0: ArrayLike, t0: float, tf: float, u: Any,
                    blocks: Any, opts: _Options, sensitivity: bool) -> Trajectory:
    """A Lagrangian system: on one frictional contact held closed (stick/slip exactly), or
    by :func:`_mechanics_run`."""
    if system.friction_dim:   # one planar contact held closed: stick/slip exactly
        if sensitivity:
            raise ModelError("sensitivity: not available with Coulomb friction; simulate "
                             "with method='moreau_jean' and a step h")
        check_frictional_system(system, blocks, opts.listeners)
        return _guarded(FrictionalContactRun(system, checked_state(system, x0), t0, tf,
                                             _check_input(system, u), opts))
    return _guarded(_mechanics_run(system, checked_state(system, x0), t0, tf,
                                   _check_input(system, u), blocks, opts, sensitivity))


def _mechanics_run(system: Any, x0: Any, t0: float, tf: float, u: Any, blocks: Any,
                   opts: _Options, sensitivity: bool = False) -> Any:
    """The runner of a Lagrangian system: exact (a linear flow) or DOP853 (a nonlinear
    model, a law evaluated along the flow, or the state transition asked)."""
    if system.is_linear and blocks is None and not sensitivity:
        return LinearMechanicsRun(system, x0, t0, tf, u, opts)
    law = None if blocks is None else blocks.step
    return NonlinearMechanicsRun(system, x0, t0, tf, u, opts, controller=law,
                                 sensitivity=sensitivity)


def _with_law_signal(blocks: Any, run: Any) -> Trajectory:
    """``run()``, and with a law evaluated along the flow (``blocks``) its input ``u`` at
    every sample as the signal ``"u"``. The law's calls during the run (DOP853's stages,
    not in time order) are dropped from the runner's log, which would otherwise map them
    onto the samples as held values."""
    if blocks is None:
        return run()
    try:
        traj = run()
    finally:
        blocks.log.clear()
    n = traj.x.shape[1] // 2
    law = np.array([blocks.step(t, x[:n], x[n:]) for t, x in zip(traj.t, traj.x,
                                                                    strict=True)])
    blocks.log.clear()
    return replace(traj, signals={**traj.signals, "u": law.reshape(len(traj.t), -1)})

"""Moreau–Jean event-capturing time-stepping for Lagrangian systems with impacts.

Integrates :class:`~nscontrol.systems.LagrangianSystem` and
:class:`~nscontrol.systems.ImpactingBodies` (through its Lagrangian form). One step is the
θ-method on the smooth forces, Newton's impact law at velocity level on the contacts predicted
to close (``g + γ h u <= 0``), and one LCP over those contacts (Acary & Brogliato 2008, §10.1):

    0 <= P ⟂ W P + G v_free + e u_k >= 0,   v_{k+1} = v_free + M̂⁻¹ Gᵀ P,
    q_{k+1} = q_k + h((1-θ) v_k + θ v_{k+1}),   W = G M̂⁻¹ Gᵀ.

**The θ-method with linearised forces.** With ``f(t, q, v) = f0 - K q - D v + force(t, q, v)``
the smooth force, the θ-method reads
``M(q_k)(v_{k+1} - v_k) = h[θ f_{k+1} + (1-θ) f_k] + S u_k h + Gᵀ P``. Linearising
``f_{k+1} ≈ f(t_{k+1}, q_k, v_k) + J_q (q_{k+1} - q_k) + J_v (v_{k+1} - v_k)`` with
``J_q = ∂f/∂q``, ``J_v = ∂f/∂v`` at ``(t_k + θh, q_k, v_k)`` and substituting
``q_{k+1} - q_k = h v_k + hθ (v_{k+1} - v_k)``:

    M̂ = M(q_k) - hθ J_v - h²θ² J_q,
    f̃_k = f(t_k + θh, q_k, v_k) + hθ J_q v_k + S u_k,
    v_free = v_k + M̂⁻¹ h f̃_k,

where ``θ f(t_{k+1}, ·) + (1-θ) f(t_k, ·)`` is replaced by ``f(t_k + θh, ·)`` (equal for a
force affine in ``t``, ``O(h²)`` otherwise: the order is kept, one evaluation saved). For
linear forces ``J_q = -K``, ``J_v = -D``: ``M̂ = M + hθD + h²θ²K`` and
``f̃ = f0 - K q_k - D v_k - hθ K v_k + S u_k``, the compiled paths' step. Without contact
and with constant ``M`` the step is a linearly implicit (Rosenbrock-type) θ-method: first
order for ``θ = 1``, second order for ``θ = ½`` (the linearisation error
``O(|q_{k+1} - q_k|²) = O(h²)`` enters multiplied by ``h``), and A-stable on linear forces.
With ``M(q)`` frozen at ``q_k`` it is first order whatever ``θ`` (the step is
``h M(q_k)⁻¹ f̄`` where the trapezoidal rule needs ``M`` at ``q_{k+½}``: an ``O(h²)`` local
error); ``mass_at="predicted"`` evaluates ``M`` at ``q_k + θ h v_k`` (within ``O(h²)`` of
``q_{k+θ}``), which restores second order for ``θ = ½``. ``J_q, J_v`` come from
the model's ``force_jacobian`` or from central differences (see
:meth:`~nscontrol.systems.LagrangianSystem.force_jacobians`). ``forces="explicit"`` keeps
``M̂ = M(q_k)``, ``f̃ = f(t_k, q_k, v_k) + S u_k``.

Paths, chosen automatically:

* constant diagonal ``M̂`` and contacts between neighbours (chains, stacks, cradles, the ball):
  a compiled O(n) loop with the shared tridiagonal LCP kernel;
* any other constant ``M`` with affine gaps: a compiled loop with dense ``M̂⁻¹`` and Lemke;
* configuration-dependent ``M(q)``, nonlinear forces or gaps (or ``forces="explicit"``): a
  Python loop evaluating the model's callables, the step by the compiled
  :func:`~nscontrol.simulate.moreau_jean._step_kernels.mj_step` (``M̂`` assembled at every step);
* a model with a compiled form (``system.compiled``), alone or under compiled blocks: one
  compiled loop around the same ``mj_step``.

One run (:class:`~nscontrol.simulate.moreau_jean._run.Run`, a stepper of
:func:`~nscontrol.simulate.loop.drive`, which owns the progress bar and the end of the run)
advances every path in chunks of steps: it records them and calls the listeners; the options
are checked once into :class:`~nscontrol.simulate.moreau_jean._options.MoreauJeanOptions`.

Recorded: states ``[q; v]``, signals ``impulse`` (per step and contact, ``P``), ``gap`` and
``energy``; events ``"impact"`` (a contact whose impulse becomes positive while approaching).
Impacts are captured within the step: impact times are exact to ``O(h)``, the position drift
(penetration) at a landing is bounded by ``h |u⁻|``.

Feedback is a closed loop, ``simulate(closed_loop(plant, controller), ...)``: its blocks run
at every step start (zero-order hold over the step) and may read the contact, the
:class:`~nscontrol.systems.feedback.Measurement` fields ``lam`` (the previous step's impulses
over ``h``, the mean contact force of that step) and ``active`` (its active set). Blocks
with a compiled form run inside the compiled model's loop; Python blocks run before each
step of the other paths and are reset at impacts.

Options
-------
h : float
    Step, ``> 0``.
theta : float
    θ of the θ-method, in ``[1/2, 1]`` (½: no numerical damping).
gamma : float
    Position-prediction weight of the active set, in ``[0, 1]``.
u : Exosystem or callable ``t -> u``, optional
    Open-loop input (through the system's actuation ``S``).
listeners : sequence of callables ``(t, x_minus, x_plus, contacts, impulse)``
    Called for every step that contains an impact (observer resets), with the states at
    the step's start and end, the impacting contacts and the step's impulses; ``t`` is
    the step's end. The same signature as the event-driven integrator's. Listeners
    observe: they are called in step order once each compiled chunk is done.
record_every : int
    Keep every k-th step (events are always kept).
signals : sequence of str, optional
    Signals to record among ``"impulse"``, ``"gap"``, ``"energy"`` (default all).
progress : bool, optional
    Progress bar (default: shown after 2 s).
activation : float, optional
    Threshold (``>= 0``) of the active set test ``g + γ h u <= activation``. Default
    ``1e-12 (1 + max|q0|)``: contacts closed up to round-off stay active (a threshold of 0
    would drop a resting contact whose gap rounds to ``+1e-19``).
forces : {"implicit", "explicit"}
    Smooth forces of the Python path (``M(q)``, a ``force`` callable or nonlinear gaps):
    ``"implicit"`` linearises them about the step's start (the θ-method of the module
    docstring; Jacobians from ``force_jacobian`` or central differences); ``"explicit"``
    evaluates ``f(t_k, q_k, v_k)`` only (the scheme before implicit forces: stable only
    for ``θ = 1`` and ``h ω < 2``; for ``θ = ½`` it grows by ``√(1 + (hω)²/2)`` per
    step on a spring), and sends a linear system to the Python path too, for
    comparison. Linear forces on the compiled paths are always implicit.
mass_at : {"start", "predicted"}
    Where a configuration-dependent ``M(q)`` is evaluated: at ``q_k`` (the scheme of the
    module docstring; first order whatever θ), or at the predicted
    ``q_k + θ h v_k`` (``O(h²)`` from ``q_{k+θ}``: second order for ``θ = ½``).
projection : bool
    After each step, project ``q`` on the admissible set ``{g(q) >= 0}`` in the kinetic
    metric (one LCP; the velocity keeps its direction, so the impulse law's outcome is
    kept, and gives back the potential energy the lift cost): no penetration beyond
    round-off, no energy added. Stats ``projection_energy`` (the net energy the
    corrections added: round-off unless the kinetic energy was smaller than the lift's),
    ``projection_lift_energy`` (what the lifts alone would have added) and
    ``max_penetration_before_projection``; signal ``projection_energy``.
contact_tol : float
    Tolerance of the relative natural-map error of each step's frictional contact
    problem (systems with ``friction``; see
    :func:`~nscontrol.numerics.friction_contact.solve_friction_contact`).

Notes
-----
Event-capturing: impacts are not located; Newton's law holds at velocity level on the
contacts of the step, so impact times are exact to ``O(h)`` and a landing penetrates by
at most ``h |u⁻|``; with ``θ = ½`` the discrete energy does not increase at impacts
(Acary & Brogliato, Prop. 10.1 for linear systems).

References
----------
Acary & Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Springer 2008,
ch. 10.

Examples
--------
>>> import numpy as np
>>> import nscontrol as nsc
>>> from nscontrol.testing.mechanics_problems import RestingStack
>>> stack = RestingStack(5)
>>> traj = nsc.simulate(stack.system(), stack.x0, (0.0, 0.01), method="moreau_jean",
...                     h=1e-3)
>>> bool(np.allclose(traj.signals["impulse"][-1], stack.impulses(1e-3), rtol=1e-12))
True

A controller reading the contact force: a unit mass on a spring ``k = 4`` pushed by
``u = 2`` onto a wall at ``q = 0.3`` (gap ``0.3 - q``) rests there with the contact force
``u - k q = 0.8``, which ``m.lam`` reports once the contact is active:

>>> from nscontrol.systems.feedback import StaticLaw
>>> from nscontrol.systems.lagrangian import LagrangianSystem
>>> wall = LagrangianSystem(np.eye(1), stiffness=[[4.0]], gap_matrix=[[-1.0]],
...                         gap_offset=[0.3])
>>> seen = []
>>> class Push(StaticLaw):
...     n_outputs, period = 1, None
...     def output(self, t, xc, m):
...         seen.append((float(m.lam[0]), m.active.tolist()))
...         return np.array([2.0 - 3.0 * m.x[1]])
>>> traj = nsc.simulate(nsc.closed_loop(wall, Push()), [0.3, 0.0], (0.0, 0.01),
...                     method="moreau_jean", h=1e-3)
>>> seen[0], seen[-1][1], round(seen[-1][0], 12)
((0.0, []), [0], 0.8)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from numpy.typing import ArrayLike

from ...errors import ModelError
from ...systems.lagrangian import LagrangianSystem
from ..loop import drive
from ._options import Feedback, MoreauJeanOptions
from ._run import Run

if TYPE_CHECKING:
    from ...systems.protocols import InputSignal
    from ..callbacks import Listener
    from ..trajectory import Trajectory

__all__ = ["integrate"]

def integrate(system: LagrangianSystem, x0: ArrayLike,
              t_span: tuple[float, float], *, h: float | None = None,
              theta: float = 0.5, gamma: float = 0.5, u: InputSignal = None,
              listeners: Sequence[Listener] = (), record_every: int = 1,
              signals: Sequence[str] | None = None, progress: bool | None = None,
              activation: float | None = None,
              forces: str = "implicit", mass_at: str = "start",
              projection: bool = False, contact_tol: float = 1e-12,
              blocks: Any = None) -> Trajectory:
    """Moreau–Jean time-stepping from ``x0 = [q0; v0]`` over ``t_span``.

    Parameters
    ----------
    system : LagrangianSystem
    x0 : array_like (2 n,)
        Admissible initial state.
    t_span : (float, float)
    h, theta, gamma, u, listeners, record_every, signals, progress, activation, forces, \
mass_at, projection, contact_tol
        The options: see "Options" in the module docstring.
    blocks : BlockRunner, optional
        The blocks of a closed loop, set by :func:`nscontrol.simulate` for
        ``closed_loop(plant, controller)`` (not a user's option).

    Returns
    -------
    Trajectory
        Samples at ``t0 + k h`` and at ``tf`` (when ``h`` does not divide the span the last
        step is shortened to end there). ``stats``: ``steps``, ``path`` (``"tridiagonal"``,
        ``"dense"``, ``"compiled_model"`` or ``"python"``; ``"tridiagonal+dense"`` when a
        singular Delassus matrix — redundant contacts — sent the run to Lemke),
        ``max_penetration``; on the Python path ``forces`` and ``force_jacobian``
        (``"analytic"`` or ``"central differences"``).

    Raises
    ------
    ModelError
        Unsupported system or option value; a block returning a non-finite input or one of
        the wrong length; a non-finite ``force``, or a ``force_jacobian`` of the wrong shape
        or non-finite, mid-run (naming the time; ``err.trajectory`` the run so far).
    DimensionError
        An input ``u`` of the wrong size.
    InadmissibleStateError
        ``x0`` penetrates or approaches a closed contact.
    SolverError
        An LCP failed, or the iteration matrix ``M̂`` is singular (``rcond(M̂) < n ε``).

    """
    if h is None:
        raise ModelError("h: Moreau-Jean time-stepping needs a step, e.g. h=1e-3 (impacts are "
                         "captured to O(h), penetration <= h |u-|)")
    if not isinstance(system, LagrangianSystem):
        raise ModelError(f"moreau_jean: integrates LagrangianSystem (and ImpactingBodies "
                         f"through nscontrol.simulate), got {type(system).__name__}")
    feedback = Feedback.checked(blocks, listeners)
    x0 = system.check_state(x0)
    opts = MoreauJeanOptions.checked(
        system, x0, h=h, theta=theta, gamma=gamma, activation=activation, u=u, forces=forces,
        mass_at=mass_at, projection=projection, contact_tol=contact_tol,
        record_every=record_every, signals=signals, progress=progress)
    t0, tf = (float(t) for t in t_span)
    if system.friction_dim or opts.projection:   # Coulomb friction, or the position projection
        return _frictional(system, x0, (t0, tf), opts, feedback)
    return drive(Run(system, x0, (t0, tf), opts, feedback), (t0, tf), desc="moreau_jean",
                 progress=opts.progress)


def _frictional(system: LagrangianSystem, x0: Any, t_span: tuple[float, float], opts: Any,
                feedback: Any) -> Trajectory:
    """The run of a system with friction or the position projection (the blocks of a closed
    loop stepped before each step, the listeners called after a step with an impact)."""
    from ._frictional_run import integrate_frictional

    return integrate_frictional(system, x0, t_span[0], t_span[1], opts, feedback=feedback)

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
  Python loop around the compiled Lemke kernel, with ``M̂`` assembled at every step.

Recorded: states ``[q; v]``, signals ``impulse`` (per step and contact, ``P``), ``gap`` and
``energy``; events ``"impact"`` (a contact whose impulse becomes positive while approaching).
Impacts are captured within the step: impact times are exact to ``O(h)``, the position drift
(penetration) at a landing is bounded by ``h |u⁻|``.

A ``controller`` may read the contact: with keyword arguments ``lam_hat`` and ``active`` it
receives the previous step's impulses over ``h`` (the mean contact force of that step) and
its active set (see :func:`integrate`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
from numpy.typing import ArrayLike

from .._progress import TimeProgress
from .._validation import FloatArray, check_bool, check_in_interval, check_positive
from ..errors import DimensionError, ModelError, SolverError
from .trajectory import ChunkProgress, Recorder, Trajectory, evaluable_prefix

if TYPE_CHECKING:   # imported where used at run time (import nscontrol stays light)
    from ..systems.lagrangian import LagrangianSystem
    from ..systems.protocols import InputSignal
    from .callbacks import Listener, StepController

__all__ = ["integrate"]

_LCP_STATUS = {1: "ray termination (no solution)", 2: "iteration limit",
               3: "numerical failure"}
#: Status of a step loop stopped by the model itself (e.g. M(q) no longer definite).
_MODEL_ERROR = -2
#: Status of a step loop stopped by a singular iteration matrix M̂.
_SINGULAR = -3
#: Unit roundoff.
_EPS = float(np.finfo(float).eps)
#: Floats per chunk of the compiled loop (bounds memory for large systems).
_CHUNK_FLOATS = 2_000_000


@dataclass(frozen=True)
class _Setup:
    """What every step needs, prepared once."""

    system: Any
    h: float
    theta: float
    gamma: float
    Sinput: FloatArray | None
    forces: str = "implicit"
    mass_at: str = "start"


def integrate(system: LagrangianSystem, x0: ArrayLike,
              t_span: tuple[float, float], *, h: float | None = None,
              theta: float = 0.5, gamma: float = 0.5, u: InputSignal = None,
              controller: StepController | None = None,
              listeners: Sequence[Listener] = (), record_every: int = 1,
              signals: Sequence[str] | None = None, progress: bool | None = None,
              activation: float | None = None,
              forces: str = "implicit", mass_at: str = "start",
              projection: bool = False, contact_tol: float = 1e-12,
              compiled_blocks: Any = None) -> Trajectory:
    """Moreau–Jean time-stepping from ``x0 = [q0; v0]`` over ``t_span``.

    Parameters
    ----------
    system : LagrangianSystem or ImpactingBodies
    x0 : array_like (2 n,)
        Admissible initial state.
    t_span : (float, float)
    h : float
        Step, ``> 0``.
    theta : float
        θ of the θ-method, in ``[1/2, 1]`` (½: no numerical damping).
    gamma : float
        Position-prediction weight of the active set, in ``[0, 1]``.
    u : Exosystem or callable ``t -> u``, optional
        Open-loop input (through the system's actuation ``S``).
    controller : callable ``(t, q, v) -> u``, optional
        Feedback evaluated at the start of every step (zero-order hold); added to ``u``. If
        it accepts the keyword arguments ``lam_hat`` and/or ``active`` (or ``**kwargs``;
        read once from its signature), it also receives ``lam_hat``, the previous step's
        contact impulses divided by ``h`` (shape ``(m,)``, an estimate of the contact
        force; zeros at the first step), and ``active``, the indices of the contacts in the
        previous step's active set (an int array, empty at the first step). On the Python
        path and without ``listeners`` it is called inside the step loop (many steps per
        chunk: the same inputs and trajectory, less overhead); otherwise the loop advances
        one step per chunk so that listeners run between steps.
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
    compiled_blocks : object, optional
        Passed by :func:`nscontrol.closed_loop` with ``controller=`` when every block of the
        loop has a compiled form. With a compiled model (``system.compiled``, a
        :class:`~nscontrol.systems.lagrangian.CompiledModel`) and implicit forces, the model,
        the blocks and their resets at impacts then run in one compiled loop
        (``stats["path"] = "compiled_model"``; without a controller the same holds for a
        compiled model alone); otherwise the Python path runs.

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
        Unsupported system or option value; a controller returning a non-finite input or
        one of the wrong length; a non-finite ``force``, or a ``force_jacobian`` of the
        wrong shape or non-finite, mid-run (naming the time; ``err.trajectory`` the run so
        far).
    DimensionError
        An input ``u`` of the wrong size.
    InadmissibleStateError
        ``x0`` penetrates or approaches a closed contact.
    SolverError
        An LCP failed, or the iteration matrix ``M̂`` is singular (``rcond(M̂) < n ε``).

    Notes
    -----
    Event-capturing: impacts are not located; Newton's law holds at velocity level on the
    contacts of the step, so impact times are exact to ``O(h)`` and a landing penetrates by
    at most ``h |u⁻|``; with ``θ = ½`` the discrete energy does not increase at impacts
    (Acary & Brogliato, Prop. 10.1 for linear systems).

    References
    ----------
    Acary & Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Springer 2008,
    ch. 10; specs ch03 §3.1 and ch04 §3.

    Examples
    --------
    >>> import nscontrol as nsc
    >>> from nscontrol.testing.mechanics_problems import RestingStack
    >>> stack = RestingStack(5)
    >>> traj = nsc.simulate(stack.system(), stack.x0, (0.0, 0.01), method="moreau_jean",
    ...                     h=1e-3)
    >>> bool(np.allclose(traj.signals["impulse"][-1], stack.impulses(1e-3), rtol=1e-12))
    True

    A controller reading the contact force: a unit mass on a spring ``k = 4`` pushed by
    ``u = 2`` onto a wall at ``q = 0.3`` (gap ``0.3 - q``) rests there with the contact force
    ``u - k q = 0.8``, which ``lam_hat`` reports once the contact is active:

    >>> from nscontrol.systems.lagrangian import LagrangianSystem
    >>> wall = LagrangianSystem(np.eye(1), stiffness=[[4.0]], gap_matrix=[[-1.0]],
    ...                         gap_offset=[0.3])
    >>> seen = []
    >>> def push(t, q, v, *, lam_hat, active):
    ...     seen.append((float(lam_hat[0]), active.tolist()))
    ...     return 2.0 - 3.0 * v[0]
    >>> traj = nsc.simulate(wall, [0.3, 0.0], (0.0, 0.01), method="moreau_jean", h=1e-3,
    ...                     controller=push)
    >>> seen[0], seen[-1][1], round(seen[-1][0], 12)
    ((0.0, []), [0], 0.8)
    """
    from ..systems.lagrangian import LagrangianSystem

    if h is None:
        raise ModelError("h: Moreau-Jean time-stepping needs a step, e.g. h=1e-3 (impacts are "
                         "captured to O(h), penetration <= h |u-|)")
    if not isinstance(system, LagrangianSystem):
        raise ModelError(f"moreau_jean: integrates LagrangianSystem (and ImpactingBodies "
                         f"through nscontrol.simulate), got {type(system).__name__}")
    h = check_positive("h", h)
    theta = check_in_interval("theta", theta, 0.5, 1.0)
    gamma = check_in_interval("gamma", gamma, 0.0, 1.0)
    if forces not in ("implicit", "explicit"):
        raise ModelError(f"forces: expected 'implicit' or 'explicit', got {forces!r}")
    if mass_at not in ("start", "predicted"):
        raise ModelError(f"mass_at: expected 'start' or 'predicted', got {mass_at!r}")
    if controller is not None and not callable(controller):
        raise ModelError("controller: expected a callable (t, q, v) -> u")
    reads = _controller_reads(controller)
    for i, fn in enumerate(listeners):
        if not callable(fn):
            raise ModelError(f"listeners[{i}]: expected a callable (t, x_minus, x_plus, "
                             f"contacts, impulse), got {type(fn).__name__}")
    _check_input(system, u)
    x0 = system.check_state(x0)
    if activation is None:
        activation = 1e-12 * (1.0 + float(np.max(np.abs(x0[: system.n_dof]), initial=0.0)))
    activation = check_positive("activation", activation, allow_zero=True)
    projection = check_bool("projection", projection)
    progress = check_bool("progress", progress, allow_none=True)
    t0, tf = (float(t) for t in t_span)
    if system.friction_dim or projection:   # Coulomb friction, or the position projection
        from ._frictional_moreau_jean import integrate_frictional

        if controller is not None or listeners:
            raise ModelError("controller, listeners: not supported yet with friction or "
                             "projection=True; simulate without them")
        return integrate_frictional(system, x0, t0, tf, h=h, theta=theta, gamma=gamma, u=u,
                                    record_every=record_every, signals=signals,
                                    progress=progress, activation=activation,
                                    projection=projection, contact_tol=contact_tol)
    # whole steps of h, then one shorter step so that the run ends exactly at tf
    n_full = int(np.floor((tf - t0) / h + 1e-9))
    h_last = (tf - t0) - n_full * h
    n_steps = n_full + (1 if h_last > 1e-9 * h else 0)
    rec = Recorder(system.n_states, every=record_every, signals=signals,
                   offered=("impulse", "gap", "energy"),
                   capacity=Recorder.capacity_for(n_steps + 2, record_every))
    _sample_initial(rec, system, t0, x0)
    setup = _Setup(system, h, theta, gamma, _input_matrix(system, u, controller), forces,
                   mass_at)
    model = system.compiled
    if model is None and compiled_blocks is not None:   # a linear plant under compiled blocks
        from ..systems.lagrangian import affine_compiled_model

        model = affine_compiled_model(system)
    if model is not None and forces == "implicit" and (
            controller is None or compiled_blocks is not None):
        from ._mj_compiled import integrate_compiled

        return integrate_compiled(system, setup, x0, (t0, tf), n_full, h_last, u,
                                  compiled_blocks, rec, activation, progress, listeners,
                                  model)
    runner = _choose_runner(system, setup, activation)
    path = runner.path
    state: dict[str, Any] = {"q": x0[: system.n_dof].copy(), "v": x0[system.n_dof:].copy(),
             "p_prev": np.zeros(system.n_contacts), "k": 0, "t0": t0, "h": h,
             "reads": reads, "active_prev": np.zeros(0, dtype=np.int64)}
    # Without listeners (which observe after each chunk) a controller on the Python path runs
    # inside the step loop: chunks of many steps, the same zero-order hold per step.
    inline = controller is not None and not listeners and runner.path == "python"
    if inline:
        state["inline"] = _inline_controller(controller, setup, state)
    per_step = controller is not None and not inline
    status, message = 0, None
    with TimeProgress(t0, tf, desc="moreau_jean", enable=progress) as bar:
        while state["k"] < n_steps:
            k = state["k"]
            if k == n_full:  # the shortened last step
                runner = _choose_runner(system, _Setup(system, h_last, theta, gamma,
                                                       setup.Sinput, forces, mass_at),
                                        activation)
                times, step = np.array([t0 + h * k]), h_last
            else:
                chunk = 1 if per_step else max(1, min(n_full - k, 20_000, _CHUNK_FLOATS // max(
                    1, 2 * system.n_dof + system.n_contacts)))
                times, step = t0 + h * np.arange(k, k + chunk), h
            fext, failed = _chunk_force(setup, u, None if inline else controller, times,
                                        state)
            if failed is not None:          # run the steps before u's first failing time
                if fext.shape[0] == 0:
                    _end_at_input_failure(failed, rec, system)
                times = times[:fext.shape[0]]
            q_pre, v_pre = state["q"].copy(), state["v"].copy()
            active = runner.active_set(q_pre, v_pre) if "active" in reads and not inline \
                else None
            with rec.chunk(partial(_record_finished, rec=rec, system=system, times=times,
                                   state=state, q_pre=q_pre, v_pre=v_pre,
                                   listeners=listeners, h=step)) as state["progress"]:
                done, code, q_out, v_out, p_out = runner(state, fext, times.size)
            if done and active is not None:  # one step per chunk with a controller
                state["active_prev"] = active
            if code and runner.path == "tridiagonal":
                # a singular Delassus matrix (redundant contacts): the tridiagonal solve has
                # no pivot; Lemke handles positive semi-definite W. Redo from the failed step.
                runner = _DenseRunner(system, setup, activation)
                path = "tridiagonal+dense"
                code = 0
            if done:
                _record_chunk(rec, system, times[:done] + step, q_out[:done], v_out[:done],
                              p_out[:done], state, q_pre, v_pre, listeners, step)
            state["k"] = k + done
            if done:
                state["last"] = (times[done - 1] + step, q_out[done - 1], v_out[done - 1],
                                 p_out[done - 1])
            bar.update(t0 + h * state["k"])
            if failed is not None and done == times.size:   # the steps before it all ran
                _end_at_input_failure(failed, rec, system)
            if code == _MODEL_ERROR:
                message = state["model_error"]
                raise ModelError(message, trajectory=rec.finish(
                    status=-1, message=message, method="moreau_jean",
                    state_names=system.state_names))
            if code == _SINGULAR:
                status, message = -1, state["solver_error"]
                break
            if code:
                status = -1
                message = (f"moreau_jean: the LCP of step {state['k']} (t = "
                           f"{t0 + h * state['k']:.6g}) failed: {_LCP_STATUS.get(code, code)}"
                           "; try a smaller h, or check the constraints for redundancy")
                break
    if "last" in state and rec.last_time < state["last"][0]:  # always keep the final state
        t_last, q_l, v_l, p_l = state["last"]
        sig = _signals(system, q_l[None], v_l[None], p_l[None], rec)
        rec.sample(t_last, np.concatenate([q_l, v_l]), force=True,
                   **{k: val[0] for k, val in sig.items()})
    stats = {"steps": int(state["k"]), "path": path, "h": h, "theta": theta}
    if path == "python":
        stats["forces"] = forces
        stats["force_jacobian"] = ("analytic" if system.force is None
                                   or system.force_jacobian is not None
                                   else "central differences")
    traj = rec.finish(status=status, message=message, method="moreau_jean", stats=stats,
                      state_names=system.state_names)
    if "gap" in traj.signals and traj.signals["gap"].size:
        traj.stats["max_penetration"] = float(max(0.0, -np.min(traj.signals["gap"])))
    if status < 0:   # the driver returns the partial run under on_failure="return"
        raise SolverError(str(message), status=_LCP_STATUS.get(code, "singular iteration matrix"),
                          trajectory=traj)
    return traj


# -- preparation ---------------------------------------------------------------------------
def _input_matrix(system: Any, u: Any, controller: Any) -> FloatArray | None:
    if u is None and controller is None:
        return None
    return (np.eye(system.n_dof) if system.actuation is None
            else np.asarray(system.actuation, float))


def _external_force(setup: _Setup, u: Any, controller: Any, times: FloatArray,
                    state: dict[str, Any]) -> FloatArray:
    """Rows ``S u(t_k)`` for the steps of a chunk (a single zero row without input)."""
    n = setup.system.n_dof
    if setup.Sinput is None:
        return np.zeros((1, n))
    S = setup.Sinput
    total = np.zeros((times.shape[0], S.shape[1]))
    if u is not None:
        vals = u.u(times) if hasattr(u, "u") else np.array([np.atleast_1d(u(t)) for t in times])
        total += np.asarray(vals, float).reshape(times.shape[0], -1)
    if controller is not None:  # one step per chunk in closed loop
        kwargs = {}
        if "lam_hat" in state["reads"]:  # the previous step's impulse over its length h
            kwargs["lam_hat"] = state["p_prev"] / state["h"]
        if "active" in state["reads"]:
            kwargs["active"] = state["active_prev"].copy()
        c = np.asarray(controller(float(times[0]), state["q"].copy(), state["v"].copy(),
                                  **kwargs), dtype=float).reshape(-1)
        if c.shape != (S.shape[1],) or not np.all(np.isfinite(c)):
            raise ModelError(f"controller: expected a finite input of length {S.shape[1]} "
                             f"from controller(t, q, v), got {c!r} at t = {times[0]:.6g}")
        total[0] += c
    return total @ S.T


def _chunk_force(setup: _Setup, u: Any, controller: Any, times: FloatArray,
                 state: dict[str, Any]) -> tuple[FloatArray, Exception | None]:
    """:func:`_external_force` over a chunk, or, when it raises, over the chunk's longest
    prefix that evaluates (empty when none does), with the error to raise once those steps
    are recorded."""
    try:
        return _external_force(setup, u, controller, times, state), None
    except Exception as err:  # noqa: BLE001 - handed back to the caller, who re-raises it
        k = evaluable_prefix(
            lambda j: _external_force(setup, u, controller, times[:j], state), times.size)
        return (_external_force(setup, u, controller, times[:k], state) if k
                else np.zeros((0, setup.system.n_dof))), err


def _end_at_input_failure(failed: Exception, rec: Recorder, system: Any) -> NoReturn:
    """Raise the error of an input that failed, once the steps before it are recorded (a
    library error carries them; the driver attaches them to any other)."""
    if isinstance(failed, ModelError):
        failed.trajectory = rec.finish(status=-1, message=str(failed), method="moreau_jean",
                                       state_names=system.state_names)
    raise failed


def _inline_controller(controller: Any, setup: _Setup, state: dict[str, Any]
                       ) -> Callable[..., FloatArray]:
    """The controller as a force ``S c(t, q, v)`` evaluated inside the Python step loop
    (same arguments and checks as :func:`_external_force`); a bad output stops the run as a
    model error (``err.trajectory`` the steps so far)."""
    S, reads, h = setup.Sinput, state["reads"], state["h"]
    assert S is not None   # a controller always sets the input matrix (_input_matrix)

    def force(t: float, q: FloatArray, v: FloatArray, p_prev: FloatArray,
              active_prev: np.ndarray) -> FloatArray:
        kwargs = {}
        if "lam_hat" in reads:
            kwargs["lam_hat"] = p_prev / h
        if "active" in reads:
            kwargs["active"] = active_prev.copy()
        c = np.asarray(controller(float(t), q.copy(), v.copy(), **kwargs),
                       dtype=float).reshape(-1)
        if c.shape != (S.shape[1],) or not np.all(np.isfinite(c)):
            raise _StepFailure(_MODEL_ERROR, "model_error",
                               f"controller: expected a finite input of length {S.shape[1]} "
                               f"from controller(t, q, v), got {c!r} at t = {t:.6g}")
        return S @ c

    return force


def _controller_reads(controller: Any) -> frozenset[str]:
    """Which of ``lam_hat`` and ``active`` the controller accepts as keyword arguments."""
    if controller is None:
        return frozenset()
    try:
        params = inspect.signature(controller).parameters.values()
    except (TypeError, ValueError):  # some builtins have no signature: (t, q, v) only
        return frozenset()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return frozenset(("lam_hat", "active"))
    keyword = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return frozenset(p.name for p in params
                     if p.name in ("lam_hat", "active") and p.kind in keyword)


def _check_input(system: Any, u: Any) -> None:
    """An :class:`Exosystem` input must have one output per actuator column."""
    from ..numerics.lti import Exosystem

    if u is None or callable(u) and not isinstance(u, Exosystem):
        return
    if not isinstance(u, Exosystem):
        raise ModelError(f"u: expected an Exosystem or a callable t -> u, got "
                         f"{type(u).__name__}")
    m = system.n_dof if system.actuation is None else system.actuation.shape[1]
    if u.n_inputs != m:
        raise DimensionError(f"u: expected an Exosystem with {m} input(s) (the actuation's "
                             f"columns), got {u.n_inputs}")


def _choose_runner(system: Any, setup: _Setup, activation: float) -> Any:
    """The fastest correct step loop for this system (see the module docstring)."""
    if system.is_linear and setup.forces == "implicit":
        K = system.stiffness
        D = system.damping
        diag = system.mass_diagonal
        offdiag = [X for X in (K, D) if X is not None and np.count_nonzero(X - np.diag(np.diag(X)))]
        pairs = system.pairwise_contacts()
        if diag is not None and not offdiag and pairs is not None and _neighbour_only(pairs):
            return _PairwiseRunner(system, setup, activation, pairs)
        return _DenseRunner(system, setup, activation)
    return _PythonRunner(system, setup, activation)


def _neighbour_only(pairs: tuple[np.ndarray, ...]) -> bool:
    """Contacts share coordinates only with their neighbours: the Delassus matrix is
    tridiagonal."""
    ia, ib, _, _ = pairs
    owner: dict[int, list[int]] = {}
    for j, (a, b) in enumerate(zip(ia, ib, strict=True)):
        for d in (a, b):
            if d >= 0:
                owner.setdefault(int(d), []).append(j)
    return all(max(js) - min(js) <= 1 for js in owner.values())


class _PairwiseRunner:
    path = "tridiagonal"

    def __init__(self, system: Any, setup: _Setup, activation: float,
                 pairs: tuple[np.ndarray, ...]) -> None:
        from ._moreau_jean_kernels import mj_pairwise_kernel

        h, th = setup.h, setup.theta
        n = system.n_dof
        self.kdiag = np.zeros(n) if system.stiffness is None else np.diag(system.stiffness).copy()
        self.ddiag = np.zeros(n) if system.damping is None else np.diag(system.damping).copy()
        self.minv = 1.0 / (system.mass_diagonal + h * th * self.ddiag + (h * th) ** 2 * self.kdiag)
        self.pairs = tuple(np.ascontiguousarray(p) for p in pairs)
        self.system, self.setup, self.activation = system, setup, float(activation)
        self.kernel = mj_pairwise_kernel

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The kernel's active set at ``(q, v)``, with its operations in its order (the
        same floating-point results)."""
        ia, ib, ca, cb = self.pairs
        two = ib >= 0
        gap = self.system.gap_offset + ca * q[ia]
        un = ca * v[ia]
        gap = np.where(two, gap + cb * q[ib], gap)
        un = np.where(two, un + cb * v[ib], un)
        st = self.setup
        return np.flatnonzero(gap + st.gamma * st.h * un <= self.activation)

    def __call__(self, state: dict[str, Any], fext: FloatArray, chunk: int) -> tuple:
        s, st = self.system, self.setup
        q_out = np.empty((chunk, s.n_dof))
        v_out = np.empty((chunk, s.n_dof))
        p_out = np.empty((chunk, s.n_contacts))
        ia, ib, ca, cb = self.pairs
        done, code = self.kernel(state["q"], state["v"], self.minv, self.kdiag, self.ddiag,
                                 s.constant_force, np.ascontiguousarray(fext), ia, ib, ca, cb,
                                 s.gap_offset, s.restitution, st.h, st.theta, st.gamma,
                                 self.activation, q_out, v_out, p_out)
        return done, code, q_out, v_out, p_out


class _DenseRunner:
    path = "dense"

    def __init__(self, system: Any, setup: _Setup, activation: float) -> None:
        from ._moreau_jean_kernels import mj_dense_kernel

        n = system.n_dof
        h, th = setup.h, setup.theta
        self.K = np.zeros((n, n)) if system.stiffness is None else system.stiffness
        self.D = np.zeros((n, n)) if system.damping is None else system.damping
        Mhat = system.mass_matrix() + h * th * self.D + (h * th) ** 2 * self.K
        self.minv = np.linalg.inv(Mhat)
        self.G = np.ascontiguousarray(system.dense_gap_matrix())
        self.minv_gt = np.ascontiguousarray(self.minv @ self.G.T)
        self.W = np.ascontiguousarray(self.G @ self.minv_gt)
        self.system, self.setup, self.activation = system, setup, float(activation)
        self.kernel = mj_dense_kernel

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The kernel's active set at ``(q, v)``: its sums are sequential, as ``cumsum``'s
        (the same floating-point results)."""
        G, g0 = self.G, self.system.gap_offset
        gap = np.cumsum(np.column_stack([g0, G * q]), axis=1)[:, -1]
        un = np.cumsum(np.column_stack([np.zeros_like(g0), G * v]), axis=1)[:, -1]
        st = self.setup
        return np.flatnonzero(gap + st.gamma * st.h * un <= self.activation)

    def __call__(self, state: dict[str, Any], fext: FloatArray, chunk: int) -> tuple:
        s, st = self.system, self.setup
        q_out = np.empty((chunk, s.n_dof))
        v_out = np.empty((chunk, s.n_dof))
        p_out = np.empty((chunk, s.n_contacts))
        done, code = self.kernel(state["q"], state["v"], self.minv, self.K, self.D,
                                 s.constant_force, np.ascontiguousarray(fext), self.G,
                                 s.gap_offset, s.restitution, self.minv_gt, self.W, st.h,
                                 st.theta, st.gamma, self.activation, q_out, v_out, p_out)
        return done, code, q_out, v_out, p_out


class _PythonRunner:
    """``M(q)`` or nonlinear forces/gaps: the θ-method with linearised (implicit) or explicit
    forces, the LCP by the compiled Lemke kernel."""

    path = "python"

    def __init__(self, system: Any, setup: _Setup, activation: float) -> None:
        from ..numerics._lcp_kernels import lemke_kernel
        from ._mj_linearised_kernel import mj_linearised_kernel

        self.system, self.setup, self.activation = system, setup, float(activation)
        self.analytic = system.force is None or system.force_jacobian is not None
        self.lemke, self.matrices = lemke_kernel, mj_linearised_kernel
        n = system.n_dof
        self.zeros = np.zeros((n, n))  # the Jacobians of explicit forces
        self.active_prev = np.zeros(0, dtype=np.int64)
        self.minv, self.dv = np.empty((n, n)), np.empty(n)
        # affine gaps (possibly scipy.sparse): one dense matrix for the whole run
        self.G = None if system.gap_matrix is None else system.dense_gap_matrix()

    def gap_jacobian(self, q: FloatArray) -> np.ndarray:
        if self.G is not None:
            return self.G
        return np.asarray(self.system.gap_jacobian(q), float)

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The contacts predicted to close, ``g + γ h G v <= activation``."""
        s, st = self.system, self.setup
        un = self.gap_jacobian(q) @ v
        return np.flatnonzero(s.gaps(q) + st.gamma * st.h * un <= self.activation)

    def __call__(self, state: dict[str, Any], fext: FloatArray, chunk: int) -> tuple:
        s = self.system
        q, v = state["q"], state["v"]
        q_out = np.empty((chunk, s.n_dof))
        v_out = np.empty((chunk, s.n_dof))
        p_out = np.zeros((chunk, s.n_contacts))
        progress = state.get("progress")
        if progress is not None:   # the rows a failed step leaves behind are kept
            progress.rows = (q_out, v_out, p_out)
        inline = state.get("inline")
        for k in range(chunk):
            # step starts are t0 + k h (also for the shortened last step, whose runner has
            # its own, shorter h)
            t = state.get("t0", 0.0) + state.get("h", self.setup.h) * (state["k"] + k)
            try:
                f_k = fext[min(k, fext.shape[0] - 1)]
                if inline is not None:
                    f_k = f_k + inline(t, q, v, p_out[k - 1] if k else state["p_prev"],
                                       self.active_prev if k else state["active_prev"])
                code, q_new, v_new = self._step(t, q, v, f_k, p_out[k])
            except _StepFailure as failure:
                state["q"], state["v"] = q, v
                state[failure.key] = failure.message
                return k, failure.code, q_out, v_out, p_out
            if code:
                state["q"], state["v"] = q, v
                return k, code, q_out, v_out, p_out
            q, v = q_new, v_new
            q_out[k], v_out[k] = q, v
            if progress is not None:
                progress.done = k + 1
        state["q"], state["v"] = q, v
        if inline is not None:
            state["active_prev"] = self.active_prev
        return chunk, 0, q_out, v_out, p_out

    def _step(self, t: float, q: FloatArray, v: FloatArray, fext: FloatArray,
              p_row: FloatArray) -> tuple[int, FloatArray, FloatArray]:
        """One step from ``(q, v)`` at ``t``; writes the impulses into ``p_row``."""
        s, st = self.system, self.setup
        h, th = st.h, st.theta
        qm = q + th * h * v if st.mass_at == "predicted" and not s.constant_mass else q
        M = s.mass_matrix(qm)
        if not s.constant_mass:  # M(q) must stay positive definite along the motion
            _check_mass(M, t, qm)
        if st.forces == "implicit":
            tm = t + th * h  # the θ-weighted time (module docstring)
            f = _checked_force(s, tm, q, v)
            Jq, Jv = self._jacobians(tm, q, v)
        else:
            f, Jq, Jv = _checked_force(s, t, q, v), self.zeros, self.zeros
        rcond = self.matrices(np.ascontiguousarray(M), Jq, Jv, f, fext, v, h, th, self.minv,
                              self.dv)
        _check_rcond(rcond, s.n_dof, t, st.forces)
        Minv = self.minv
        v_free = v + self.dv
        G = self.gap_jacobian(q)
        un = G @ v
        active = np.flatnonzero(s.gaps(q) + st.gamma * h * un <= self.activation)
        self.active_prev = active
        v_new = v_free
        if active.size:
            GA = G[active]
            MinvGt = Minv @ GA.T
            W = GA @ MinvGt
            qa = GA @ v_free + s.restitution[active] * un[active]
            if active.size == 1:  # closed form, as in the compiled paths
                z = np.maximum(-qa / W[0], 0.0)
            else:
                z, w = np.empty(active.size), np.empty(active.size)
                code, _ = self.lemke(np.ascontiguousarray(W), qa, z, w, 0)
                if code:
                    return code, q, v
            v_new = v_free + MinvGt @ z
            p_row[active] = z
        return 0, q + h * ((1 - th) * v + th * v_new), v_new

    def _jacobians(self, t: float, q: FloatArray, v: FloatArray
                   ) -> tuple[FloatArray, FloatArray]:
        """``∂f/∂q, ∂f/∂v`` at ``(t, q, v)``, finite (a ``_StepFailure`` otherwise)."""
        try:
            Jq, Jv, _ = self.system.force_jacobians(t, q, v)
        except ModelError as err:
            raise _StepFailure(_MODEL_ERROR, "model_error", str(err)) from None
        if not self.analytic and not (np.isfinite(Jq).all() and np.isfinite(Jv).all()):
            raise _StepFailure(_MODEL_ERROR, "model_error",
                               f"force: its central differences are not finite at t = "
                               f"{t:.6g}, q = {q!r}, v = {v!r}; give force_jacobian or "
                               "keep the force finite near the motion")
        return np.ascontiguousarray(Jq), np.ascontiguousarray(Jv)


class _StepFailure(Exception):
    """A step stopped by the model (``_MODEL_ERROR``) or a singular ``M̂`` (``_SINGULAR``)."""

    def __init__(self, code: int, key: str, message: str) -> None:
        super().__init__(message)
        self.code, self.key, self.message = code, key, message


def _check_mass(M: FloatArray, t: float, q: FloatArray) -> None:
    try:
        np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        raise _StepFailure(_MODEL_ERROR, "model_error",
                           f"mass: M(q) is not positive definite at t = {t:.6g}, q = {q!r}; "
                           "the model is only valid where the mass matrix is") from None


def _checked_force(system: Any, t: float, q: FloatArray, v: FloatArray) -> FloatArray:
    f = np.asarray(system.forces(t, q, v), float)
    if f.shape != (system.n_dof,) or not np.isfinite(f).all():
        raise _StepFailure(_MODEL_ERROR, "model_error",
                           f"force: expected a finite vector of length {system.n_dof} at "
                           f"t = {t:.6g}, got {f!r} (q = {q!r}, v = {v!r})")
    return f


def _check_rcond(rcond: float, n: int, t: float, forces: str) -> None:
    """Refuse an iteration matrix ``M̂`` singular to working precision: ``rcond < n ε``,
    ``rcond = 1 / (scale ‖M̂⁻¹‖₁)`` with ``scale`` the 1-norm of the terms summed into
    ``M̂`` (cancellation between ``M`` and ``h²θ² ∂f/∂q`` is measured against the terms,
    not against the result: a 1 x 1 ``M̂`` is never ill-conditioned by itself)."""
    if not rcond >= n * _EPS:  # also catches NaN
        what = ("M(q) - hθ ∂f/∂v - h²θ² ∂f/∂q" if forces == "implicit" else "M(q)")
        raise _StepFailure(_SINGULAR, "solver_error",
                           f"moreau_jean: the iteration matrix {what} is singular at "
                           f"t = {t:.6g} (reciprocal condition number {rcond:.3g}); a "
                           "negative stiffness of size M/(hθ)² does this: try a smaller h")


# -- recording -----------------------------------------------------------------------------
def _signals(system: Any, q: FloatArray, v: FloatArray, p: FloatArray,
             rec: Recorder) -> dict[str, FloatArray]:
    out: dict[str, FloatArray] = {}
    if rec.wants("impulse"):
        out["impulse"] = p
    if rec.wants("gap"):
        out["gap"] = np.array([system.gaps(qi) for qi in q]) if system.gap is not None \
            else np.asarray((system.gap_matrix @ q.T).T) + system.gap_offset
    if rec.wants("energy"):
        out["energy"] = system.energy(np.hstack([q, v]))
    return out


def _sample_initial(rec: Recorder, system: Any, t0: float, x0: FloatArray) -> None:
    n = system.n_dof
    sig = _signals(system, x0[None, :n], x0[None, n:], np.zeros((1, system.n_contacts)), rec)
    rec.extend(np.array([t0]), x0[None, :], **sig)


def _record_finished(progress: ChunkProgress, *, rec: Recorder, system: Any,
                     times: FloatArray, state: dict[str, Any], q_pre: FloatArray,
                     v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                     h: float) -> None:
    """Record the steps a failed chunk finished (see :meth:`Recorder.chunk`)."""
    q, v, p = progress.written()
    _record_chunk(rec, system, times[:progress.done] + h, q, v, p, state, q_pre, v_pre,
                  listeners, h)


def _record_chunk(rec: Recorder, system: Any, times: FloatArray, q: FloatArray,
                  v: FloatArray, p: FloatArray, state: dict[str, Any], q_pre: FloatArray,
                  v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                  h: float, signals: dict[str, FloatArray] | None = None) -> None:
    """Write a chunk of steps and its impact events; call the jump listeners. ``signals``:
    the chunk's signals when the caller computed them (the compiled path)."""
    rec.extend(times, (q, v), **(_signals(system, q, v, p, rec) if signals is None
                                 else signals))
    prev = np.vstack([state["p_prev"][None, :], p[:-1]])
    rising = (p > 0.0) & (prev == 0.0)
    steps = np.flatnonzero(rising.any(axis=1))
    for k in steps:
        qb = q_pre if k == 0 else q[k - 1]
        vb = v_pre if k == 0 else v[k - 1]
        G = system.gap_jacobian(qb)
        contacts = np.flatnonzero(rising[k])
        un = np.asarray(G[contacts] @ vb).ravel()
        keep = un < 0.0
        contacts, un = contacts[keep], un[keep]
        if contacts.size == 0:
            continue
        # the impact time inside the step, where the gap extrapolated from the step's start
        # reaches zero (the step's end would bias every impact time by up to h)
        gap = np.asarray(system.gaps(qb))[contacts]
        tau = np.clip(gap / -un, 0.0, h)
        x_minus, x_plus = np.concatenate([qb, vb]), np.concatenate([q[k], v[k]])
        for j, tj in zip(contacts, tau, strict=True):
            rec.event(times[k] - h + tj, "impact", int(j), x_minus, x_plus)
        for listener in listeners:
            listener(float(times[k]), x_minus, x_plus, contacts, p[k].copy())
    state["p_prev"] = p[-1].copy()

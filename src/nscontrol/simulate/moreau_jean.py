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
  :func:`~nscontrol.simulate._moreau_jean_kernels.mj_step` (``M̂`` assembled at every step);
* a model with a compiled form (``system.compiled``), alone or under compiled blocks: one
  compiled loop around the same ``mj_step``.

One run (``_Run``) drives every path in chunks of steps: it records, calls the listeners and
a ``controller`` between chunks, shows the progress and ends the run on a failure; the
options are checked once into :class:`~nscontrol.simulate._mj_options.MoreauJeanOptions`.

Recorded: states ``[q; v]``, signals ``impulse`` (per step and contact, ``P``), ``gap`` and
``energy``; events ``"impact"`` (a contact whose impulse becomes positive while approaching).
Impacts are captured within the step: impact times are exact to ``O(h)``, the position drift
(penetration) at a landing is bounded by ``h |u⁻|``.

A ``controller`` may read the contact: with keyword arguments ``lam_hat`` and ``active`` it
receives the previous step's impulses over ``h`` (the mean contact force of that step) and
its active set (see :func:`integrate`).

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

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
from numpy.typing import ArrayLike

from .._progress import TimeProgress
from .._validation import FloatArray
from ..errors import ModelError, SolverError
from ._mj_options import Feedback, MoreauJeanOptions, input_matrix
from ._mj_runners import LCP_STATUS, DenseRunner, Runner, RunState, StepFailure, choose_runner
from .trajectory import ChunkProgress, Recorder, Trajectory, evaluable_prefix

if TYPE_CHECKING:   # imported where used at run time (import nscontrol stays light)
    from ..systems.lagrangian import LagrangianSystem
    from ..systems.protocols import InputSignal
    from .callbacks import Listener, StepController

__all__ = ["integrate"]

#: Floats per chunk of the compiled loop (bounds memory for large systems).
_CHUNK_FLOATS = 2_000_000


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
    system : LagrangianSystem
    x0 : array_like (2 n,)
        Admissible initial state.
    t_span : (float, float)
    h, theta, gamma, u, controller, listeners, record_every, signals, progress, \
activation, forces, mass_at, projection, contact_tol, compiled_blocks
        The options: see "Options" in the module docstring.

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

    """
    from ..systems.lagrangian import LagrangianSystem

    if h is None:
        raise ModelError("h: Moreau-Jean time-stepping needs a step, e.g. h=1e-3 (impacts are "
                         "captured to O(h), penetration <= h |u-|)")
    if not isinstance(system, LagrangianSystem):
        raise ModelError(f"moreau_jean: integrates LagrangianSystem (and ImpactingBodies "
                         f"through nscontrol.simulate), got {type(system).__name__}")
    feedback = Feedback.checked(controller, listeners, compiled_blocks)
    x0 = system.check_state(x0)
    opts = MoreauJeanOptions.checked(
        system, x0, h=h, theta=theta, gamma=gamma, activation=activation, u=u, forces=forces,
        mass_at=mass_at, projection=projection, contact_tol=contact_tol,
        record_every=record_every, signals=signals, progress=progress)
    t0, tf = (float(t) for t in t_span)
    if system.friction_dim or opts.projection:   # Coulomb friction, or the position projection
        from ._frictional_moreau_jean import integrate_frictional

        if controller is not None or listeners:
            raise ModelError("controller, listeners: not supported yet with friction or "
                             "projection=True; simulate without them")
        return integrate_frictional(system, x0, t0, tf, opts)
    return _Run(system, x0, (t0, tf), opts, feedback).run()


@dataclass(frozen=True)
class _Grid:
    """Whole steps of ``h`` from ``t0``, then one shorter step so that the run ends exactly
    at ``tf``."""

    t0: float
    tf: float
    h: float

    def __post_init__(self) -> None:   # read at every chunk: computed once
        n_full = math.floor((self.tf - self.t0) / self.h + 1e-9)
        h_last = (self.tf - self.t0) - n_full * self.h
        object.__setattr__(self, "n_full", n_full)
        object.__setattr__(self, "h_last", h_last)
        object.__setattr__(self, "n_steps", n_full + (1 if h_last > 1e-9 * self.h else 0))

    #: whole steps of ``h``
    n_full: int = field(init=False)
    #: the shortened last step's length
    h_last: float = field(init=False)
    #: steps in all
    n_steps: int = field(init=False)


class _Run:
    """One run over a chunk loop: whichever runner steps, this records, calls the listeners
    and the controller between chunks, shows the progress and ends the run on a failure."""

    def __init__(self, system: Any, x0: FloatArray, t_span: tuple[float, float],
                 opts: MoreauJeanOptions, feedback: Feedback) -> None:
        n, m = system.n_dof, system.n_contacts
        self.system, self.opts, self.fb = system, opts, feedback
        self.grid = _Grid(t_span[0], t_span[1], opts.h)
        self.rec = Recorder(system.n_states, every=opts.record_every, signals=opts.signals,
                            offered=("impulse", "gap", "energy"),
                            capacity=Recorder.capacity_for(self.grid.n_steps + 2,
                                                           opts.record_every))
        _sample_initial(self.rec, system, t_span[0], x0)
        self.S = input_matrix(system, opts.u is not None or feedback.controller is not None)
        self.runner = _first_runner(system, opts, feedback, self.S)
        self.path = self.runner.path
        self.state = RunState(q=x0[:n].copy(), v=x0[n:].copy(), p_prev=np.zeros(m),
                              reads=feedback.reads)
        # Without listeners (which observe after each chunk) a controller on the Python path
        # runs inside the step loop: chunks of many steps, the same zero-order hold per step.
        ctrl = feedback.controller if self.runner.takes_controller else None
        if ctrl is not None and not feedback.listeners and self.runner.path == "python":
            assert self.S is not None   # a controller always sets the input matrix
            self.state.inline = _inline_controller(ctrl, self.S, feedback.reads, opts.h)
            ctrl = None
        #: the controller evaluated between chunks (then one step per chunk)
        self.ctrl = ctrl

    def run(self) -> Trajectory:
        """Every chunk, then the trajectory (a ``SolverError`` carrying it on a failure)."""
        g, st = self.grid, self.state
        status, message, code = 0, None, 0
        with TimeProgress(g.t0, g.tf, desc="moreau_jean", enable=self.opts.progress) as bar:
            while st.k < g.n_steps:
                code, t_fail = self._chunk()
                bar.update(g.t0 + g.h * st.k)
                if code:
                    status, message = -1, self._failure(code, t_fail)
                    break
        return self._finish(status, message, code)

    def _chunk(self) -> tuple[int, float]:
        """Run and record the next chunk; returns the stopping code and time (0 and the
        chunk's end when every step ran)."""
        g, st, system = self.grid, self.state, self.system
        k = st.k
        if k == g.n_full:  # the shortened last step
            self.runner = self.runner.for_step(g.h_last)
            times, step = np.array([g.t0 + g.h * k]), g.h_last
        else:
            chunk = 1 if self.ctrl is not None else max(1, min(g.n_full - k, 20_000,
                _CHUNK_FLOATS // max(1, 2 * system.n_dof + system.n_contacts)))
            times, step = g.t0 + g.h * np.arange(k, k + chunk), g.h
        fext, failed = _chunk_force(self, times)
        if failed is not None:          # run the steps before u's first failing time
            if fext.shape[0] == 0:
                self._end_at_input_failure(failed)
            times = times[:fext.shape[0]]
        q_pre, v_pre = st.q.copy(), st.v.copy()
        active = (self.runner.active_set(q_pre, v_pre)
                  if self.ctrl is not None and "active" in st.reads else None)
        observers = self.runner.observers(self.fb.listeners)
        with self.rec.chunk(partial(_record_finished, rec=self.rec, system=system,
                                    times=times, state=st, q_pre=q_pre, v_pre=v_pre,
                                    listeners=observers, h=step)) as st.progress:
            done, code, q_out, v_out, p_out = self.runner(st, fext, times)
        if done and active is not None:  # one step per chunk with a controller
            st.active_prev = active
        if code and self.runner.path == "tridiagonal":
            # a singular Delassus matrix (redundant contacts): the tridiagonal solve has
            # no pivot; Lemke handles positive semi-definite W. Redo from the failed step.
            self.runner = DenseRunner(system, self.runner.opts, self.S)
            self.path, code = "tridiagonal+dense", 0
        if done:
            q_out, v_out, p_out = q_out[:done], v_out[:done], p_out[:done]
            _record_chunk(self.rec, system, times[:done] + step, q_out, v_out, p_out, st,
                          q_pre, v_pre, observers, step,
                          self.runner.signals(q_out, v_out, p_out, self.rec))
            st.last = (times[done - 1] + step, q_out[-1], v_out[-1], p_out[-1])
        st.k = k + done
        if failed is not None and done == times.size:   # the steps before it all ran
            self._end_at_input_failure(failed)
        return code, float(times[done]) if code else float(times[-1] + step)

    def _failure(self, code: int, t_fail: float) -> str:
        """The message of a run stopped by ``code``; a model error is raised here."""
        from ._moreau_jean_kernels import MODEL_ERROR

        message = self.runner.failure(code, t_fail, self.state)
        if code == MODEL_ERROR:
            raise ModelError(message, trajectory=self.rec.finish(
                status=-1, message=message, method="moreau_jean",
                state_names=self.system.state_names))
        return message

    def _end_at_input_failure(self, failed: Exception) -> NoReturn:
        """Raise the error of an input that failed, once the steps before it are recorded
        (a library error carries them; the driver attaches them to any other)."""
        if isinstance(failed, ModelError):
            failed.trajectory = self.rec.finish(status=-1, message=str(failed),
                                                method="moreau_jean",
                                                state_names=self.system.state_names)
        raise failed

    def _finish(self, status: int, message: str | None, code: int) -> Trajectory:
        """The trajectory, its final state always kept (a ``SolverError`` on a failure)."""
        rec, system, st = self.rec, self.system, self.state
        if st.last is not None and rec.last_time < st.last[0]:
            t_last, q_l, v_l, p_l = st.last
            sig = _signals(system, q_l[None], v_l[None], p_l[None], rec)
            rec.sample(t_last, np.concatenate([q_l, v_l]), force=True,
                       **{key: val[0] for key, val in sig.items()})
        stats = {"steps": int(st.k), "path": self.path, "h": self.opts.h,
                 "theta": self.opts.theta, **self.runner.stats()}
        traj = rec.finish(status=status, message=message, method="moreau_jean", stats=stats,
                          state_names=system.state_names)
        if "gap" in traj.signals and traj.signals["gap"].size:
            traj.stats["max_penetration"] = float(max(0.0, -np.min(traj.signals["gap"])))
        if status < 0:   # the driver returns the partial run under on_failure="return"
            raise SolverError(str(message), status=LCP_STATUS.get(code,
                                                                  "singular iteration matrix"),
                              trajectory=traj)
        return traj


def _first_runner(system: Any, opts: MoreauJeanOptions, feedback: Feedback,
                  S: FloatArray | None) -> Runner:
    """The compiled model's loop (with the blocks of a closed loop) when it applies, else
    the fastest step loop for the system."""
    model = system.compiled
    if model is None and feedback.compiled_blocks is not None:
        # a linear plant under compiled blocks
        from ..systems.lagrangian import affine_compiled_model

        model = affine_compiled_model(system)
    if model is not None and opts.forces == "implicit" and (
            feedback.controller is None or feedback.compiled_blocks is not None):
        from ._mj_compiled import ModelRunner

        return ModelRunner(system, opts, S, model, feedback.compiled_blocks)
    return choose_runner(system, opts, S)


# -- the input ---------------------------------------------------------------------------
def _external_force(run: _Run, times: FloatArray) -> FloatArray:
    """Rows ``S u(t_k)`` for the steps of a chunk (a single zero row without input), the
    controller's ``S c`` added to the first (one step per chunk in closed loop)."""
    S, u, st = run.S, run.opts.u, run.state
    if S is None:
        return np.zeros((1, run.system.n_dof))
    total = np.zeros((times.shape[0], S.shape[1]))
    if u is not None:
        vals = u.u(times) if hasattr(u, "u") else np.array([np.atleast_1d(u(t)) for t in times])
        total += np.asarray(vals, float).reshape(times.shape[0], -1)
    if run.ctrl is not None:
        total[0] += _controller_input(run.ctrl, run.S, st.reads, run.opts.h, float(times[0]),
                                      st.q, st.v, st.p_prev, st.active_prev, ModelError)
    return total @ S.T


def _chunk_force(run: _Run, times: FloatArray) -> tuple[FloatArray, Exception | None]:
    """:func:`_external_force` over a chunk, or, when it raises, over the chunk's longest
    prefix that evaluates (empty when none does), with the error to raise once those steps
    are recorded."""
    try:
        return _external_force(run, times), None
    except Exception as err:  # noqa: BLE001 - handed back to the caller, who re-raises it
        k = evaluable_prefix(lambda j: _external_force(run, times[:j]), times.size)
        return (_external_force(run, times[:k]) if k
                else np.zeros((0, run.system.n_dof))), err


def _controller_input(controller: Any, S: Any, reads: frozenset[str], h: float, t: float,
                      q: FloatArray, v: FloatArray, p_prev: FloatArray,
                      active_prev: np.ndarray, error: Callable[[str], Exception]
                      ) -> FloatArray:
    """``c(t, q, v[, lam_hat=P/h, active=])``, checked (``error(message)`` raised when not
    a finite input of the actuation's width)."""
    kwargs = {}
    if "lam_hat" in reads:  # the previous step's impulse over its length h
        kwargs["lam_hat"] = p_prev / h
    if "active" in reads:
        kwargs["active"] = active_prev.copy()
    c = np.asarray(controller(t, q.copy(), v.copy(), **kwargs), dtype=float).reshape(-1)
    if c.shape != (S.shape[1],) or not np.all(np.isfinite(c)):
        raise error(f"controller: expected a finite input of length {S.shape[1]} from "
                    f"controller(t, q, v), got {c!r} at t = {t:.6g}")
    return c


def _inline_controller(controller: Any, S: FloatArray, reads: frozenset[str], h: float
                       ) -> Callable[..., FloatArray]:
    """The controller as a force ``S c(t, q, v)`` evaluated inside the Python step loop
    (same arguments and checks as between chunks); a bad output stops the run as a model
    error (``err.trajectory`` the steps so far)."""
    from ._moreau_jean_kernels import MODEL_ERROR

    def error(message: str) -> Exception:
        return StepFailure(MODEL_ERROR, message)

    def force(t: float, q: FloatArray, v: FloatArray, p_prev: FloatArray,
              active_prev: np.ndarray) -> FloatArray:
        return S @ _controller_input(controller, S, reads, h, t, q, v, p_prev, active_prev,
                                     error)

    return force


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
    rec.sample(t0, x0, **{key: val[0] for key, val in sig.items()})   # the first: kept


def _record_finished(progress: ChunkProgress, *, rec: Recorder, system: Any,
                     times: FloatArray, state: RunState, q_pre: FloatArray,
                     v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                     h: float) -> None:
    """Record the steps a failed chunk finished (see :meth:`Recorder.chunk`)."""
    q, v, p = progress.written()
    _record_chunk(rec, system, times[:progress.done] + h, q, v, p, state, q_pre, v_pre,
                  listeners, h)


def _record_chunk(rec: Recorder, system: Any, times: FloatArray, q: FloatArray,
                  v: FloatArray, p: FloatArray, state: RunState, q_pre: FloatArray,
                  v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                  h: float, signals: dict[str, FloatArray] | None = None) -> None:
    """Write a chunk of steps and its impact events; call the jump listeners. ``signals``:
    the chunk's signals when the caller computed them (the compiled path)."""
    rec.extend(times, (q, v), **(_signals(system, q, v, p, rec) if signals is None
                                 else signals))
    positive = p > 0.0
    if not positive.any():   # no impulse, no impact (most chunks of a flight)
        state.p_prev = p[-1].copy()
        return
    prev = np.vstack([state.p_prev[None, :], p[:-1]])
    rising = positive & (prev == 0.0)
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
    state.p_prev = p[-1].copy()

"""Event-driven integration of switched systems (``method="switching"``).

Accepted systems:

* :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` — between crossings the flow is affine
  with an exosystem input, propagated exactly by the shared
  :class:`~nscontrol.numerics.lti.LTIFlow` of the augmented system ``[x; ω; 1]``; crossings are
  located by :func:`nscontrol.numerics.lti.first_event` (machine precision, grazing detected).
  With an input that is an arbitrary function of time, each piece is integrated by DOP853 with
  one direction-aware event per facet and a grazing event per facet. With a ``domain``, an
  ``x0`` outside it is refused and leaving it stops the run (``status = 1``).
* :class:`~nscontrol.systems.switched.FilippovSystem` — smooth fields on the sides of switching
  surfaces ``h_j(x) = 0``; DOP853 with event location and grazing detection; attracting
  sliding by the Filippov (equivalent) vector field with exit detection, the state projected
  back onto the surface; repelling sliding raises ``ModelError``.
* :class:`~nscontrol.systems.nonlinear.NonlinearSystem` — a smooth field ``f(t, x[, u])``:
  the Filippov path with no surface (one DOP853 piece; with ``sensitivity=True`` the
  variational equation gives the state transition).
* :class:`~nscontrol.systems.switched.SwitchedAffineSystem` with a PWM controller — the
  switching instants ``t_k + o_j`` follow from the state sampled at the exact ``t_k = t0 + kT``
  in closed form, and each sub-interval is propagated exactly by the mode's ``LTIFlow``.

Event kinds: ``"crossing"``, ``"sliding_start"``, ``"sliding_exit"``, ``"two_sliding_start"``,
``"two_sliding_exit"`` (second-order sliding of a Filippov system, see
``_switching_filippov``), ``"grazing"``,
``"domain_exit"`` (PWA with a domain) and ``"switch"`` (PWM instants), each with ``mode_from``
/ ``mode_to`` and the surface/facet (or domain row) in ``index``.

Options
-------
u : Exosystem or callable, optional
    Input (PWA and nonlinear systems), overriding the system's default.
t_eval : array_like, optional
    Sample times (event instants are always added). Default: ``n_samples`` equally spaced.
n_samples : int
    Number of regular samples when ``t_eval`` is not given (1001; at least 2).
sensitivity : bool
    Also compute ``stats["state_transition"]`` (``∂x(tf)/∂x(t0)``, from the flows' exponentials
    or variational equations and the saltation matrices) and ``stats["saltation_matrices"]``
    (array ``(k, n, n)``, one per crossing / sliding start / sliding exit, in event order).
rtol, atol : float
    Tolerances of DOP853 where an ODE solver is used (1e-11, 1e-13; both > 0).
max_events : int
    Event budget: more events than this raises :class:`~nscontrol.errors.BudgetExceededError`
    (``budget="max_events"``, 1e6) with the computed part. Every DOP853 piece ends at an
    event, so this also bounds the number of pieces.
max_steps : int
    Step budget (1e6): the accepted DOP853 steps of the whole run (Filippov, nonlinear, PWA
    with an input function) plus the periods of a PWM run; spending it raises
    :class:`~nscontrol.errors.BudgetExceededError` (``budget="max_steps"``).
min_rel_step : float
    Smallest DOP853 step as a fraction of the span ``tf - t0`` (1e-12, in ``(0, 1)``; the last
    step, cut at ``tf``, is exempt): a field that blows up or loses its smoothness makes the
    steps shrink, and a step below this raises ``BudgetExceededError``
    (``budget="min_rel_step"``) instead of creeping on. The tests' smallest step is 3e-8 of
    the span.
progress : bool, optional
A failure during the run (``ZenoError``, ``SolverError``: DOP853 failed, and its subclass
``BudgetExceededError``: a budget spent — ``max_events``, ``max_steps``, ``min_rel_step``)
raises with the partial trajectory, every sample computed before it, in ``err.trajectory``
(``simulate(..., on_failure="return")`` returns it
with ``status = -1``); errors in the model or its initial state are always raised.
``stats["steps"]`` counts the steps spent on ``max_steps``.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._progress import TimeProgress
from .._validation import (
    FloatArray,
    as_float_array,
    as_vector,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
)
from ..errors import BudgetExceededError, ModelError, NscontrolError, SolverError, ZenoError
from .trajectory import Recorder, Trajectory

if TYPE_CHECKING:   # imported where used at run time (import nscontrol stays light)
    from ..systems.nonlinear import NonlinearSystem
    from ..systems.pwa import PiecewiseAffineSystem
    from ..systems.switched import FilippovSystem, SwitchedAffineSystem

__all__ = ["integrate", "saltation_matrix"]

_OPTIONS = {"u", "t_eval", "n_samples", "sensitivity", "rtol", "atol", "max_events",
            "progress"}


def saltation_matrix(f_minus: Any, f_plus: Any, normal: Any) -> FloatArray:
    """The jump of the state sensitivity at a transversal crossing of a switching surface.

    Parameters
    ----------
    f_minus : (n,) array_like
        The field ``F⁻`` before the crossing.
    f_plus : (n,) array_like
        The field ``F⁺`` after it.
    normal : (n,) array_like
        The surface gradient ``n`` at the crossing point.

    Returns
    -------
    ndarray, shape (n, n)
        ``S = I + (F⁺ - F⁻) nᵀ / (nᵀ F⁻)``: ``∂x(t⁺)/∂x(t⁻)`` including the shift of the
        crossing time; the identity for a continuous field.

    Raises
    ------
    ModelError
        ``nᵀF⁻ = 0`` (grazing: the saltation matrix is unbounded).

    Notes
    -----
    Hypotheses: the surface is crossed transversally (``nᵀF⁻ ≠ 0``) and both fields are
    smooth near the crossing point (Aizerman and Gantmacher, 1958; Leine and Nijmeijer,
    *Dynamics and bifurcations of non-smooth mechanical systems*, 2004, §7.2).

    Examples
    --------
    >>> S = saltation_matrix([1.0, 1.0], [1.0, -1.0], [0.0, 1.0])
    >>> S.tolist()
    [[1.0, 0.0], [0.0, -1.0]]
    """
    fm, fp, n = (np.asarray(v, float) for v in (f_minus, f_plus, normal))
    den = float(n @ fm)
    if den == 0.0:
        raise ModelError("saltation_matrix: nᵀF⁻ = 0 (grazing contact): no saltation matrix")
    return np.eye(fm.shape[0]) + np.outer(fp - fm, n) / den


class _Run:
    """State shared by the integrators: recorder, events, sensitivity, Zeno guard, the step
    budget."""

    def __init__(self, system: Any, x0: FloatArray, t_span: tuple[float, float],
                 options: dict[str, Any], max_steps: int, min_rel_step: float) -> None:
        unknown = set(options) - _OPTIONS
        if unknown:
            hint = ("; a PWM controller is part of the model: build "
                    "SwitchedAffineSystem(modes, controller=PWMController(period, duty))"
                    if "controller" in unknown else "")
            raise ModelError(f"switching: unknown option(s) {sorted(unknown)}; accepted: "
                             f"{sorted(_OPTIONS)}{hint}")
        self.system = system
        self.n = x0.shape[0]
        self.t0, self.tf = t_span
        t_eval = options.get("t_eval")
        n_samples = check_integer("n_samples", options.get("n_samples", 1001), minimum=2)
        if t_eval is None:
            t_eval = np.linspace(self.t0, self.tf, n_samples)
        t_eval = as_float_array("t_eval", t_eval)
        if t_eval.ndim != 1 or np.any(np.diff(t_eval) < 0):
            raise ModelError(f"t_eval: expected an increasing 1-d array of times, got shape "
                             f"{t_eval.shape}" + ("" if t_eval.ndim != 1 else " (not sorted)"))
        self.t_eval = t_eval[(t_eval >= self.t0) & (t_eval <= self.tf)]
        self._ptr = 0
        self.sensitivity = check_bool("sensitivity", options.get("sensitivity", False))
        self.rtol = check_positive("rtol", options.get("rtol", 1e-11))
        self.atol = check_positive("atol", options.get("atol", 1e-13))
        self.max_events = check_integer("max_events", options.get("max_events", 1_000_000),
                                        minimum=0)
        self.max_steps = check_integer("max_steps", max_steps, minimum=1)
        self.min_rel_step = check_in_interval("min_rel_step", min_rel_step, 0.0, 1.0,
                                              open_interval=True)
        self.min_step = self.min_rel_step * (self.tf - self.t0)
        self.steps = 0
        self.spent: str | None = None      # the budget a DOP853 piece stopped on
        self.status, self.message = 0, None
        self.rec = Recorder(self.n, offered=())   # states and events only, no signals
        self.Phi = np.eye(self.n)
        self.saltations: list[FloatArray] = []
        self.counts: dict[str, int] = {}
        self.bar = TimeProgress(self.t0, self.tf, desc="switching",
                                enable=options.get("progress"))
        self.n_events = 0
        self.stuck = 0

    def samples(self, t_lo: float, t_hi: float, last: bool) -> FloatArray:
        """Requested sample times in ``(t_lo, t_hi]`` (``[t_lo, t_hi]`` at the first piece)."""
        te = self.t_eval
        size = te.shape[0]
        i = self._ptr   # runs ask for consecutive windows: try the remembered position first
        if not (i <= size and (i == 0 or te[i - 1] <= t_lo) and (i == size or te[i] > t_lo)):
            i = int(np.searchsorted(te, t_lo, side="right"))
        if i == size or te[i] > t_hi:
            self._ptr = i
            return te[i:i]
        j = int(np.searchsorted(te, t_hi, side="right"))
        self._ptr = j
        return te[i:j]

    def event(self, t: float, kind: str, index: int, pre: FloatArray, post: FloatArray,
              mode_from: int, mode_to: int, S: FloatArray | None = None) -> None:
        self.rec.event(t, kind, index, pre, post, mode_from, mode_to)
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if S is not None and self.sensitivity:
            self.saltations.append(S)
            self.Phi = S @ self.Phi
        self.n_events += 1
        if self.n_events > self.max_events:
            raise self.spent_error("max_events", t)

    def step(self, t: float) -> None:
        """Count one step of a loop that is not DOP853's (a PWM period) on ``max_steps``."""
        if self.steps >= self.max_steps:
            raise self.spent_error("max_steps", t)
        self.steps += 1

    def dop853(self, rhs: Any, t: float, y0: FloatArray, events: list[Any]) -> Any:
        """``solve_ivp`` by DOP853 from ``t`` to ``tf`` (``rtol``, ``atol``, dense output),
        its accepted steps counted on ``max_steps`` and none shorter than ``min_rel_step``
        times the span (but the last one, cut at ``tf``): spending either stops the piece as a
        failed one (``status = -1``, ``self.spent`` names the budget), with every step before
        in the solution."""
        from scipy.integrate import solve_ivp

        self.spent = None
        return solve_ivp(rhs, (t, self.tf), y0, method=_budgeted_dop853(), run=self,
                         rtol=self.rtol, atol=self.atol, events=events, dense_output=True)

    def piece_failure(self, sol: Any, t_end: float, hint: str) -> SolverError:
        """The error of a DOP853 piece that failed at ``t_end``: the budget it spent, or the
        solver's own failure (``hint`` says what to check)."""
        if self.spent is not None:
            return self.spent_error(self.spent, t_end)
        return SolverError(f"switching: DOP853 failed at t = {t_end:.6g} ({sol.message}); "
                           f"{hint}. The trajectory up to that time is in err.trajectory",
                           status="dop853")

    def spent_error(self, budget: str, t: float) -> BudgetExceededError:
        """The error of a spent budget (``max_events``, ``max_steps`` or ``min_rel_step``)
        at ``t``: the option named first, what to do, the computed part kept."""
        span = f"[{self.t0:.6g}, {self.tf:.6g}]"
        if budget == "max_events":
            return BudgetExceededError(
                f"max_events: the run spent its budget of {self.max_events} events by t = "
                f"{t:.12g} of {span}; raise max_events for a long run (one event per "
                f"switching), or look for an accumulation of switchings (Zeno), chattering or "
                f"sliding. The computed part is in err.trajectory", budget="max_events",
                limit=self.max_events, used=self.n_events)
        if budget == "max_steps":
            return BudgetExceededError(
                f"max_steps: the run spent its {self.max_steps} steps (DOP853 steps, or PWM "
                f"periods) by t = {t:.12g} of {span}; raise max_steps for a long run, or check "
                f"the model for a field that chatters or whose step keeps shrinking. The "
                f"trajectory up to that time is in err.trajectory", budget="max_steps",
                limit=self.max_steps, used=self.steps)
        return BudgetExceededError(
            f"min_rel_step: DOP853 needed a step below min_rel_step = {self.min_rel_step:g} "
            f"times the span {span} (min step {self.min_step:.3g}) at t = {t:.12g}: the field "
            f"may blow up or lose smoothness there; check the model near that time, or lower "
            f"min_rel_step. The trajectory up to that time is in err.trajectory",
            budget="min_rel_step", limit=self.min_rel_step, used=self.steps)

    def zero_length(self, t: float) -> None:
        self.stuck += 1
        if self.stuck > 50:
            raise ZenoError(f"switching: 50 consecutive events at t = {t:.12g} without "
                            f"progress (Zeno point or an undecidable mode)", time=t)

    def finish(self, status: int = 0, message: str | None = None,
               extra: dict[str, Any] | None = None) -> Trajectory:
        self.bar.close()
        stats: dict[str, Any] = {"events": self.n_events, "steps": self.steps,
                                 **{f"n_{k}": v for k, v in self.counts.items()}}
        stats.update(extra or {})
        if self.sensitivity:
            stats["state_transition"] = self.Phi.copy()
            stats["saltation_matrices"] = (np.array(self.saltations) if self.saltations
                                           else np.zeros((0, self.n, self.n)))
        return self.rec.finish(status=status, message=message, method="switching", stats=stats,
                               state_names=getattr(self.system, "state_names", ()))


@functools.cache
def _budgeted_dop853() -> type:
    """scipy's DOP853 counting its accepted steps on a run's budget (built on first use:
    ``import nscontrol`` does not load scipy.integrate)."""
    from scipy.integrate import DOP853

    class BudgetedDOP853(DOP853):
        def __init__(self, fun: Any, t0: float, y0: FloatArray, t_bound: float, *, run: _Run,
                     **options: Any) -> None:
            self.run = run
            super().__init__(fun, t0, y0, t_bound, **options)

        def _step_impl(self) -> tuple[bool, str | None]:
            run = self.run
            if run.steps >= run.max_steps:
                run.spent = "max_steps"
                return False, "max_steps spent"
            t = self.t
            ok, message = super()._step_impl()
            if ok:
                run.steps += 1
                if abs(self.t - t) < run.min_step and self.t != self.t_bound:
                    run.spent = "min_rel_step"   # solve_ivp keeps the steps before this one
                    return False, "step below min_rel_step"
            return ok, message

    return BudgetedDOP853


def integrate(system: PiecewiseAffineSystem | FilippovSystem | SwitchedAffineSystem
              | NonlinearSystem, x0: ArrayLike, t_span: tuple[float, float], *,
              max_steps: int = 1_000_000, min_rel_step: float = 1e-12,
              **options: Any) -> Trajectory:
    """Integrate a PWA, Filippov or PWM-switched system with every switching located (or a
    smooth nonlinear system, which has none).

    Parameters
    ----------
    system : PiecewiseAffineSystem or FilippovSystem or SwitchedAffineSystem or NonlinearSystem
    x0 : array_like, shape (n,)
    t_span : (float, float)
    max_steps : int
        Budget of accepted DOP853 steps over the run plus PWM periods (``>= 1``; default
        1e6, about a minute for a small model): spending it raises
        :class:`~nscontrol.errors.BudgetExceededError` naming ``max_steps``.
    min_rel_step : float
        Smallest DOP853 step as a fraction of ``tf - t0`` (in ``(0, 1)``; default 1e-12); a
        step below it (but the last one, cut at ``tf``) raises ``BudgetExceededError`` naming
        ``min_rel_step``.
    **options
        See the module docstring.

    Returns
    -------
    Trajectory
        Samples at ``t_eval`` and at every event; the event table; ``stats`` with event
        counts and, with ``sensitivity=True``, ``state_transition`` and
        ``saltation_matrices``. ``status = 1`` when a PWA trajectory left its ``domain``.

    Raises
    ------
    ModelError
        Unsupported system, unknown or invalid option, repelling sliding, a non-finite PWM
        duty, or (PWA) a sliding motion on a facet of a discontinuous PWA system (use
        ``FilippovSystem.from_pwa``).
    InadmissibleStateError
        ``x0`` outside a PWA system's domain or in no region.
    ZenoError
        Accumulation of events; ``err.trajectory`` holds the computed part.
    BudgetExceededError
        ``max_steps`` spent, or a step below ``min_rel_step`` (``err.budget`` names which);
        ``err.trajectory`` holds every sample computed before.
    SolverError
        DOP853 failed (e.g. a field that blows up); ``err.trajectory`` holds the computed part.

    Examples
    --------
    >>> from nscontrol.testing.setvalued_problems import relay_feedback
    >>> p = relay_feedback(T=2.0)
    >>> tr = integrate(p.switched, p.x0, p.t_span, sensitivity=True)
    >>> [e.kind for e in tr.events], tr.stats["saltation_matrices"].shape
    (['sliding_start'], (1, 2, 2))
    """
    from ..systems.nonlinear import NonlinearSystem
    from ..systems.pwa import PiecewiseAffineSystem
    from ..systems.switched import FilippovSystem, SwitchedAffineSystem

    if isinstance(system, PiecewiseAffineSystem):
        from ._switching_pwa import run_pwa as runner
    elif isinstance(system, FilippovSystem):
        from ._switching_filippov import run_filippov as runner
    elif isinstance(system, SwitchedAffineSystem):
        from ._switching_pwm import run_pwm as runner
    elif isinstance(system, NonlinearSystem):
        from ._switching_filippov import run_smooth as runner
    else:
        raise ModelError(f"switching: expected a PiecewiseAffineSystem, FilippovSystem, "
                         f"SwitchedAffineSystem or NonlinearSystem, got "
                         f"{type(system).__name__}; Lur'e systems use method='implicit_euler'")
    x0 = as_vector("x0", x0, system.n_states)
    run = _Run(system, x0, t_span, options, max_steps, min_rel_step)
    try:
        extra = runner(system, x0, run, options)
    except NscontrolError as exc:
        exc.trajectory = run.finish(status=-1, message=str(exc))
        raise
    return run.finish(status=run.status, message=run.message, extra=extra)

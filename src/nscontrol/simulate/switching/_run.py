"""The shared part of the switching runners (:mod:`nscontrol.simulate.switching`): the typed
options, the run state (recorder, events, sensitivity, budgets, Zeno guard), the stepper base
that :func:`~nscontrol.simulate.loop.drive` advances, budgeted DOP853 and the saltation matrix
of a crossing.

The runners (``_pwa``, ``_filippov``, ``_pwm``: steppers on :class:`SwitchingStepper`) import
from here and :mod:`~nscontrol.simulate.switching` dispatches to them: no module imports its
importer.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._validation import (
    FloatArray,
    as_float_array,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
)
from ...errors import BudgetExceededError, ModelError, SolverError, ZenoError
from ...numerics.saltation import saltation_matrix as _saltation
from ..loop import Recording, Stop
from ..trajectory import Recorder

__all__ = ["SwitchingOptions", "SwitchingRun", "SwitchingStepper", "saltation_matrix"]


@dataclass(frozen=True)
class SwitchingOptions:
    """The options of ``method="switching"``, validated once (see the module docstring of
    :mod:`nscontrol.simulate.switching` for their meaning).

    Build it with :meth:`parse` from the keyword options of ``simulate``.
    """

    u: Any = None
    t_eval: FloatArray | None = None
    n_samples: int = 1001
    sensitivity: bool = False
    rtol: float = 1e-11
    atol: float = 1e-13
    max_events: int = 1_000_000
    max_steps: int = 1_000_000
    min_rel_step: float = 1e-12
    progress: bool | None = None

    @classmethod
    def parse(cls, options: Mapping[str, Any]) -> SwitchingOptions:
        """The checked options: unknown names and bad values raise ``ModelError``."""
        unknown = set(options) - _NAMES
        if unknown:
            hint = ("; a PWM controller is part of the model: build "
                    "SwitchedAffineSystem(modes, controller=PWMController(period, duty))"
                    if "controller" in unknown else "")
            raise ModelError(f"switching: unknown option(s) {sorted(unknown)}; accepted: "
                             f"{sorted(_NAMES)}{hint}")
        get = options.get
        return cls(
            u=get("u"), t_eval=_check_t_eval(get("t_eval")),
            n_samples=check_integer("n_samples", get("n_samples", 1001), minimum=2),
            sensitivity=check_bool("sensitivity", get("sensitivity", False)),
            rtol=check_positive("rtol", get("rtol", 1e-11)),
            atol=check_positive("atol", get("atol", 1e-13)),
            max_events=check_integer("max_events", get("max_events", 1_000_000), minimum=0),
            max_steps=check_integer("max_steps", get("max_steps", 1_000_000), minimum=1),
            min_rel_step=check_in_interval("min_rel_step", get("min_rel_step", 1e-12), 0.0,
                                           1.0, open_interval=True),
            progress=check_bool("progress", get("progress"), allow_none=True))


_NAMES = frozenset(f.name for f in SwitchingOptions.__dataclass_fields__.values())


@functools.lru_cache(maxsize=16)
def _regular_samples(t0: float, tf: float, n: int) -> FloatArray:
    """``np.linspace(t0, tf, n)`` kept for the runs over one span (a sweep): copying it is
    cheaper than building it (callers copy, the compiled loop takes writable arrays)."""
    return np.linspace(t0, tf, n)


def _check_t_eval(t_eval: Any) -> FloatArray | None:
    if t_eval is None:
        return None
    t_eval = as_float_array("t_eval", t_eval)
    if t_eval.ndim != 1 or np.any(np.diff(t_eval) < 0):
        raise ModelError(f"t_eval: expected an increasing 1-d array of times, got shape "
                         f"{t_eval.shape}" + ("" if t_eval.ndim != 1 else " (not sorted)"))
    return t_eval


def saltation_matrix(f_minus: Any, f_plus: Any, normal: Any) -> FloatArray:
    """The jump of the state sensitivity at a transversal crossing of a switching surface.

    The case without a state jump of :func:`nscontrol.numerics.saltation.saltation_matrix`
    (the one source of the formula), in the switching runners' argument order.

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
    SolverError
        ``nᵀF⁻ = 0`` to rounding (grazing: the saltation matrix is unbounded).

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
    fm = np.asarray(f_minus, dtype=float).reshape(-1)
    return _saltation(np.eye(fm.shape[0]), fm, f_plus, normal)


class SwitchingRun:
    """State shared by the switching runners: the options, recorder, events, sensitivity,
    Zeno guard and the step budget."""

    def __init__(self, system: Any, x0: FloatArray, t_span: tuple[float, float],
                 opts: SwitchingOptions) -> None:
        self.system, self.opts = system, opts
        self.n = x0.shape[0]
        self.t0, self.tf = t_span
        t_eval = opts.t_eval
        if t_eval is None:
            self.t_eval = _regular_samples(self.t0, self.tf, opts.n_samples).copy()
        else:
            self.t_eval = t_eval[(t_eval >= self.t0) & (t_eval <= self.tf)]
        self._ptr = 0
        self.sensitivity, self.rtol, self.atol = opts.sensitivity, opts.rtol, opts.atol
        self.max_events, self.max_steps = opts.max_events, opts.max_steps
        self.min_rel_step = opts.min_rel_step
        self.min_step = self.min_rel_step * (self.tf - self.t0)
        self.steps = 0
        self.spent: str | None = None      # the budget a DOP853 piece stopped on
        self.status: int = 0
        self.message: str | None = None
        self.rec: Recorder       # the run's record, given by drive (SwitchingDrive.start)
        self.Phi = np.eye(self.n)
        self.saltations: list[FloatArray] = []
        self.counts: dict[str, int] = {}
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

    def stats(self, extra: dict[str, Any]) -> dict[str, Any]:
        """The run's statistics (``traj.stats``), with the runner's own ``extra``."""
        stats: dict[str, Any] = {"events": self.n_events, "steps": self.steps,
                                 **{f"n_{k}": v for k, v in self.counts.items()}}
        stats.update(extra)
        if self.sensitivity:
            stats["state_transition"] = self.Phi.copy()
            stats["saltation_matrices"] = (np.array(self.saltations) if self.saltations
                                           else np.zeros((0, self.n, self.n)))
        return stats


class SwitchingDrive:
    """A switching run as :func:`~nscontrol.simulate.loop.drive`'s stepper: it records
    states and events (no signals) into the record ``drive`` holds, the runner (built by
    ``make(system, x0, run)`` at :meth:`start`, when it records its first sample) running
    the pieces."""

    def __init__(self, make: Any, system: Any, x0: FloatArray, run: SwitchingRun) -> None:
        self.make, self.system, self.x0, self.run = make, system, x0, run
        self.recording = Recording(run.n, offered=(),
                                   state_names=tuple(getattr(system, "state_names", ())))
        self.runner: SwitchingStepper | None = None

    def start(self, rec: Recorder) -> None:
        self.run.rec = rec
        self.runner = self.make(self.system, self.x0, self.run)

    def advance(self) -> float | Stop:
        assert self.runner is not None
        return self.runner.advance()

    def settle(self) -> None:
        """Nothing held back: a runner records each piece as it ends."""

    def end(self, stop: Stop) -> dict[str, Any]:
        assert self.runner is not None
        return self.run.stats(self.runner.extra())


class SwitchingStepper:
    """What a switching runner gives :func:`~nscontrol.simulate.loop.drive`: its
    :meth:`advance` runs one piece (a flight to the next event and that event, a call of
    the compiled PWA loop, a PWM period) and returns the time reached; at the end it
    records the final sample and returns a :class:`~nscontrol.simulate.loop.Stop`.
    A runner keeps the time reached in ``t``, sets ``done`` when its last piece ran, and
    gives :meth:`extra` (its stats)."""

    def __init__(self, run: SwitchingRun) -> None:
        self.run = run
        self.t = run.t0
        self.done = False

    def state(self) -> FloatArray:
        """The current state (recorded at ``tf`` when the last sample is earlier)."""
        raise NotImplementedError

    def piece(self) -> float:
        """Run and record the next piece; the time reached (``done`` set after the last)."""
        raise NotImplementedError

    def extra(self) -> dict[str, Any]:
        """The runner's own statistics."""
        return {}

    def advance(self) -> float | Stop:
        run = self.run
        if not self.done and self.t < run.tf:
            return self.piece()
        if run.rec.last_time < run.tf and run.status == 0:
            run.rec.sample(run.tf, self.state(), force=True)
        return Stop(run.status, run.message)


#: A DOP853 piece's first step is at least this many ``min_rel_step`` floors of the span.
_FIRST_STEP_FLOORS = 4.0


@functools.cache
def _budgeted_dop853() -> type:
    """scipy's DOP853 counting its accepted steps on a run's budget (built on first use:
    ``import nscontrol`` does not load scipy.integrate)."""
    from scipy.integrate import DOP853

    class BudgetedDOP853(DOP853):
        def __init__(self, fun: Any, t0: float, y0: FloatArray, t_bound: float, *,
                     run: SwitchingRun, **options: Any) -> None:
            self.run = run
            super().__init__(fun, t0, y0, t_bound, **options)
            # scipy's first step, 1% of the state's scaled size over the field's, is about
            # eps |t| / |F| for a state at rounding level (a piece starting at a crossing of a
            # surface through 0: the event's state carries a rounding of eps |t| |F|), and
            # the step is then cut to scipy's floor of 10 ulp(t), below min_rel_step of the
            # span for t far from 0. Raised to a few floors (the rounding of t + h stays above
            # it), it is a start the error control accepts for a field smooth at that scale.
            floor = _FIRST_STEP_FLOORS * run.min_step
            self.h_abs: float = min(max(float(self.h_abs), floor), abs(t_bound - t0))

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

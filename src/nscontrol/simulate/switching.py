"""Event-driven integration of switched systems (``method="switching"``).

Accepted systems:

* :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` — between crossings the flow is affine
  with an exosystem input, propagated exactly by matrix exponentials of the augmented system
  ``[x; ω; 1]``; crossings are located by :func:`nscontrol.numerics.lti.first_event` (machine
  precision, grazing detected). With an input that is an arbitrary function of time, each piece
  is integrated by DOP853 with one direction-aware event per facet.
* :class:`~nscontrol.systems.switched.FilippovSystem` — smooth fields on the sides of switching
  surfaces ``h_j(x) = 0``; DOP853 with event location; attracting sliding by the Filippov
  (equivalent) vector field with exit detection; repelling sliding raises ``ModelError``.
* :class:`~nscontrol.systems.switched.SwitchedAffineSystem` with a PWM controller — the
  switching instants follow from the sampled state in closed form and each sub-interval is
  propagated exactly.

Event kinds: ``"crossing"``, ``"sliding_start"``, ``"sliding_exit"``, ``"grazing"`` (and
``"switch"`` for PWM instants), each with ``mode_from`` / ``mode_to`` and the surface/facet in
``index``.

Options
-------
u : Exosystem or callable, optional
    Input (PWA systems), overriding the system's default.
t_eval : array_like, optional
    Sample times (event instants are always added). Default: ``n_samples`` equally spaced.
n_samples : int
    Default number of regular samples (1001).
sensitivity : bool
    Also compute ``stats["state_transition"]`` (``∂x(tf)/∂x(t0)``, from the flows' exponentials
    or variational equations and the saltation matrices) and ``stats["saltation_matrices"]``
    (array ``(k, n, n)``, one per crossing / sliding start / sliding exit, in event order).
rtol, atol : float
    Tolerances of DOP853 where an ODE solver is used (1e-11, 1e-13).
max_events : int
    Zeno guard: more events than this raises :class:`~nscontrol.errors.ZenoError` (1e6).
progress : bool, optional
on_failure : {"raise", "return"}
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._progress import TimeProgress
from .._validation import FloatArray, as_vector
from ..errors import ModelError, NscontrolError, ZenoError
from .trajectory import Recorder, Trajectory

__all__ = ["integrate", "saltation_matrix"]

_OPTIONS = {"u", "t_eval", "n_samples", "sensitivity", "rtol", "atol", "max_events",
            "progress", "on_failure"}


def saltation_matrix(f_minus: Any, f_plus: Any, normal: Any) -> FloatArray:
    """``S = I + (F⁺ - F⁻) nᵀ / (nᵀ F⁻)``: the jump of the state sensitivity at a crossing of a
    surface with gradient ``n`` where the field switches from ``F⁻`` to ``F⁺``.

    Raises
    ------
    ModelError
        ``nᵀF⁻ = 0`` (grazing: the saltation matrix is unbounded).
    """
    fm, fp, n = (np.asarray(v, float) for v in (f_minus, f_plus, normal))
    den = float(n @ fm)
    if den == 0.0:
        raise ModelError("saltation_matrix: nᵀF⁻ = 0 (grazing contact): no saltation matrix")
    return np.eye(fm.shape[0]) + np.outer(fp - fm, n) / den


class _Run:
    """State shared by the integrators: recorder, events, sensitivity, Zeno guard."""

    def __init__(self, system: Any, x0: FloatArray, t_span: tuple[float, float],
                 options: dict[str, Any]) -> None:
        unknown = set(options) - _OPTIONS
        if unknown:
            raise ModelError(f"switching: unknown option(s) {sorted(unknown)}; accepted: "
                             f"{sorted(_OPTIONS)}")
        self.system = system
        self.n = x0.shape[0]
        self.t0, self.tf = t_span
        t_eval = options.get("t_eval")
        if t_eval is None:
            t_eval = np.linspace(self.t0, self.tf, int(options.get("n_samples", 1001)))
        t_eval = np.asarray(t_eval, float)
        if t_eval.ndim != 1 or np.any(np.diff(t_eval) < 0):
            raise ModelError("t_eval: expected an increasing 1-d array of times")
        self.t_eval = t_eval[(t_eval >= self.t0) & (t_eval <= self.tf)]
        self.sensitivity = bool(options.get("sensitivity", False))
        self.rtol = float(options.get("rtol", 1e-11))
        self.atol = float(options.get("atol", 1e-13))
        self.max_events = int(options.get("max_events", 1_000_000))
        self.on_failure = options.get("on_failure", "raise")
        if self.on_failure not in ("raise", "return"):
            raise ModelError(f"on_failure: expected 'raise' or 'return', got "
                             f"{self.on_failure!r}")
        self.rec = Recorder(self.n)
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
        lo = np.searchsorted(te, t_lo, side="right")
        hi = np.searchsorted(te, t_hi, side="right")
        return te[lo:hi]

    def event(self, t: float, kind: str, index: int, pre: FloatArray, post: FloatArray,
              mode_from: int, mode_to: int, S: FloatArray | None = None) -> None:
        self.rec.event(t, kind, index, pre, post, mode_from, mode_to)
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if S is not None and self.sensitivity:
            self.saltations.append(S)
            self.Phi = S @ self.Phi
        self.n_events += 1
        if self.n_events > self.max_events:
            raise ZenoError(f"switching: more than max_events = {self.max_events} events by "
                            f"t = {t:.6g}; an accumulation of switchings (Zeno) or chattering. "
                            f"Raise max_events, or check for sliding", time=t)

    def zero_length(self, t: float) -> None:
        self.stuck += 1
        if self.stuck > 50:
            raise ZenoError(f"switching: 50 consecutive events at t = {t:.12g} without "
                            f"progress (Zeno point or an undecidable mode)", time=t)

    def finish(self, status: int = 0, message: str | None = None,
               extra: dict[str, Any] | None = None) -> Trajectory:
        self.bar.close()
        stats: dict[str, Any] = {"events": self.n_events, **{f"n_{k}": v
                                                            for k, v in self.counts.items()}}
        stats.update(extra or {})
        if self.sensitivity:
            stats["state_transition"] = self.Phi.copy()
            stats["saltation_matrices"] = (np.array(self.saltations) if self.saltations
                                           else np.zeros((0, self.n, self.n)))
        return self.rec.finish(status=status, message=message, method="switching", stats=stats,
                               state_names=getattr(self.system, "state_names", ()))


def integrate(system: Any, x0: Any, t_span: tuple[float, float], **options: Any) -> Trajectory:
    """Integrate a PWA, Filippov or PWM-switched system with every switching located.

    Parameters
    ----------
    system : PiecewiseAffineSystem or FilippovSystem or SwitchedAffineSystem
    x0 : array_like, shape (n,)
    t_span : (float, float)
    **options
        See the module docstring.

    Returns
    -------
    Trajectory
        Samples at ``t_eval`` and at every event; the event table; ``stats`` with event
        counts and, with ``sensitivity=True``, ``state_transition`` and
        ``saltation_matrices``.

    Raises
    ------
    ModelError
        Unsupported system, unknown option, repelling sliding, or (PWA) a sliding motion on a
        facet of a discontinuous PWA system (use ``FilippovSystem.from_pwa``).
    ZenoError
        Accumulation of events; ``err.trajectory`` holds the computed part.
    """
    from ..systems.pwa import PiecewiseAffineSystem
    from ..systems.switched import FilippovSystem, SwitchedAffineSystem

    if isinstance(system, PiecewiseAffineSystem):
        from ._switching_pwa import run_pwa as runner
    elif isinstance(system, FilippovSystem):
        from ._switching_filippov import run_filippov as runner
    elif isinstance(system, SwitchedAffineSystem):
        from ._switching_pwm import run_pwm as runner
    else:
        raise ModelError(f"switching: expected a PiecewiseAffineSystem, FilippovSystem or "
                         f"SwitchedAffineSystem, got {type(system).__name__}; Lur'e systems use "
                         f"method='implicit_euler'")
    x0 = as_vector("x0", x0, system.n_states)
    run = _Run(system, x0, t_span, options)
    try:
        extra = runner(system, x0, run, options)
    except NscontrolError as exc:
        traj = run.finish(status=-1, message=str(exc))
        if run.on_failure == "return" and not isinstance(exc, ModelError):
            return traj
        exc.trajectory = traj
        raise
    return run.finish(extra=extra)

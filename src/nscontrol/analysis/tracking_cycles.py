"""Per-impact events, per-cycle reports and the weak-stability verdict of a tracking run.

Reads a Moreau–Jean trajectory of a closed loop with the switching tracking controller of
:mod:`nscontrol.design.complementarity_tracking`, whose log was merged as signals (``V``,
``V1``, ``phase``, ``cycle``, ``lam_d``, ``lam_hat``, ``q_task``, ``dq_task``, ``qd``; one row
per sample, the row of a step start holding the values the controller used over that step),
plus ``impulse`` and ``gap`` of the integrator.

* an **impact event** is a step whose impulse becomes positive (after a step without) while
  the normal velocity at its start is negative; its jump of ``V`` is ``σ_V = V(end) - V(start)``
  and the kinetic-energy loss Newton's law predicts is
  ``ΔT = -(1 - e²) (u⁻)² / (2 D M_q⁻¹ Dᵀ)`` — equal to ``σ_V`` for every impact after the first
  of a cycle (the reference is at rest on the surface then);
* the **accumulation point** of the impact times is extrapolated geometrically from the last
  three (flight times shrinking by a ratio ``r < 1``);
* **weak stability** across cycles: ``V`` at the start of each transition does not grow from
  cycle to cycle (up to a stated floor) and never exceeds its first value.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray, check_positive
from ..errors import ModelError

__all__ = ["ImpactEvent", "CycleReport", "WeakStabilityVerdict", "impact_events",
           "cycle_reports", "accumulation_estimate", "check_weak_stability",
           "free_phase_growth", "PHASE_NAMES"]

#: Names of the logged phase ids (``Phase`` of the design module).
PHASE_NAMES = ("free", "approach", "impacts", "constrained")


@dataclass(frozen=True)
class ImpactEvent:
    """One impact of the end effector.

    Attributes
    ----------
    t
        Start of the step that contains it.
    step
        Index of that step's starting sample.
    u_minus, u_plus
        Normal velocity before and after the step (``u⁺`` through the constraint gradient
        at the step's start, the one Newton's law is imposed on).
    sigma_V
        ``V(end) - V(start)`` over the step.
    dT_predicted
        ``-(1 - e²) (u⁻)² / (2 D M_q⁻¹ Dᵀ)``.
    cycle, phase
        Cycle index and phase id at the step's start.
    first
        Whether it is the first impact of its cycle's transition phase.
    """

    t: float
    step: int
    u_minus: float
    u_plus: float
    sigma_V: float
    dT_predicted: float
    cycle: int
    phase: int
    first: bool


@dataclass(frozen=True)
class CycleReport:
    """The quantities of one cycle (free motion, transition, constrained motion).

    Attributes
    ----------
    index
        Cycle ``k``.
    tau0, V_tau0, V1_tau0
        Start of the transition design and ``V``, ``V1`` there.
    depth
        ``d_k``.
    t_first_impact, sigma_V_first, sigma_V_rest
        First impact, its jump of ``V``, the sum of the later jumps.
    n_impacts
        Impact events of the transition phase.
    t_accumulation
        Extrapolated accumulation point of the impact times (``nan`` with fewer than 3).
    flight_ratios
        Successive flight-time ratios ``(t_{l+1} - t_l)/(t_l - t_{l-1})``.
    t_constrained, V_constrained
        Start of the constrained phase and ``V`` there.
    t_detach, V_detach
        Take-off and ``V`` there.
    min_gap
        Smallest gap over the cycle (negative: penetration).
    tracking_error_tau0
        ``|q - q_d|`` at ``τ0`` (end of the free phase).
    force_error_last_second
        ``max |λ̂ - λ_d|`` over the last second before take-off.
    t_star, u_star
        Crossing of the surface by the virtual dive and its speed there (designed switching).
    events
        The cycle's impact events.
    """

    index: int
    tau0: float
    V_tau0: float
    V1_tau0: float
    depth: float
    t_first_impact: float
    sigma_V_first: float
    sigma_V_rest: float
    n_impacts: int
    t_accumulation: float
    flight_ratios: tuple[float, ...]
    t_constrained: float
    V_constrained: float
    t_detach: float
    V_detach: float
    min_gap: float
    tracking_error_tau0: float
    force_error_last_second: float
    t_star: float = math.nan
    u_star: float = math.nan
    events: tuple[ImpactEvent, ...] = field(default=(), repr=False)

    def to_json(self) -> dict[str, Any]:
        """The report as plain numbers (events left out)."""
        out: dict[str, Any] = {}
        for key, value in self.__dict__.items():
            if key == "events":
                continue
            out[key] = list(value) if isinstance(value, tuple) else value
        return out


@dataclass(frozen=True)
class WeakStabilityVerdict:
    """Cycle-level (practical) weak stability from ``V`` at the transition starts.

    Attributes
    ----------
    holds
        Every cycle reached the constrained phase, ``V(τ0ᵏ⁺¹) <= growth V(τ0ᵏ) + v_floor``
        and (for ``growth <= 1``) ``V(τ0ᵏ) <= V(τ0⁰) + v_floor``.
    V_tau0
        ``V(τ0ᵏ)`` per cycle.
    worst_growth
        ``max_k V(τ0ᵏ⁺¹) - growth V(τ0ᵏ)`` (``-inf`` with one cycle).
    cycles_completed
        Cycles that reached the constrained phase.
    message
        The verdict in words.
    """

    holds: bool
    V_tau0: tuple[float, ...]
    worst_growth: float
    cycles_completed: int
    message: str


def _rows(traj: Any, name: str) -> FloatArray:
    if name not in traj.signals:
        raise ModelError(f"traj: signal {name!r} missing; run the loop through the chapter's "
                         "runner so that the controller's log is merged")
    return np.asarray(traj.signals[name], float)


def impact_events(traj: Any, model: Any, restitution: float) -> list[ImpactEvent]:
    """The impact events of a tracking run (module docstring).

    Parameters
    ----------
    traj : Trajectory
        Run with the controller's log merged.
    model : TaskSpaceModel
        The plant's task map and dynamics (``M_q`` for ``ΔT``).
    restitution : float
        Newton coefficient of the contact.
    """
    P = _rows(traj, "impulse")[:, 0]
    dq = _rows(traj, "dq_task")
    V, phase, cycle = _rows(traj, "V"), _rows(traj, "phase"), _rows(traj, "cycle")
    n = model.n_dof
    out: list[ImpactEvent] = []
    seen_first: set[int] = set()
    # sample k + 1 holds the impulse of step k (from sample k to k + 1)
    for k in np.flatnonzero((P[1:] > 0.0) & (P[:-1] == 0.0)):
        u_minus = float(dq[k, 0])
        if u_minus >= 0.0:
            continue
        x = traj.x[k]
        Mq, _, _, J = model.task_dynamics(x[:n], x[n:])
        # the scheme enforces Newton's law on the normal velocity through the constraint
        # gradient at the step's start: u⁺ = ∇F(θ_k)ᵀ θ'_{k+1}
        u_plus = float(J[0] @ traj.x[k + 1][n:])
        W = float(np.linalg.solve(Mq, np.eye(n)[:, 0])[0])
        dT = -(1.0 - restitution**2) * u_minus**2 / (2.0 * W)
        c, ph = int(cycle[k]), int(phase[k])
        first = ph in (1, 2) and c not in seen_first
        if first:
            seen_first.add(c)
        out.append(ImpactEvent(float(traj.t[k]), int(k), u_minus, u_plus,
                               float(V[k + 1] - V[k]), dT, c, ph, first))
    return out


def accumulation_estimate(event_times: Sequence[float]) -> float:
    """Accumulation point of impact times from the last three (geometric flight times).

    ``r = (t_L - t_{L-1})/(t_{L-1} - t_{L-2})``, ``t_∞ ≈ t_L + (t_L - t_{L-1}) r/(1 - r)``;
    ``nan`` with fewer than three times or ``r >= 1`` (no accumulation).

    Parameters
    ----------
    event_times : sequence of float
        Increasing impact times.

    Examples
    --------
    >>> accumulation_estimate([0.0, 1.0, 1.5, 1.75])
    2.0
    """
    t = np.asarray(event_times, float)
    if t.size < 3:
        return math.nan
    d1, d0 = t[-1] - t[-2], t[-2] - t[-3]
    if d0 <= 0.0:
        return math.nan
    r = d1 / d0
    if r >= 1.0:
        return math.nan
    return float(t[-1] + d1 * r / (1.0 - r))


def _value_at(traj: Any, name: str, t: float) -> float:
    if not math.isfinite(t):
        return math.nan
    k = int(np.clip(np.searchsorted(traj.t, t - 1e-12), 0, traj.t.size - 1))
    return float(_rows(traj, name)[k])


def cycle_reports(traj: Any, controller: Any, model: Any,
                  restitution: float) -> list[CycleReport]:
    """One :class:`CycleReport` per cycle whose transition started.

    Parameters
    ----------
    traj : Trajectory
        Run with the controller's log merged.
    controller : SwitchingTrackingController
        The controller after the run (its per-cycle instants).
    model : TaskSpaceModel
        The plant model.
    restitution : float
        Newton coefficient.
    """
    events = impact_events(traj, model, restitution)
    gap = _rows(traj, "gap")[:, 0]
    q, qd = _rows(traj, "q_task"), _rows(traj, "qd")
    lam_hat, lam_d = _rows(traj, "lam_hat"), _rows(traj, "lam_d")
    phase = _rows(traj, "phase")
    t = np.asarray(traj.t)
    reports = []
    for c in controller.cycles:
        if not math.isfinite(c.tau0):
            continue
        t_end = c.t_detach if math.isfinite(c.t_detach) else t[-1]
        ev = [e for e in events if e.cycle == c.index and e.phase in (1, 2)]
        times = [e.t for e in ev]
        flights = np.diff(times)
        ratios = tuple(float(r) for r in flights[1:] / flights[:-1]) if flights.size > 1 \
            else ()
        in_cycle = (t >= c.tau0) & (t <= t_end)
        k0 = int(np.searchsorted(t, c.tau0 - 1e-12))
        last = in_cycle & (t >= t_end - 1.0) & (phase == 3)
        reports.append(CycleReport(
            index=c.index, tau0=c.tau0, V_tau0=c.V_tau0, V1_tau0=c.V1_tau0, depth=c.depth,
            t_first_impact=c.t_first_impact,
            sigma_V_first=ev[0].sigma_V if ev else math.nan,
            sigma_V_rest=float(sum(e.sigma_V for e in ev[1:])), n_impacts=len(ev),
            t_accumulation=accumulation_estimate(times), flight_ratios=ratios,
            t_constrained=c.t_constrained, V_constrained=_value_at(traj, "V", c.t_constrained),
            t_detach=c.t_detach, V_detach=_value_at(traj, "V", c.t_detach),
            min_gap=float(gap[in_cycle].min()) if in_cycle.any() else math.nan,
            tracking_error_tau0=float(np.linalg.norm(q[k0] - qd[k0])),
            force_error_last_second=float(np.abs(lam_hat[last] - lam_d[last]).max())
            if last.any() else math.nan,
            t_star=c.t_star, u_star=c.u_star, events=tuple(ev)))
    return reports


def check_weak_stability(reports: Sequence[CycleReport], v_floor: float = 1e-8,
                         growth: float = 1.0) -> WeakStabilityVerdict:
    """Cycle-level weak stability: ``V(τ0ᵏ⁺¹) <= growth V(τ0ᵏ) + v_floor`` for all ``k``,
    ``V(τ0ᵏ) <= V(τ0⁰) + v_floor`` and every cycle reached its constrained phase.

    Parameters
    ----------
    reports : sequence of CycleReport
        From :func:`cycle_reports`.
    v_floor : float
        Allowance for the discretisation floor of ``V`` (``O(h²)``).
    growth : float
        Allowed factor per cycle (1: no growth; > 1 under model error).
    """
    check_positive("v_floor", v_floor, allow_zero=True)
    check_positive("growth", growth)
    V = tuple(r.V_tau0 for r in reports)
    completed = sum(math.isfinite(r.t_constrained) for r in reports)
    diffs = [V[k + 1] - growth * V[k] for k in range(len(V) - 1)]
    worst = max(diffs) if diffs else -math.inf
    # with growth allowed (model error) only the per-cycle bound is asked for
    bounded = all(v <= V[0] + v_floor for v in V) if growth <= 1.0 else True
    holds = bool(V) and worst <= v_floor and bounded and completed == len(reports)
    if not V:
        message = "no transition started: nothing to judge"
    elif holds:
        message = (f"weakly stable over {len(V)} cycles: V at the transition starts "
                   f"{', '.join(f'{v:.3g}' for v in V)} (growth allowance {growth}, floor "
                   f"{v_floor:.1g})")
    else:
        message = (f"not shown: V at the transition starts {', '.join(f'{v:.3g}' for v in V)}, "
                   f"worst growth {worst:.3g}, {completed} of {len(V)} cycles reached the "
                   "constrained phase")
    return WeakStabilityVerdict(holds, V, worst, completed, message)


def free_phase_growth(traj: Any) -> float:
    """Largest rise of ``V`` above its running minimum inside a free-motion segment.

    ``V`` decreases in free motion (``V' <= -γV``); the discrete ``V`` may rise by the
    scheme's ``O(h²)`` floor at the reference's acceleration discontinuities.

    Parameters
    ----------
    traj : Trajectory
        Run with the controller's log merged.
    """
    V, phase = _rows(traj, "V"), _rows(traj, "phase")
    worst, start = 0.0, None
    free = phase == 0
    for k in range(V.size + 1):
        if k < V.size and free[k]:
            if start is None:
                start = k
            continue
        if start is not None:
            seg = V[start:k]
            worst = max(worst, float(np.max(seg - np.minimum.accumulate(seg))))
            start = None
    return worst

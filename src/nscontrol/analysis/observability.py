"""Observability and reconstructibility of bodies that interact only through impacts (ch. 2).

The (n-1, 1) case of chapter 2: an actuated body ``a`` of ``n - 1`` masses, measured through
``y = q_1``, hits a free mass ``b`` that is unobservable between impacts. This module
analyses a model and a simulated run:

* :func:`impact_observability` -- Theorem 1 for an
  :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies` model;
* :func:`reconstructibility` -- Theorem 2 for a given impact record;
* :func:`impact_decay_rate` -- the decay rate of ``||x~||`` measured on a simulated run;
* :func:`impact_error_contraction` -- the error propagated alone along the run's impacts
  (its contraction over each inter-impact interval, without the rounding floor).

The conditions the observer design itself needs are defined in
:mod:`nscontrol.design.impact_conditions` and re-exported here, so that the chapter's tests
read from one place: :func:`theorem1_test`, :func:`jury_second_order`, :func:`alpha_limit`,
:func:`observer_flow_norms`, :func:`search_epsilon`, :func:`certified_rate`; the
Popov-Belevitch-Hautus test :func:`pbh_observability` is pure linear algebra, in
:mod:`nscontrol.numerics.observability`. All are decided on balanced, dimensionless matrices,
so that their verdicts do not depend on the units of the model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_square,
    as_vector,
    check_bool,
    check_integer,
    check_positive,
    check_t_span,
)
from ..design.impact_conditions import (
    EpsilonCertificate,
    Theorem1Result,
    alpha_limit,
    certified_rate,
    jury_second_order,
    observer_flow_norms,
    search_epsilon,
    theorem1_test,
)
from ..errors import DimensionError, ModelError
from ..numerics.observability import RANK_RTOL, pbh_observability

__all__ = [
    "Theorem1Result",
    "ReconstructibilityResult",
    "EpsilonCertificate",
    "DecayMeasurement",
    "ErrorContraction",
    "RANK_RTOL",
    "theorem1_test",
    "impact_observability",
    "pbh_observability",
    "reconstructibility",
    "jury_second_order",
    "alpha_limit",
    "observer_flow_norms",
    "search_epsilon",
    "certified_rate",
    "impact_decay_rate",
    "impact_error_contraction",
    "ROUNDING_PER_STATE",
    "MAX_RELATIVE_ROUNDING",
]


# ----------------------------------------------------------------------------------------------
# Theorem 1 on a model
# ----------------------------------------------------------------------------------------------
def impact_observability(bodies: Any) -> Theorem1Result:
    """Theorem 1 for an :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies` model.

    Parameters
    ----------
    bodies : ImpactingBodies
        The plant; the contact mass is the last of body a.

    Returns
    -------
    Theorem1Result

    Examples
    --------
    >>> from nscontrol.systems.impacting_bodies import ImpactingBodies
    >>> chain = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0, (0, 1): 6.0},
    ...                                      {(0, 0): 4.0})
    >>> impact_observability(chain).observable
    True
    >>> cut = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0}, {(0, 0): 4.0})
    >>> impact_observability(cut).reason.split(":")[0]
    'condition (1) fails'
    """
    n_a = int(bodies.n_a)
    contact = np.zeros(2 * n_a)
    contact[n_a - 1] = 1.0
    return theorem1_test(bodies.A_a, bodies.B_a, bodies.C_a, contact)


# ----------------------------------------------------------------------------------------------
# Theorem 2
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReconstructibilityResult:
    """Outcome of the Theorem 2 test on one impact record.

    Attributes
    ----------
    reconstructible
        ``(C_a, A_a)`` observable and the record holds at least one and finitely many impacts
        in ``[t0, tf)``.
    n_impacts
        Impacts in ``[t0, tf)``.
    pair_observable
        Whether ``(C_a, A_a)`` is observable (PBH test).
    min_dwell
        Smallest interval between consecutive impacts (``inf`` with fewer than two).
    reason
        One sentence with the numbers.
    """

    reconstructible: bool
    n_impacts: int
    pair_observable: bool
    min_dwell: float
    reason: str


def reconstructibility(A_a: ArrayLike, C_a: ArrayLike, impacts: Any, t_span: Sequence[float], *,
                       min_dwell: float = 1e-9) -> ReconstructibilityResult:
    """Theorem 2 of chapter 2: is the state at ``tf`` determined by ``u`` and ``y`` on
    ``[t0, tf)`` for this input?

    Parameters
    ----------
    A_a, C_a : array_like
        Flow matrix and measurement row of the actuated body.
    impacts : array_like or Trajectory
        Impact times of the simulated record, or a trajectory whose ``"impact"`` events are used.
    t_span : (float, float)
        The interval ``[t0, tf)``.
    min_dwell : float
        Two impacts closer than this are taken as an accumulation (Zeno): not "finitely many".

    Returns
    -------
    ReconstructibilityResult

    Notes
    -----
    Theorem 2 (sufficient): if ``(C_a, A_a)`` is observable, the system is reconstructible on
    ``[t0, tf)`` for every input producing (a) at least one and (b) finitely many impacts there.
    Both hypotheses are checked on the record; an accumulation of impacts (dwell below
    ``min_dwell``) counts as failing (b).

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorem 2 (Martinelli, Menini, Tornambe 2003).

    Examples
    --------
    >>> import numpy as np
    >>> A = np.array([[0.0, 0, 1, 0], [0, 0, 0, 1], [-10, 6, 0, 0], [6, -6, 0, 0]])
    >>> C = [1.0, 0, 0, 0]
    >>> reconstructibility(A, C, [1.02, 2.9], (0.0, 10.0)).reconstructible
    True
    >>> reconstructibility(A, C, [], (0.0, 10.0)).reason.split(":")[0]
    'no impact in [0, 10)'
    """
    t0, tf = check_t_span(t_span)
    if hasattr(impacts, "event_times"):
        impacts = impacts.event_times("impact")
    times = np.sort(as_float_array("impacts", impacts).ravel())
    times = times[(times >= t0) & (times < tf)]
    min_dwell = check_positive("min_dwell", min_dwell, allow_zero=True)
    A = as_square("A_a", A_a)
    pair_ok, margin, modes = pbh_observability(A, np.reshape(C_a, (1, -1)))
    dwell = float(np.min(np.diff(times))) if times.size > 1 else np.inf
    if not pair_ok:
        ok, reason = False, (f"(C_a, A_a) is unobservable (PBH margin {margin:.3g} at "
                             f"{', '.join(f'{m:.6g}' for m in modes)})")
    elif times.size == 0:
        ok, reason = False, (f"no impact in [{t0:g}, {tf:g}): body b is never touched, its state "
                             "is not determined by u and y")
    elif dwell < min_dwell:
        ok, reason = False, (f"impacts accumulate (smallest dwell {dwell:.3g} < {min_dwell:g}): "
                             "not finitely many impacts")
    else:
        ok, reason = True, (f"reconstructible: {times.size} impact(s) in [{t0:g}, {tf:g}), "
                            f"smallest dwell {dwell:.4g}, (C_a, A_a) observable")
    return ReconstructibilityResult(ok, int(times.size), pair_ok, dwell, reason)


# ----------------------------------------------------------------------------------------------
# Measured convergence of an observer along a simulated run
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DecayMeasurement:
    """Decay rate of ``||x~||`` fitted over impact cycles.

    Attributes
    ----------
    rate
        ``-slope`` of the least-squares line through ``(t_i, ln ||x~(t_i-)||)``.
    intercept
        Its value at ``t = 0``: the fitted line is ``ln ||x~|| ~ intercept - rate t``.
    times, norms
        The pre-impact instants and error norms used (above the rounding floor).
    initial_norm
        ``||x~(t0)||``.
    dwell_min, dwell_max
        Observed dwell times between the impacts of the run (Assumption 2's bounds, seen).
    n_points
        Number of pre-impact norms the fit used (``times.size``).
    n_floor
        Number of pre-impact norms left out at the end as the error's numerical floor.
    roundoff
        The roundoff level ``u ||E||_2 ||x(t_i-)||`` of each pre-impact norm (all impacts
        after ``skip``, the excluded ones too).
    rate_error
        Bound on ``|rate - exact|``, ``exact`` being the same fit through the exact error
        norms at the same impacts, from the estimated rounding of each norm used
        (:data:`ROUNDING_PER_STATE`); ``inf`` when a norm at the floor is used
        (``through_floor``).
    """

    rate: float
    intercept: float
    times: FloatArray
    norms: FloatArray
    initial_norm: float
    dwell_min: float
    dwell_max: float
    n_points: int = 0
    n_floor: int = 0
    roundoff: FloatArray = field(default_factory=lambda: np.zeros(0))
    rate_error: float = np.inf


#: Estimated rounding of a measured pre-impact norm ``||E x(t_i-)||`` per closed-loop state, in
#: units of its level ``u ||E||_2 ||x(t_i-)||``: ``|measured - exact| <= kappa u ||E|| ||x||``
#: with ``kappa = ROUNDING_PER_STATE * n``. The estimate: every flight between impacts adds
#: the rounding of three products of length ``n`` -- the propagation ``V (e^{lambda t}
#: V^-1 x)`` and ``E x`` -- ``3 n u ||E|| ||x||`` by the standard bound; what earlier flights
#: added is carried along and contracted by the error dynamics, by a factor ``q`` per impact,
#: a geometric sum ``3 n / (1 - q)``: ``10 n`` for ``q <= 0.7`` (an observer slower than that
#: does not reach its floor within a run of tens of impacts, so the margin never decides
#: there). ``tests/analysis/test_decay_fit.py`` checks it against the exactly propagated error.
ROUNDING_PER_STATE = 10.0
#: Largest estimated relative rounding ``kappa u ||E|| ||x(t_i-)|| / ||x~(t_i-)||`` of a norm
#: the fit uses: ``ln ||x~||`` is then off by at most ``-ln(1 - 0.1) = 0.105``.
MAX_RELATIVE_ROUNDING = 0.1


def _least_squares_line(t: FloatArray, log_n: FloatArray) -> tuple[float, float, FloatArray]:
    """``(slope, intercept, w)`` of the least-squares line through ``(t_i, log_n_i)``; the
    slope is ``sum_i w_i log_n_i``, so an error ``d_i`` in each ``log_n_i`` moves it by at
    most ``sum_i |w_i| |d_i|``."""
    dt = t - t.mean()
    w = dt / float(np.sum(dt * dt))
    slope = float(np.sum(w * log_n))
    return slope, float(log_n.mean() - slope * t.mean()), w


def impact_decay_rate(trajectory: Any, error_matrix: Any, *, floor: float = 0.0,
                      kind: str = "jump", skip: int = 0,
                      through_floor: bool = False,
                      roundoff_margin: float | None = None) -> DecayMeasurement:
    """Fit the decay rate of ``||x~(t_i-)||`` at the impacts of a closed-loop run.

    Parameters
    ----------
    trajectory : Trajectory
        A closed-loop run (events of ``kind`` are the plant's impacts).
    error_matrix : (k, n) array_like
        Maps the closed-loop state to the estimation error (``closed_loop.outputs["error"]``).
    floor : float
        Norms below ``floor * ||x~(t0)||`` are left out too (default 0: only the rounding
        floor below decides).
    roundoff_margin : float, optional
        Norms below ``roundoff_margin * u ||E||_2 ||x(t_i-)||`` are at the rounding floor:
        the error ``x~ = E x`` is formed from states of size ``||x||``. Default
        ``ROUNDING_PER_STATE * n / MAX_RELATIVE_ROUNDING`` (``n`` closed-loop states, i.e.
        ``100 n``): every norm used is then within 10 % of the exact error by the rounding
        estimate.
    kind : str
        Event kind marking impacts (``"jump"`` for linear hybrid systems).
    skip : int
        Impacts left out at the start (transient before the observer engages).
    through_floor : bool
        Also use the first norm under the floor. The measured norm there is the rounding
        level, above the true error, so the fitted rate is a *lower bound* of the decay rate
        until rounding takes over -- the measurement for observers so fast that they reach
        the floor within an impact or two.

    Returns
    -------
    DecayMeasurement

    Raises
    ------
    ModelError
        Fewer than two usable pre-impact norms: no rate can be fitted.

    Notes
    -----
    Theorems 3 and 4 bound ``||x~(t)|| <= mu e^{-alpha (t - t0)} ||x~(t0)||``; the error is
    sampled just before the impacts (``t_i-``), where the observer's jumps have not yet acted,
    so the samples compare like with like from one impact cycle to the next. The fit stops at
    the first sample at the rounding floor: past it the "decay" is rounding. Only the impacts
    before the floor are seen, so a fast observer is measured over its first few impacts; the
    rate over the whole run is :func:`impact_error_contraction`'s, which propagates the error
    alone and has no floor. ``rate_error`` bounds the effect of rounding on the fitted slope;
    it says nothing of how far a fit over a few impacts is from the rate over many.

    The floor: the measured error is ``E x`` with ``x`` the closed-loop state, so its
    rounding scales with ``u ||E|| ||x||`` (a small ``eps`` makes ``||E||`` large), not with
    the error itself; :data:`ROUNDING_PER_STATE` states the factor. A fixed threshold relative
    to ``||x~(t0)||`` cannot say where that floor is: on a chapter-2 run with ``k33 = 0.08``,
    ``eps = 0.0125`` the error bottoms out near ``3e-10`` after one impact cycle, and a fit
    through all eight norms above ``1e-10 ||x~(t0)||`` returns 0.34 where the exact
    propagation of the error over the same impacts gives 12.9.

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorems 3 and 4 (the rate is read from a fit of
    ``log ||x~||`` over impact cycles, docs/ch02.md).

    Examples
    --------
    An error ``e' = -0.5 e`` and a clock ``tau' = -1`` reset to 1 (a constant state) at every
    "impact" ``tau = 0``, i.e. once per second:

    >>> import numpy as np
    >>> from nscontrol.simulate import simulate
    >>> from nscontrol.systems.hybrid import LinearHybridSystem
    >>> A = [[-0.5, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]
    >>> J = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]       # tau <- 1
    >>> clock = LinearHybridSystem(A, [[0.0, 1.0, 0.0]], [0.0], J)
    >>> traj = simulate(clock, [1.0, 1.0, 1.0], (0.0, 10.5), progress=False)
    >>> fit = impact_decay_rate(traj, [[1.0, 0.0, 0.0]])
    >>> round(fit.rate, 9), fit.times.size, round(fit.dwell_max, 9), fit.rate_error < 1e-11
    (0.5, 10, 1.0, True)
    """
    E = as_matrix("error_matrix", error_matrix, cols=trajectory.n_states)
    floor = check_positive("floor", floor, allow_zero=True)
    kappa = ROUNDING_PER_STATE * E.shape[1]
    margin = (kappa / MAX_RELATIVE_ROUNDING if roundoff_margin is None
              else check_positive("roundoff_margin", roundoff_margin, allow_zero=True))
    skip = check_integer("skip", skip, minimum=0)
    events = trajectory.events_of(kind)[skip:]
    times = np.array([ev.time for ev in events])
    norms = np.array([np.linalg.norm(E @ ev.pre) for ev in events])
    roundoff = np.finfo(float).eps * np.linalg.norm(E, 2) * np.array(
        [np.linalg.norm(ev.pre) for ev in events])
    e0 = float(np.linalg.norm(E @ trajectory.x[0]))
    keep = (norms > floor * e0) & (norms > margin * roundoff)
    below = np.flatnonzero(~keep)
    end = int(below[0]) if below.size else norms.size   # past the floor: rounding, not decay
    if check_bool("through_floor", through_floor) and below.size:
        end += 1
    if end < 2:
        extra = ", plus the first under it" if through_floor else ""
        hint = "" if through_floor else ", or through_floor=True"
        raise ModelError(f"trajectory: {end} pre-impact error norm(s) usable (above the "
                         f"floor {floor:g} x ||x~(t0)|| and {margin:g} x the roundoff level "
                         f"u ||E|| ||x||{extra}); need two to fit a rate -- "
                         f"simulate longer, use a larger eps{hint}, or measure the rate "
                         f"with impact_error_contraction")
    t_fit, n_fit = times[:end], norms[:end]
    slope, intercept, w = _least_squares_line(t_fit, np.log(n_fit))
    rho = kappa * roundoff[:end] / n_fit       # estimated relative rounding of each norm
    with np.errstate(divide="ignore"):   # inf where the rounding may be the whole norm
        dlog = -np.log1p(-np.minimum(rho, 1.0))   # |ln measured - ln exact| <= dlog
    rate_error = float(np.sum(np.abs(w) * dlog))
    dwell = np.diff(trajectory.event_times(kind))
    return DecayMeasurement(-slope, intercept, t_fit, n_fit, e0,
                            float(dwell.min()) if dwell.size else np.inf,
                            float(dwell.max()) if dwell.size else np.inf,
                            n_points=int(end), n_floor=int(norms.size - end),
                            roundoff=roundoff, rate_error=rate_error)


@dataclass(frozen=True)
class ErrorContraction:
    """The estimation error propagated alone along the impacts of a run.

    Attributes
    ----------
    times
        Pre-impact instants ``t_i`` (after ``skip``).
    log_norms
        ``ln ||x~(t_i-)||`` of the propagated error.
    factors
        Contraction over each inter-impact interval,
        ``||x~(t_{i+1}-)|| / ||x~(t_i-)||`` (one fewer than ``times``).
    rate
        Mean contraction rate from the first to the last of ``times``:
        ``-ln(prod factors) / (t_last - t_first)``.
    initial_norm
        ``||x~(t0)||``.
    """

    times: FloatArray
    log_norms: FloatArray
    factors: FloatArray
    rate: float
    initial_norm: float

    def rate_over(self, times: ArrayLike) -> float:
        """The least-squares rate of the propagated error at the given pre-impact instants
        (a subset of :attr:`times`): the exact counterpart of a
        :class:`DecayMeasurement` fitted at the same impacts.

        Parameters
        ----------
        times : array_like
            Instants of :attr:`times`, at least two.

        Returns
        -------
        float
        """
        t = as_float_array("times", times).ravel()
        idx = np.minimum(np.searchsorted(self.times, t), self.times.size - 1)
        if t.size < 2 or not np.array_equal(self.times[idx], t):
            raise ModelError(f"times: expected at least two of the pre-impact instants of "
                             f"this propagation, got {t!r}")
        return -_least_squares_line(t, self.log_norms[idx])[0]


def impact_error_contraction(closed_loop: Any, trajectory: Any, error_state0: ArrayLike,
                             error_matrix: ArrayLike, *, kind: str = "jump",
                             skip: int = 0) -> ErrorContraction:
    """Propagate the estimation error alone along the impacts of a closed-loop run.

    The state difference ``dz`` between the run and the same run with a zero estimation error
    (the observer started at the true state) has a zero plant part, so it moves no guard:
    it follows the closed loop's flow ``e^{A (t_{i+1} - t_i)}`` and jump matrices at the
    run's own impact times, and ``E dz = x~``. Propagated with ``scipy.linalg.expm`` and
    rescaled after every interval, it carries rounding relative to ``||x~||`` instead of to
    the closed-loop state: no floor, so the rate is seen over the whole run, however fast
    the observer.

    Parameters
    ----------
    closed_loop : LinearHybridSystem
        The loop that was simulated (its ``A`` and ``jump_matrices``).
    trajectory : Trajectory
        The run: the impact times and which guard each one hit.
    error_state0 : (n,) array_like
        ``dz(t0)``: the run's initial state minus that of the same run with the observer at
        the true state (for chapter 2,
        :meth:`~nscontrol.design.impact_observer.ImpactObserverDesign.error_state`).
    error_matrix : (k, n) array_like
        Maps the closed-loop state to the estimation error.
    kind : str
        Event kind marking impacts.
    skip : int
        Impacts left out at the start of :attr:`ErrorContraction.times` (the propagation
        still runs through them).

    Returns
    -------
    ErrorContraction

    Raises
    ------
    ModelError
        The loop has no linear jumps, ``error_state0`` moves a guard (it is not such a
        difference), the run has other events than ``kind``, or fewer than two impacts are
        left after ``skip``.
    DimensionError
        ``error_state0`` or ``error_matrix`` do not match the loop's state.

    Notes
    -----
    The rate is the product of the per-interval contractions, i.e. the mean rate between the
    first and the last pre-impact instant; the interval before the first impact (where an
    unmeasured body's error is not touched at all) is left out. A fit of the measured norms
    (:func:`impact_decay_rate`) at the same impacts must agree with :meth:`rate_over` within
    its ``rate_error``.

    Examples
    --------
    The clock of :func:`impact_decay_rate`: the error ``e' = -0.5 e`` contracts by
    ``e^{-0.5}`` over every one-second interval.

    >>> import numpy as np
    >>> from nscontrol.simulate import simulate
    >>> from nscontrol.systems.hybrid import LinearHybridSystem
    >>> A = [[-0.5, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]
    >>> J = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    >>> clock = LinearHybridSystem(A, [[0.0, 1.0, 0.0]], [0.0], J)
    >>> traj = simulate(clock, [1.0, 1.0, 1.0], (0.0, 10.5), progress=False)
    >>> c = impact_error_contraction(clock, traj, [1.0, 0.0, 0.0], [[1.0, 0.0, 0.0]])
    >>> round(c.rate, 12), c.factors.size, bool(np.allclose(c.factors, np.exp(-0.5)))
    (0.5, 9, True)
    """
    from scipy.linalg import expm

    A = np.asarray(closed_loop.A, dtype=float)
    jumps = closed_loop.jump_matrices
    if jumps is None:
        raise ModelError("closed_loop: its jumps are not linear (no jump_matrices); the error "
                         "can only be propagated through linear jumps")
    n = A.shape[0]
    if trajectory.n_states != n:
        raise DimensionError(f"trajectory: {trajectory.n_states} states, the closed loop has "
                             f"{n}; pass the run of this loop")
    dz = as_vector("error_state0", error_state0, n)
    E = as_matrix("error_matrix", error_matrix, cols=n)
    skip = check_integer("skip", skip, minimum=0)
    G = np.asarray(closed_loop.G, dtype=float)
    # a difference of two runs with the same plant state moves no guard (up to the rounding
    # of the two initial states, n u ||G|| ||z0||, with a factor 10)
    z0 = np.asarray(trajectory.x[0], dtype=float)
    tol = 10.0 * n * np.finfo(float).eps * np.linalg.norm(G, 2) * (
        np.linalg.norm(z0) + np.linalg.norm(dz))
    if np.any(np.abs(G @ dz) > tol):
        raise ModelError(f"error_state0: moves the guards by {np.abs(G @ dz).max():.3g} "
                         f"(> {tol:.3g}); pass the initial state of the run minus that of the "
                         f"same run with the observer at the true state (zero plant part)")
    others = {ev.kind for ev in trajectory.events} - {kind}
    if others:
        raise ModelError(f"trajectory: has events of kind(s) {sorted(others)} besides {kind!r}; "
                         "only runs whose every event is an impact can be propagated")
    events = trajectory.events_of(kind)
    if len(events) - skip < 2:
        raise ModelError(f"trajectory: {len(events)} impact(s) of kind {kind!r} and skip="
                         f"{skip}; need two after the skipped ones to measure a contraction")
    t_prev, log_scale, logs = float(trajectory.t[0]), 0.0, []
    e0 = float(np.linalg.norm(E @ dz))
    for ev in events:
        dz = expm(A * (ev.time - t_prev)) @ dz
        s = float(np.linalg.norm(dz))
        log_scale, dz = log_scale + np.log(s), dz / s     # rescaled: it never underflows
        logs.append(log_scale + np.log(np.linalg.norm(E @ dz)))
        dz, t_prev = jumps[ev.index] @ dz, ev.time
    times = np.array([ev.time for ev in events])[skip:]
    log_norms = np.array(logs)[skip:]
    rate = float((log_norms[0] - log_norms[-1]) / (times[-1] - times[0]))
    return ErrorContraction(times, log_norms, np.exp(np.diff(log_norms)), rate, e0)

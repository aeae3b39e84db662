"""Observability and reconstructibility of bodies that interact only through impacts (ch. 2).

The (n-1, 1) case of chapter 2: an actuated body ``a`` of ``n - 1`` masses, measured through
``y = q_1``, hits a free mass ``b`` that is unobservable between impacts. This module
analyses a model and a simulated run:

* :func:`impact_observability` -- Theorem 1 for an
  :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies` model;
* :func:`reconstructibility` -- Theorem 2 for a given impact record;
* :func:`impact_decay_rate` -- the decay rate of ``||x~||`` measured on a simulated run.

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
from ..errors import ModelError
from ..numerics.observability import RANK_RTOL, pbh_observability

__all__ = [
    "Theorem1Result",
    "ReconstructibilityResult",
    "EpsilonCertificate",
    "DecayMeasurement",
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
        The pre-impact instants and error norms used (above the floor).
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


#: A pre-impact norm enters the decay fit only above this multiple of its roundoff level
#: ``u ||E|| ||x(t_i-)||``. The propagation accumulates rounding over the steps between
#: impacts: on chapter 2's runs the observed floor lies 1 to 25 times above ``u ||E|| ||x||``,
#: so a norm 100 times above it carries a relative error <= 25 % in the worst case observed
#: (<= 1 % on most runs), while the floor itself (<= 25 times the level) is always excluded.
ROUNDOFF_MARGIN = 100.0


def impact_decay_rate(trajectory: Any, error_matrix: Any, *, floor: float = 1e-10,
                      kind: str = "jump", skip: int = 0,
                      through_floor: bool = False,
                      roundoff_margin: float = ROUNDOFF_MARGIN) -> DecayMeasurement:
    """Fit the decay rate of ``||x~(t_i-)||`` at the impacts of a closed-loop run.

    Parameters
    ----------
    trajectory : Trajectory
        A closed-loop run (events of ``kind`` are the plant's impacts).
    error_matrix : (k, n) array_like
        Maps the closed-loop state to the estimation error (``closed_loop.outputs["error"]``).
    floor : float
        Norms below ``floor * ||x~(t0)||`` are left out (rounding level, not convergence).
    roundoff_margin : float
        Norms below ``roundoff_margin * u ||E||_2 ||x(t_i-)||`` are left out too: the error
        ``x~ = E x`` is formed from states of size ``||x||``, so that is its rounding level,
        which a large observer gain (a small ``eps``) lifts far above ``floor`` (default
        :data:`ROUNDOFF_MARGIN`).
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
    the first sample under the floor (past it the "decay" is rounding). A rate fitted on two
    or three points is only indicative; ``times.size`` says how many were used. Any norm
    gives the same asymptotic rate.

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorems 3 and 4; spec ch02 §7 ("fit of log ||x~|| over impact
    cycles").

    The floor: the measured error is ``E x`` with ``x`` the closed-loop state, rounded at
    ``u ||x||`` per component; once the true error is that small, the measured norm stays at
    ``~u ||E|| ||x||`` (within a factor ~25 on chapter 2's runs, the rounding of the
    propagation accumulating over the steps) while the true error keeps decaying. Fitting those
    points flattens the line: on a chapter-2 run with ``k33 = 0.08``, ``eps = 0.0125`` the
    error reaches its floor ``~3e-10`` (above the fixed ``floor``) after one impact cycle, and
    a fit through all eight norms returns 0.34 where the exact propagation of the error over
    the same impacts gives 12.9. The fit therefore stops at the first norm under
    ``roundoff_margin`` times that level (there: one norm is left, a ``ModelError``; with
    ``through_floor=True`` a lower bound, 1.9); ``n_points`` and ``n_floor`` report how many
    norms were used and left out.

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
    >>> round(fit.rate, 9), fit.times.size, round(fit.dwell_max, 9)
    (0.5, 10, 1.0)
    """
    E = as_matrix("error_matrix", error_matrix, cols=trajectory.n_states)
    floor = check_positive("floor", floor, allow_zero=True)
    margin = check_positive("roundoff_margin", roundoff_margin, allow_zero=True)
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
    if through_floor and below.size:
        end += 1
    if end < 2:
        extra = ", plus the first under it" if through_floor else ""
        hint = "" if through_floor else ", or through_floor=True"
        raise ModelError(f"trajectory: {end} pre-impact error norm(s) usable (above the "
                         f"floor {floor:g} x ||x~(t0)|| and {margin:g} x the roundoff level "
                         f"u ||E|| ||x||{extra}); need two to fit a rate -- "
                         f"simulate longer, use a larger eps{hint}")
    t_fit, n_fit = times[:end], norms[:end]
    slope, intercept = (float(c) for c in np.polyfit(t_fit, np.log(n_fit), 1))
    dwell = np.diff(trajectory.event_times(kind))
    return DecayMeasurement(-slope, intercept, t_fit, n_fit, e0,
                            float(dwell.min()) if dwell.size else np.inf,
                            float(dwell.max()) if dwell.size else np.inf,
                            n_points=int(end), n_floor=int(norms.size - end),
                            roundoff=roundoff)

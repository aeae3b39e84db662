"""Corner collisions of a planar limit cycle with a switching wedge: section returns, the
controlled cycle by shooting, its events in the wedge's terms, the verification of a corner
design and the diagram against the corner position.

The leading-order theory — :func:`corner_gain`, the corner discontinuity map
(:func:`corner_discontinuity_map`), the piecewise-linear return map (:class:`PWLReturnMap`),
:func:`crossing_gain_interval`, :func:`reachable_multipliers` and the corner's placement on
a cycle (:func:`corner_site`) — is defined in :mod:`nscontrol.design.limit_cycle_switching`
(the design uses it; the design layer sits below this one) and re-exported here.

* :func:`section_returns` — Poincaré points of any planar run, located as events of a marker
  line (:func:`nscontrol.systems.wedge.with_marker_line`).
* :func:`controlled_cycle` — the closed loop's cycle by single shooting
  (:func:`~nscontrol.analysis.orbits.find_cycle`: the monodromy through the saltation
  matrices of face crossings and of sliding entry and exit), with its multiplier, the
  distance of its trivial multiplier to 1, and its events (:func:`wedge_events`).
* :func:`verify_corner_design` — a :class:`~nscontrol.design.limit_cycle_switching.CornerDesign`
  checked by shooting; refused (``InfeasibleDesignError``) when no cycle is found or it is
  not stable.
* :func:`corner_diagram` — the controlled cycle against the corner's offset ``μ_c`` on
  :func:`nscontrol.sweep.run` (serial, local processes or Dask, identical results).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_vector, check_integer, check_positive
from ..design.limit_cycle_switching import (
    CornerDesign,
    CornerDiscontinuityMap,
    CornerSite,
    PWLFixedPoint,
    PWLReturnMap,
    Section,
    corner_discontinuity_map,
    corner_gain,
    corner_site,
    crossing_gain_interval,
    gain_for_corner_gain,
    reachable_multipliers,
)
from ..errors import InfeasibleDesignError, SolverError
from ..systems.wedge import Wedge, WedgeSwitchedSystem, marker_crossings, with_marker_line

__all__ = ["corner_gain", "gain_for_corner_gain", "crossing_gain_interval",
           "reachable_multipliers", "CornerDiscontinuityMap", "corner_discontinuity_map",
           "PWLFixedPoint", "PWLReturnMap", "Section", "CornerSite", "corner_site",
           "section_returns", "ControlledCycle", "controlled_cycle", "wedge_events",
           "verify_corner_design", "CornerFamily", "CornerDiagram", "corner_diagram"]


def section_returns(system: Any, x0: ArrayLike, section: Section, n_returns: int, *,
                    period: float, rtol: float = 1e-11, atol: float = 1e-13) -> FloatArray:
    """The first ``n_returns`` crossings of ``section`` (in its normal's direction).

    Parameters
    ----------
    system : FilippovSystem or NonlinearSystem
        A planar system (a :class:`~nscontrol.systems.wedge.WedgeSwitchedSystem`, a plant).
    x0 : (2,) array_like
        The start (a crossing at ``t = 0`` is not counted).
    section : Section
        The section.
    n_returns : int
        Crossings wanted.
    period : float
        A bound on the time between returns (runs last ``(n_returns + 1)·period·1.5``).
    rtol, atol : float
        Tolerances of the integration.

    Returns
    -------
    ndarray, shape (n_returns, 2)

    Raises
    ------
    SolverError
        Fewer crossings than asked within the run.
    """
    from ..simulate import simulate

    n = check_integer("n_returns", n_returns, minimum=1)
    T = check_positive("period", period)
    marked, j = with_marker_line(system, section.normal, section.offset)
    tf = 1.5 * (n + 1) * T
    tr = simulate(marked, as_vector("x0", x0, 2), (0.0, tf), t_eval=np.array([0.0, tf]),
                  rtol=rtol, atol=atol)
    pts = [np.asarray(ev.post, float) for ev in marker_crossings(tr, j)]
    if len(pts) < n:
        raise SolverError(f"n_returns: only {len(pts)} returns to the section in t = {tf:.4g}; "
                          f"the orbit may have left the section's neighbourhood (give a "
                          f"larger period or another start)")
    return np.array(pts[:n])



@dataclass(frozen=True, eq=False)
class ControlledCycle:
    """A cycle of a wedge-switched system, found by shooting.

    Attributes
    ----------
    offset : float
        Its offset on the site's section.
    multiplier : float
        Its non-trivial multiplier (real part; planar).
    trivial_error : float
        ``|μ_trivial − 1|``, the built-in accuracy check of the monodromy.
    cycle : Cycle
        The shooting result (``x0``, ``period``, ``monodromy``, ``signature``).
    events : tuple of str
        One period's events in the wedge's terms (:func:`wedge_events`).
    """

    offset: float
    multiplier: float
    trivial_error: float
    cycle: Any
    events: tuple[str, ...]


def controlled_cycle(system: WedgeSwitchedSystem, site: CornerSite, offset_guess: float, *,
                     tol: float = 1e-10) -> ControlledCycle:
    """The cycle of ``system`` through the site's section near ``offset_guess``.

    Parameters
    ----------
    system : WedgeSwitchedSystem
        The closed loop.
    site : CornerSite
        Gives the section and the period guess.
    offset_guess : float
        The guess of the cycle's offset on the section.
    tol : float
        Newton's tolerance (:func:`~nscontrol.analysis.orbits.find_cycle`).

    Raises
    ------
    SolverError
        Shooting did not converge.
    """
    from ..simulate import simulate
    from .orbits import find_cycle

    x0 = site.section_state(offset_guess)
    cyc = find_cycle(system, x0, site.period, normal=site.section.normal,
                     offset=site.section.offset, tol=tol)
    mu = np.delete(cyc.multipliers, cyc.trivial_index)
    tr = simulate(system, cyc.x0, (0.0, cyc.period), t_eval=np.array([0.0, cyc.period]))
    return ControlledCycle(site.section_offset(cyc.x0), float(np.real(mu[0])),
                           abs(complex(cyc.multipliers[cyc.trivial_index]) - 1.0), cyc,
                           wedge_events(system, tr))


def wedge_events(system: WedgeSwitchedSystem, trajectory: Any) -> tuple[str, ...]:
    """A run's events in the wedge's terms; crossings of a face's line away from the wedge
    (no field jump) are left out.

    Parameters
    ----------
    system : WedgeSwitchedSystem
        The system that was run.
    trajectory : Trajectory
        Its run.

    Returns
    -------
    tuple of str
        In time order: ``"enters through H_in"``, ``"leaves through H_out"``,
        ``"enters through H_out"``, ``"leaves through H_in"``, ``"sliding starts on H_in"``
        (or ``H_out``), ``"sliding ends at the corner"``, ``"sliding ends on H_in"`` (a
        tangential exit), ``"grazing"``.
    """
    names = ("H_in", "H_out")
    out: list[str] = []
    events = list(trajectory.events)
    i = 0
    while i < len(events):
        ev = events[i]
        nxt = events[i + 1] if i + 1 < len(events) else None
        inside_from = (ev.mode_from & 3) == 3
        inside_to = (ev.mode_to & 3) == 3
        if ev.kind == "sliding_start":
            out.append(f"sliding starts on {names[ev.index]}")
        elif ev.kind == "crossing" and nxt is not None and nxt.kind == "sliding_exit" \
                and nxt.time == ev.time:
            out.append("sliding ends at the corner")
            i += 1
        elif ev.kind == "sliding_exit":
            out.append(f"sliding ends on {names[ev.index]}")
        elif ev.kind == "crossing" and inside_from != inside_to:
            verb = "enters" if inside_to else "leaves"
            out.append(f"{verb} through {names[ev.index]}")
        elif ev.kind == "grazing":
            out.append("grazing")
        i += 1
    return tuple(out)


def verify_corner_design(design: CornerDesign) -> CornerDesign:
    """Check a corner design by shooting the closed loop's cycle from the prediction.

    Parameters
    ----------
    design : CornerDesign
        From :func:`~nscontrol.design.limit_cycle_switching.design_corner_controller`.

    Returns
    -------
    CornerDesign
        A copy with ``verified`` (the :class:`ControlledCycle`) and ``status`` set.

    Raises
    ------
    InfeasibleDesignError
        No cycle near the predicted offset, or a cycle whose multiplier is outside the
        unit circle.
    """
    site = design.site
    guess = design.predicted_offset / site.tau
    try:
        cc = controlled_cycle(design.system, site, guess)
    except SolverError as exc:
        raise InfeasibleDesignError(f"design: no controlled cycle found near the predicted "
                                    f"section offset {guess:.6g} ({exc})") from exc
    if not abs(cc.multiplier) < 1.0:
        raise InfeasibleDesignError(f"design: the controlled cycle's multiplier "
                                    f"{cc.multiplier:.6g} is outside the unit circle")
    status = (f"verified: cycle at section offset {cc.offset:.6g} (predicted {guess:.6g}), "
              f"multiplier {cc.multiplier:.6g} (predicted {design.predicted_multiplier:.6g})")
    return design.with_verification(cc, status)



@dataclass(frozen=True, eq=False)
class CornerFamily:
    """Wedge-switched systems with the corner at ``p_Γ + μ e`` (a picklable ``μ ↦ system``).

    Attributes
    ----------
    site : CornerSite
        Anchor, direction and section.
    b : ndarray
        The input direction.
    k : float
        The gain.
    half_angle : float
        The symmetric wedge's half-angle.
    """

    site: CornerSite
    b: FloatArray
    k: float
    half_angle: float = np.pi / 4

    def __call__(self, mu: float) -> WedgeSwitchedSystem:
        c = self.site.corner(mu)
        w = Wedge.symmetric(c, self.site.e, self.half_angle,
                            flow=self.site.plant.rhs(0.0, c))
        return WedgeSwitchedSystem(self.site.plant, w, self.b, self.k)

    def prediction(self, mu: float) -> PWLReturnMap:
        """The piecewise-linear return map at ``μ`` (fields at the corner).

        Parameters
        ----------
        mu : float
            The corner's offset.
        """
        system = self(mu)
        c = system.wedge.corner
        f1 = self.site.plant.rhs(0.0, c)
        a = corner_gain(f1, f1 + self.k * self.b, system.wedge.n_in, system.wedge.n_out,
                        self.site.e)
        return PWLReturnMap(self.site.lam, a, float(mu))


@dataclass(frozen=True)
class _DiagramPoint:
    """One ``μ``: the controlled cycle by shooting and brute-force section points."""

    family: CornerFamily
    n_transient: int
    n_record: int
    start_offset: float | None

    def __call__(self, mu: float) -> dict[str, Any]:
        site = self.family.site
        pred = self.family.prediction(mu)
        system = self.family(mu)
        out: dict[str, Any] = {"mu": mu, "a": pred.a, "q": pred.q}
        right = [p for p in pred.fixed_points() if p.branch == "right"]
        if right:
            guess = right[0].z / site.tau
            cc = controlled_cycle(system, site, guess)
            out.update(offset=cc.offset, offset_sigma=cc.offset * site.tau,
                       multiplier=cc.multiplier, trivial_error=cc.trivial_error)
        if self.n_record:
            z0 = self.start_offset if self.start_offset is not None else 2.0 * abs(mu)
            pts = section_returns(system, site.section_state(z0), site.section,
                                  self.n_transient + self.n_record, period=site.period)
            out["returns"] = np.array([site.section_offset(x)
                                       for x in pts[self.n_transient:]])
        return out


@dataclass(frozen=True, eq=False)
class CornerDiagram:
    """The controlled cycle against the corner's offset ``μ_c``.

    Attributes
    ----------
    mu : ndarray
        The corner offsets.
    offset : ndarray
        The shot cycle's offset on the section (NaN where none is predicted or it failed).
    offset_sigma : ndarray
        That offset transported to ``Σ_c`` (times ``τ``).
    multiplier : ndarray
        Its multiplier.
    q : ndarray
        The prediction ``z*/μ_c``.
    a : ndarray
        The corner gain at each ``μ``.
    returns : ndarray
        ``(len(mu), n_record)`` brute-force section offsets (empty without them).
    errors : tuple
        ``(index, message)`` of the failed points.
    seconds : float
        Wall time of the sweep.
    """

    mu: FloatArray
    offset: FloatArray
    offset_sigma: FloatArray
    multiplier: FloatArray
    q: FloatArray
    a: FloatArray
    returns: FloatArray
    errors: tuple[tuple[int, str], ...]
    seconds: float


def corner_diagram(family: CornerFamily, mu_values: ArrayLike, *, n_transient: int = 0,
                   n_record: int = 0, start_offset: float | None = None,
                   executor: Any = "serial", progress: bool | None = False) -> CornerDiagram:
    """The controlled cycle (and optionally brute-force section points) against ``μ_c``.

    Each value is one point of :func:`nscontrol.sweep.run`, so the diagram runs serially,
    on local processes or on a Dask cluster with identical results.

    Parameters
    ----------
    family : CornerFamily
        ``μ ↦`` closed loop.
    mu_values : array_like
        Corner offsets.
    n_transient, n_record : int
        Brute force: returns discarded, then recorded (``n_record = 0``: none).
    start_offset : float, optional
        Section offset of the brute-force start (default ``2|μ|``).
    executor
        As :func:`nscontrol.sweep.run`.
    progress : bool, optional
        Progress bar.

    Returns
    -------
    CornerDiagram
    """
    import time

    from .. import sweep

    mus = as_vector("mu_values", mu_values)
    task = _DiagramPoint(family, check_integer("n_transient", n_transient, minimum=0),
                         check_integer("n_record", n_record, minimum=0), start_offset)
    t0 = time.perf_counter()
    res = sweep.run(task, [float(m) for m in mus], executor=executor, progress=progress,
                    desc="corner diagram")
    seconds = time.perf_counter() - t0
    N = len(mus)
    cols = {k: np.full(N, np.nan) for k in ("offset", "offset_sigma", "multiplier", "q", "a")}
    returns = np.full((N, task.n_record), np.nan)
    errors = []
    for i, (val, err) in enumerate(zip(res.values, res.errors, strict=True)):
        if err is not None:
            errors.append((i, f"{err.type}: {err.message}"))
            continue
        for key in cols:
            if key in val:
                cols[key][i] = val[key]
        if "returns" in val:
            returns[i] = val["returns"]
    return CornerDiagram(mus, cols["offset"], cols["offset_sigma"], cols["multiplier"],
                         cols["q"], cols["a"], returns, tuple(errors), seconds)

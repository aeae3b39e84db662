"""Pseudo-arclength continuation of periodic orbits in one parameter, with bifurcation detection.

:func:`continue_orbit` follows the ``kT``-periodic orbits of ``factory(p)`` (a
:class:`~nscontrol.analysis.orbits.Forced`) as ``p`` varies. The unknown is
``y = (x_0, ..., x_{k-1}, p)`` (the multiple-shooting nodes and the parameter); the branch is
the solution curve of the ``kn`` equations ``G(y) = (P_p(x_i) - x_{i+1})_i = 0``.

Steps
-----
* **Predictor** ``y + h t`` along the unit tangent ``t`` (``[G_y; t_prevᵀ] t = [0; 1]``, so
  the branch is followed through folds).
* **Corrector**: Newton on ``G(y) = 0``, ``t·(y - y_pred) = 0`` (the pseudo-arclength
  condition). ``∂G/∂x`` is exact (saltation-based, :func:`~nscontrol.analysis.orbits.
  stroboscopic_map`); ``∂G/∂p`` is a central difference with step ``δ = ε^{1/3}·max(1, |p|)``
  (truncation ``O(δ²)`` balancing rounding ``O(ε/δ)``; it only affects the tangent and the
  corrector's rate, never the converged residual). Predictor, corrector, tangent and
  location are the engine shared with equilibria (:mod:`~nscontrol.analysis._arclength`).
* **Step control**: the step grows by 1.5 after a corrector that converged in at most 3
  iterations, halves after a failure; below ``step_min`` the run stops, saying where and why.

Detection and location
----------------------
Test functions on the multipliers ``μ`` of the monodromy: fold ``Re ∏(μ_i - 1)``, flip
``Re ∏(μ_i + 1)``, Neimark–Sacker ``Re ∏_{i<j}(μ_iμ_j - 1)`` (a sign change with a real
pair — a neutral saddle — is discarded). **Grazing** is a change of the orbit's event
signature (reported as a **sliding** bifurcation when the number of sliding segments
changes); its monitor is the smallest free-flight gap of a non-impacting orbit and minus
the smallest impact speed of an impacting one, both of which go to zero at the grazing. A
sign change between two points is located by the Illinois variant of regula falsi on the
arclength, each trial point corrected onto the branch, until the parameter is known to
``locate_tol`` (relative).

Branch switching at a flip (:func:`switch_at_flip`): the flip orbit taken twice solves the
``2kT`` problem, where the period-doubled branch crosses it tangentially to the flip
eigenvector ``(w, -w)``; continuation of the doubled problem starts along that direction.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._files import Reader, load_hdf5, put, save_hdf5
from .._validation import FloatArray, as_vector, check_integer
from ..errors import BudgetExceededError, ModelError, SolverError
from ._arclength import (
    CORRECTOR_MAX_ITER,
    LOCATE_MAX_ITER,
    ArclengthProblem,
    FactoryMemo,
    Options,
    Point,
    check_options,
    locate,
    parameter_derivative,
)
from .orbits import Forced, Orbit, _initial_nodes, _shooting_system, make_orbit

__all__ = ["SpecialPoint", "Branch", "continue_orbit", "switch_at_flip"]



@dataclass(frozen=True, eq=False)
class SpecialPoint:
    """A located bifurcation on a branch.

    Attributes
    ----------
    kind
        Orbits: ``"fold"``, ``"flip"``, ``"neimark_sacker"``, ``"grazing"`` or
        ``"sliding"``; equilibria: ``"fold"``, ``"hopf"`` or ``"boundary_equilibrium"``.
    parameter
        Where it is.
    index
        Its row in the branch's arrays.
    nodes
        Shooting nodes of the orbit there (an equilibrium: ``(1, n)``, the state).
    multipliers
        Floquet multipliers there (for a grazing: those of the last orbit before it); for
        an equilibrium the eigenvalues of the Jacobian.
    uncertainty
        Width of the last parameter bracket.
    """

    kind: str
    parameter: float
    index: int
    nodes: FloatArray
    multipliers: np.ndarray
    uncertainty: float


@dataclass(frozen=True, eq=False)
class Branch:
    """A continued branch of periodic orbits or of equilibria (``solution``).

    An equilibrium is stored as a one-node "orbit": ``nodes[:, 0]`` is the state, ``period``
    is NaN, ``multipliers`` holds the Jacobian's eigenvalues (also :attr:`eigenvalues`) and
    ``stable`` means all of them in the open left half-plane.

    Attributes
    ----------
    parameter_name
        Name of the parameter (axis label).
    p
        ``(N,)`` parameter values.
    nodes
        ``(N, k, n)`` shooting nodes (``nodes[:, 0]``: the state at ``t = 0``).
    period
        ``(N,)`` orbit periods ``kT`` (NaN for equilibria).
    multipliers
        ``(N, n)`` Floquet multipliers by decreasing modulus (equilibria: eigenvalues by
        decreasing real part).
    stable
        ``(N,)`` all multipliers inside the unit circle (equilibria: all eigenvalues with
        negative real part).
    n_impacts
        ``(N,)`` impacts per orbit period (equilibria of a PWA system: the region index,
        ``-1`` otherwise).
    points
        Located bifurcations, in branch order.
    stop_reason
        Why the continuation ended.
    n_steps, corrector_iterations
        Continuation steps taken and Newton iterations spent (location included).
    state_names
        Names of the state components.
    solution
        ``"periodic"`` or ``"equilibrium"``.
    """

    parameter_name: str
    p: FloatArray
    nodes: FloatArray
    period: FloatArray
    multipliers: np.ndarray
    stable: np.ndarray
    n_impacts: np.ndarray
    points: tuple[SpecialPoint, ...]
    stop_reason: str
    n_steps: int = 0
    corrector_iterations: int = 0
    state_names: tuple[str, ...] = ()
    solution: str = "periodic"

    def __len__(self) -> int:
        return int(self.p.shape[0])

    @property
    def x0(self) -> FloatArray:
        """``(N, n)`` states at ``t = 0``."""
        return self.nodes[:, 0]

    @property
    def eigenvalues(self) -> np.ndarray:
        """``(N, n)`` eigenvalues of an equilibrium branch (``ModelError`` for orbits)."""
        if self.solution != "equilibrium":
            raise ModelError("branch: a branch of periodic orbits has multipliers, not "
                             "eigenvalues; read Branch.multipliers")
        return self.multipliers

    def special(self, kind: str) -> tuple[SpecialPoint, ...]:
        """The located points of one kind."""
        return tuple(pt for pt in self.points if pt.kind == kind)

    def to_pandas(self) -> Any:
        """One row per branch point: parameter, state at ``t = 0``, period, multipliers'
        moduli, stability, impacts, and the kind of bifurcation located there (or ``""``);
        for equilibria: parameter, state, eigenvalues' real and imaginary parts, stability,
        region."""
        import pandas as pd

        names = self.state_names or tuple(f"x{i}" for i in range(self.nodes.shape[2]))
        data: dict[str, Any] = {self.parameter_name: self.p}
        for i, nm in enumerate(names):
            data[nm] = self.x0[:, i]
        if self.solution == "equilibrium":
            for i in range(self.multipliers.shape[1]):
                data[f"Re lambda{i}"] = self.multipliers[:, i].real
                data[f"Im lambda{i}"] = self.multipliers[:, i].imag
            data["stable"] = self.stable
            data["region"] = self.n_impacts
        else:
            data["period"] = self.period
            for i in range(self.multipliers.shape[1]):
                data[f"|mu{i}|"] = np.abs(self.multipliers[:, i])
            data["stable"] = self.stable
            data["n_impacts"] = self.n_impacts
        kinds = [""] * len(self)
        for pt in self.points:
            kinds[pt.index] = pt.kind
        data["special"] = kinds
        return pd.DataFrame(data)

    def plot(self, ax: Any = None, *, component: int = 0, label: str | None = None,
             color: str | None = None) -> Any:
        """Plot ``x0[component]`` against the parameter: stable parts solid, unstable dashed,
        bifurcation points marked and named in the legend. Returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        y = self.x0[:, component]
        color = color or "C0"
        start = 0
        for i in range(1, len(self) + 1):
            if i == len(self) or self.stable[i] != self.stable[start]:
                seg = slice(start, min(i + 1, len(self)))
                ax.plot(self.p[seg], y[seg], "-" if self.stable[start] else "--", color=color,
                        label=label if start == 0 else None)
                start = i
        marks = {"fold": "s", "flip": "o", "neimark_sacker": "D", "grazing": "^",
                 "sliding": "v", "hopf": "D", "boundary_equilibrium": "^"}
        for kind, mk in marks.items():
            pts = self.special(kind)
            if pts:
                ax.plot([pt.parameter for pt in pts], [pt.nodes[0, component] for pt in pts],
                        mk, color="k", mfc="none", ms=8, label=kind.replace("_", "-"))
        names = self.state_names or ()
        ax.set_xlabel(self.parameter_name)
        where = "(equilibrium)" if self.solution == "equilibrium" else "at t = 0 mod T"
        ax.set_ylabel(f"{names[component] if names else f'x{component}'} {where}")
        ax.legend(loc="best", fontsize="small")
        return ax

    # -- HDF5 ------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write to HDF5 (format ``nscontrol.Branch/2``: ``/1`` and the ``solution``
        attribute), with a Fletcher-32 checksum on every non-empty dataset, atomically: a
        temporary file in the same folder, renamed over ``path`` only once complete (the
        mechanism of every result type, :mod:`nscontrol._files`).

        Parameters
        ----------
        path : str or path-like
            The file to write; its folder must exist.

        Returns
        -------
        Path
            ``path``.

        Raises
        ------
        FileNotFoundError, IsADirectoryError
            The folder of ``path`` does not exist, or ``path`` is a folder.
        OSError
            The disk is full (or a quota, a file size limit): the previous file is unchanged
            and no temporary file remains.
        """
        return save_hdf5(path, self._write)

    def _write(self, f: Any) -> None:
        """The body of :meth:`save`, into the open (empty) ``f``."""
        f.attrs.update(format=_FORMAT, solution=self.solution,
                       parameter_name=self.parameter_name, stop_reason=self.stop_reason,
                       n_steps=self.n_steps, corrector_iterations=self.corrector_iterations)
        f.attrs["state_names"] = np.array(self.state_names, dtype="S")
        for key in ("p", "nodes", "period", "multipliers", "stable", "n_impacts"):
            put(f, key, getattr(self, key))
        g = f.create_group("points")
        g.attrs["count"] = len(self.points)     # a lost point group is then noticed
        for i, pt in enumerate(self.points):
            s = g.create_group(str(i))
            s.attrs.update(kind=pt.kind, parameter=pt.parameter, index=pt.index,
                           uncertainty=pt.uncertainty)
            put(s, "nodes", pt.nodes)
            put(s, "multipliers", pt.multipliers)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Branch:
        """Read a file written by :meth:`save` (formats ``/1``, periodic only, and ``/2``).

        Parameters
        ----------
        path : str or path-like
            The file.

        Returns
        -------
        Branch
            The branch saved there.

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ModelError
            ``path`` is not a branch file: not HDF5 (a text file), empty, truncated, of
            another format, missing a group, dataset or attribute, or a dataset fails its
            checksum (flipped bytes). The message says which, and names the member.
        """
        return load_hdf5(path, cls._read, formats=(_FORMAT, _FORMAT_V1), what="branch",
                         writer="Branch.save")

    @classmethod
    def _read(cls, r: Reader, fmt: str) -> Branch:
        """The body of :meth:`load`; every member goes through ``r`` (errors named)."""
        points = []
        names = sorted(r.group("points"), key=int)
        # absent in files of earlier versions
        count = int(r.attr("count", of="points", default=len(names)))
        if names != [str(i) for i in range(count)]:
            raise KeyError(f"the file should hold {count} special point group(s) named 0, "
                           f"1, ..., it holds {names}")
        for k in names:
            at = f"points/{k}"
            points.append(SpecialPoint(
                str(r.attr("kind", of=at)), float(r.attr("parameter", of=at)),
                int(r.attr("index", of=at)), r.data(f"{at}/nodes"),
                r.data(f"{at}/multipliers"), float(r.attr("uncertainty", of=at))))
        p, nodes, period = r.data("p"), r.data("nodes"), r.data("period")
        multipliers, stable = r.data("multipliers"), r.data("stable").astype(bool)
        n_impacts = r.data("n_impacts")
        state_names = tuple(s.decode() for s in r.attr("state_names"))
        return cls(str(r.attr("parameter_name")), p, nodes, period, multipliers, stable,
                   n_impacts, tuple(points), str(r.attr("stop_reason")),
                   int(r.attr("n_steps")), int(r.attr("corrector_iterations")), state_names,
                   str(r.attr("solution", default="periodic")))


_FORMAT = "nscontrol.Branch/2"
_FORMAT_V1 = "nscontrol.Branch/1"     # periodic orbits only: no "solution" attribute


# -- the continuation problem ------------------------------------------------------------------

def _as_forced(hit: Any, p: float) -> Forced:
    if not isinstance(hit, Forced):
        raise ModelError(f"factory: expected a Forced (system, input, period) for p = {p}, "
                         f"got {type(hit).__name__}")
    return hit


#: The test functions :func:`continue_orbit` watches (``detect``) and the kinds it can stop
#: at (``stop_at``: a grazing is reported as ``"sliding"`` when a sliding segment appears).
ORBIT_KINDS = ("fold", "flip", "neimark_sacker", "grazing")
ORBIT_STOP_KINDS = (*ORBIT_KINDS, "sliding")


@dataclass
class _Problem(ArclengthProblem):
    """``G(y) = 0`` for ``y = (nodes, p)`` (multiple shooting); corrector and tangent are the
    shared engine's (:class:`~nscontrol.analysis._arclength.ArclengthProblem`)."""

    factory: Callable[[float], Forced]
    k: int
    n: int
    tol: float
    iterations: int = 0

    def __post_init__(self) -> None:
        self.forced: FactoryMemo = FactoryMemo(self.factory, _as_forced)

    def split(self, y: FloatArray) -> tuple[FloatArray, float]:
        return y[:-1].reshape(self.k, self.n), float(y[-1])

    def residual(self, y: FloatArray, G_p: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray, list[Any]]:
        """``G(y)``, ``[G_x, G_p]`` and the node maps (``G_p`` recomputed unless given)."""
        X, p = self.split(y)
        R, Jx, maps = _shooting_system(self.forced(p), X)
        if G_p is None:
            G_p = self.parameter_derivative(y)
        return R, np.column_stack([Jx, G_p]), maps

    def parameter_derivative(self, y: FloatArray) -> FloatArray:
        """``∂G/∂p`` by central differences (step ``ε^{1/3}·max(1, |p|)``)."""
        X, p = self.split(y)
        return parameter_derivative(lambda q: _shooting_system(self.forced(q), X)[0], p)

    def solution(self, y: FloatArray, aux: Any, iterations: int, residual: float) -> Orbit:
        X, p = self.split(y)
        return make_orbit(self.forced(p), X, aux, iterations, residual)

    def point(self, y_pred: FloatArray, t: FloatArray) -> Point:
        """The corrected point with its test functions."""
        y, orbit = self.correct(y_pred, t)
        return Point(y, orbit, _tests(orbit))


def _orbit_at(factory: Callable[[float], Forced], p: float, nodes: FloatArray, *,
              tol: float = 1e-10, max_iter: int = 6) -> Orbit:
    """The engine's corrector with the parameter pinned: the ``k``-node orbit of
    ``factory(p)`` near ``nodes`` by plain Newton (no line search: from a good predictor it
    converges quadratically; from a bad one it fails fast with ``SolverError``)."""
    k, n = nodes.shape
    prob = _Problem(factory, k, n, tol)
    pin = np.zeros(k * n + 1)
    pin[-1] = 1.0
    return prob.correct(np.append(nodes.ravel(), float(p)), pin, max_iter,
                        G_p=np.zeros(k * n))[1]


# -- test functions --------------------------------------------------------------------------

def _tests(orbit: Orbit) -> dict[str, float]:
    mu = orbit.multipliers
    pairs = [mu[i] * mu[j] - 1.0 for i in range(len(mu)) for j in range(i + 1, len(mu))]
    return {"fold": float(np.prod(mu - 1.0).real), "flip": float(np.prod(mu + 1.0).real),
            "neimark_sacker": float(np.prod(pairs).real) if pairs else 1.0,
            "grazing": _grazing_monitor(orbit)}


def _grazing_monitor(orbit: Orbit) -> float:
    """Positive on a non-impacting orbit (its smallest gap), negative on an impacting one
    (minus its smallest impact speed); both vanish at a grazing."""
    if any(kind == "grazing" for kind, _ in orbit.signature):
        return 0.0
    if orbit.n_impacts:
        return -orbit.min_impact_speed
    return orbit.min_gap if np.isfinite(orbit.min_gap) else 1.0


def _genuine(kind: str, orbit: Orbit) -> bool:
    """A Neimark–Sacker sign change needs a complex pair on the unit circle."""
    if kind != "neimark_sacker":
        return True
    mu = orbit.multipliers
    return bool(np.any((np.abs(mu.imag) > 1e-8) & (np.abs(np.abs(mu) - 1.0) < 1e-6)))


def continue_orbit(factory: Callable[[float], Forced], p0: float, x0: Any, *,
                   p_range: tuple[float, float], n_periods: int = 1, step: float = 0.01,
                   step_min: float = 1e-6, step_max: float = 0.1, max_steps: int = 500,
                   direction: int = 1, tol: float = 1e-10, locate_tol: float = 1e-10,
                   detect: tuple[str, ...] = ("fold", "flip", "neimark_sacker", "grazing"),
                   stop_at: tuple[str, ...] = ("grazing", "sliding"), parameter_name: str = "p",
                   initial_tangent: Any = None, state_names: tuple[str, ...] = (),
                   corrector_max_iter: int = CORRECTOR_MAX_ITER,
                   locate_max_iter: int = LOCATE_MAX_ITER) -> Branch:
    """Continue the ``n_periods·T``-periodic orbit through ``x0`` at ``p0`` in ``p``.

    Parameters
    ----------
    factory
        ``p -> Forced``: the system at parameter ``p`` (picklable when used in a sweep).
    p0, x0
        Start: parameter (inside ``p_range``) and a guess of the orbit (one state or the
        ``(k, n)`` nodes).
    p_range
        ``(lo, hi)`` with ``lo < hi``: stop when ``p`` leaves ``[lo, hi]``.
    n_periods
        ``k`` of the ``kT``-periodic orbit.
    step, step_min, step_max
        Initial, smallest and largest arclength steps (``step_min <= step_max``). A failed
        correction halves the step; below ``step_min`` the continuation stops.
    max_steps
        Largest number of continuation steps (then it stops, ``stop_reason`` naming it).
    direction
        ``+1``: start towards increasing ``p``; ``-1``: decreasing.
    tol
        Corrector tolerance on the shooting residual (relative to ``max(1, |x|)``).
    locate_tol
        Relative width of the parameter bracket at which a bifurcation counts as located.
    detect
        Which test functions to watch: any of ``"fold"``, ``"flip"``, ``"neimark_sacker"``,
        ``"grazing"``.
    stop_at
        Kinds after whose location the continuation stops (default: grazing and sliding
        bifurcations, where the event sequence and hence the map change); any of those of
        ``detect`` and ``"sliding"``.
    parameter_name, state_names
        Labels kept in the :class:`Branch`.
    initial_tangent
        Start along this direction in ``y = (nodes, p)`` instead of the computed tangent
        (branch switching); ``x0`` must then be on the branch already.
    corrector_max_iter
        Newton iterations per correction. Spent at the start: :class:`BudgetExceededError`;
        on the way the step is halved (down to ``step_min``).
    locate_max_iter
        Corrected trial points per location of a bifurcation.

    Returns
    -------
    Branch
        Its ``stop_reason`` says why it ended: ``p_range`` left, a kind of ``stop_at``
        located, ``max_steps`` spent, or the step halved below ``step_min``.

    Raises
    ------
    ModelError
        Bad options (refused before anything is computed), a factory returning no
        :class:`Forced`.
    BudgetExceededError
        ``corrector_max_iter`` spent on the starting orbit (its last iterate in
        ``err.partial``), or ``locate_max_iter`` spent locating a bifurcation (the branch
        computed so far in ``err.partial``).
    SolverError
        The starting orbit cannot be found.
    """
    k = check_integer("n_periods", n_periods, minimum=1)
    opts = check_options(factory, p0, p_range, step=step, step_min=step_min,
                         step_max=step_max, max_steps=max_steps, direction=direction, tol=tol,
                         locate_tol=locate_tol, corrector_max_iter=corrector_max_iter,
                         locate_max_iter=locate_max_iter, detect=detect, stop_at=stop_at,
                         kinds=ORBIT_KINDS, stop_kinds=ORBIT_STOP_KINDS)
    forced0 = _as_forced(factory(opts.p0), opts.p0)
    prob = _Problem(factory, k, forced0.n_states, opts.tol)
    prob.max_iter = opts.corrector_max_iter
    X0 = _initial_nodes(forced0, x0, k, forced0.n_states)
    y0 = np.append(X0.ravel(), opts.p0)
    if initial_tangent is None:
        t0 = np.zeros_like(y0)
        t0[-1] = float(opts.direction)
        y, orbit = prob.correct(y0, t0, start=True)   # fixed p: the row (0..0, 1) pins it
        t = prob.tangent(y, t0)
    else:
        t = as_vector("initial_tangent", initial_tangent, y0.size)
        if not np.any(t):
            raise ModelError("initial_tangent: expected a nonzero direction in (nodes, p), "
                             "got zeros")
        t = t / np.linalg.norm(t)
        y = y0
        _, orbit = prob.correct(y0, t, start=True)
    pts = [Point(y, orbit, _tests(orbit))]
    special: list[SpecialPoint] = []
    try:
        reason, n_steps = _march(prob, opts, pts, special, t)
    except BudgetExceededError as exc:      # a location's budget: keep what was computed
        so_far = _branch(pts, special, f"{exc.budget} spent: {exc}",
                         len(pts) - 1 - len(special),
                         prob.iterations, parameter_name, state_names, k, forced0)
        raise BudgetExceededError(
            f"{exc}; the branch computed so far ({len(so_far)} points, p up to "
            f"{so_far.p[-1]:.9g}) is in err.partial", budget=exc.budget, limit=exc.limit,
            used=exc.used, partial=so_far) from exc
    return _branch(pts, special, reason, n_steps, prob.iterations, parameter_name, state_names,
                   k, forced0)


def _march(prob: _Problem, opts: Options, pts: list[Point], special: list[SpecialPoint],
           t: FloatArray) -> tuple[str, int]:
    """The continuation's steps from ``pts[-1]`` along ``t``, appending to ``pts`` and
    ``special``; returns the stop reason and the steps taken."""
    lo, hi, detect, stop_at = opts.lo, opts.hi, opts.detect, opts.stop_at
    h, n_steps, reason = opts.step, 0, ""
    while not reason:
        if n_steps >= opts.max_steps:
            reason = (f"max_steps ({opts.max_steps}) reached at p = {pts[-1].y[-1]:.9g}; "
                      f"raise max_steps to go on")
            break
        s_g = (_grazing_ahead(pts[-2], pts[-1], h)
               if "grazing" in detect and len(pts) >= 2 else None)
        if s_g is not None:
            sp = _locate(prob, pts[-1], t, h, "grazing", opts, s_first=s_g)
            if sp is not None:
                pts.append(sp)
                special.append(_special("grazing", sp, len(pts) - 1, prob))
                if "grazing" in stop_at:
                    reason = f"grazing at p = {sp.y[-1]:.12g}"
                    break
        try:
            y_new, orb = prob.correct(pts[-1].y + h * t, t)
        except SolverError as exc:
            h /= 2
            if h < opts.step_min:
                reason = (f"step_min: the corrector failed at p ≈ {pts[-1].y[-1]:.9g} with "
                          f"every step down to {2 * h:.3g} < 2·step_min = "
                          f"{2 * opts.step_min:.3g}: {exc}")
            continue
        n_steps += 1
        new = Point(y_new, orb, _tests(orb))
        found = _crossings(pts[-1], new, detect)
        stop_kind = None
        for kind in found:
            sp = _locate(prob, pts[-1], t, h, kind, opts)
            if sp is None or not _genuine(kind, sp.sol):
                continue
            if kind == "grazing":
                kind = _event_change_kind(pts[-1].sol.signature, new.sol.signature)
            pts.append(sp)
            special.append(_special(kind, sp, len(pts) - 1, prob))
            if kind in stop_at:
                stop_kind = kind
                break
        if stop_kind is not None:      # what lies past it belongs to another branch
            reason = f"{stop_kind} at p = {special[-1].parameter:.12g}"
            break
        pts.append(new)
        p_new = float(y_new[-1])
        if not lo <= p_new <= hi:
            reason = f"left p_range [{lo:g}, {hi:g}] at p = {p_new:.9g}"
            break
        t = prob.tangent(y_new, t)
        if orb.iterations <= 3:
            h = min(1.5 * h, opts.step_max)
    return reason, n_steps


def _crossings(a: Point, b: Point, detect: tuple[str, ...]) -> list[str]:
    out = [kind for kind in detect
           if kind in a.tests and a.tests[kind] * b.tests[kind] < 0.0]
    if "grazing" in detect and "grazing" not in out and a.sol.signature != b.sol.signature:
        out.append("grazing")
    return out


def _event_change_kind(before: tuple[tuple[str, int], ...],
                       after: tuple[tuple[str, int], ...]) -> str:
    """``"sliding"`` when a sliding segment appears or vanishes between two event signatures
    (a sliding bifurcation), ``"grazing"`` otherwise."""
    def slides(sig: tuple[tuple[str, int], ...]) -> int:
        return sum(1 for k, _ in sig if k.startswith("sliding"))

    return "sliding" if slides(before) != slides(after) else "grazing"


def _value(kind: str, pt: Point, ref: Point) -> float:
    """The test function; for a grazing, the monitor's modulus signed by whether the event
    signature is still the reference's (the side the continuation came from)."""
    if kind != "grazing":
        return pt.tests[kind]
    mag = abs(pt.tests["grazing"])
    return mag if pt.sol.signature == ref.sol.signature else -mag


def _locate(prob: _Problem, a: Point, t: FloatArray, h: float, kind: str, opts: Options,
            s_first: float | None = None) -> Point | None:
    """Zero of ``test(kind)`` along the arclength from ``a`` (the shared
    :func:`~nscontrol.analysis._arclength.locate`, within ``opts.locate_tol`` and
    ``opts.locate_max_iter``); for a grazing the point kept is on ``a``'s side (past it the
    event sequence, hence the map, is another)."""
    return locate(prob.point, a, t, h, lambda pt: _value(kind, pt, a), opts.locate_tol,
                  s_first=s_first, closest=kind != "grazing", max_iter=opts.locate_max_iter)


def _grazing_ahead(prev: Point, cur: Point, h: float) -> float | None:
    """Arclength to the grazing predicted by linear extrapolation of the grazing monitor over
    the last step (same event signature), or ``None`` when it is not within ``h``."""
    if prev.sol.signature != cur.sol.signature:
        return None
    m0, m1 = abs(prev.tests["grazing"]), abs(cur.tests["grazing"])
    ds = float(np.linalg.norm(cur.y - prev.y))
    if not m1 < m0 or ds == 0.0:
        return None
    s = m1 * ds / (m0 - m1)
    return s if s < h else None


def _special(kind: str, pt: Point, index: int, prob: _Problem) -> SpecialPoint:
    X, p = prob.split(pt.y)
    return SpecialPoint(kind, p, index, X.copy(), pt.sol.multipliers.copy(),
                        float(pt.tests.get("_width", 0.0)))


def _branch(pts: list[Point], special: list[SpecialPoint], reason: str, n_steps: int,
            iterations: int, name: str, state_names: tuple[str, ...], k: int,
            forced0: Forced) -> Branch:
    n = forced0.n_states
    names = tuple(state_names) or tuple(getattr(forced0.system, "state_names", ()) or ())
    return Branch(name, np.array([pt.y[-1] for pt in pts]),
                  np.array([pt.y[:-1].reshape(k, n) for pt in pts]),
                  np.array([k * pt.sol.period for pt in pts]),
                  np.array([pt.sol.multipliers for pt in pts]),
                  np.array([pt.sol.stable for pt in pts]),
                  np.array([pt.sol.n_impacts for pt in pts]), tuple(special), reason,
                  n_steps, iterations, names)


def switch_at_flip(factory: Callable[[float], Forced], branch: Branch,
                   point: SpecialPoint | None = None, **options: Any) -> Branch:
    """Continue the period-doubled branch born at a flip of ``branch``.

    The flip orbit traversed twice solves the doubled problem; the doubled branch leaves it
    along the flip eigenvector ``w`` (``M w = -w``), propagated to the nodes
    (``w_{i+1} = J_i w_i``) and taken with opposite signs on the two copies. ``options`` go
    to :func:`continue_orbit` (``p_range`` is required).

    Parameters
    ----------
    factory : callable ``p -> Forced``
        The family of forced systems.
    branch : Branch
        The branch with the flip.
    point : SpecialPoint, optional
        The flip (default: the first one found on ``branch``).
    **options
        Passed to :func:`continue_orbit`.

    Raises
    ------
    ModelError
        ``branch`` not a :class:`Branch`, ``point`` not one of its flips, or no flip on it.
    """
    if not isinstance(branch, Branch):
        raise ModelError(f"branch: expected the Branch continue_orbit returned, got "
                         f"{type(branch).__name__}")
    flips = branch.special("flip")
    if point is not None and not (isinstance(point, SpecialPoint) and point.kind == "flip"):
        what = f"a {point.kind!r} point" if isinstance(point, SpecialPoint) else \
            type(point).__name__
        raise ModelError(f"point: expected a flip of the branch (branch.special('flip')), got "
                         f"{what}")
    if point is None:
        if not flips:
            raise ModelError("branch: no flip point located on this branch")
        point = flips[0]
    k, n = point.nodes.shape
    forced = factory(point.parameter)
    X = point.nodes
    _, _, maps = _shooting_system(forced, X)
    M = np.eye(n)
    for m in maps:
        M = m.jacobian @ M
    mu, V = np.linalg.eig(M)
    w = np.real(V[:, int(np.argmin(np.abs(mu + 1.0)))])
    ws = [w]
    for m in maps[:-1]:
        ws.append(m.jacobian @ ws[-1])
    W = np.array(ws)
    tangent = np.append(np.concatenate([W, -W]).ravel(), 0.0)
    opts = dict(options)
    opts.setdefault("parameter_name", branch.parameter_name)
    # the doubled flip orbit has the multiplier +1: a fold test would fire at the start
    opts.setdefault("detect", ("flip", "neimark_sacker", "grazing"))
    return continue_orbit(factory, point.parameter, np.concatenate([X, X]),
                          n_periods=2 * k, initial_tangent=tangent, **opts)

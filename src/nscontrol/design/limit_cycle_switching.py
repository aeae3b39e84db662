"""Feedback control of a planar limit cycle by a corner (wedge) switching controller.

The controller adds ``k·b`` to the plant's field inside a wedge whose corner sits at offset
``μ_c`` from the cycle ``Γ`` (:class:`~nscontrol.systems.wedge.WedgeSwitchedSystem`). When
``Γ`` passes the corner, a corner collision makes the cycle's return map piecewise linear to
leading order (:class:`PWLReturnMap`): slope ``λ`` for orbits
that miss the wedge, ``λ(1 + a)`` for orbits that cross it, ``a`` the corner gain. A new
cycle appears at offset ``z* = −λaμ_c/(1 − λ(1 + a))`` with multiplier ``λ(1 + a)``.

Design (:func:`design_corner_controller`) for a target multiplier ``λ_d`` and offset ``z_d``:
``a = λ_d/λ − 1``, ``μ_c = z_d(1 − λ_d)/(λ − λ_d)``, then ``k`` from ``a(k) = a`` in closed
form; the crossing condition is checked at the corner. The prediction is verified by
shooting the closed loop with saltation matrices,
:func:`nscontrol.analysis.corner_maps.verify_corner_design`, the first time the design's
:attr:`CornerDesign.verified` is read. The orbit engine sits in the analysis layer, above this
one, so this module does not import it: the package root provides it as the hook
``"corner_verifier"`` (``nscontrol._lazy.provided``), resolved at that first read. While
both faces are crossed ``1 + a > 0``:
a target ``λ_d <= 0`` (``a <= −1``) is refused, or met with the sliding design when
``allow_sliding=True`` (the motion slides along the entry face into the corner: every
orbit that meets the wedge leaves it at the corner, ``λ_new = 0`` whatever ``k``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_real_scalar,
    as_vector,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import DimensionError, InfeasibleDesignError, ModelError, SolverError
from ..systems.nonlinear import NonlinearSystem
from ..systems.wedge import (
    Wedge,
    WedgeSwitchedSystem,
    cross,
    marker_crossings,
    with_marker_line,
)

__all__ = ["corner_gain", "gain_for_corner_gain", "crossing_gain_interval",
           "reachable_multipliers", "CornerDiscontinuityMap", "corner_discontinuity_map",
           "PWLFixedPoint", "PWLReturnMap", "Section", "CornerSite", "corner_site",
           "CornerDesign", "design_corner_controller", "SLIDING_GAIN_FACTOR"]

def _vec(name: str, v: ArrayLike) -> FloatArray:
    return as_vector(name, v, 2)


def _kappa(F1: FloatArray, F2: FloatArray, n_in: FloatArray, n_out: FloatArray,
           e: FloatArray) -> float:
    s_in1, s_out2 = float(n_in @ F1), float(n_out @ F2)
    if s_in1 == 0.0 or s_out2 == 0.0:
        raise ModelError(f"F1, F2: a zero normal speed at the corner (n_inᵀF1 = {s_in1:.3g}, "
                         f"n_outᵀF2 = {s_out2:.3g}): the flow grazes a face and the corner map "
                         f"is not piecewise linear there")
    bracket = float(n_out @ e) - float(n_out @ F1) * float(n_in @ e) / s_in1
    return -bracket / s_out2


def corner_gain(F1: ArrayLike, F2: ArrayLike, n_in: ArrayLike, n_out: ArrayLike,
                e: ArrayLike) -> float:
    """The slope change ``a`` of the corner discontinuity map on the line ``Σ_c``.

    Parameters
    ----------
    F1, F2 : (2,) array_like
        The fields outside and inside the wedge, at the corner.
    n_in, n_out : (2,) array_like
        Inward normals of the entry and exit faces.
    e : (2,) array_like
        The direction offsets are measured along (transverse to ``F1``).

    Returns
    -------
    float
        ``a = κ (F2 × F1)/(e × F1)``: an orbit at offset ``z > μ_c`` leaves the wedge at
        offset ``z + a (z − μ_c)`` (leading order).

    Raises
    ------
    ModelError
        ``e`` parallel to ``F1``, or a zero normal speed on a face.

    Examples
    --------
    Symmetric wedge of half-angle 45° along ``e``, ``b = e``, ``F1 ⊥ e`` of speed ``v``:
    ``a = 2k tanα/(v − k tanα)``.

    >>> s = np.sqrt(0.5)
    >>> a = corner_gain([0, 1.0], [-0.5, 1.0], [s, s], [s, -s], [1.0, 0])
    >>> bool(abs(a - 2 * (-0.5) / (1 + 0.5)) < 1e-15)
    True
    """
    f1, f2, ni, no, ee = (_vec(n, v) for n, v in (("F1", F1), ("F2", F2), ("n_in", n_in),
                                                  ("n_out", n_out), ("e", e)))
    ef = cross(ee, f1)
    if ef == 0.0:
        raise ModelError("e: parallel to F1; offsets must be measured across the flow")
    return _kappa(f1, f2, ni, no, ee) * cross(f2, f1) / ef


def gain_for_corner_gain(a: float, F1: ArrayLike, b: ArrayLike, n_in: ArrayLike,
                         n_out: ArrayLike, e: ArrayLike) -> float:
    """The gain ``k`` for which :func:`corner_gain` of ``F1`` and ``F1 + k·b`` equals ``a``.

    ``a(k) = −B k (b × F1) / ((e × F1)(n_outᵀF1 + k n_outᵀb))`` with
    ``B = n_outᵀe − (n_outᵀF1)(n_inᵀe)/(n_inᵀF1)`` is a Möbius function of ``k``, solved in
    closed form.

    Parameters
    ----------
    a : float
        The wanted corner gain.
    F1 : (2,) array_like
        The plant's field at the corner.
    b : (2,) array_like
        The input direction.
    n_in, n_out, e : (2,) array_like
        Face normals and offset direction, as in :func:`corner_gain`.

    Raises
    ------
    ModelError
        ``b`` parallel to ``F1`` (no first-order effect) or ``a`` not reachable by any ``k``.
    """
    aa = as_real_scalar("a", a)
    f1, bb, ni, no, ee = (_vec(n, v) for n, v in (("F1", F1), ("b", b), ("n_in", n_in),
                                                  ("n_out", n_out), ("e", e)))
    beta, E = cross(bb, f1), cross(ee, f1)
    if beta == 0.0:
        raise ModelError("b: parallel to the flow at the corner, so the input has no "
                         "first-order effect on the cycle; move the corner where b × f ≠ 0")
    B = float(no @ ee) - float(no @ f1) * float(ni @ ee) / float(ni @ f1)
    den = -B * beta - aa * E * float(no @ bb)
    if den == 0.0:
        raise ModelError(f"a: the corner gain {aa:.6g} is the asymptote of a(k); no finite "
                         f"gain reaches it")
    return aa * E * float(no @ f1) / den


def crossing_gain_interval(F1: ArrayLike, b: ArrayLike, n_in: ArrayLike, n_out: ArrayLike
                           ) -> tuple[float, float]:
    """The gains ``k`` for which the motion crosses both faces at the corner.

    Parameters
    ----------
    F1 : (2,) array_like
        The plant's field at the corner.
    b : (2,) array_like
        The input direction.
    n_in, n_out : (2,) array_like
        Inward normals of the entry and exit faces.

    Returns
    -------
    (k_lo, k_hi)
        ``n_inᵀ(F1 + kb) > 0`` and ``n_outᵀ(F1 + kb) < 0`` for ``k_lo < k < k_hi``
        (``±inf`` when a bound does not exist). Below ``k_lo`` (with ``n_inᵀb > 0``, else
        above ``k_hi``) the motion slides on the entry face.

    Raises
    ------
    ModelError
        ``F1`` does not enter through ``n_in`` and leave through ``n_out`` (no gain crosses).
    """
    f1, bb, ni, no = (_vec(n, v) for n, v in (("F1", F1), ("b", b), ("n_in", n_in),
                                              ("n_out", n_out)))
    si, so = float(ni @ f1), float(no @ f1)
    if not (si > 0.0 > so):
        raise ModelError(f"F1: the plant's flow must enter the wedge through n_in and leave "
                         f"through n_out at the corner (n_inᵀF1 = {si:.3g} > 0 > n_outᵀF1 = "
                         f"{so:.3g}); swap the faces or move the corner")
    lo, hi = -np.inf, np.inf
    for s, w, sign in ((si, float(ni @ bb), 1.0), (so, float(no @ bb), -1.0)):
        if w != 0.0:   # sign·(s + k w) > 0
            bound = -s / w
            if sign * w > 0.0:
                lo = max(lo, bound)
            else:
                hi = min(hi, bound)
    return float(lo), float(hi)


def reachable_multipliers(lam: float, F1: ArrayLike, b: ArrayLike, n_in: ArrayLike,
                          n_out: ArrayLike, e: ArrayLike) -> tuple[float, float]:
    """The multipliers ``λ(1 + a(k))`` of the controlled cycle over the crossing gains.

    Parameters
    ----------
    lam : float
        The uncontrolled cycle's multiplier ``λ``.
    F1, b, n_in, n_out, e : (2,) array_like
        As in :func:`corner_gain` and :func:`crossing_gain_interval`.

    Returns
    -------
    (lo, hi)
        The open interval of multipliers; for the corner-collision geometry it is
        ``(0, ∞)`` times ``sign λ`` (``1 + a > 0`` while both faces are crossed). Beyond the
        entry face's sliding threshold the multiplier is ``0`` whatever ``k``.
    """
    lm = as_real_scalar("lam", lam)
    lo, hi = crossing_gain_interval(F1, b, n_in, n_out)
    f1, bb, no = _vec("F1", F1), _vec("b", b), _vec("n_out", n_out)
    w_out = float(no @ bb)
    pole = -float(no @ f1) / w_out if w_out != 0.0 else None

    def mult(k: float) -> float:
        # the interval's ends are sliding thresholds: where the exit face's normal speed
        # n_outᵀF2 vanishes, a has a pole (1 + a > 0 inside: the limit is +∞ times sign λ);
        # where the entry face's vanishes, 1 + a -> 0. Evaluated at the end itself, round-off
        # in n_outᵀF2 ~ 0 gave any sign and size (-2.25e16 for λ = 1.01), so take the limits
        if np.isfinite(k):
            return float(np.sign(lm)) * np.inf if k == pole else 0.0
        k = np.sign(k) * 1e12 * (1.0 + float(np.linalg.norm(f1)) / float(np.linalg.norm(bb)))
        return lm * (1.0 + corner_gain(f1, f1 + k * bb, n_in, n_out, e))
    ends = sorted((mult(lo), mult(hi)))
    return float(ends[0]), float(ends[1])


@dataclass(frozen=True)
class CornerDiscontinuityMap:
    """The zero-time discontinuity map of a corner, ``x ↦ x + (F2 − F1)·Δt(x)``.

    ``Δt(x) = max(0, −[h_out(x) − (n_outᵀF1/n_inᵀF1) h_in(x)]/(n_outᵀF2))`` is the time an
    ``F1``-orbit through ``x`` would spend in the wedge (fields frozen at the corner); the map
    is continuous, piecewise linear and the identity on the side whose orbits miss the wedge.

    Attributes
    ----------
    F1, F2 : ndarray
        The fields at the corner.
    wedge : Wedge
        The wedge.
    """

    F1: FloatArray
    F2: FloatArray
    wedge: Wedge

    def dwell_time(self, x: ArrayLike) -> float:
        """``Δt(x)``, the leading-order time spent in the wedge.

        Parameters
        ----------
        x : (2,) array_like
            A point near the corner.
        """
        w = self.wedge
        ratio = float(w.n_out @ self.F1) / float(w.n_in @ self.F1)
        return max(0.0, -(w.h_out(x) - ratio * w.h_in(x)) / float(w.n_out @ self.F2))

    def __call__(self, x: ArrayLike) -> FloatArray:
        xx = _vec("x", x)
        return xx + (self.F2 - self.F1) * self.dwell_time(xx)


def corner_discontinuity_map(F1: ArrayLike, F2: ArrayLike, wedge: Wedge
                             ) -> CornerDiscontinuityMap:
    """The corner discontinuity map of a wedge (see :class:`CornerDiscontinuityMap`).

    Parameters
    ----------
    F1, F2 : (2,) array_like
        The fields outside and inside the wedge at its corner.
    wedge : Wedge
        The wedge.

    Raises
    ------
    ModelError
        ``F1`` not entering through the entry face, or ``F2`` not leaving through the exit
        face (the crossing-only geometry the map describes).
    """
    f1, f2 = _vec("F1", F1), _vec("F2", F2)
    if not float(wedge.n_in @ f1) > 0.0:
        raise ModelError("F1: the flow does not enter the wedge through its entry face")
    if not float(wedge.n_out @ f2) < 0.0:
        raise ModelError("F2: the controlled flow does not leave through the exit face")
    return CornerDiscontinuityMap(f1, f2, wedge)


@dataclass(frozen=True)
class PWLFixedPoint:
    """A fixed point of a :class:`PWLReturnMap`.

    Attributes
    ----------
    z : float
        Its offset.
    slope : float
        The map's slope there (the cycle's multiplier, leading order).
    branch : str
        ``"left"`` (orbits miss the wedge) or ``"right"`` (they cross it).
    stable : bool
        ``|slope| < 1``.
    """

    z: float
    slope: float
    branch: str
    stable: bool


@dataclass(frozen=True)
class PWLReturnMap:
    """``P(z) = λz`` for ``z <= μ``, ``λ(1 + a)z − λaμ`` for ``z > μ``.

    Attributes
    ----------
    lam : float
        The uncontrolled multiplier ``λ`` (left slope).
    a : float
        The corner gain.
    mu : float
        The corner's offset ``μ_c``.

    Examples
    --------
    Stabilising an unstable cycle (``λ = 2``) with ``a = −0.75`` and the corner just outside:

    >>> P = PWLReturnMap(2.0, -0.75, 0.01)
    >>> [(round(p.z, 6), p.slope, p.stable) for p in P.fixed_points()]
    [(0.0, 2.0, False), (0.03, 0.5, True)]
    """

    lam: float
    a: float
    mu: float

    def __call__(self, z: ArrayLike) -> Any:
        """The map at ``z`` (scalar or array).

        Parameters
        ----------
        z : float or array_like
            Offsets.
        """
        zz = np.asarray(z, float)
        out = np.where(zz <= self.mu, self.lam * zz,
                       self.lam * (1.0 + self.a) * zz - self.lam * self.a * self.mu)
        return float(out) if out.ndim == 0 else out

    @property
    def right_slope(self) -> float:
        """``λ(1 + a)``, the multiplier of a cycle crossing the wedge."""
        return self.lam * (1.0 + self.a)

    @property
    def q(self) -> float:
        """``z*/μ_c = −λa/(1 − λ(1 + a))``, the controlled cycle's offset per unit ``μ_c``."""
        return -self.lam * self.a / (1.0 - self.right_slope)

    def fixed_points(self) -> list[PWLFixedPoint]:
        """Both branches' fixed points that lie on their branch, by increasing ``z``."""
        out = []
        if self.mu >= 0.0:
            out.append(PWLFixedPoint(0.0, self.lam, "left", abs(self.lam) < 1.0))
        if self.right_slope != 1.0:
            z = self.q * self.mu
            if z > self.mu:
                out.append(PWLFixedPoint(float(z), self.right_slope, "right",
                                         abs(self.right_slope) < 1.0))
        return sorted(out, key=lambda p: p.z)

    def classify(self) -> str:
        """The border-collision scenario as ``μ`` crosses 0 with slopes
        ``(λ_L, λ_R) = (λ, λ(1 + a))``.

        Returns
        -------
        str
            ``"persistence"`` (one fixed point on each side of the collision, ``λ_L``,
            ``λ_R`` both below 1 or both above), ``"nonsmooth fold"`` (two fixed points on one
            side, none on the other: one slope above 1, one below), ``"flip"`` when a slope
            is below −1 (period doubling or chaos may follow), ``"degenerate"`` with a slope
            equal to 1.
        """
        left, right = self.lam, self.right_slope
        if left == 1.0 or right == 1.0:
            return "degenerate"
        if left < -1.0 or right < -1.0:
            return "flip"
        return "persistence" if (left < 1.0) == (right < 1.0) else "nonsmooth fold"


@dataclass(frozen=True)
class Section:
    """A Poincaré section: the line ``normalᵀx = offset``, crossed with ``normalᵀẋ > 0``;
    offsets on it are measured along ``direction``.

    Attributes
    ----------
    normal : ndarray, shape (2,)
        The line's normal (the crossing direction counted as a return).
    offset : float
        ``normalᵀx`` on the line.
    direction : ndarray, shape (2,)
        Unit vector along the line (offsets are ``directionᵀ(x − point)``).

    Examples
    --------
    The ray ``θ = −π/3`` of a counter-clockwise flow around the origin:

    >>> th = -np.pi / 3
    >>> S = Section([-np.sin(th), np.cos(th)], 0.0, [np.cos(th), np.sin(th)])
    >>> bool(abs(S.direction @ S.normal) < 1e-15)
    True
    """

    normal: FloatArray
    offset: float
    direction: FloatArray

    if TYPE_CHECKING:
        def __init__(self, normal: ArrayLike, offset: float, direction: ArrayLike) -> None: ...

    def __post_init__(self) -> None:
        nv = _vec("normal", self.normal)
        d = _vec("direction", self.direction)
        if not np.any(nv) or not np.any(d):
            raise ModelError("normal, direction: expected non-zero 2-vectors")
        d = d / np.linalg.norm(d)
        if abs(float(d @ nv)) > 1e-12 * float(np.linalg.norm(nv)):
            raise ModelError("direction: must lie along the section line (orthogonal to "
                             "normal)")
        object.__setattr__(self, "normal", nv)
        object.__setattr__(self, "direction", d)
        object.__setattr__(self, "offset", as_real_scalar("offset", self.offset))


@dataclass(frozen=True, eq=False)
class CornerSite:
    """Where a corner is placed on a plant's cycle, and how offsets are measured.

    Attributes
    ----------
    plant : NonlinearSystem
        The plant.
    anchor : ndarray
        ``p_Γ``: the point of the cycle on the corner's line ``Σ_c``.
    e : ndarray
        Unit outward normal of the cycle at ``p_Γ`` (offsets on ``Σ_c`` along it).
    F1 : ndarray
        The plant's field at ``p_Γ``.
    lam : float
        The cycle's non-trivial multiplier ``λ``.
    period : float
        Its period.
    section : Section
        An upstream Poincaré section (outside the wedge).
    section_point : ndarray
        The cycle's point on it.
    tau : float
        ``∂(offset on Σ_c)/∂(offset on the section)`` along the uncontrolled flow.
    orientation : int
        ``+1`` counter-clockwise cycle, ``−1`` clockwise.
    """

    plant: NonlinearSystem
    anchor: FloatArray
    e: FloatArray
    F1: FloatArray
    lam: float
    period: float
    section: Section
    section_point: FloatArray
    tau: float
    orientation: int

    def corner(self, mu: float) -> FloatArray:
        """The corner at offset ``μ``: ``p_Γ + μ e``.

        Parameters
        ----------
        mu : float
            The corner's offset.
        """
        return self.anchor + float(mu) * self.e

    def section_offset(self, x: ArrayLike) -> float:
        """The offset of a point of the section from the cycle, ``directionᵀ(x − p_s)``.

        Parameters
        ----------
        x : (2,) array_like
            A point of the section.
        """
        return float(self.section.direction @ (_vec("x", x) - self.section_point))

    def section_state(self, z: float) -> FloatArray:
        """The point of the section at offset ``z``.

        Parameters
        ----------
        z : float
            The offset.
        """
        return self.section_point + float(z) * self.section.direction


def _first_crossing(system: Any, x0: FloatArray, normal: FloatArray, offset: float,
                    t_max: float) -> tuple[float, FloatArray]:
    """The first crossing after ``t = 0`` of the line ``normalᵀx = offset`` along ``normal``."""
    from ..simulate import simulate

    marked, j = with_marker_line(system, normal, offset)
    tr = simulate(marked, x0, (0.0, t_max), t_eval=np.array([0.0, t_max]))
    hits = marker_crossings(tr, j)
    if not hits:
        raise SolverError(f"the orbit from {np.asarray(x0).tolist()} does not cross the line "
                          f"{np.asarray(normal).tolist()}ᵀx = {offset:.6g} within "
                          f"t = {t_max:.4g}")
    return float(hits[0].time), np.asarray(hits[0].post, float)


def _check_plant_and_cycle(plant: Any, cycle: Any, section: Any) -> None:
    """A planar :class:`NonlinearSystem`, a cycle object (``x0``, ``period``, ``nontrivial``:
    a ``Cycle`` of the analysis layer, which this layer does not import) and a
    :class:`Section` or ``None``: refused here, not by an ``AttributeError`` mid-design."""
    check_type("plant", plant, NonlinearSystem,
               hint="the corner design needs the planar vector field x' = f(x)")
    if int(plant.n_states) != 2:
        raise DimensionError(f"plant: expected a planar system (2 states), got "
                             f"{plant.n_states} states")
    missing = [a for a in ("x0", "period", "nontrivial") if not hasattr(cycle, a)]
    if missing:
        raise ModelError(f"cycle: expected a Cycle (x0, period, nontrivial), got a "
                         f"{type(cycle).__name__} without {', '.join(missing)}; find it "
                         f"with nscontrol.analysis.orbits.find_cycle(plant, ...)")
    if section is not None:
        check_type("section", section, Section, hint="build it with Section(normal, offset, "
                                                     "direction) or pass None")


def corner_site(plant: NonlinearSystem, cycle: Any, *, b: ArrayLike,
                anchor: ArrayLike | None = None, axis: ArrayLike | None = None,
                section: Section | None = None, upstream: float = 0.25,
                samples: int = 720) -> CornerSite:
    """Place a corner on a plant's cycle: anchor, offset direction, upstream section, ``τ``.

    Parameters
    ----------
    plant : NonlinearSystem
        The planar plant.
    cycle : Cycle
        Its cycle (:func:`~nscontrol.analysis.orbits.find_cycle`): ``x0``, ``period`` and the
        non-trivial multiplier are used.
    b : (2,) array_like
        The input direction; the default anchor maximises ``|b × f|`` over the cycle.
    anchor : (2,) array_like, optional
        A point near the cycle; the anchor ``p_Γ`` is the cycle's crossing of the line through
        it along ``e``.
    axis : (2,) array_like, optional
        The offset direction ``e`` (turned to point out of the cycle); default: the cycle's
        outward normal at the anchor.
    section : Section, optional
        The upstream section (default: the line through the cycle's point ``upstream``
        periods before the anchor, normal to the flow there, offsets along the outward
        normal there).
    upstream : float
        Fraction of a period between the default section and the anchor.
    samples : int
        Samples of the cycle searched for the default anchor.

    Returns
    -------
    CornerSite

    Raises
    ------
    ModelError
        ``b`` or ``axis`` parallel to the flow at the anchor; ``plant`` not a planar
        :class:`NonlinearSystem`, ``cycle`` not a cycle, ``section`` not a :class:`Section`.
    SolverError
        The cycle does not cross a requested line.
    """
    from ..simulate import simulate

    _check_plant_and_cycle(plant, cycle, section)
    T = check_positive("period", cycle.period)
    lam = float(np.real(cycle.nontrivial[0]))
    bb = _vec("b", b)
    grid = np.linspace(0.0, T, check_integer("samples", samples, minimum=8) + 1)
    X = np.asarray(simulate(plant, cycle.x0, (0.0, T), t_eval=grid).x, float)
    area = 0.5 * float(np.sum(X[:-1, 0] * X[1:, 1] - X[1:, 0] * X[:-1, 1]))
    orient = 1 if area > 0 else -1
    if anchor is None:
        guess = X[int(np.argmax([abs(cross(bb, plant.rhs(0.0, x))) for x in X]))]
    else:
        guess = _vec("anchor", anchor)
    f = plant.rhs(0.0, guess)
    e = _outward(f, orient) if axis is None else _unit_vector("axis", axis)
    m = np.array([-e[1], e[0]])
    if cross(e, f) == 0.0:
        raise ModelError("axis: parallel to the flow at the anchor; offsets must be measured "
                         "across the cycle")
    m = m * np.sign(float(m @ f))          # the corner's line, crossed along the flow
    t_anchor, p = _first_crossing(plant, cycle.x0, m, float(m @ guess), 2.0 * T)
    f = plant.rhs(0.0, p)
    if axis is None:
        e = _outward(f, orient)
    elif float(e @ _outward(f, orient)) < 0.0:
        e = -e
    if abs(cross(bb, f)) <= 1e-8 * float(np.linalg.norm(bb) * np.linalg.norm(f)):
        raise ModelError("b: parallel to the flow at the anchor; choose an anchor where the "
                         "input crosses the cycle")
    if section is None:
        t_s = (t_anchor - check_positive("upstream", upstream) * T) % T
        ps = (simulate(plant, cycle.x0, (0.0, t_s), t_eval=np.array([0.0, t_s])).x[-1]
              if t_s > 0.0 else np.asarray(cycle.x0, float))
        fs = plant.rhs(0.0, ps)
        section = Section(fs / np.linalg.norm(fs), float(fs @ ps) / float(np.linalg.norm(fs)),
                          _outward(fs, orient))
    _, ps = _first_crossing(plant, p, section.normal, section.offset, 2.0 * T)
    tau = _transport(plant, ps, section.direction, p, e, T)
    return CornerSite(plant, np.asarray(p, float), e, f, lam, T, section, ps, tau, orient)


def _unit_vector(name: str, v: ArrayLike) -> FloatArray:
    w = _vec(name, v)
    if not np.any(w):
        raise ModelError(f"{name}: the zero vector has no direction")
    return w / np.linalg.norm(w)


def _outward(f: FloatArray, orient: int) -> FloatArray:
    """The unit normal to ``f`` pointing out of a cycle of orientation ``orient``."""
    return orient * np.array([f[1], -f[0]]) / float(np.linalg.norm(f))


def _transport(plant: NonlinearSystem, ps: FloatArray, d: FloatArray, p: FloatArray,
               e: FloatArray, T: float) -> float:
    """``τ``: an offset ``δ`` along ``d`` at ``ps`` arrives on the line through ``p`` along
    ``e`` at offset ``τδ`` (variational equation, then projection along the flow)."""
    from ..simulate import simulate

    m_c = np.array([-e[1], e[0]])
    m_c = m_c * np.sign(float(m_c @ plant.rhs(0.0, p)))   # Σ_c crossed along the flow
    t_c, _ = _first_crossing(plant, ps, m_c, float(m_c @ p), 2.0 * T)
    tr = simulate(plant, ps, (0.0, t_c), t_eval=np.array([0.0, t_c]), sensitivity=True)
    Phi = np.asarray(tr.stats["state_transition"], float)
    fc = plant.rhs(0.0, tr.x[-1])
    P = np.eye(2) - np.outer(fc, m_c) / float(m_c @ fc)
    return float(e @ (P @ Phi @ d))


_UNVERIFIED = ("predicted only: read .verified to shoot the controlled cycle "
               "(nscontrol.analysis.corner_maps.verify_corner_design)")

#: The sliding design's gain is this multiple of the entry face's sliding threshold (any
#: gain beyond it gives the same cycle; a margin keeps the design away from the threshold).
SLIDING_GAIN_FACTOR = 2.0


@dataclass(frozen=True, eq=False)
class CornerDesign:
    """A corner controller, its prediction and its verification.

    Attributes
    ----------
    system : WedgeSwitchedSystem
        The closed loop (plant, wedge, ``b``, ``k``).
    site : CornerSite
        Anchor, offset direction ``e``, section and transport factor ``τ``.
    k : float
        The gain.
    mu_c : float
        The corner's offset from the uncontrolled cycle.
    a : float
        The corner gain at the design (``−1`` for the sliding design's limit).
    return_map : PWLReturnMap
        The predicted return map on ``Σ_c``.
    predicted_offset : float
        ``z*`` on ``Σ_c`` (the sliding design: ``μ_c``).
    predicted_multiplier : float
        ``λ(1 + a)`` (the sliding design: ``0``).
    verified : ControlledCycle
        The shot cycle: found at the first read by
        :func:`nscontrol.analysis.corner_maps.verify_corner_design` (a shooting run, about a
        second), then kept. Reading it raises :class:`~nscontrol.errors.InfeasibleDesignError`
        when no controlled cycle is found near the prediction, or its multiplier is outside
        the unit circle.
    regime : {"crossing", "sliding"}
        Whether the motion crosses both faces or slides on the entry face.
    status : str
        A sentence on the verification ("predicted only" until :attr:`verified` is read).
    """

    system: WedgeSwitchedSystem
    site: CornerSite
    k: float
    mu_c: float
    a: float
    return_map: PWLReturnMap
    predicted_offset: float
    predicted_multiplier: float
    regime: Literal["crossing", "sliding"]
    #: the verification once made: {"cycle": ControlledCycle, "status": str}
    _checked: dict[str, Any] = field(default_factory=dict, init=False, repr=False,
                                     compare=False)

    @property
    def verified(self) -> Any:
        """The shot cycle (a ``ControlledCycle``), found at the first read and kept."""
        if "cycle" not in self._checked:
            from .._lazy import provided

            checked = provided("corner_verifier")(self)   # the analysis layer's shooting
            self._checked.update(checked._checked)
        return self._checked["cycle"]

    @property
    def status(self) -> str:
        """A sentence on the verification."""
        return str(self._checked.get("status", _UNVERIFIED))

    def with_verification(self, cycle: Any, status: str) -> CornerDesign:
        """A copy of this design with its verification made.

        Parameters
        ----------
        cycle : ControlledCycle
            The shot cycle.
        status : str
            A sentence on it.

        Returns
        -------
        CornerDesign
        """
        copy = replace(self)
        copy._checked.update(cycle=cycle, status=str(status))
        return copy

    @property
    def wedge(self) -> Wedge:
        """The wedge."""
        return self.system.wedge

    @property
    def predicted_section_offset(self) -> float:
        """``z*/τ``: the predicted offset on the upstream section."""
        return self.predicted_offset / self.site.tau


def _targets(lam: float, lam_d: float, z_d: float) -> tuple[float, float]:
    """``a = λ_d/λ − 1`` and ``μ_c = z_d(1 − λ_d)/(λ − λ_d)``."""
    if lam == lam_d:
        raise InfeasibleDesignError(f"target_multiplier: equals the cycle's own multiplier "
                                    f"{lam:.6g}; there is nothing to change (a = 0)")
    return lam_d / lam - 1.0, z_d * (1.0 - lam_d) / (lam - lam_d)


def _wedge_at(site: CornerSite, mu: float, half_angle: float) -> Wedge:
    c = site.corner(mu)
    return Wedge.symmetric(c, site.e, half_angle, flow=site.plant.rhs(0.0, c))


def design_corner_controller(plant: NonlinearSystem, cycle: Any, *, b: ArrayLike,
                             target_multiplier: float, target_offset: float,
                             anchor: ArrayLike | None = None, axis: ArrayLike | None = None,
                             section: Section | None = None, half_angle: float = np.pi / 4,
                             allow_sliding: bool = False) -> CornerDesign:
    """Design a corner controller that gives ``Γ``'s neighbour cycle a chosen multiplier and
    offset.

    Parameters
    ----------
    plant : NonlinearSystem
        The planar plant ``x' = f(x)``.
    cycle : Cycle
        Its cycle ``Γ`` (:func:`~nscontrol.analysis.orbits.find_cycle`).
    b : (2,) array_like
        The input direction.
    target_multiplier : float
        ``λ_d``, in ``(0, ∞)`` for the crossing design.
    target_offset : float
        ``z_d``: the controlled cycle's offset from ``Γ`` on the corner's line ``Σ_c``
        (along the outward normal ``e``; negative: inside ``Γ``).
    anchor : (2,) array_like, optional
        Where on ``Γ`` the corner goes (default: where ``|b × f|`` is largest).
    axis : (2,) array_like, optional
        The direction ``e`` the wedge opens along and offsets are measured along (default:
        the cycle's outward normal at the anchor).
    section : Section, optional
        The upstream Poincaré section used for verification and for offsets.
    half_angle : float
        The symmetric wedge's half-angle ``α`` in ``(0, π/2)``.
    allow_sliding : bool
        Meet a target ``λ_d <= 0`` by the sliding design (``λ_new = 0``) instead of refusing
        it: the controlled cycle is the plant's orbit of the corner, which returns to ``Σ_c``
        at ``λ μ_c``, so the corner goes at ``μ_c = z_d/λ`` for the cycle to cross ``Σ_c`` at
        ``z_d``.

    Returns
    -------
    CornerDesign

    Raises
    ------
    InfeasibleDesignError
        A target needing ``a <= −1`` without ``allow_sliding``; ``λ_d = λ``; a gain outside
        the crossing interval, or no controlled cycle on the crossing branch.
    ModelError
        Invalid arguments (``half_angle`` outside ``(0, π/2)``, ``b`` parallel to the flow at
        the anchor, ``target_offset`` zero, ``plant``, ``cycle`` or ``section`` of the wrong
        type, a non-bool ``allow_sliding``).

    Examples
    --------
    The sliding design needs no target multiplier but zero:

    >>> from nscontrol.analysis.orbits import find_cycle
    >>> from nscontrol.testing.cycle_problems import polar_normal_form
    >>> plant, _ = polar_normal_form((-0.08, 0.0, 0.1, 0.0, -0.02), omega=1.0)
    >>> cyc = find_cycle(plant, [1.0, 0.0], 2 * np.pi, normal=[0.0, 1.0])
    >>> d = design_corner_controller(plant, cyc, b=[1.0, 0.0], target_multiplier=-0.5,
    ...                              target_offset=0.01, anchor=[1.0, 0.0],
    ...                              allow_sliding=True)
    >>> d.regime, d.predicted_multiplier
    ('sliding', 0.0)
    """
    _check_plant_and_cycle(plant, cycle, section)
    allow_sliding = check_bool("allow_sliding", allow_sliding)
    lam_d = as_real_scalar("target_multiplier", target_multiplier)
    z_d = as_real_scalar("target_offset", target_offset)
    if not np.isfinite(lam_d) or not np.isfinite(z_d):
        raise ModelError("target_multiplier, target_offset: expected finite numbers")
    if z_d == 0.0:
        raise ModelError("target_offset: zero puts the corner on the cycle; give a small "
                         "non-zero offset (the design is first order in it)")
    alpha = check_in_interval("half_angle", half_angle, 0.0, np.pi / 2, open_interval=True)
    bb = as_vector("b", b, 2)
    site = corner_site(plant, cycle, b=bb, anchor=anchor, axis=axis, section=section)
    lam = site.lam
    if lam_d <= 0.0:
        if not allow_sliding:
            raise InfeasibleDesignError(
                f"target_multiplier: λ_d = {lam_d:.6g} needs a corner gain a = λ_d/λ − 1 = "
                f"{lam_d / lam - 1.0:.6g} <= −1, out of reach while the motion crosses both "
                f"faces (1 + a > 0); choose λ_d > 0, or pass allow_sliding=True for the "
                f"sliding design (λ_new = 0)")
        return _sliding_design(site, bb, z_d, alpha)
    a, mu = _targets(lam, lam_d, z_d)
    wedge = _wedge_at(site, mu, alpha)
    f1 = plant.rhs(0.0, wedge.corner)
    k = gain_for_corner_gain(a, f1, bb, wedge.n_in, wedge.n_out, site.e)
    lo, hi = crossing_gain_interval(f1, bb, wedge.n_in, wedge.n_out)
    if not lo < k < hi:
        raise InfeasibleDesignError(f"target_multiplier: the gain k = {k:.6g} it needs is "
                                    f"outside the crossing interval ({lo:.6g}, {hi:.6g}) of "
                                    f"this wedge; choose λ_d closer to λ = {lam:.6g}")
    system = WedgeSwitchedSystem(plant, wedge, bb, k)
    a_check = corner_gain(f1, f1 + k * bb, wedge.n_in, wedge.n_out, site.e)
    pwl = PWLReturnMap(lam, a_check, mu)
    right = [p for p in pwl.fixed_points() if p.branch == "right"]
    if not right:
        raise InfeasibleDesignError(f"target_offset: no controlled cycle crosses the wedge "
                                    f"(z* <= μ_c = {mu:.6g}); change the sign of "
                                    f"target_offset")
    z_star, lam_new = right[0].z, pwl.right_slope
    return CornerDesign(system, site, float(k), float(mu), float(a_check), pwl, float(z_star),
                        float(lam_new), "crossing")


def _sliding_design(site: CornerSite, b: FloatArray, z_d: float, alpha: float
                    ) -> CornerDesign:
    """The sliding design: every orbit meeting the wedge leaves it at the corner, so the
    controlled cycle is the plant's orbit of the corner and arrives on ``Σ_c`` at ``λμ_c``;
    ``μ_c = z_d/λ`` puts it at ``z_d``. The gain is :data:`SLIDING_GAIN_FACTOR` times the
    entry face's sliding threshold ``n_inᵀ(F1 + kb) = 0``."""
    lam = site.lam
    mu = z_d / lam
    if not z_d > mu:
        raise InfeasibleDesignError(f"target_offset: the corner's orbit returns at z_d = "
                                    f"{z_d:.6g}, which must lie beyond the corner (μ_c = "
                                    f"{mu:.6g}) to meet the wedge again; change its sign")
    wedge = _wedge_at(site, mu, alpha)
    f1 = site.plant.rhs(0.0, wedge.corner)
    w = float(wedge.n_in @ b)
    if w == 0.0:
        raise InfeasibleDesignError("b: parallel to the entry face, so no gain makes the motion "
                                    "slide on it; choose another input direction")
    k = SLIDING_GAIN_FACTOR * (-float(wedge.n_in @ f1) / w)
    system = WedgeSwitchedSystem(site.plant, wedge, b, k)
    if system.face_status(wedge.corner, "in") != "attracting_sliding":
        raise InfeasibleDesignError("b: with this input direction the entry face does not "
                                    "become attracting; no sliding design")
    pwl = PWLReturnMap(lam, -1.0, mu)
    return CornerDesign(system, site, float(k), float(mu), -1.0, pwl, float(z_d), 0.0,
                        "sliding")

"""A smooth planar flow with a constant input switched on inside a wedge (a corner controller).

The plant ``x' = f(x)`` (a :class:`~nscontrol.systems.nonlinear.NonlinearSystem`, planar and
autonomous) receives the input ``u = k·b`` only inside the wedge

    ``D = {x : h_in(x) >= 0 and h_out(x) >= 0}``,  ``h_i(x) = n_iᵀ(x - c)``,

with vertex (corner) ``c`` and inward unit normals ``n_in``, ``n_out``:

    ``x' = F1(x) = f(x)`` outside ``D``,   ``x' = F2(x) = f(x) + k·b`` inside.

:class:`WedgeSwitchedSystem` *is* a :class:`~nscontrol.systems.switched.FilippovSystem` with
the two face lines as its switching surfaces (surface 0 the entry face ``H_in``, surface 1
the exit face ``H_out``), so ``simulate(..., method="switching")`` integrates it with every
face crossing located on its own smooth event function, attracting sliding on a face by
Filippov's convex combination and the saltation matrices of crossings and sliding
entry/exit. A face line crossed away from the wedge (where ``F1`` holds on both sides) is a
crossing with the identity saltation matrix; sliding on ``H_in`` that reaches the corner
ends by a crossing of the exit line (``F_s`` to ``F1``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_real_scalar, as_vector, check_in_interval
from ..errors import DimensionError, ModelError
from .switched import FilippovSystem

if TYPE_CHECKING:
    from .nonlinear import NonlinearSystem

__all__ = ["Wedge", "WedgeSwitchedSystem", "with_marker_line", "marker_crossings", "cross"]

#: Smallest ``|sin|`` of the angle between the faces (parallel faces make no corner).
_MIN_SINE = 1e-6

FaceStatus = Literal["crossing", "attracting_sliding", "repelling_sliding", "grazing"]


def _unit(name: str, v: ArrayLike) -> FloatArray:
    w = as_vector(name, v, 2)
    norm = float(np.linalg.norm(w))
    if norm == 0.0:
        raise ModelError(f"{name}: the zero vector has no direction; give a non-zero "
                         f"2-vector")
    return w / norm


def cross(u: ArrayLike, v: ArrayLike) -> float:
    """The planar cross product ``u × v = u₁v₂ − u₂v₁``.

    Parameters
    ----------
    u, v : (2,) array_like
        Planar vectors.
    """
    a, b = np.asarray(u, float), np.asarray(v, float)
    return float(a[0] * b[1] - a[1] * b[0])


@dataclass(frozen=True)
class Wedge:
    """The wedge ``D = {h_in >= 0, h_out >= 0}`` with ``h_i(x) = n_iᵀ(x - corner)``.

    Parameters
    ----------
    corner : (2,) array_like
        The vertex ``c``.
    n_in : (2,) array_like
        Inward normal of the entry face ``H_in`` (normalised here).
    n_out : (2,) array_like
        Inward normal of the exit face ``H_out`` (normalised here).

    Raises
    ------
    DimensionError
        A vector that is not a 2-vector.
    ModelError
        A zero or non-finite vector, or parallel faces (no corner).

    Examples
    --------
    >>> w = Wedge.symmetric([1.0, 0.0], axis=[1.0, 0.0], half_angle=np.pi / 4, flow=[0.0, 1.0])
    >>> w.n_in.round(4).tolist(), w.contains([1.5, 0.2]), w.contains([0.9, 0.0])
    ([0.7071, 0.7071], True, False)
    """

    corner: FloatArray
    n_in: FloatArray
    n_out: FloatArray

    if TYPE_CHECKING:
        def __init__(self, corner: ArrayLike, n_in: ArrayLike, n_out: ArrayLike) -> None: ...

    def __post_init__(self) -> None:
        object.__setattr__(self, "corner", as_vector("corner", self.corner, 2))
        object.__setattr__(self, "n_in", _unit("n_in", self.n_in))
        object.__setattr__(self, "n_out", _unit("n_out", self.n_out))
        if abs(cross(self.n_in, self.n_out)) < _MIN_SINE:
            raise ModelError(f"n_in, n_out: the faces are parallel (normals "
                             f"{self.n_in.round(6).tolist()}, {self.n_out.round(6).tolist()}); "
                             f"a wedge needs two faces meeting at an angle")

    @classmethod
    def symmetric(cls, corner: ArrayLike, axis: ArrayLike, half_angle: float,
                  flow: ArrayLike) -> Wedge:
        """The wedge of half-angle ``α`` opening along ``axis`` from ``corner``.

        Parameters
        ----------
        corner : (2,) array_like
            The vertex.
        axis : (2,) array_like
            The direction ``e`` the wedge opens along (normalised here).
        half_angle : float
            ``α`` in ``(0, π/2)``.
        flow : (2,) array_like
            The plant's field at the corner: it fixes which face is the entry face (the one
            the flow meets first), ``n_in = sinα·e + d·cosα·e⊥`` and
            ``n_out = sinα·e − d·cosα·e⊥`` with ``e⊥`` the axis turned by +90° and ``d`` the
            sign of ``flow·e⊥``.

        Returns
        -------
        Wedge

        Raises
        ------
        ModelError
            ``half_angle`` outside ``(0, π/2)``, or ``flow`` along the axis (no entry side).
        """
        e = _unit("axis", axis)
        alpha = check_in_interval("half_angle", half_angle, 0.0, np.pi / 2, open_interval=True)
        e_perp = np.array([-e[1], e[0]])
        along = float(as_vector("flow", flow, 2) @ e_perp)
        if along == 0.0:
            raise ModelError("flow: the plant's field at the corner is parallel to the axis, so "
                             "no face is met first; open the wedge across the flow")
        d = 1.0 if along > 0.0 else -1.0
        s, c = np.sin(alpha), np.cos(alpha)
        return cls(corner, s * e + d * c * e_perp, s * e - d * c * e_perp)

    def h_in(self, x: ArrayLike) -> float:
        """``n_inᵀ(x − c)``: positive on the wedge's side of the entry face.

        Parameters
        ----------
        x : (2,) array_like
            State.
        """
        return float(self.n_in @ (np.asarray(x, float) - self.corner))

    def h_out(self, x: ArrayLike) -> float:
        """``n_outᵀ(x − c)``: positive on the wedge's side of the exit face.

        Parameters
        ----------
        x : (2,) array_like
            State.
        """
        return float(self.n_out @ (np.asarray(x, float) - self.corner))

    def contains(self, x: ArrayLike) -> bool:
        """Whether ``x`` lies in the closed wedge.

        Parameters
        ----------
        x : (2,) array_like
            State.
        """
        return self.h_in(x) >= 0.0 and self.h_out(x) >= 0.0

    def moved_to(self, corner: ArrayLike) -> Wedge:
        """The same wedge with its vertex at ``corner``.

        Parameters
        ----------
        corner : (2,) array_like
            The new vertex.
        """
        return Wedge(corner, self.n_in, self.n_out)


class _Face:
    """``h(x) = nᵀ(x - c)`` (picklable)."""

    def __init__(self, normal: FloatArray, corner: FloatArray) -> None:
        self.normal, self.corner = normal, corner

    def __call__(self, x: FloatArray) -> float:
        return float(self.normal @ (np.asarray(x, float)[:2] - self.corner))


class _Gradient:
    """The constant gradient ``n`` of a face (picklable)."""

    def __init__(self, normal: FloatArray) -> None:
        self.normal = normal

    def __call__(self, x: FloatArray) -> FloatArray:
        return self.normal


class _WedgeField:
    """``f(x) + k·b`` where both face signs are positive, ``f(x)`` elsewhere (picklable)."""

    def __init__(self, plant: Any, input_vector: FloatArray) -> None:
        self.plant, self.input_vector = plant, input_vector

    def __call__(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        f = self.plant.rhs(t, x)
        return f + self.input_vector if signs[0] > 0 and signs[1] > 0 else f

    def jacobian(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return self.plant.jac(t, x)     # the input is constant: one Jacobian on both sides


@dataclass(frozen=True, eq=False, init=False)
class WedgeSwitchedSystem(FilippovSystem):
    """A planar plant with the input ``k·b`` switched on inside a :class:`Wedge`.

    A :class:`~nscontrol.systems.switched.FilippovSystem` whose surfaces are the entry face
    (index 0) and the exit face (index 1); integrate it with ``simulate(system, x0, t_span)``
    (method ``"switching"``).

    Parameters
    ----------
    plant : NonlinearSystem
        The smooth planar autonomous flow ``x' = f(x)`` (two states, no input).
    wedge : Wedge
        Where the input acts.
    b : (2,) array_like
        The input direction (not normalised).
    k : float
        The gain.

    Attributes
    ----------
    plant : NonlinearSystem
        The plant.
    wedge : Wedge
        The wedge.
    b : ndarray, shape (2,)
        The input direction.
    k : float
        The gain.

    Raises
    ------
    ModelError
        ``plant`` not a NonlinearSystem without inputs, ``wedge`` not a Wedge, ``b`` zero or
        non-finite, ``k`` not a finite real number.
    DimensionError
        A plant that is not planar, or ``b`` not a 2-vector.

    Examples
    --------
    >>> from nscontrol.testing.cycle_problems import polar_normal_form
    >>> plant, _ = polar_normal_form((-0.08, 0.0, 0.1, 0.0, -0.02), omega=1.0)
    >>> w = Wedge.symmetric([1.01, 0.0], [1.0, 0.0], np.pi / 4, flow=[0.0, 1.0])
    >>> sys = WedgeSwitchedSystem(plant, w, b=[1.0, 0.0], k=-3.0)
    >>> sys.face_status(w.corner, "in")
    'attracting_sliding'
    """

    plant: Any = None
    wedge: Any = None
    b: Any = None
    k: float = 0.0

    def __init__(self, plant: NonlinearSystem, wedge: Wedge, b: ArrayLike, k: float) -> None:
        from .nonlinear import NonlinearSystem

        if not isinstance(plant, NonlinearSystem) or plant.n_inputs != 0:
            raise ModelError(f"plant: expected a NonlinearSystem without inputs (x' = f(x)), "
                             f"got {type(plant).__name__}")
        if plant.n_states != 2:
            raise DimensionError(f"plant: the corner controller is planar; got a plant with "
                                 f"{plant.n_states} states")
        if not isinstance(wedge, Wedge):
            raise ModelError(f"wedge: expected a Wedge (Wedge.symmetric(...)), got "
                             f"{type(wedge).__name__}")
        bb = as_vector("b", b, 2)
        if not np.any(bb):
            raise ModelError("b: the input direction is zero, so the controller does "
                             "nothing; give a non-zero 2-vector")
        kk = as_real_scalar("k", k)
        if not np.isfinite(kk):
            raise ModelError(f"k: expected a finite gain, got {kk}")
        field = _WedgeField(plant, kk * bb)
        values = {"n_states": 2, "surfaces": (_Face(wedge.n_in, wedge.corner),
                                              _Face(wedge.n_out, wedge.corner)),
                  "field": field, "gradients": (_Gradient(wedge.n_in), _Gradient(wedge.n_out)),
                  "jacobian": field.jacobian, "state_names": plant.state_names,
                  "plant": plant, "wedge": wedge, "b": bb, "k": kk}
        for key, value in values.items():
            object.__setattr__(self, key, value)
        self.__post_init__()

    def with_gain(self, k: float) -> WedgeSwitchedSystem:
        """The same plant, wedge and direction with the gain ``k``.

        Parameters
        ----------
        k : float
            The new gain.
        """
        return WedgeSwitchedSystem(self.plant, self.wedge, self.b, k)

    def with_wedge(self, wedge: Wedge) -> WedgeSwitchedSystem:
        """The same plant, direction and gain with another wedge.

        Parameters
        ----------
        wedge : Wedge
            The new wedge.
        """
        return WedgeSwitchedSystem(self.plant, wedge, self.b, self.k)

    def mode_field(self, x: ArrayLike, mode: Literal["out", "in", "slide_in", "slide_out"]
                   ) -> FloatArray:
        """The field of one mode at ``x``.

        Parameters
        ----------
        x : (2,) array_like
            State.
        mode : {"out", "in", "slide_in", "slide_out"}
            ``F1`` (outside), ``F2`` (inside), or Filippov's sliding field on the entry or
            exit face, ``F_s = (σ2·F1 − σ1·F2)/(σ2 − σ1)`` with ``σi = nᵀFi``.

        Raises
        ------
        ModelError
            An unknown mode, or a sliding mode where ``σ1 = σ2`` (no sliding field).
        """
        xx = as_vector("x", x, 2)
        f1 = self.plant.rhs(0.0, xx)
        f2 = f1 + self.k * self.b
        if mode == "out":
            return f1
        if mode == "in":
            return f2
        if mode not in ("slide_in", "slide_out"):
            raise ModelError(f"mode: expected 'out', 'in', 'slide_in' or 'slide_out', got "
                             f"{mode!r}")
        n = self.wedge.n_in if mode == "slide_in" else self.wedge.n_out
        s1, s2 = float(n @ f1), float(n @ f2)
        if s1 == s2:
            raise ModelError(f"mode: no sliding field on the {mode[6:]} face at "
                             f"{xx.tolist()}: the input is parallel to the face (σ1 = σ2)")
        return (s2 * f1 - s1 * f2) / (s2 - s1)

    def face_status(self, x: ArrayLike, face: Literal["in", "out"]) -> FaceStatus:
        """How the motion meets a face at ``x`` (Filippov's conventions).

        Parameters
        ----------
        x : (2,) array_like
            A point of the face.
        face : {"in", "out"}
            The entry or the exit face.

        Returns
        -------
        str
            ``"crossing"`` (``σ1σ2 > 0``), ``"attracting_sliding"`` (``σ1 > 0 > σ2``),
            ``"repelling_sliding"`` (``σ1 < 0 < σ2``) or ``"grazing"`` (a ``σ`` is zero), with
            ``σi = nᵀFi`` and ``n`` the face's inward normal.

        Raises
        ------
        ModelError
            An unknown face.
        """
        if face not in ("in", "out"):
            raise ModelError(f"face: expected 'in' or 'out', got {face!r}")
        n = self.wedge.n_in if face == "in" else self.wedge.n_out
        s1 = float(n @ self.mode_field(x, "out"))
        s2 = float(n @ self.mode_field(x, "in"))
        if s1 * s2 > 0.0:
            return "crossing"
        if s1 > 0.0 > s2:
            return "attracting_sliding"
        if s1 < 0.0 < s2:
            return "repelling_sliding"
        return "grazing"

    def crossing_margins(self) -> dict[str, float]:
        """The four normal speeds at the corner whose signs decide crossing-only operation.

        Returns
        -------
        dict
            ``in_F1 = n_inᵀF1``, ``in_F2 = n_inᵀF2`` (both ``> 0`` to cross the entry face)
            and ``out_F1 = n_outᵀF1``, ``out_F2 = n_outᵀF2`` (both ``< 0`` to cross the exit
            face), at the corner.
        """
        c = self.wedge.corner
        f1, f2 = self.mode_field(c, "out"), self.mode_field(c, "in")
        w = self.wedge
        return {"in_F1": float(w.n_in @ f1), "in_F2": float(w.n_in @ f2),
                "out_F1": float(w.n_out @ f1), "out_F2": float(w.n_out @ f2)}

    def crosses_only(self) -> bool:
        """Whether the crossing condition holds at the corner (no sliding on either face)."""
        m = self.crossing_margins()
        return m["in_F1"] > 0 and m["in_F2"] > 0 and m["out_F1"] < 0 and m["out_F2"] < 0


class _MarkedField:
    """The field of a system with one more surface that changes nothing (a section)."""

    def __init__(self, base: Any, n_base: int) -> None:
        self.base, self.n_base = base, n_base

    def __call__(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return np.asarray(self.base.field(t, x, signs[:self.n_base]), float)

    def jacobian(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return np.asarray(self.base.jac(t, x, signs[:self.n_base]), float)


class _SmoothAsFilippov:
    """A :class:`NonlinearSystem` seen through the Filippov interface (no surface)."""

    def __init__(self, plant: Any) -> None:
        self.plant = plant

    def field(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return np.asarray(self.plant.rhs(t, x), float)

    def jac(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return np.asarray(self.plant.jac(t, x), float)


class _Line:
    """``h(x) = normalᵀx − offset`` (picklable)."""

    def __init__(self, normal: FloatArray, offset: float) -> None:
        self.normal, self.offset = normal, offset

    def __call__(self, x: FloatArray) -> float:
        return float(self.normal @ np.asarray(x, float)[:2]) - self.offset


class _GradientOf:
    """Surface ``j``'s gradient of a Filippov system (picklable)."""

    def __init__(self, system: FilippovSystem, j: int) -> None:
        self.system, self.j = system, j

    def __call__(self, x: FloatArray) -> FloatArray:
        return self.system.gradient(self.j, x)


def with_marker_line(system: Any, normal: ArrayLike, offset: float
                     ) -> tuple[FilippovSystem, int]:
    """A planar system with the line ``normalᵀx = offset`` as one more switching surface that
    changes no field: a Poincaré section whose crossings the integrator locates as events.

    The marker's crossings are ``"crossing"`` events with the identity saltation matrix, found
    by the same event search as the switchings, so section points are as accurate as the
    integration itself; :func:`marker_crossings` reads them back.

    Parameters
    ----------
    system : FilippovSystem or NonlinearSystem
        A planar system (e.g. a :class:`WedgeSwitchedSystem` or its plant).
    normal : (2,) array_like
        The line's normal; crossings with ``normalᵀẋ > 0`` are the returns.
    offset : float
        ``normalᵀx`` on the line.

    Returns
    -------
    (FilippovSystem, int)
        The marked system and the marker's surface index.

    Raises
    ------
    ModelError
        Another kind of system, or a zero normal.
    DimensionError
        A system that is not planar.
    """
    from .nonlinear import NonlinearSystem

    nv = as_vector("normal", normal, 2)
    if not np.any(nv):
        raise ModelError("normal: the zero vector defines no line; give a non-zero 2-vector")
    off = as_real_scalar("offset", offset)
    base: Any
    if isinstance(system, FilippovSystem):
        base, surfaces = system, tuple(system.surfaces)
        grads = tuple(_GradientOf(system, j) for j in range(len(surfaces)))
    elif isinstance(system, NonlinearSystem) and system.n_inputs == 0:
        base, surfaces, grads = _SmoothAsFilippov(system), (), ()
    else:
        raise ModelError(f"system: expected a FilippovSystem (e.g. a WedgeSwitchedSystem) or "
                         f"a NonlinearSystem without inputs, got {type(system).__name__}")
    if system.n_states != 2:
        raise DimensionError(f"system: a marker line needs a planar system, got "
                             f"{system.n_states} states")
    field = _MarkedField(base, len(surfaces))
    marked = FilippovSystem(2, surfaces + (_Line(nv, off),), field,
                            gradients=grads + (_Gradient(nv),), jacobian=field.jacobian,
                            state_names=system.state_names)
    return marked, len(surfaces)


def marker_crossings(trajectory: Any, index: int) -> list[Any]:
    """The events of a run of a marked system (:func:`with_marker_line`) where the marker
    line was crossed in its normal's direction, after ``t = 0``.

    Parameters
    ----------
    trajectory : Trajectory
        The run.
    index : int
        The marker's surface index.

    Returns
    -------
    list of Event
        In time order; ``event.post`` is the section point.
    """
    bit = 1 << int(index)
    return [ev for ev in trajectory.events
            if ev.index == index and ev.kind == "crossing" and ev.time > 0.0
            and ev.mode_to & bit and not ev.mode_from & bit]

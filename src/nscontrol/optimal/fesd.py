r"""Optimal control of a system that switches between two affine vector fields across a
hyperplane, with finite elements and switch detection (FESD) so that the switching times
are unknowns of the problem and come out exact, rather than rounded to a grid.

The model (Filippov's convention on the surface, written in Stewart's form)::

    x' = θ₁ f₁(x, u) + θ₂ f₂(x, u),     f_i = A_i x + b_i + B u,
    g(x) = (ψ(x), -ψ(x)) = λ + μ 1,     0 <= θ ⟂ λ >= 0,     θ₁ + θ₂ = 1,

``ψ(x) = cᵀ x + d`` (mode 1 where ``ψ < 0``): ``λ_i = g_i - min g`` is zero exactly on the
modes that are active, and ``θ`` selects among them.

**Transcription.** This is one case of the general FESD transcription of :mod:`.stewart`
(:meth:`SwitchingProblem.engine`; one source, no second transcription): ``N`` finite
elements, each with its own input and its own length ``h_n``; implicit Euler on each
element, the algebraic variables ``θ_n, λ_n, μ_n`` at the element's end. With
``switch_detection=True`` the lengths are unknowns (``Σ h_n = T``, each in
``[h̄/10, 10 h̄]`` by default) and the *cross complementarity* ``θ_{n,i} λ_{n-1,i} = 0``
forbids a mode active at the end of element ``n - 1`` (``λ = 0``) to be left inside element
``n``: a switch can only happen at an element boundary, which the solver moves onto the
switching instant. With ``switch_detection=False`` the grid is fixed (``h_n = T / N``), the
switch falls inside an element and its time is only known to ``O(h)``.

Implicit Euler is exact on an element where the field is constant (``A_i = 0``), so there
FESD's plan is the continuous one up to the solver's tolerance.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_matrix,
    as_real_scalar,
    as_vector,
    check_bool,
    check_integer,
    check_positive,
)
from ..errors import DimensionError, ModelError
from ._casadi import require_casadi
from .contact import Relaxation, _bound, _vector_with_nan
from .stewart import FesdProblem, StewartSystem, _check_equilibration, _sign_changes

__all__ = ["SwitchingProblem", "SwitchingPlan"]


@dataclass(frozen=True)
class SwitchingPlan:
    """A planned motion of a :class:`SwitchingProblem` on its finite elements.

    Attributes
    ----------
    t : ndarray, shape (N + 1,)
        Element boundaries.
    x : ndarray, shape (N + 1, n)
        States at the boundaries.
    u : ndarray, shape (N, p)
        Input of each element.
    theta : ndarray, shape (N, 2)
        The modes' weights on each element (``(1, 0)``: mode 1).
    cost : float
        ``Σ h_n |u_n|²``.
    residual : float
        Largest ``|min(a, b)|`` over the complementarity pairs (cross ones included).
    stats : dict
        ``stages``, ``solve_time``, ``iterations``, ``polished``, ``switch_detection``.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    theta: FloatArray
    cost: float
    residual: float
    stats: dict[str, Any] = field(default_factory=dict)

    def switch_times(self, c: ArrayLike, d: float) -> FloatArray:
        """Where ``ψ = cᵀx + d`` changes sign along the plan (linear between boundaries,
        exact for constant fields).

        Parameters
        ----------
        c : array_like (n,)
            The switching function's gradient.
        d : float
            Its offset.

        Returns
        -------
        ndarray
        """
        return _sign_changes(self.t, self.x @ np.asarray(c, float) + float(d))


@dataclass(frozen=True, eq=False)
class SwitchingProblem:
    """Least effort ``∫ |u|² dt`` from ``x0`` to ``x_final`` in time ``T`` for the two-mode
    system of the module docstring.

    Parameters
    ----------
    A : pair of array_like (n, n)
        ``A₁`` (where ``ψ < 0``) and ``A₂``.
    b : pair of array_like (n,)
        ``b₁`` and ``b₂``.
    B : array_like (n, p)
        Input matrix (both modes).
    c : array_like (n,)
        Gradient of ``ψ``.
    d : float
        Offset of ``ψ``.
    x0, x_final : array_like (n,)
        End states (``x_final`` NaN components free).
    T : float
        Horizon.
    elements : int
        Number of finite elements ``N``.
    switch_detection : bool
        FESD (free element lengths, cross complementarity), or a fixed grid.
    u_min, u_max : array_like (p,), optional
        Input bounds (a scalar applies to every input).
    element_bounds : (float, float)
        With switch detection, each element's length within these multiples of ``T / N``
        (``0 < low < 1 < high``).
    equilibration : float
        Step equilibration weight ``ρ >= 0`` (:class:`~.stewart.FesdProblem`'s): with
        ``equilibration_form="mean"`` the objective gains ``ρ Σ_k (h_k - T/N)²``.
    equilibration_form : {"mean", "delta"}
        As :class:`~.stewart.FesdProblem`'s; ``"delta"`` penalises the differences of
        the lengths *within* a stage, so with this problem's one element per input it adds
        nothing (as nosnoc's ``HEURISTIC_DELTA`` with one finite element per stage).
    warm_homotopy : bool
        As :class:`~.stewart.FesdProblem`'s (``False``: each relaxed solve cold from the
        previous primal solution).

    Raises
    ------
    DimensionError
        Shapes that disagree.
    ModelError
        A bad value.
    """

    A: Any
    b: Any
    B: Any
    c: Any
    d: float
    x0: Any
    x_final: Any
    T: float
    elements: int
    switch_detection: bool = True
    u_min: Any = None
    u_max: Any = None
    element_bounds: tuple[float, float] = (0.1, 10.0)
    equilibration: float = 0.0
    equilibration_form: str = "mean"
    warm_homotopy: bool = True
    n: int = field(init=False)
    _engine: list[FesdProblem] = field(init=False, repr=False, default_factory=list)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        x0 = as_vector("x0", self.x0)
        n = x0.shape[0]
        set_(self, "n", n)
        set_(self, "x0", x0)
        if len(self.A) != 2 or len(self.b) != 2:
            raise DimensionError("A, b: expected one matrix and one vector per mode (two)")
        set_(self, "A", tuple(as_matrix("A", a, rows=n, cols=n) for a in self.A))
        set_(self, "b", tuple(as_vector("b", v, n) for v in self.b))
        set_(self, "B", as_matrix("B", self.B, rows=n))
        set_(self, "c", as_vector("c", self.c, n))
        set_(self, "d", as_real_scalar("d", self.d))
        set_(self, "x_final", _vector_with_nan("x_final", self.x_final, n))
        set_(self, "T", check_positive("T", self.T))
        set_(self, "elements", check_integer("elements", self.elements, minimum=2))
        set_(self, "switch_detection", check_bool("switch_detection", self.switch_detection))
        for name in ("u_min", "u_max"):
            set_(self, name, _bound(name, getattr(self, name), self.B.shape[1]))
        lo, hi = (check_positive("element_bounds", v) for v in self.element_bounds)
        if not lo < 1.0 < hi:
            raise ModelError(f"element_bounds: ({lo:g}, {hi:g}) must hold the uniform length "
                             "strictly inside (low < 1 < high)")
        set_(self, "element_bounds", (lo, hi))
        set_(self, "equilibration", _check_equilibration(self.equilibration,
                                                        self.equilibration_form))
        set_(self, "warm_homotopy", check_bool("warm_homotopy", self.warm_homotopy))

    def engine(self) -> FesdProblem:
        """The general FESD problem this one is (:mod:`.stewart`): one layer of two affine
        fields split by ``ψ`` (``signs = ((-1,), (1,))``: field 1 where ``ψ < 0``), one
        element per input, the lengths free summing to ``T``. Built once: the same
        object every call, so that its transcription, built by its first solve, serves the
        next ones.

        Returns
        -------
        FesdProblem
        """
        if not self._engine:
            self._engine.append(self._build_engine())
        return self._engine[0]

    def _build_engine(self) -> FesdProblem:
        ca = require_casadi()
        B = ca.DM(self.B)

        def affine(i: int) -> Callable[[Any, Any], Any]:
            A, b = ca.DM(self.A[i]), ca.DM(self.b[i])
            return lambda x, u: ca.mtimes(A, x) + b + ca.mtimes(B, u)

        c, d = ca.DM(self.c[None, :]), self.d
        layer = StewartSystem(fields=(affine(0), affine(1)),
                              switching=lambda x: ca.mtimes(c, x) + d, signs=((-1.0,), (1.0,)))
        return FesdProblem(layer, self.x0, self.T, self.elements, elements=1,
                           inputs=self.B.shape[1], x_final=self.x_final, u_min=self.u_min,
                           u_max=self.u_max, switch_detection=self.switch_detection,
                           equidistant_control_grid=False, element_bounds=self.element_bounds,
                           equilibration=self.equilibration,
                           equilibration_form=self.equilibration_form,
                           warm_homotopy=self.warm_homotopy)

    def solve(self, relaxation: Relaxation | None = None, *,
              guess: ArrayLike | None = None) -> SwitchingPlan:
        """Solve the Scholtes homotopy (and its polish) of the transcription.

        Parameters
        ----------
        relaxation : Relaxation, optional
            The homotopy (default :class:`Relaxation()`).
        guess : array_like (N + 1, n), optional
            States on the uniform grid to start from (e.g. ``x0`` repeated: at rest);
            default the straight line from ``x0`` to ``x_final``. The modes, inputs and
            multipliers of the start are made consistent with them.

        Returns
        -------
        SwitchingPlan

        Raises
        ------
        SolverError
            IPOPT failed on a relaxed problem.
        """
        plan = self.engine().solve(relaxation, guess=guess)
        return SwitchingPlan(t=plan.t, x=plan.x, u=plan.u, theta=plan.theta, cost=plan.cost,
                             residual=plan.residual, stats=plan.stats)

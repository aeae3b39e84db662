r"""Optimal control of a system that switches between two affine vector fields across a
hyperplane, with finite elements and switch detection (FESD) so that the switching times
are unknowns of the problem and come out exact, rather than rounded to a grid.

The model (Filippov's convention on the surface, written in Stewart's form)::

    x' = θ₁ f₁(x, u) + θ₂ f₂(x, u),     f_i = A_i x + b_i + B u,
    g(x) = (ψ(x), -ψ(x)) = λ + μ 1,     0 <= θ ⟂ λ >= 0,     θ₁ + θ₂ = 1,

``ψ(x) = cᵀ x + d`` (mode 1 where ``ψ < 0``): ``λ_i = g_i - min g`` is zero exactly on the
modes that are active, and ``θ`` selects among them.

**Transcription.** The horizon ``T`` is cut into ``N`` finite elements, each with its own
input ``u_n`` and its own length ``h_n``; implicit Euler on each element, the algebraic
variables ``θ_n, λ_n, μ_n`` at the element's end. With ``switch_detection=True`` the
lengths are unknowns (``Σ h_n = T``, each in ``[h̄/10, 10 h̄]`` by default) and the *cross
complementarity* ``θ_{n,i} λ_{n-1,i} = 0`` forbids a mode active at the end of element
``n - 1`` (``λ = 0``) to be left inside element ``n``: a switch can only happen at an
element boundary, which the solver moves onto the switching instant. With
``switch_detection=False`` the grid is fixed (``h_n = T / N``), the switch falls inside an
element and its time is only known to ``O(h)``.

Implicit Euler is exact on an element where the field is constant (``A_i = 0``), so there
FESD's plan is the continuous one up to the solver's tolerance.
"""

from __future__ import annotations

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
    check_type,
)
from ..errors import DimensionError, ModelError
from .contact import Relaxation, _bound, _vector_with_nan
from .homotopy import residual, solve_homotopy, stage_stats

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
        psi = self.x @ np.asarray(c, float) + float(d)
        k = np.flatnonzero(np.sign(psi[:-1]) * np.sign(psi[1:]) < 0)
        out = self.t[k] + (self.t[k + 1] - self.t[k]) * psi[k] / (psi[k] - psi[k + 1])
        zero = np.flatnonzero((psi == 0.0)[1:-1]) + 1
        return np.sort(np.concatenate([out, self.t[zero]]))


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
    n: int = field(init=False)

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
        relaxation = Relaxation() if relaxation is None else check_type(
            "relaxation", relaxation, Relaxation)
        nlp = _SwitchingNLP(self)
        states = None if guess is None else as_matrix("guess", guess, rows=self.elements + 1,
                                                      cols=self.n).T
        stages: list[dict[str, Any]] = []
        sol, polished = solve_homotopy(nlp, nlp.guess(states), relaxation, stages)
        H = np.atleast_1d(sol["H"])
        return SwitchingPlan(t=np.concatenate([[0.0], np.cumsum(H)]), x=sol["X"].T.copy(),
                             u=sol["U"].T.copy(), theta=sol["TH"].T.copy(),
                             cost=float(sol["cost"]), residual=residual(nlp, sol),
                             stats={**stage_stats(stages, polished),
                                    "switch_detection": self.switch_detection})


class _SwitchingNLP:
    """The NLP of a :class:`SwitchingProblem` (a
    :class:`~nscontrol.optimal.homotopy.Builder`)."""

    def __init__(self, problem: SwitchingProblem) -> None:
        self.p = problem
        g0 = np.array([1.0, -1.0]) * (problem.c @ problem.x0 + problem.d)
        self.lam_start = g0 - g0.min()     # λ at x0: zero on the modes active there

    def guess(self, X: FloatArray | None = None) -> dict[str, Any]:
        """The states ``X`` (``(n, N + 1)``; default the straight line from ``x0`` to
        ``x_final``) on a uniform grid, with everything else consistent with them: the
        modes of its end points (``θ``, ``λ``, ``μ``) and the inputs that make each
        element's step (least squares, clipped to the bounds). A guess whose algebraic
        variables contradict its states starts the homotopy in a poor local optimum."""
        p, N = self.p, self.p.elements
        h = p.T / N
        if X is None:
            xf = np.where(np.isnan(p.x_final), p.x0, p.x_final)
            X = p.x0[:, None] + (xf - p.x0)[:, None] * np.linspace(0, 1, N + 1)[None, :]
        psi = p.c @ X[:, 1:] + p.d
        mode = (psi > 0).astype(int)
        g = np.vstack([psi, -psi])
        U = np.empty((p.B.shape[1], N))
        for k in range(N):
            i = mode[k]
            rhs = (X[:, k + 1] - X[:, k]) / h - p.A[i] @ X[:, k + 1] - p.b[i]
            U[:, k] = np.linalg.lstsq(p.B, rhs, rcond=None)[0]
        U = np.clip(U, -np.inf if p.u_min is None else p.u_min[:, None],
                    np.inf if p.u_max is None else p.u_max[:, None])
        return {"X": X, "U": U, "TH": np.vstack([1.0 - mode, mode]).astype(float),
                "LAM": g - g.min(axis=0), "MU": g.min(axis=0), "H": np.full(N, h)}

    def variables(self, opti: Any) -> dict[str, Any]:
        p, N = self.p, self.p.elements
        var = {"X": opti.variable(p.n, N + 1), "U": opti.variable(p.B.shape[1], N),
               "TH": opti.variable(2, N), "LAM": opti.variable(2, N), "MU": opti.variable(N)}
        var["H"] = opti.variable(N) if p.switch_detection else np.full(N, p.T / N)
        return var

    def constraints(self, opti: Any, var: dict[str, Any]) -> None:
        from ._casadi import require_casadi

        ca, p, N = require_casadi(), self.p, self.p.elements
        X, U, TH, H = var["X"], var["U"], var["TH"], var["H"]
        Xn = X[:, 1:]
        for k in range(N):
            f = [ca.mtimes(ca.DM(p.A[i]), Xn[:, k]) + p.b[i] + ca.mtimes(ca.DM(p.B), U[:, k])
                 for i in range(2)]
            opti.subject_to(Xn[:, k] - X[:, k] - H[k] * (TH[0, k] * f[0] + TH[1, k] * f[1])
                            == 0)
        psi = ca.mtimes(ca.DM(p.c[None, :]), Xn) + p.d
        opti.subject_to(ca.vec(ca.vertcat(psi, -psi) - var["LAM"]
                               - ca.repmat(ca.transpose(var["MU"]), 2, 1)) == 0)
        opti.subject_to(ca.vec(TH[0, :] + TH[1, :]) == 1)
        opti.subject_to(X[:, 0] == p.x0)
        idx = np.flatnonzero(~np.isnan(p.x_final)).tolist()
        opti.subject_to(X[idx, N] == p.x_final[idx])
        for bound, sign in ((p.u_min, 1.0), (p.u_max, -1.0)):
            if bound is not None:
                opti.subject_to(ca.vec(sign * (U - np.tile(bound[:, None], (1, N)))) >= 0)
        if p.switch_detection:
            hbar = p.T / N
            left = np.flatnonzero(self.lam_start > 0).tolist()
            if left:   # a mode inactive at x0 stays off on the first element
                opti.subject_to(TH[left, 0] == 0)
            opti.subject_to(ca.sum1(H) == p.T)
            lo, hi = p.element_bounds
            opti.subject_to(opti.bounded(lo * hbar, H, hi * hbar))

    def cost(self, var: dict[str, Any]) -> Any:
        from ._casadi import require_casadi

        ca = require_casadi()
        U, H = var["U"], var["H"]
        return ca.mtimes(ca.sum1(U * U), ca.DM(H) if isinstance(H, np.ndarray) else H)

    def pair_keys(self) -> list[tuple[Any, Any]]:
        """Which ``θ`` and ``λ`` entries (column-major) each pair holds."""
        N = self.p.elements
        keys = [([("TH", j) for j in range(2 * N)], [("LAM", j) for j in range(2 * N)])]
        if self.p.switch_detection:
            keys.append(([("TH", j + 2) for j in range(2 * (N - 1))],
                         [("LAM", j) for j in range(2 * (N - 1))]))
        return keys

    def pairs(self, var: dict[str, Any], ops: Any) -> list[tuple[Any, Any]]:
        """``θ ⟂ λ`` on every element; with switch detection also the cross pairs
        ``θ_n ⟂ λ_{n-1}`` (those of the first element, against the known ``λ`` at ``x0``,
        are constraints: :meth:`constraints`)."""
        N = self.p.elements
        every = list(range(2 * N))
        TH, LAM = var["TH"], var["LAM"]
        out = [(ops.select(TH, every), ops.select(LAM, every))]
        if self.p.switch_detection:
            out.append((ops.select(TH[:, 1:], list(range(2 * (N - 1)))),
                        ops.select(LAM[:, :-1], list(range(2 * (N - 1))))))
        return out

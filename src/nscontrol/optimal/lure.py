r"""Trajectory optimisation of a Lur'e system with a piecewise-linear set-valued law,
transcribed by the implicit Euler step of ``simulate(..., method="implicit_euler",
theta=1)``, its law written as complementarity constraints.

The system (:class:`~nscontrol.systems.LureSystem`) is ``x' = A x + G w + B u``,
``z = H x + D w + g``, ``w ∈ -φ(z)``. On the grid ``t_k = k h`` the step is the library's
(θ = 1)::

    x_{k+1} = x_k + h (A x_{k+1} + G w_k + B u_k),     z_{k+1} = H x_{k+1} + D w_k + g,

and ``w_k ∈ -φ(z_{k+1})`` in the law's complementarity form
(:meth:`~nscontrol.laws.base.SetValuedLaw.complementarity_form`: ``w = w0 + E ξ``,
``0 <= ξ ⟂ Nz z + Nxi ξ + r >= 0``; a relay, Coulomb friction, normal cones, their products).
The pairs go through the same Scholtes homotopy and polish as the contact transcription
(:mod:`.homotopy`). The input of step ``k`` is what the integrator reads at the step's end
(θ = 1 reads ``u(t_{k+1})``): :meth:`LurePlan.input` is that signal, for replay.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray, check_integer, check_positive, check_type
from ..errors import ModelError
from ..systems.lure import LureSystem
from .contact import Relaxation, _bound, _vector_with_nan, casadi
from .homotopy import residual, solve_homotopy, stage_stats
from .plan import ZeroOrderHold

__all__ = ["LureProblem", "LurePlan"]


@dataclass(frozen=True)
class LurePlan:
    """A planned motion of a :class:`LureProblem` on the grid ``t_k = k h``.

    Attributes
    ----------
    t : ndarray, shape (N + 1,)
        Grid times.
    x : ndarray, shape (N + 1, n)
        Planned states.
    u : ndarray, shape (N, q)
        Input of each step.
    w : ndarray, shape (N, m)
        The law's output on each step (``w_k ∈ -φ(z_{k+1})``).
    h : float
        The step.
    cost : float
        ``h Σ |u_k|²``.
    residual : float
        Largest ``|min(ξ, η)|`` over the law's complementarity pairs.
    stats : dict
        ``stages``, ``solve_time``, ``iterations``, ``polished``.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    w: FloatArray
    h: float
    cost: float
    residual: float
    stats: dict[str, Any] = field(default_factory=dict)

    def input(self) -> ZeroOrderHold:
        """The inputs as the signal ``u=`` of ``simulate(..., method="implicit_euler",
        h=h, theta=1)``, which reads step ``k``'s input at ``t_{k+1}``."""
        return ZeroOrderHold(float(self.t[0] + self.h), self.h, self.u)


@dataclass(frozen=True, eq=False)
class LureProblem:
    """Least effort ``h Σ |u_k|²`` from ``x0`` to ``x_final`` in ``steps`` implicit Euler
    steps of a Lur'e system (the module docstring).

    Parameters
    ----------
    system : LureSystem
        With an input matrix ``B``, a constant shift ``g`` (or none) and a law with a
        complementarity form.
    x0 : array_like (n,)
        Initial state.
    steps : int
        ``N``.
    h : float
        The step.
    x_final : array_like (n,), optional
        Final state (NaN components free).
    u_min, u_max : array_like (q,), optional
        Input bounds (a scalar applies to every input).

    Raises
    ------
    ModelError
        A system the transcription does not cover, a bad value.
    DimensionError
        A vector of the wrong length.
    """

    system: LureSystem
    x0: Any
    steps: int
    h: float
    x_final: Any = None
    u_min: Any = None
    u_max: Any = None
    form: Any = field(init=False, repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        s = check_type("system", self.system, LureSystem)
        if s.B is None:
            raise ModelError("system: no input matrix B; give LureSystem(..., B=...) so that "
                             "there is something to plan")
        if callable(s.g):
            raise ModelError("system: a time-varying shift g(t) is not transcribed; give a "
                             "constant g")
        set_(self, "form", s.law.complementarity_form())
        n = s.A.shape[0]
        set_(self, "x0", _vector_with_nan("x0", self.x0, n))
        if np.isnan(self.x0).any():
            raise ModelError("x0: NaN entries; the initial state is given whole")
        set_(self, "steps", check_integer("steps", self.steps, minimum=1))
        set_(self, "h", check_positive("h", self.h))
        set_(self, "x_final", None if self.x_final is None else _vector_with_nan(
            "x_final", self.x_final, n))
        for name in ("u_min", "u_max"):
            set_(self, name, _bound(name, getattr(self, name), s.B.shape[1]))

    def solve(self, relaxation: Relaxation | None = None) -> LurePlan:
        """Solve the Scholtes homotopy (and its polish) of the transcription, from the
        straight line between the end states (zero inputs, the law's outputs zero).

        Parameters
        ----------
        relaxation : Relaxation, optional
            The homotopy (default :class:`Relaxation()`).

        Returns
        -------
        LurePlan

        Raises
        ------
        SolverError
            IPOPT failed on a relaxed problem.
        """
        relaxation = Relaxation() if relaxation is None else check_type(
            "relaxation", relaxation, Relaxation)
        nlp = _LureNLP(self)
        stages: list[dict[str, Any]] = []
        sol, polished = solve_homotopy(nlp, nlp.guess(), relaxation, stages)
        f = self.form
        W = f.w0[:, None] + f.E @ sol["XI"]
        return LurePlan(t=self.h * np.arange(self.steps + 1, dtype=np.float64),
                        x=sol["X"].T.copy(), u=sol["U"].T.copy(), w=W.T.copy(), h=self.h,
                        cost=float(sol["cost"]), residual=residual(nlp, sol),
                        stats=stage_stats(stages, polished))


class _LureNLP:
    """The NLP of a :class:`LureProblem` (a :class:`~nscontrol.optimal.homotopy.Builder`)."""

    def __init__(self, problem: LureProblem) -> None:
        self.p = problem
        B = problem.system.B
        assert B is not None    # LureProblem refuses a system without one
        self.q = int(B.shape[1])

    def guess(self) -> dict[str, Any]:
        p, N = self.p, self.p.steps
        xf = p.x0 if p.x_final is None else np.where(np.isnan(p.x_final), p.x0, p.x_final)
        X = p.x0[:, None] + (xf - p.x0)[:, None] * np.linspace(0.0, 1.0, N + 1)[None, :]
        k = p.form.n_complementarity
        return {"X": X, "U": np.zeros((self.q, N)), "XI": np.zeros((k, N)),
                "lam_g": None}

    def variables(self, opti: Any) -> dict[str, Any]:
        p, N = self.p, self.p.steps
        return {"X": opti.variable(p.x0.shape[0], N + 1),
                "U": opti.variable(self.q, N),
                "XI": opti.variable(p.form.n_complementarity, N)}

    def constraints(self, opti: Any, var: dict[str, Any]) -> None:
        ca, p, N, s = casadi(), self.p, self.p.steps, self.p.system
        X, U, W = var["X"], var["U"], self._w(var, ca.DM, ca.mtimes)
        Xn = X[:, 1:]
        step = Xn - X[:, :-1] - p.h * (ca.mtimes(ca.DM(s.A), Xn) + ca.mtimes(ca.DM(s.G), W)
                                       + ca.mtimes(ca.DM(s.B), U))
        opti.subject_to(ca.vec(step) == 0)
        opti.subject_to(X[:, 0] == p.x0)
        if p.x_final is not None:
            idx = np.flatnonzero(~np.isnan(p.x_final)).tolist()
            opti.subject_to(X[idx, N] == p.x_final[idx])
        for bound, sign in ((p.u_min, 1.0), (p.u_max, -1.0)):
            if bound is not None:
                opti.subject_to(ca.vec(sign * (U - np.tile(bound[:, None], (1, N)))) >= 0)

    def cost(self, var: dict[str, Any]) -> Any:
        return self.p.h * casadi().sumsqr(var["U"])

    def _w(self, var: dict[str, Any], const: Any, mm: Any) -> Any:
        f, N = self.p.form, self.p.steps
        return const(np.tile(f.w0[:, None], (1, N))) + mm(const(f.E), var["XI"])

    def pair_keys(self) -> list[tuple[Any, Any]]:
        """The first entries are the unknowns ``ξ`` (the second are expressions)."""
        size = self.p.form.n_complementarity * self.p.steps
        return [([("XI", j) for j in range(size)], None)]

    def pairs(self, var: dict[str, Any], ops: Any) -> list[tuple[Any, Any]]:
        """``0 <= ξ_k ⟂ Nz z_{k+1} + Nxi ξ_k + r >= 0`` on every step."""
        N, s, f = self.p.steps, self.p.system, self.p.form
        W = self._w(var, ops.const, ops.mm)
        Z = ops.mm(ops.const(s.H), var["X"][:, 1:]) + ops.mm(ops.const(s.D), W)
        if s.g is not None:
            Z = Z + ops.const(np.tile(np.asarray(s.g, float).reshape(-1, 1), (1, N)))
        eta = (ops.mm(ops.const(f.Nz), Z) + ops.mm(ops.const(f.Nxi), var["XI"])
               + ops.const(np.tile(f.r[:, None], (1, N))))
        every = list(range(f.n_complementarity * N))
        return [(ops.select(var["XI"], every), ops.select(eta, every))]

"""The Scholtes homotopy, for any transcription that declares its NLP as a :class:`Builder`
(the contact problem of :mod:`.contact`, the switching problem of :mod:`.fesd`): the NLPs
are built with CasADi's ``Opti`` (the Jacobians and Hessians are CasADi's sparse algorithmic
derivatives) and solved by IPOPT.

A builder writes its complementarity pairs once, over array operations (:class:`Ops`),
evaluated on CasADi's symbols for the constraints and on numpy arrays for the residual and
the branches of a solution.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..errors import SolverError
from ._casadi import require_casadi

if TYPE_CHECKING:
    from .contact import Relaxation

#: IPOPT's options of every solve (the adaptive barrier update takes a third of the monotone
#: one's iterations on the FESD problems, whose relaxed complementarity makes the barrier
#: problem hard to follow at a fixed μ).
IPOPT_OPTIONS: dict[str, Any] = {"print_level": 0, "sb": "yes", "mu_strategy": "adaptive"}

#: Added when a solve starts from the previous one's primal and dual solution: a small
#: barrier. (IPOPT's pushes of the start into the interior stay at their defaults: pushes of
#: 1e-9 let a frictional plan creep along the relaxed stick branch, as the MPC found.)
WARM_OPTIONS: dict[str, Any] = {"warm_start_init_point": "yes", "mu_init": 1e-6}

#: IPOPT's statuses that count as a solution.
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass(frozen=True)
class Ops:
    """Matrix product, constant and selection of entries (column-major, CasADi's order)
    of one array family (numpy's or CasADi's)."""

    mm: Any
    const: Any
    select: Any


def numpy_ops() -> Ops:
    """Ops on numpy arrays."""
    return Ops(mm=lambda A, B: A @ B, const=lambda a: np.asarray(a, float),
               select=lambda a, idx: np.asarray(a, float).ravel(order="F")[idx])


def casadi_ops() -> Ops:
    """Ops on CasADi symbols."""
    ca = require_casadi()
    return Ops(mm=lambda A, B: ca.mtimes(A, B), const=lambda a: ca.DM(np.asarray(a, float)),
               select=lambda a, idx: ca.vec(a)[list(idx)])


class Builder(Protocol):
    """What a transcription declares: its unknowns, constraints, cost and pairs."""

    def variables(self, opti: Any) -> dict[str, Any]:
        """The unknowns (CasADi symbols; a float entry is a constant)."""

    def constraints(self, opti: Any, var: dict[str, Any]) -> None:
        """Every constraint but the complementarity pairs."""

    def cost(self, var: dict[str, Any]) -> Any:
        """The objective."""

    def pairs(self, var: dict[str, Any], ops: Ops) -> list[tuple[Any, Any]]:
        """The pairs ``0 <= a ⟂ b >= 0`` as flat vectors (a builder may also define
        ``pair_keys()``: per pair, the unknowns its entries are, so that the polish sets an
        unknown to zero once; see :func:`pair_keys`)."""


def residual(builder: Builder, sol: dict[str, Any]) -> float:
    """The largest ``|min(a, b)|`` over the pairs of a numeric solution."""
    return max((float(np.max(np.abs(np.minimum(a, b)), initial=0.0))
                for a, b in builder.pairs(sol, numpy_ops())), default=0.0)


def _pair_constraints(opti: Any, pairs: list[tuple[Any, Any]], sigma: Any,
                      branches: list[np.ndarray] | None, keys: list[tuple[Any, Any]]) -> None:
    """Relaxed pairs ``a, b >= 0, a b <= σ``; with ``branches`` the polish:
    ``a = 0 <= b`` where the branch is true, ``b = 0 <= a`` elsewhere, an entry that
    several pairs set to zero (the same ``key``) constrained once (a repeated equality would
    leave IPOPT too few degrees of freedom)."""
    fixed: set[Any] = set()
    for i, (a, b) in enumerate(pairs):
        if a.numel() == 0:
            continue
        if branches is None:
            opti.subject_to(a >= 0)
            opti.subject_to(b >= 0)
            opti.subject_to(a * b <= sigma)
            continue
        for zero_side, keep_side, zero_keys, mask in ((a, b, keys[i][0], branches[i]),
                                                      (b, a, keys[i][1], ~branches[i])):
            idx = np.flatnonzero(mask)
            fresh = [int(j) for j in idx if zero_keys is None or zero_keys[j] not in fixed]
            fixed.update(zero_keys[j] for j in idx if zero_keys is not None)
            if fresh:
                opti.subject_to(zero_side[fresh] == 0)
            if idx.size:
                opti.subject_to(keep_side[idx.tolist()] >= 0)


def pair_keys(builder: Any, pairs: list[tuple[Any, Any]]) -> list[tuple[Any, Any]]:
    """The builder's ``pair_keys()`` (which unknown each pair entry is, ``None`` for an
    expression), or ``None`` everywhere when it has none."""
    keys = getattr(builder, "pair_keys", None)
    return keys() if keys is not None else [(None, None)] * len(pairs)


class _NLP:
    """One NLP of a builder (relaxed with a parameter ``σ``, or the polish of fixed
    branches)."""

    def __init__(self, builder: Builder, relaxation: Relaxation,
                 branches: list[np.ndarray] | None = None) -> None:
        ca = require_casadi()
        self.relaxation = relaxation
        self.opti = opti = ca.Opti()
        self.var = builder.variables(opti)
        self.sigma = opti.parameter()
        builder.constraints(opti, self.var)
        pairs = builder.pairs(self.var, casadi_ops())
        _pair_constraints(opti, pairs, self.sigma, branches, pair_keys(builder, pairs))
        self.cost = builder.cost(self.var)
        opti.minimize(self.cost)
        self.warm: bool | None = None

    def solve(self, guess: dict[str, Any], sigma: float) -> tuple[dict[str, Any], dict]:
        """Solve from ``guess`` (primal, and dual when it has ``lam_g`` of this NLP's size);
        returns the solution and the stage's record."""
        opti, rel = self.opti, self.relaxation
        for name, sym in self.var.items():
            if _symbolic(sym):
                opti.set_initial(sym, guess[name])
        warm = guess.get("lam_g") is not None and guess["lam_g"].size == opti.ng
        if warm:
            opti.set_initial(opti.lam_g, guess["lam_g"])
        opti.set_value(self.sigma, sigma)
        if warm != self.warm:   # a new solver only when its options change (it costs)
            self.warm = warm
            opti.solver("ipopt", {"print_time": False, "error_on_fail": False, "expand": True},
                        {**IPOPT_OPTIONS, "tol": rel.tol, "acceptable_constr_viol_tol": rel.tol,
                         "max_iter": int(rel.max_iter), **(WARM_OPTIONS if warm else {})})
        start = time.perf_counter()
        try:
            sol = opti.solve()
        except RuntimeError:   # IPOPT gave up; its status says why, the caller decides
            sol = opti.debug
        elapsed = time.perf_counter() - start
        stats = opti.stats()
        record = {"sigma": sigma, "iterations": int(stats.get("iter_count", 0)),
                  "status": str(stats.get("return_status", "")), "solve_time": elapsed}
        return self._values(sol, guess), record

    def _values(self, sol: Any, guess: dict[str, Any]) -> dict[str, Any]:
        out = dict(guess)
        for name, sym in self.var.items():
            if not _symbolic(sym):
                continue
            value = np.asarray(sol.value(sym), float)
            out[name] = (float(value) if np.ndim(guess[name]) == 0
                         else value.reshape(np.shape(guess[name])))
        out["cost"] = float(sol.value(self.cost))
        out["lam_g"] = np.asarray(sol.value(self.opti.lam_g), float).reshape(-1)
        return out


def _symbolic(value: Any) -> bool:
    """An unknown of the NLP (a builder may give a constant, a float or an array, instead)."""
    return isinstance(value, require_casadi().MX)


def solve_homotopy(builder: Builder, guess: dict[str, Any], relaxation: Relaxation,
                   stages: list[dict[str, Any]]) -> tuple[dict[str, Any], bool]:
    """The relaxed solves along ``relaxation.sigmas()`` then the polish; the records are
    appended to ``stages``. Returns the solution and whether the polish was kept.

    Raises
    ------
    SolverError
        IPOPT failed on a relaxed problem.
    """
    nlp = _NLP(builder, relaxation)
    guess = {**guess, "lam_g": None}
    for sigma in relaxation.sigmas():
        sol, record = nlp.solve(guess, sigma)
        stages.append(record)
        if record["status"] not in SOLVED:
            raise SolverError(f"optimal: IPOPT failed on the relaxation σ = {sigma:.3g} "
                              f"({record['status']}); try another sigma0, more steps or a "
                              "better initial guess", status=record["status"])
        guess = sol
    pairs = builder.pairs(guess, numpy_ops())
    if not relaxation.polish or not sum(a.size for a, _ in pairs):
        return guess, False
    polish = _NLP(builder, relaxation, [a <= b for a, b in pairs])
    sol, record = polish.solve({**guess, "lam_g": None}, 0.0)
    record["sigma"] = "polish"
    stages.append(record)
    if record["status"] in SOLVED and sol["cost"] <= guess["cost"] + 1e-6 * (
            1.0 + abs(guess["cost"])):
        return sol, True
    return guess, False


def stage_stats(stages: list[dict[str, Any]], polished: bool) -> dict[str, Any]:
    """The stats every plan reports: the stages, their total time and iterations."""
    return {"stages": stages, "solve_time": float(sum(st["solve_time"] for st in stages)),
            "iterations": int(sum(st["iterations"] for st in stages)), "polished": polished}


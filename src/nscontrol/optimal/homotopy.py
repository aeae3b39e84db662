"""The Scholtes homotopy, for any transcription that declares its NLP as a :class:`Builder`
(the contact problem of :mod:`.contact`, the switching problem of :mod:`.fesd`): a builder
declares its unknowns and constraints on CasADi's ``Opti``; the homotopy turns them, with the
pairs, into one NLP expanded to SX (the Jacobians and Hessians are CasADi's sparse
algorithmic derivatives, generated once) whose relaxed stages and polish differ only in
their bounds, solved by IPOPT through ``nlpsol``.

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
#: problem hard to follow at a fixed μ). A cold solve starts the rows' multipliers at zero
#: (``constr_mult_init_max = 0``), not at IPOPT's least-squares estimate, which depends on
#: whether a bound is a row or a variable bound (its bound multipliers start at 1 in the
#: estimate): with the pairs' unknown sides as variable bounds the estimate led nosnoc's
#: motor to another local optimum (1.002427 instead of nosnoc's 0.999900), zero to nosnoc's.
#: The relaxed complementarity makes the Hessian indefinite: on the cart-pole IPOPT
#: factorizes the KKT matrix 2.2 times per iteration (its inertia correction, first at no
#: regularization, then raising it by ``perturb_inc_fact`` until the inertia is right); that
#: factorization, not the adaptive μ oracle's own work (about a tenth), is most of IPOPT's
#: time. Raising by 4 instead of IPOPT's 8 stops at a smaller regularization, closer to the
#: Newton step: a few more trial factorizations per iteration but fewer iterations on all
#: four nosnoc examples (cart-pole 769 -> 630 iterations, 1699 -> 1468 factorizations), at
#: the same optima, landing on the cart-pole's as often (47 of 48 perturbed starts).
IPOPT_OPTIONS: dict[str, Any] = {"print_level": 0, "sb": "yes", "mu_strategy": "adaptive",
                                 "constr_mult_init_max": 0.0, "perturb_inc_fact": 4.0}

#: Added when a solve starts from the previous one's primal and dual solution: a small
#: barrier. (IPOPT's pushes of the start into the interior stay at their defaults: pushes of
#: 1e-9 let a frictional plan creep along the relaxed stick branch, as the MPC found.)
WARM_OPTIONS: dict[str, Any] = {"warm_start_init_point": "yes", "mu_init": 1e-6}

#: Added on the polish: IPOPT's bounds relaxed by 1e-10 (relative) instead of its default
#: 1e-8, which moved nosnoc's motor optimum by 5e-7 relative (inputs on their bounds; 4e-9
#: at 1e-10). Not 0: with no interior left around an active bound the cart-pole's polish
#: took 143 iterations and was rejected (13 at 1e-10).
EXACT_OPTIONS: dict[str, Any] = {"bound_relax_factor": 1e-10}

#: Options of CasADi's nlpsol around IPOPT (none beyond its defaults).
NLPSOL_OPTIONS: dict[str, Any] = {}

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
    """The NLP of a builder, built once for the whole homotopy: the builder's constraints,
    then for each complementarity pair the sides ``a``, ``b`` and a row ``a b``. A side
    whose entries are unknowns (the builder's ``pair_keys``) is bounded as those unknowns
    (``lbx, ubx``), an expression side is a row; so is a builder's inequality on one
    unknown a bound (:meth:`_simple_bounds`): IPOPT adds a slack per inequality row, and a
    bound needs none. A relaxed solve bounds them by ``a, b >= 0, a b <= σ``; the polish,
    by ``a = 0 <= b`` where the branch is true and ``b = 0 <= a`` elsewhere, the products
    free. So ``σ`` and the branches are bounds, never a new NLP: CasADi differentiates and
    expands (to SX) once, and the polish starts from the last relaxed solve's primal and
    dual solution.

    ``layout`` has per pair ``(sides, product, n)``: each side either the unknowns' indices
    in ``x`` (an int array) or its first row (an int), then the first of the ``n`` product
    rows."""

    def __init__(self, builder: Builder, relaxation: Relaxation) -> None:
        ca = require_casadi()
        self.relaxation = relaxation   # IPOPT's options of the next solves
        self.builder = builder
        opti = ca.Opti()      # a container of the builder's declarations only
        self.var = builder.variables(opti)
        builder.constraints(opti, self.var)
        self.cost = builder.cost(self.var)
        pairs = [(a, b) for a, b in builder.pairs(self.var, casadi_ops())]
        self.keys = pair_keys(builder, pairs)
        bounds = ca.Function("bounds", [opti.p], [opti.lbg, opti.ubg])
        lbg, ubg = (np.asarray(v, float).reshape(-1) for v in bounds(np.zeros(opti.np)))
        self.names = [name for name, sym in self.var.items() if _symbolic(sym)]
        symbols = [self.var[name] for name in self.names]
        self.index, first = [], 0     # each unknown's entries in x, in its shape
        for sym in symbols:
            shape = (int(sym.size1()), int(sym.size2()))
            self.index.append(first + np.arange(sym.numel()).reshape(shape, order="F"))
            first += int(sym.numel())
        self.nx = first
        at = dict(zip(self.names, (i.ravel(order="F") for i in self.index), strict=True))
        # a side whose entries are unknowns (pair_keys) is bounded as those unknowns (lbx),
        # not as rows: IPOPT then needs no slack for it and no row for an unknown that
        # several pairs share (FESD's λ_k in θ_k ⟂ λ_k and θ_{k+1} ⟂ λ_k)
        self.lbx, self.ubx = np.full(first, -np.inf), np.full(first, np.inf)
        rows: list[Any] = []
        lower: list[np.ndarray] = []
        upper: list[np.ndarray] = []
        self.layout: list[tuple[list[np.ndarray | int], int, int]] = []
        start = 0    # the pair rows' offsets after the builder's rows that stay rows
        for (a, b), keys in zip(pairs, self.keys, strict=True):
            size, sides = int(a.numel()), list[np.ndarray | int]()
            for side, side_keys in ((a, keys[0]), (b, keys[1])):
                if side_keys is not None and all(name in at for name, _ in side_keys):
                    x_of = np.array([at[name][int(j)] for name, j in side_keys], dtype=int)
                    self.lbx[x_of] = 0.0
                    sides.append(x_of)
                    continue
                rows.append(side)
                lower.append(np.zeros(size))
                upper.append(np.full(size, np.inf))
                sides.append(start)
                start += size
            rows.append(a * b)
            lower.append(np.full(size, -np.inf))
            upper.append(np.full(size, np.inf))
            self.layout.append((sides, start, size))
            start += size
        x_mx = ca.veccat(*symbols)   # every unknown, even one only the pairs hold
        nlp = ca.Function("nlp", [x_mx], [self.cost, opti.g, ca.vertcat(*rows)]).expand()
        x = ca.SX.sym("x", x_mx.numel())
        f, g_builder, g_pairs = nlp(x)
        kept = self._simple_bounds(g_builder, x, lbg, ubg)
        self.layout = [([side + kept.size if isinstance(side, int) else side
                         for side in sides], product + kept.size, n)
                       for sides, product, n in self.layout]
        self.lbg = np.concatenate([lbg[kept], *lower])
        self.ubg = np.concatenate([ubg[kept], *upper])
        self.problem = {"x": x, "f": f, "g": ca.vertcat(g_builder[kept.tolist()], g_pairs)}
        self.ng = kept.size + start
        self._solvers: dict[tuple[bool, float, int, bool], Any] = {}

    def _simple_bounds(self, g: Any, x: Any, lbg: np.ndarray, ubg: np.ndarray
                       ) -> np.ndarray:
        """Move the builder's inequality rows that bound one unknown (``l <= c x_j + d <=
        u``, an input's, a state's or an element length's bound) onto ``lbx, ubx``: IPOPT
        then needs no slack and no row for them. Returns the rows that stay rows (the
        others, equalities included: an equality bound would fix the unknown, which IPOPT
        removes from the problem, and with it the multipliers of a warm start)."""
        ca = require_casadi()
        simple = np.zeros(lbg.size, dtype=bool)
        rows = np.flatnonzero(lbg != ubg)        # the inequalities
        if not rows.size:
            return np.arange(lbg.size)
        g = g[rows.tolist()]
        J = ca.jacobian(g, x)
        at, cols = (np.asarray(v, dtype=int) for v in J.sparsity().get_triplet())
        count = np.bincount(at, minlength=rows.size)
        at_zero = np.asarray(ca.Function("g0", [x], [g])(np.zeros(x.numel())),
                             float).reshape(-1)
        for k in np.flatnonzero(count[at] == 1):    # the rows on one unknown
            c, i, j = J.nz[int(k)], rows[at[k]], cols[k]
            if not c.is_constant() or float(c) == 0.0 or not np.isfinite(at_zero[at[k]]):
                continue     # nonlinear in its unknown, or not finite at 0: a row
            lo, hi = sorted(((lbg[i] - at_zero[at[k]]) / float(c),
                             (ubg[i] - at_zero[at[k]]) / float(c)))
            self.lbx[j], self.ubx[j] = max(self.lbx[j], lo), min(self.ubx[j], hi)
            simple[i] = True
        return np.flatnonzero(~simple)

    def bounds(self, sigma: float | None, branches: list[np.ndarray] | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The bounds ``lbx, ubx, lbg, ubg`` of the relaxation ``σ``, or of the polish of
        ``branches`` (``a = 0 <= b`` where true, ``b = 0 <= a`` elsewhere, the products
        free). A side on unknowns is set to zero by its unknowns' bounds, so an unknown that
        several pairs set to zero is fixed once whatever the pairs (a repeated equality row
        would leave IPOPT too few degrees of freedom); an expression side by its rows."""
        lbx, ubx = self.lbx.copy(), self.ubx.copy()
        lbg, ubg = self.lbg.copy(), self.ubg.copy()
        for i, (sides, product, n) in enumerate(self.layout):
            if branches is None:
                ubg[product: product + n] = sigma
                continue
            for side, zero in ((sides[0], branches[i]), (sides[1], ~branches[i])):
                idx = np.flatnonzero(zero)
                if isinstance(side, np.ndarray):
                    ubx[side[idx]] = 0.0
                else:
                    ubg[side + idx] = 0.0
        return lbx, ubx, lbg, ubg

    def solver(self, warm: bool, tol: float | None = None, exact: bool = False) -> Any:
        """IPOPT on the NLP, cold or warm-started, with the tolerance ``tol`` (default the
        relaxation's) and the relaxation's iteration limit (the options differ; built once
        each, every one after the first on the first's derivatives: CasADi's cache takes its
        functions, so the Jacobian and the Hessian of the Lagrangian are generated once)."""
        rel = self.relaxation
        tol = float(rel.tol if tol is None else tol)
        key = (warm, tol, int(rel.max_iter), exact)
        if key not in self._solvers:
            built = next(iter(self._solvers.values()), None)
            cache = {} if built is None else {name: built.get_function(name)
                                               for name in built.get_function()}
            self._solvers[key] = require_casadi().nlpsol(
                "homotopy", "ipopt", self.problem,
                {"print_time": False, "error_on_fail": False, "cache": cache,
                 **NLPSOL_OPTIONS,
                 "ipopt": {**IPOPT_OPTIONS, "tol": tol,
                           "acceptable_constr_viol_tol": tol,
                           "max_iter": int(rel.max_iter), **(WARM_OPTIONS if warm else {}),
                           **(EXACT_OPTIONS if exact else {})}})
        return self._solvers[key]

    def solve(self, guess: dict[str, Any], sigma: float | None,
              branches: list[np.ndarray] | None = None, tol: float | None = None
              ) -> tuple[dict[str, Any], dict]:
        """Solve the relaxation ``σ`` (or the polish of ``branches``) from ``guess`` (primal,
        and dual when it has ``lam_g`` and ``lam_x`` of this NLP) to ``tol`` (default the
        relaxation's); returns the solution and the stage's record."""
        x0 = np.zeros(self.nx)
        for name, index in zip(self.names, self.index, strict=True):
            x0[index] = np.asarray(guess[name], float).reshape(index.shape)
        lbx, ubx, lbg, ubg = self.bounds(sigma, branches)
        args: dict[str, Any] = {"x0": x0, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
        lam_g = guess.get("lam_g")
        warm = lam_g is not None and lam_g.size == self.ng
        if warm:
            args.update(lam_g0=lam_g, lam_x0=guess["lam_x"])
        solver = self.solver(warm, tol, exact=branches is not None)
        start = time.perf_counter()
        out = solver(**args)
        elapsed = time.perf_counter() - start
        stats = solver.stats()
        record = {"sigma": "polish" if branches is not None else sigma,
                  "iterations": int(stats.get("iter_count", 0)),
                  "status": str(stats.get("return_status", "")), "solve_time": elapsed}
        return self._values(out, guess), record

    def _values(self, out: dict[str, Any], guess: dict[str, Any]) -> dict[str, Any]:
        sol = dict(guess)
        x = np.asarray(out["x"], float).reshape(-1)
        for name, index in zip(self.names, self.index, strict=True):
            value = x[index]
            sol[name] = (float(value.reshape(-1)[0]) if np.ndim(guess[name]) == 0
                         else value.reshape(np.shape(guess[name])))
        sol["cost"] = float(out["f"])
        sol["lam_g"] = np.asarray(out["lam_g"], float).reshape(-1)
        sol["lam_x"] = np.asarray(out["lam_x"], float).reshape(-1)
        return sol


def _symbolic(value: Any) -> bool:
    """An unknown of the NLP (a builder may give a constant, a float or an array, instead)."""
    return isinstance(value, require_casadi().MX)


def off_the_corner(builder: Builder, guess: dict[str, Any], sigma: float) -> dict[str, Any]:
    """``guess`` with the pairs whose two sides are unknowns (the builder's ``pair_keys``:
    FESD's ``θ ⟂ λ``) lifted to at least ``√σ / 2`` on both sides, so that the first
    relaxed solve starts inside its region ``a, b >= 0, a b <= σ`` rather than at the corner
    ``a = b = 0``, where the product's gradient vanishes (a degenerate start): from the
    corner IPOPT took 176 iterations on nosnoc's motor at σ = 1, from inside 25, to the same
    point. A pair with an expression side (a contact's velocity, a Lur'e law's output) is
    left as given: lifting the block's forces alone (a force with no motion) started its
    homotopy in a worse local optimum."""
    floor = 0.5 * float(np.sqrt(sigma))
    out = dict(guess)
    pairs = builder.pairs(guess, numpy_ops())
    for keys in pair_keys(builder, pairs):
        if keys[0] is None or keys[1] is None:
            continue
        for name, j in (*keys[0], *keys[1]):
            if out[name] is guess[name]:
                out[name] = np.array(guess[name], dtype=float)
            at = np.unravel_index(int(j), out[name].shape, order="F")
            out[name][at] = max(out[name][at], floor)
    return out


def solve_homotopy(builder: Builder, guess: dict[str, Any], relaxation: Relaxation,
                   stages: list[dict[str, Any]], *, warm: bool = True,
                   built: dict[str, Any] | None = None) -> tuple[dict[str, Any], bool]:
    """The relaxed solves along ``relaxation.sigmas()`` then the polish; the records are
    appended to ``stages``. Returns the solution and whether the polish was kept.

    Each relaxed solve but the last stops at IPOPT's tolerance ``max(tol, stage_tol σ)``
    (:class:`Relaxation`): the next relaxation moves its point by ``O(σ)`` anyway.

    With ``relaxation.early_polish``, once a relaxed solve leaves all but a
    ``settle_fraction`` of the pairs on the branch the previous one chose (the active set
    settled, but for pairs at their corner), its polish is tried at once and kept
    when its cost continues the relaxed path to ``σ = 0`` (:func:`_continues_path`): the
    remaining relaxations would lead to that point, and are skipped. A polish that does not
    continue the path (another local optimum) is discarded and the homotopy goes on.

    ``built``, a dict the caller keeps with the builder (its problem's), holds the NLP and
    its IPOPT instances after the first homotopy: a later one of the same builder neither
    rebuilds, differentiates nor expands it (the builder's NLP does not depend on the
    guess or the relaxation, only its bounds and IPOPT's options do).

    With ``warm`` each relaxed solve starts from the previous one's primal and dual
    solution at a small barrier (:data:`WARM_OPTIONS`); without, from its primal solution
    alone at IPOPT's default barrier, which lets the iterate leave the branch the first
    relaxations chose (more iterations; the polish is warm either way).

    Raises
    ------
    SolverError
        IPOPT failed on a relaxed problem.
    """
    nlp = None if built is None else built.get("nlp")
    if nlp is None or nlp.builder is not builder:
        nlp = _NLP(builder, relaxation)
        if built is not None:
            built["nlp"] = nlp
    nlp.relaxation = relaxation
    guess = off_the_corner(builder, {**guess, "lam_g": None}, relaxation.sigma0)
    sigmas, previous = relaxation.sigmas(), None
    for sigma in sigmas:
        # a relaxation before the last is a waypoint: solved to a hundredth of its σ
        # (stage_tol), not to the final tolerance, its point moves by O(σ) at the next
        tol = relaxation.tol if sigma == sigmas[-1] else max(relaxation.tol,
                                                             relaxation.stage_tol * sigma)
        start = guess if warm else {**guess, "lam_g": None}
        sol, record = nlp.solve(start, sigma, tol=tol)
        stages.append(record)
        if record["status"] not in SOLVED and tol > relaxation.tol:
            # IPOPT's infeasibility test follows its tolerance: a loose one can give up on
            # a hard start that the final tolerance solves (SpeedUp from rest, σ = 1e-3)
            sol, record = nlp.solve(start, sigma)
            stages.append(record)
        if record["status"] not in SOLVED:
            raise SolverError(f"optimal: IPOPT failed on the relaxation σ = {sigma:.3g} "
                              f"({record['status']}); try another sigma0, more steps or a "
                              "better initial guess", status=record["status"])
        guess = sol
        if not (relaxation.polish and relaxation.early_polish) or sigma == sigmas[-1]:
            continue
        branches = [a <= b for a, b in builder.pairs(sol, numpy_ops())]
        total = sum(b.size for b in branches)
        settled = previous is not None and sum(
            int(np.count_nonzero(x != y)) for x, y in zip(branches, previous, strict=True)
        ) <= relaxation.settle_fraction * total
        previous = branches
        if settled and total:
            polished, record = nlp.solve(sol, None, branches)
            stages.append(record)
            if record["status"] in SOLVED and _continues_path(nlp, sol, polished, sigma):
                return polished, True
    pairs = builder.pairs(guess, numpy_ops())
    if not relaxation.polish or not sum(a.size for a, _ in pairs):
        return guess, False
    sol, record = nlp.solve(guess, None, [a <= b for a, b in pairs])
    stages.append(record)
    if record["status"] in SOLVED and sol["cost"] <= guess["cost"] + 1e-6 * (
            1.0 + abs(guess["cost"])):
        return sol, True
    return guess, False


#: How far the polished cost may lie from the relaxed path's first-order continuation to
#: ``σ = 0``, as a fraction of the predicted rise ``σ Σ ν``: the remainder is ``O(σ²)``, so
#: a polish onto the path's limit lands well within a tenth of the rise (measured with a
#: polish after every relaxation, cold path: nosnoc's motor 1 % at σ = 1e-3 and 0.1 % at
#: 1e-4, its sliding-mode problem 8 % at 1e-3, the cart-pole 0.04 % at 1e-4), one onto
#: another local optimum far outside (61 % on the motor at σ = 1e-2, branches unsettled).
PATH_FRACTION = 0.1


def _continues_path(nlp: _NLP, relaxed: dict[str, Any], polished: dict[str, Any],
                    sigma: float) -> bool:
    """Whether a polish of a relaxed solution is the limit of the relaxed path: along it
    the cost rises as ``dJ/dσ = -Σ ν`` (the envelope theorem; ``ν`` the multipliers of the
    rows ``a b <= σ``), so the limit's cost is ``J(σ) + σ Σ ν + O(σ²)``. The polished cost
    must match that within :data:`PATH_FRACTION` of the rise (and IPOPT's tolerance)."""
    nu = sum(float(np.sum(relaxed["lam_g"][product: product + n]))
             for _, product, n in nlp.layout)
    rise = sigma * max(nu, 0.0)
    predicted = relaxed["cost"] + rise
    slack = PATH_FRACTION * rise + 1e-6 * (1.0 + abs(predicted))
    return abs(polished["cost"] - predicted) <= slack


def stage_stats(stages: list[dict[str, Any]], polished: bool) -> dict[str, Any]:
    """The stats every plan reports: the stages, their total time and iterations."""
    return {"stages": stages, "solve_time": float(sum(st["solve_time"] for st in stages)),
            "iterations": int(sum(st["iterations"] for st in stages)), "polished": polished}


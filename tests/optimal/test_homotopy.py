"""The homotopy's one NLP (nscontrol.optimal.homotopy): the complementarity pairs are
bounds (a side on unknowns) and rows (an expression side, the products) whose bounds say the
relaxation σ or the polish's branches, so one NLP serves every stage; they evaluate the
builder's pairs (the CasADi and numpy forms of one declaration); a builder's inequality on
one unknown is a bound; the polish fixes every unknown once; the first relaxed solve starts
off the pairs' corner."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import casadi as ca  # noqa: E402

from nscontrol.optimal import (  # noqa: E402
    ContactProblem,
    PushedBlock,
    Relaxation,
    SpeedUp,
    homotopy,
)
from nscontrol.optimal.contact import _ContactNLP, active_sets, initial_guess  # noqa: E402
from nscontrol.optimal.stewart import _FesdNLP  # noqa: E402

N = 12


@pytest.fixture(scope="module")
def fesd():
    builder = _FesdNLP(SpeedUp().problem(N).engine())
    return builder, homotopy._NLP(builder, Relaxation())


def _sides(nlp, x):
    """Per pair: the values of a and of b at ``x`` (from the unknowns a side is bounded as,
    or from its rows) and of the product rows."""
    g = np.asarray(ca.Function("g", [nlp.problem["x"]], [nlp.problem["g"]])(x)).ravel()
    out = []
    for sides, product, n in nlp.layout:
        values = [x[side] if isinstance(side, np.ndarray) else g[side: side + n]
                  for side in sides]
        out.append((*values, g[product: product + n]))
    return out


def test_the_rows_and_bounds_evaluate_the_builders_pairs(fesd):
    """At a random point, the NLP's pair sides (unknowns or rows) are the pairs the builder
    evaluates on numpy arrays, and the product rows their products (the same arithmetic:
    equal to a few ulps)."""
    builder, nlp = fesd
    rng = np.random.default_rng(3)
    x = rng.standard_normal(nlp.nx)
    values = {name: x[index] for name, index in zip(nlp.names, nlp.index, strict=True)}
    values["H"] = values["H"].ravel()
    pairs = builder.pairs(values, homotopy.numpy_ops())
    assert len(pairs) == len(nlp.layout) == 2
    for (a, b), (va, vb, vab) in zip(pairs, _sides(nlp, x), strict=True):
        assert np.array_equal(va, a) and np.array_equal(vb, b)
        assert np.allclose(vab, a * b, rtol=4 * np.finfo(float).eps, atol=0.0)


def test_sides_on_unknowns_are_bounds_not_rows(fesd):
    """FESD's θ ⟂ λ: both sides are unknowns, so the pairs add only their product rows (a
    λ in two pairs, the element's and the cross one, bounded once); the builder's
    inequalities on one unknown (the input bounds, the lengths' bounds) are bounds too,
    its equalities and every other row stay. A contact's pair (a force ⟂ a velocity
    expression) keeps a row for the expression side only."""
    builder, nlp = fesd
    opti = ca.Opti()
    var = builder.variables(opti)
    builder.constraints(opti, var)
    p = builder.p
    lengths = 1 if p.free_lengths else 0
    simple = (p.u_min is not None) * p.inputs * p.stages + (
        p.u_max is not None) * p.inputs * p.stages + lengths * builder.K
    assert simple > 0
    products = sum(n for _, _, n in nlp.layout)
    assert nlp.ng == opti.ng - simple + products
    index = dict(zip(nlp.names, nlp.index, strict=True))
    for name in ("TH", "LAM"):
        assert np.all(nlp.lbx[index[name]] == 0) and np.all(nlp.ubx[index[name]] == np.inf)
    U = index["U"]
    u_min = np.full(p.inputs, -np.inf) if p.u_min is None else p.u_min
    u_max = np.full(p.inputs, np.inf) if p.u_max is None else p.u_max
    assert np.all(nlp.lbx[U] == u_min[:, None]) and np.all(nlp.ubx[U] == u_max[:, None])
    lo, hi = p.element_bounds
    assert np.allclose(nlp.lbx[index["H"]], lo * builder.hbar, rtol=4 * np.finfo(float).eps)
    assert np.allclose(nlp.ubx[index["H"]], hi * builder.hbar, rtol=4 * np.finfo(float).eps)
    block = PushedBlock()
    problem = ContactProblem(block.system(), block.x0, 10, 0.1, x_final=block.x_final)
    start = initial_guess(problem)
    contact = homotopy._NLP(_ContactNLP(problem, active_sets(problem, start["X"],
                                                             start["h"])), Relaxation())
    for sides, _, _ in contact.layout:
        assert isinstance(sides[0], np.ndarray) and not isinstance(sides[1], np.ndarray)


class _Toy:
    """min (x0 - 2)^2 + (x1 - 2)^2 + x2^2 with 2 x0 - 1 >= 0 and -x1 >= -3 (bounds on one
    unknown each), x2^2 <= 4 and x0 + x1 >= 0 (rows), x2 == 1 (an equality: a row), and
    0 <= x0 ⟂ x1 + x2 >= 0 (an unknown against an expression)."""

    def variables(self, opti):
        return {"x": opti.variable(3)}

    def constraints(self, opti, var):
        x = var["x"]
        opti.subject_to(2 * x[0] - 1 >= 0)
        opti.subject_to(-x[1] >= -3)
        opti.subject_to(x[2] ** 2 <= 4)
        opti.subject_to(x[0] + x[1] >= 0)
        opti.subject_to(x[2] == 1)

    def cost(self, var):
        x = var["x"]
        return (x[0] - 2) ** 2 + (x[1] - 2) ** 2 + x[2] ** 2

    def pair_keys(self):
        return [([("x", 0)], None)]

    def pairs(self, var, ops):
        x = var["x"]
        return [(ops.select(x, [0]), ops.select(x, [1]) + ops.select(x, [2]))]


def test_simple_bounds_are_found_by_structure():
    """Only an inequality affine in one unknown becomes a bound, intersected with the
    pair's ``>= 0``: x0 >= max(1/2, 0), x1 <= 3; the rows left are x2^2 <= 4,
    x0 + x1 >= 0, x2 == 1, the pair's expression side and its product."""
    nlp = homotopy._NLP(_Toy(), Relaxation())
    assert np.array_equal(nlp.lbx, [0.5, -np.inf, -np.inf])
    assert np.array_equal(nlp.ubx, [np.inf, 3.0, np.inf])
    assert nlp.ng == 3 + 2
    assert np.array_equal(nlp.lbg[:3], [-np.inf, 0.0, 1.0])
    (sides, product, n), = nlp.layout
    assert np.array_equal(sides[0], [0]) and sides[1] == 3 and product == 4 and n == 1


def test_relaxed_bounds_are_scholtes(fesd):
    _, nlp = fesd
    lbx, ubx, lbg, ubg = nlp.bounds(1e-4)
    assert np.array_equal(lbx, nlp.lbx) and np.array_equal(ubx, nlp.ubx)
    for sides, product, n in nlp.layout:
        for side in sides:
            assert np.all(lbx[side] == 0) and np.all(ubx[side] == np.inf)
        assert np.all(lbg[product: product + n] == -np.inf)
        assert np.all(ubg[product: product + n] == 1e-4)


def test_the_polish_fixes_the_zero_sides_unknowns(fesd):
    """Random branches: the products are free; each unknown some pair's branch sets to zero
    is fixed by its bounds (lbx = ubx = 0: once, whatever the number of pairs that set it:
    θ and λ are in two pairs each, the element's and the cross one), every other pair
    unknown stays ``>= 0``; no row's bounds but the products' change."""
    builder, nlp = fesd
    rng = np.random.default_rng(7)
    branches = [rng.random(n) < 0.5 for _, _, n in nlp.layout]
    lbx, ubx, lbg, ubg = nlp.bounds(None, branches)
    zeroed, kept = set(), set()
    for i, (sides, product, n) in enumerate(nlp.layout):
        assert np.all(lbg[product: product + n] == -np.inf)
        assert np.all(ubg[product: product + n] == np.inf)
        for side, zero in ((sides[0], branches[i]), (sides[1], ~branches[i])):
            zeroed.update(side[zero].tolist())
            kept.update(side[~zero].tolist())
    zeroed_ = np.array(sorted(zeroed))
    free = np.array(sorted(kept - zeroed))
    assert np.all(lbx[zeroed_] == 0) and np.all(ubx[zeroed_] == 0)
    assert np.all(lbx[free] == 0) and np.all(ubx[free] == np.inf)
    others = np.setdiff1d(np.arange(nlp.nx), np.r_[zeroed_, free])
    assert np.array_equal(lbx[others], nlp.lbx[others])
    assert np.array_equal(ubx[others], nlp.ubx[others])
    products = np.concatenate([np.arange(p, p + n) for _, p, n in nlp.layout])
    rest = np.setdiff1d(np.arange(nlp.ng), products)
    assert np.array_equal(lbg[rest], nlp.lbg[rest]) and np.array_equal(ubg[rest], nlp.ubg[rest])


def test_one_nlp_serves_the_whole_homotopy(monkeypatch):
    """The relaxed stages and the polish are solved on one NLP (σ and the branches are
    bounds), and the polish starts from the last relaxed solve's multipliers."""
    built, starts = [], []
    init, solve = homotopy._NLP.__init__, homotopy._NLP.solve

    def spy_init(self, *args, **kwargs):
        built.append(self)
        init(self, *args, **kwargs)

    def spy_solve(self, guess, sigma, branches=None, tol=None):
        starts.append(guess.get("lam_g") is not None)
        return solve(self, guess, sigma, branches, tol)

    monkeypatch.setattr(homotopy._NLP, "__init__", spy_init)
    monkeypatch.setattr(homotopy._NLP, "solve", spy_solve)
    plan = SpeedUp().problem(N).solve()
    stages = plan.stats["stages"]
    assert len(built) == 1 and stages[-1]["sigma"] == "polish" and plan.stats["polished"]
    assert starts == [False] + [True] * (len(stages) - 1)


def test_the_first_solve_starts_off_the_corner(fesd):
    """θ ⟂ λ (both unknowns) lifted to √σ0/2 where below, nothing else moved; a contact's
    pairs (a velocity on one side) left as given."""
    builder, _ = fesd
    guess = builder.guess()
    sigma0 = 1e-2
    out = homotopy.off_the_corner(builder, guess, sigma0)
    floor = 0.5 * np.sqrt(sigma0)
    for name in ("TH", "LAM"):
        assert np.array_equal(out[name], np.maximum(guess[name], floor))
        assert out[name] is not guess[name]
    for name in set(guess) - {"TH", "LAM"}:
        assert out[name] is guess[name]
    block = PushedBlock()
    problem = ContactProblem(block.system(), block.x0, 10, 0.1, x_final=block.x_final)
    start = initial_guess(problem)
    contact = _ContactNLP(problem, active_sets(problem, start["X"], start["h"]))
    lifted = homotopy.off_the_corner(contact, start, sigma0)
    assert all(lifted[name] is start[name] for name in start)


def test_the_warm_solver_reuses_the_cold_ones_derivatives():
    """The second IPOPT instance (warm-start options) takes the first one's generated
    functions (the same objects: CasADi's cache), so the Jacobian and the Hessian of the
    Lagrangian are generated once per homotopy."""
    nlp = homotopy._NLP(_FesdNLP(SpeedUp().problem(N).engine()), Relaxation())
    cold, warm = nlp.solver(False), nlp.solver(True)
    assert cold is not warm
    for name in ("nlp_jac_g", "nlp_hess_l", "nlp_grad_f"):
        assert hash(cold.get_function(name)) == hash(warm.get_function(name))
    # a solver built apart generates its own
    other = homotopy._NLP(_FesdNLP(SpeedUp().problem(N).engine()), Relaxation()).solver(False)
    assert hash(other.get_function("nlp_hess_l")) != hash(cold.get_function("nlp_hess_l"))


def test_the_early_polish_ends_at_the_homotopys_point():
    """Once the branches settle, the polish is tried and kept when it continues the relaxed
    path: the same branches as the full homotopy's last solve, so the same smooth NLP and
    the same optimum (costs equal to IPOPT's tolerance 1e-10 on a cost of order 1, times a
    factor 100 for the two solves' different starts), with fewer relaxed solves."""
    early = SpeedUp().problem(N).solve(Relaxation())
    full = SpeedUp().problem(N).solve(Relaxation(early_polish=False))
    assert early.stats["polished"] and full.stats["polished"]
    assert abs(early.cost - full.cost) <= 100 * 1e-10 * (1.0 + abs(full.cost))
    # the lengths of the elements without a switch are free (no equilibration): compare
    # the switch, which FESD places exactly (constant fields) up to the solver's tolerance
    assert np.allclose(early.switch_times([1.0], 0.0), full.switch_times([1.0], 0.0),
                       rtol=0.0, atol=1e-6 * SpeedUp().T)
    relaxed = [len([s for s in plan.stats["stages"] if s["sigma"] != "polish"])
               for plan in (early, full)]
    assert relaxed[0] < relaxed[1] == len(Relaxation().sigmas())


@pytest.mark.parametrize("fraction", [0.0, 0.03, 0.05, 1.0])
def test_the_polish_is_tried_once_few_branches_change(monkeypatch, fraction):
    """The first polish follows the first relaxed solve after which at most
    ``settle_fraction`` of the pairs changed branch (``0``: none; ``1``: the second solve).
    From σ = 1 the speed-up's 46 pairs change by 3, 2, 1, 1, 0 between solves, so the
    four fractions try it at four different solves."""
    calls = []
    solve = homotopy._NLP.solve

    def spy_solve(self, guess, sigma, branches=None, tol=None):
        sol, record = solve(self, guess, sigma, branches, tol)
        calls.append(None if sigma is None else
                     [a <= b for a, b in self.builder.pairs(sol, homotopy.numpy_ops())])
        return sol, record

    monkeypatch.setattr(homotopy._NLP, "solve", spy_solve)
    SpeedUp().problem(N).solve(Relaxation(sigma0=1.0, settle_fraction=fraction))
    first = calls.index(None)
    relaxed = calls[:first]
    total = sum(b.size for b in relaxed[0])
    changed = [sum(int(np.count_nonzero(x != y)) for x, y in zip(now, before, strict=True))
               for before, now in zip(relaxed[:-1], relaxed[1:], strict=True)]
    assert first >= 2 and changed[-1] <= fraction * total
    assert all(c > fraction * total for c in changed[:-1])


def test_a_polish_off_the_path_is_not_kept():
    """The first-order continuation of the relaxed path, ``J + σ Σ ν``, decides: a polished
    cost within a tenth of the rise ``σ Σ ν`` is kept, one beyond it is not."""

    class Rows:
        layout = [([0, 2], 4, 2)]   # one pair of two entries: rows 0-1 a, 2-3 b, 4-5 a b

    sigma, relaxed = 1e-3, {"cost": 1.0, "lam_g": np.array([0, 0, 0, 0, 1.0, 1.0])}
    rise = sigma * 2.0
    keep = homotopy._continues_path(Rows(), relaxed, {"cost": 1.0 + 1.05 * rise}, sigma)
    drop = homotopy._continues_path(Rows(), relaxed, {"cost": 1.0 + 1.5 * rise}, sigma)
    assert keep and not drop


def test_a_problem_builds_its_nlp_once(monkeypatch):
    """A second solve of the same problem (another relaxation, another start) reuses the
    first one's NLP and IPOPT instance, and gives the plan a fresh problem gives: the
    same NLP from the same start (equal to IPOPT's tolerance on a cost of order 1, times 100
    for the rounding of two runs)."""
    built = []
    init = homotopy._NLP.__init__

    def spy_init(self, *args, **kwargs):
        built.append(self)
        init(self, *args, **kwargs)

    monkeypatch.setattr(homotopy._NLP, "__init__", spy_init)
    problem = SpeedUp().problem(N)
    problem.solve(Relaxation(sigma0=1e-2))
    again = problem.solve(Relaxation(tol=1e-9))
    assert len(built) == 1 and problem.engine() is problem.engine()
    fresh = SpeedUp().problem(N).solve(Relaxation(tol=1e-9))
    assert len(built) == 2
    assert abs(again.cost - fresh.cost) <= 100 * 1e-9 * (1.0 + abs(fresh.cost))


def test_relaxations_before_the_last_are_waypoints(monkeypatch):
    """Each relaxed solve but the last stops at max(tol, stage_tol σ); the last one and the
    polish at tol; the plan is the one every solve to tol gives (the same branches, so the
    same polished NLP: costs equal to tol on a cost of order 1, times 100)."""
    calls = []
    solve = homotopy._NLP.solve

    def spy_solve(self, guess, sigma, branches=None, tol=None):
        calls.append((sigma, tol))
        return solve(self, guess, sigma, branches, tol)

    monkeypatch.setattr(homotopy._NLP, "solve", spy_solve)
    rel = Relaxation(early_polish=False)
    plan = SpeedUp().problem(N).solve(rel)
    sigmas = rel.sigmas()
    assert [s for s, _ in calls] == [*sigmas, None]
    assert [t for _, t in calls[:-2]] == [max(rel.tol, rel.stage_tol * s) for s in sigmas[:-1]]
    assert calls[-2][1] == rel.tol and calls[-1][1] is None
    exact = SpeedUp().problem(N).solve(Relaxation(early_polish=False, stage_tol=0.0))
    assert plan.stats["polished"] and exact.stats["polished"]
    assert abs(plan.cost - exact.cost) <= 100 * rel.tol * (1.0 + abs(exact.cost))

"""The homotopy's one NLP (nscontrol.optimal.homotopy): the complementarity pairs are rows
whose bounds say the relaxation σ or the polish's branches, so one NLP serves every stage;
the rows evaluate the builder's pairs (the CasADi and numpy forms of one declaration); the
polish fixes every unknown once; the first relaxed solve starts off the pairs' corner."""

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


def _pair_rows(nlp):
    """Per pair: the rows of a, of b, of a b."""
    out = []
    for start, n in nlp.layout:
        out.append([start + k * n + np.arange(n) for k in range(3)])
    return out


def test_the_rows_evaluate_the_builders_pairs(fesd):
    """At a random point, the NLP's pair rows are the pairs the builder evaluates on numpy
    arrays, and their products (the same arithmetic: equal to a few ulps)."""
    builder, nlp = fesd
    rng = np.random.default_rng(3)
    x = rng.standard_normal(nlp.nx)
    g = np.asarray(ca.Function("g", [nlp.problem["x"]], [nlp.problem["g"]])(x)).ravel()
    values = {name: x[index] for name, index in zip(nlp.names, nlp.index, strict=True)}
    values["H"] = values["H"].ravel()
    pairs = builder.pairs(values, homotopy.numpy_ops())
    assert len(pairs) == len(nlp.layout) == 2
    for (a, b), (ra, rb, rab) in zip(pairs, _pair_rows(nlp), strict=True):
        assert np.array_equal(g[ra], a) and np.array_equal(g[rb], b)
        assert np.allclose(g[rab], a * b, rtol=4 * np.finfo(float).eps, atol=0.0)


def test_relaxed_bounds_are_scholtes(fesd):
    _, nlp = fesd
    lbg, ubg = nlp.bounds(1e-4)
    for ra, rb, rab in _pair_rows(nlp):
        assert np.all(lbg[ra] == 0) and np.all(ubg[ra] == np.inf)
        assert np.all(lbg[rb] == 0) and np.all(ubg[rb] == np.inf)
        assert np.all(lbg[rab] == -np.inf) and np.all(ubg[rab] == 1e-4)


def test_the_polish_fixes_every_unknown_once(fesd):
    """Random branches: the products are free, each pair's kept side stays >= 0, and each
    unknown the branches set to zero has exactly one equality row (θ and λ are in two pairs
    each, the element's and the cross one: a second equality on the same unknown would be a
    dependent constraint), its other zero-side rows free."""
    builder, nlp = fesd
    rng = np.random.default_rng(7)
    branches = [rng.random(n) < 0.5 for _, n in nlp.layout]
    lbg, ubg = nlp.bounds(None, branches)
    equalities: dict = {}
    for i, (ra, rb, rab) in enumerate(_pair_rows(nlp)):
        assert np.all(lbg[rab] == -np.inf) and np.all(ubg[rab] == np.inf)
        for rows, keys, zero in ((ra, nlp.keys[i][0], branches[i]),
                                 (rb, nlp.keys[i][1], ~branches[i])):
            kept = rows[~zero]
            assert np.all(lbg[kept] == 0) and np.all(ubg[kept] == np.inf)
            for j in np.flatnonzero(zero):
                if lbg[rows[j]] == 0 and ubg[rows[j]] == 0:
                    equalities[keys[j]] = equalities.get(keys[j], 0) + 1
                else:
                    assert lbg[rows[j]] == -np.inf and ubg[rows[j]] == np.inf
    zeroed = {keys[j] for i, (k0, k1) in enumerate(nlp.keys)
              for keys, zero in ((k0, branches[i]), (k1, ~branches[i]))
              for j in np.flatnonzero(zero)}
    assert set(equalities) == zeroed and set(equalities.values()) == {1}


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


def test_a_polish_off_the_path_is_not_kept():
    """The first-order continuation of the relaxed path, ``J + σ Σ ν``, decides: a polished
    cost within a tenth of the rise ``σ Σ ν`` is kept, one beyond it is not."""

    class Rows:
        layout = [(0, 2)]   # one pair of two entries: rows 0-1 a, 2-3 b, 4-5 a b

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

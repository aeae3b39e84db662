"""The general FESD transcription (nscontrol.optimal.stewart) and its piecewise-affine front
(nscontrol.optimal.pwa) on a problem with two switching surfaces whose optimal switching
times have a closed form.

**The problem.** ``x₁' = u₁ + a(x₁)``, ``x₂' = u₂ + b(x₂)`` with drifts that switch on the
two surfaces ``x₁ = 0`` (``a = 1`` below, ``3`` above) and ``x₂ = 0`` (``b = 1`` below, ``2``
above): four regions, the quadrants. Least ``∫ |u|² dt`` from ``(-1, -1)`` to
``(√3, ¾√19)`` in ``T = 1``. The cost is the sum of the two components' costs and each
component is a :class:`~nscontrol.optimal.SpeedUp` (closed form in
``nscontrol.optimal.problems``): the first switches at ``s₁ = 1/2``, the second where
``x_T² / r² - L² / s² = b₂² - b₁²`` (``r = 1 - s``), which ``x_T = ¾√19`` puts at
``s₂ = 1/4``. Each side's input is constant, so the continuous optimum is piecewise
constant with jumps at ``s₂`` and ``s₁``; with free element lengths (one input per element)
implicit Euler is exact on every element and the discrete optimum *is* the continuous one
once two element boundaries sit on ``s₂`` and ``s₁``.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import DimensionError, ModelError  # noqa: E402
from nscontrol.optimal import SpeedUp  # noqa: E402
from nscontrol.optimal.pwa import pwa_problem, stewart_form  # noqa: E402
from nscontrol.optimal.stewart import FesdProblem, StewartSystem  # noqa: E402
from nscontrol.systems import FilippovSystem, PiecewiseAffineSystem  # noqa: E402

FIRST = SpeedUp()                                            # s₁ = 1/2
SECOND = SpeedUp(a1=1.0, a2=2.0, L=1.0, x_T=0.75 * np.sqrt(19.0))   # s₂ = 1/4
X0 = np.array([-FIRST.L, -SECOND.L])
XF = np.array([FIRST.x_T, SECOND.x_T])
N = 16
# The polish meets the constraints to IPOPT's tol (1e-10) and the plan's slopes are O(1-10):
# the switching instants and the cost within 1e-10 x (slopes, elements) ~ 1e-8.
EXACT = 1e-8


def drift(x, u, s1, s2):
    """Field of the quadrant of signs (s1, s2), numpy-friendly (traced by CasADi)."""
    a = FIRST.a1 if s1 < 0 else FIRST.a2
    b = SECOND.a1 if s2 < 0 else SECOND.a2
    return [u[0] + a, u[1] + b]


def two_surfaces() -> StewartSystem:
    """Default signs (every sign vector, first switching function slowest), and a nonlinear
    second switching function with the same zero set and sign as x₂."""
    fields = [lambda x, u, s=s: drift(x, u, *s) for s in ((-1, -1), (-1, 1), (1, -1), (1, 1))]
    return StewartSystem(fields, [lambda x: x[0], lambda x: x[1] * (1 + x[1] ** 2)])


def problem(**kw) -> FesdProblem:
    opts = {"stages": N, "elements": 1, "inputs": 2, "x_final": XF,
            "equidistant_control_grid": False}
    return FesdProblem(two_surfaces(), X0, 1.0, **{**opts, **kw})


@pytest.fixture(scope="module")
def plan():
    return problem().solve()


def test_closed_forms_of_the_two_switches():
    assert FIRST.switch_time() == pytest.approx(0.5, abs=1e-14)
    assert SECOND.switch_time() == pytest.approx(0.25, abs=1e-14)


def test_fesd_finds_both_switching_times_and_the_cost(plan):
    (t1,) = plan.crossings(lambda x: x[0])
    (t2,) = plan.crossings(lambda x: x[1])
    assert abs(t1 - FIRST.switch_time()) <= EXACT
    assert abs(t2 - SECOND.switch_time()) <= EXACT
    assert abs(plan.cost - (FIRST.cost() + SECOND.cost())) <= EXACT
    assert plan.residual <= EXACT and plan.stats["polished"]
    # the inputs of the closed form: L/s - a₁ before each switch, x_T/r - a₂ after it
    mid = 0.5 * (plan.t[:-1] + plan.t[1:])
    for k, case, ts in ((0, FIRST, t1), (1, SECOND, t2)):
        before = mid < ts
        assert np.allclose(plan.u[before, k], case.L / ts - case.a1, atol=1e-6)
        assert np.allclose(plan.u[~before, k], case.x_T / (1 - ts) - case.a2, atol=1e-6)


def test_two_layers_summed_find_the_same_switches():
    """The same system as two layers, one per surface, their fields summed (nosnoc's
    subsystems): ``x₁`` driven by layer 1 across ``x₁ = 0``, ``x₂`` by layer 2 across the
    nonlinear ``x₂ + x₂³ = 0``. Constant fields again: both switches exact."""
    def first(side):
        return lambda x, u: [u[0] + (FIRST.a1 if side < 0 else FIRST.a2), 0.0]

    def second(side):
        return lambda x, u: [0.0, u[1] + (SECOND.a1 if side < 0 else SECOND.a2)]

    layers = [StewartSystem([first(-1), first(1)], lambda x: x[0], signs=[[-1.0], [1.0]]),
              StewartSystem([second(-1), second(1)], [lambda x: x[1] + x[1] ** 3],
                            signs=[[-1.0], [1.0]])]
    two = FesdProblem(layers, X0, 1.0, N, elements=1, inputs=2, x_final=XF,
                      equidistant_control_grid=False).solve()
    assert two.theta.shape == (N, 4)
    (t1,) = two.crossings(lambda x: x[0])
    (t2,) = two.crossings(lambda x: x[1])
    assert abs(t1 - FIRST.switch_time()) <= EXACT
    assert abs(t2 - SECOND.switch_time()) <= EXACT
    assert abs(two.cost - (FIRST.cost() + SECOND.cost())) <= EXACT


def test_a_fixed_grid_misses_the_switches_by_the_grid():
    """Without switch detection the crossing falls inside an element (an O(h) error: the
    step landing on a surface may use either field); h = 1/16 puts neither switch (1/4 and
    1/2 are grid points, so shift the horizon's grid by taking N = 13)."""
    fixed = problem(stages=13, switch_detection=False).solve()
    h = 1.0 / 13
    errors = [abs(fixed.crossings(lambda x, j=j: x[j])[0] - case.switch_time())
              for j, case in ((0, FIRST), (1, SECOND))]
    assert max(errors) >= 1e3 * EXACT      # far from FESD's exactness
    assert max(errors) <= 3 * h            # but within the grid's order
    assert fixed.residual <= EXACT


def quadrants() -> PiecewiseAffineSystem:
    regions, b = [], []
    for s1, s2 in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        # the quadrant s₁ x₁ >= 0, s₂ x₂ >= 0 as H x <= 0
        regions.append((-np.diag([float(s1), float(s2)]), np.zeros(2)))
        b.append(drift(None, [0.0, 0.0], s1, s2))
    return PiecewiseAffineSystem(A=[np.zeros((2, 2))] * 4, b=b, regions=regions, E=np.eye(2),
                                 continuous=False)


def test_pwa_front_plans_the_same_and_replays_through_simulate(plan):
    """The PWA front writes the quadrants in Stewart's form (two hyperplanes, four cells) and
    plans the same optimum; the plan's inputs replayed element by element through the
    library's switching integrator (the PWA's own Filippov method, exact flows of constant
    fields between located crossings) give back its states: both exact, so within the
    polish's tolerance accumulated over the elements."""
    pwa = quadrants()
    layer = stewart_form(pwa)
    assert layer.m == 2 and len(layer.fields) == 4
    front = pwa_problem(pwa, X0, 1.0, N, elements=1, x_final=XF,
                        equidistant_control_grid=False).solve()
    assert abs(front.cost - plan.cost) <= EXACT
    x, ends = X0.copy(), []
    for k in range(N):
        traj = nsc.simulate(pwa, x, (0.0, front.t[k + 1] - front.t[k]), u=front.u[k],
                            rtol=1e-12, atol=1e-12)
        x = traj.x[-1]
        ends.append(x)
    assert np.max(np.abs(np.array(ends) - front.x[1:])) <= EXACT * N


def test_nonlinear_fields_replay_within_the_scheme_order():
    """Nonlinear fields ``x' = u + 1 + x²`` below ``x = 0`` and ``u + 3 + sin x`` above, from
    -1 to 1.5 in T = 1 (control stages of two elements, step equilibration): the plan's held
    inputs replayed stage by stage through the library's switching integrator (DOP853
    between located crossings at 1e-10). Implicit Euler is first order, its global error
    ``≈ (T/2) h̄ max|x''|``: halving the elements must halve the replay's error (ratio
    0.5 ± 0.15, the plans themselves moving with h̄), and the error must stay below
    ``h̄`` (``max|x''| <= 2`` on these plans)."""
    def below(x, u):
        return [u[0] + 1 + x[0] ** 2]

    def above(x, u):
        return [u[0] + 3 + np.sin(x[0])]     # numpy's sin on a CasADi symbol: traced

    layer = StewartSystem([below, above], lambda x: x[0], signs=[[-1.0], [1.0]])
    x0, T = np.array([-1.0]), 1.0
    errors = []
    for stages in (10, 20):
        problem = FesdProblem(layer, x0, T, stages, elements=2, inputs=1, x_final=[1.5],
                              equilibration=1.0)
        fesd = problem.solve()
        assert fesd.residual <= EXACT and len(fesd.crossings(lambda x: x[0])) == 1
        # the plan's cost and objective, recomputed from its trajectory by cost_of
        # (roundoff of a sum of 2 N terms of size 1)
        assert problem.cost_of(fesd.t, fesd.x, fesd.u) == pytest.approx(fesd.cost, abs=1e-12)
        assert problem.cost_of(fesd.t, fesd.x, fesd.u, penalty=True) == pytest.approx(
            fesd.objective, abs=1e-9)
        err, x = 0.0, x0.copy()
        for s in range(stages):   # each stage's fields with its held input
            us = fesd.u[s]
            sys = FilippovSystem.two_sided(lambda t, x, us=us: np.array(below(x, us), float),
                                           lambda t, x, us=us: np.array(above(x, us), float),
                                           lambda x: x[0], 1, gradient=lambda x: np.ones(1))
            traj = nsc.simulate(sys, x, (0.0, fesd.t_stages[s + 1] - fesd.t_stages[s]),
                                rtol=1e-10, atol=1e-10)
            x = traj.x[-1]
            err = max(err, float(np.max(np.abs(x - fesd.x[(s + 1) * 2]))))
        assert err <= T / (2 * stages)
        errors.append(err)
    assert 0.35 <= errors[1] / errors[0] <= 0.65


def test_bad_inputs_are_refused_with_specific_errors():
    f = [lambda x, u: [u[0], u[1]]] * 4
    with pytest.raises(ModelError, match="^fields"):
        StewartSystem([f[0], 3.0], lambda x: x[0], signs=[[-1.0], [1.0]])
    with pytest.raises(ModelError, match="^fields"):
        StewartSystem(lambda x, u: x, lambda x: x[0])
    with pytest.raises(DimensionError, match="^signs"):
        StewartSystem(f[:3], lambda x: x[0])                       # 3 fields, not 2^m
    with pytest.raises(DimensionError, match="^signs"):
        StewartSystem(f, lambda x: x[0], signs=[[-1.0], [1.0]])    # 2 rows for 4 fields
    with pytest.raises(ModelError, match="^signs"):
        StewartSystem(f[:2], lambda x: x[0], signs=[[0.0], [1.0]])
    with pytest.raises(ModelError, match="^signs"):
        StewartSystem(f[:2], lambda x: x[0], signs=[[1.0], [1.0]])
    with pytest.raises(ModelError, match="^switching"):
        StewartSystem(f[:2], 2.0, signs=[[-1.0], [1.0]])
    layer = StewartSystem(f, lambda x: x[0], signs=[[-1, -1], [-1, 1], [1, -1], [1, 1]])
    with pytest.raises(DimensionError, match="^switching"):         # c returns 1, S has 2
        FesdProblem(layer, X0, 1.0, 4, inputs=2)
    with pytest.raises(DimensionError, match="^fields"):            # a field of size 1
        FesdProblem(StewartSystem([lambda x, u: [u[0]]] * 2, lambda x: x[0],
                                  signs=[[-1.0], [1.0]]), X0, 1.0, 4, inputs=2)
    with pytest.raises(DimensionError, match="^x_final"):
        problem(x_final=[1.0])
    with pytest.raises(DimensionError, match="^x_max"):
        problem(x_max=[1.0, 2.0, 3.0])
    with pytest.raises(ModelError, match="^x_min"):
        problem(x_min=[np.nan, 0.0])
    with pytest.raises(ModelError, match="^equilibration_form"):
        problem(equilibration_form="exact")
    with pytest.raises(ModelError, match="^element_bounds"):
        problem(element_bounds=(1.0, 2.0))
    with pytest.raises(ModelError, match="^systems"):
        FesdProblem([], X0, 1.0, 4)
    with pytest.raises(ModelError, match="^stage_cost"):
        problem(stage_cost=1.0)
    with pytest.raises(ModelError, match="^inputs"):
        pwa_problem(quadrants(), X0, 1.0, 4, inputs=2)


def test_residual_of_a_plan_from_its_states_and_weights(plan):
    """``residual_of`` recomputes ``λ`` from the states: on the polished plan it meets the
    plan's own residual bound; weights on the wrong regions (columns reversed: field 4 where
    field 1 rules) are caught at the size of the switching functions, and bad shapes are
    refused."""
    problem_ = problem()
    assert problem_.residual_of(plan.x, plan.theta) <= EXACT
    # the reversed weights put θ = 1 on the opposite quadrant, whose λ = g - min g is
    # 2 (|c₁| + |c₂|): above 1 wherever the states are 1/2 from both surfaces (the first
    # elements, near x₀ = (-1, -1)), so the largest min(θ, λ) is θ = 1
    assert problem_.residual_of(plan.x, plan.theta[:, ::-1]) == pytest.approx(1.0, abs=EXACT)
    with pytest.raises(DimensionError, match="^theta"):
        problem_.residual_of(plan.x, plan.theta[:-1])
    with pytest.raises(DimensionError, match="^x"):
        problem_.residual_of(plan.x[:-1], plan.theta)


def test_transcription_rows_are_implicit_euler_on_every_element():
    """The transcription's rows (one element's function mapped over the K elements) at a
    random point are the implicit Euler step ``x_{k+1} - x_k - h_k Σ θ_i f_i(x_{k+1},
    u_s)`` and the algebraic rows ``g(x_{k+1}) - λ_k - μ_k`` (``g = -S c``) written out
    element by element from the fields themselves, each element on its stage's input (3
    elements per stage); the cost is ``Σ h_k |u_s|²``. Both sides are a few flops on entries
    of size <= 10: equal to 1e-12 (about 50 ulps of 10)."""
    import casadi as ca

    stages, elements = 4, 3
    prob = problem(stages=stages, elements=elements)
    nlp = prob._transcription()
    opti = ca.Opti()
    var = nlp.variables(opti)
    nlp.constraints(opti, var)
    names = ["X", "U", "TH", "LAM", "MU", "H"]
    rng = np.random.default_rng(3)
    K = stages * elements
    shapes = {"X": (2, K + 1), "U": (2, stages), "TH": (4, K), "LAM": (4, K), "MU": (1, K),
              "H": (K, 1)}
    vals = {k: rng.uniform(-2.0, 2.0, shapes[k]) for k in names}
    rows = ca.Function("rows", [var[k] for k in names], [opti.g, nlp.cost(var)])
    g, cost = (np.asarray(v, float).ravel() for v in rows(*[vals[k] for k in names]))
    X, U, TH, H = vals["X"], vals["U"], vals["TH"], vals["H"].ravel()
    signs = [(-1, -1), (-1, 1), (1, -1), (1, 1)]
    steps, algebraic = [], []
    for k in range(K):
        xn, u = X[:, k + 1], U[:, k // elements]
        f = sum(TH[i, k] * np.array(drift(xn, u, *s)) for i, s in enumerate(signs))
        steps.append(xn - X[:, k] - H[k] * f)
        c = np.array([xn[0], xn[1] * (1 + xn[1] ** 2)])
        algebraic.append(-np.array(signs, float) @ c - vals["LAM"][:, k] - vals["MU"][0, k])
    expected = np.concatenate([np.concatenate(steps), np.concatenate(algebraic)])
    np.testing.assert_allclose(g[:expected.size], expected, rtol=0, atol=1e-12)
    effort = sum(H[k] * np.sum(U[:, k // elements] ** 2) for k in range(K))
    assert cost[0] == pytest.approx(effort, rel=1e-12)
    assert nlp.plan_cost(X, U, H) == pytest.approx(effort, rel=1e-12)

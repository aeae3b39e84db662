"""The one-step frictional contact problem: known answers, the two planar methods agree,
and every solution satisfies Coulomb's law (cone, maximal dissipation)."""

import pickle

import numpy as np
import pytest
import scipy.sparse as sp

from nscontrol.errors import BudgetExceededError, DimensionError, ModelError
from nscontrol.numerics import (
    FrictionContactResult,
    contact_states,
    friction_residual,
    frictionless_impulses,
    planar_friction_lcp,
    solve_friction_contact,
)
from nscontrol.numerics import _friction_kernels as kernels

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(float).eps


@pytest.mark.parametrize("q, r, u, state", [
    ([-1.0, 0.2, 0.0], [1.0, -0.2, 0.0], [0.0, 0.0, 0.0], 1),    # stick
    ([-1.0, 1.0, 0.0], [1.0, -0.5, 0.0], [0.0, 0.5, 0.0], 2),    # slip
    ([1.0, 0.3, 0.0], [0.0, 0.0, 0.0], [1.0, 0.3, 0.0], 0),      # take-off
])
def test_one_spatial_contact_known_answers(q, r, u, state):
    res = solve_friction_contact(np.eye(3), q, 0.5, dim=3)
    # W = I: the answers are sums of two numbers of order 1, exact to a few ulps
    assert np.allclose(res.r, r, rtol=0, atol=4 * EPS)
    assert np.allclose(res.u, u, rtol=0, atol=4 * EPS)
    assert res.states.tolist() == [state]


def _random_problem(rng, m, dim, cond=50.0):
    A = rng.standard_normal((m * dim, m * dim))
    Q, _ = np.linalg.qr(A)
    W = Q @ np.diag(np.geomspace(1.0, cond, m * dim)) @ Q.T
    return 0.5 * (W + W.T), rng.standard_normal(m * dim)


def _check_coulomb(res, mu, dim, scale):
    """The cone and maximal dissipation, to ``scale`` (the solver's tolerance)."""
    r = res.r.reshape(-1, dim)
    u = res.u.reshape(-1, dim)
    assert np.all(r[:, 0] >= 0.0)
    assert np.all(np.linalg.norm(r[:, 1:], axis=1) <= mu * r[:, 0] + scale)
    assert np.all(u[:, 0] >= -scale)
    # maximal dissipation: the friction impulse never does positive work on the slip
    assert np.all(np.einsum("ij,ij->i", r[:, 1:], u[:, 1:]) <= scale * (1 + np.abs(r).max()))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_nsgs_reaches_tolerance_and_obeys_coulomb(dim, seed):
    rng = np.random.default_rng(seed)
    W, q = _random_problem(rng, 20, dim)
    res = solve_friction_contact(W, q, 0.5, dim=dim, method="nsgs", tol=1e-12)
    assert res.success and res.residual <= 1e-12
    # the residual the solver reports is the one recomputed from r alone
    assert friction_residual(W, q, 0.5, res.r, dim) <= 1e-12
    # the natural map at tol: each violation is at most tol x max(|q|, |r|, |u|)
    scale = 1e-12 * max(np.linalg.norm(q), np.linalg.norm(res.r), np.linalg.norm(res.u))
    _check_coulomb(res, 0.5, dim, 10 * scale)


@pytest.mark.parametrize("seed", range(3))
def test_planar_lcp_and_nsgs_agree(seed):
    rng = np.random.default_rng(seed)
    W, q = _random_problem(rng, 12, 2)
    lcp = solve_friction_contact(W, q, 0.3, dim=2, method="lcp")
    nsgs = solve_friction_contact(W, q, 0.3, dim=2, method="nsgs", tol=1e-13)
    # Lemke: round-off only (residual ~ n eps); NSGS: its tolerance
    assert lcp.residual <= 4 * 12 * EPS * 50
    # W positive definite: the solution is unique; |Δr| <= cond(W) x residual scale
    scale = max(np.linalg.norm(q), np.linalg.norm(lcp.r))
    assert np.max(np.abs(lcp.r - nsgs.r)) <= 50 * 1e-13 * scale * 10
    assert lcp.states.tolist() == nsgs.states.tolist()


def test_planar_lcp_matrix_shape_and_slack_row():
    M, qq = planar_friction_lcp(np.eye(2), [-1.0, 0.2], 0.5)
    assert M[3].tolist() == [0.5, -1.0, -1.0, 0.0] and qq.tolist() == [-1.0, 0.2, -0.2, 0.0]


def test_bad_input_is_refused():
    with pytest.raises(ModelError, match=r"^mu: expected a finite number >= 0"):
        solve_friction_contact(np.eye(2), [-1.0, 0.0], -0.5, dim=2)
    with pytest.raises(DimensionError, match="W"):
        solve_friction_contact(np.eye(3), [-1.0, 0.0], 0.5, dim=2)
    with pytest.raises(ModelError, match="method"):
        solve_friction_contact(np.eye(3), [-1.0, 0.0, 0.0], 0.5, dim=3, method="lcp")


# ----------------------------------------------------------------------------- bad input


def _planar(m=2):
    rng = np.random.default_rng(0)
    W, q = _random_problem(rng, m, 2)
    return W, q


@pytest.mark.parametrize("method", ["auto", "lcp", "nsgs"])
@pytest.mark.parametrize("r0", [np.zeros(3), np.zeros(5), np.zeros((2, 2))])
def test_warm_start_of_the_wrong_shape_is_refused_by_every_method(method, r0):
    # before: "auto" solved by the LCP first and never looked at r0
    W, q = _planar()
    with pytest.raises(DimensionError, match=r"^r0: expected a vector"):
        solve_friction_contact(W, q, 0.3, dim=2, method=method, r0=r0)
    if r0.ndim == 1:
        with pytest.raises(DimensionError,
                           match=rf"^r0: expected a vector of length 4, got length {r0.size}"):
            solve_friction_contact(W, q, 0.3, dim=2, method=method, r0=r0)


@pytest.mark.parametrize(("W", "q", "mu", "error", "name"), [
    ([["1", "0"], ["0", "1"]], [-1.0, 0.2], 0.5, ModelError, "W"),       # parsed before
    (np.array([["1", "0"], ["0", "1"]]), [-1.0, 0.2], 0.5, ModelError, "W"),
    ("1 0; 0 1", [-1.0, 0.2], 0.5, ModelError, "W"),
    (np.eye(2) * (1 + 1j), [-1.0, 0.2], 0.5, ModelError, "W"),           # imaginary dropped
    (sp.csr_matrix(np.eye(2) * 1j), [-1.0, 0.2], 0.5, ModelError, "W"),
    (np.array([[1.0, np.nan], [0.0, 1.0]]), [-1.0, 0.2], 0.5, ModelError, "W"),
    (sp.csr_matrix(np.array([[1.0, np.inf], [0.0, 1.0]])), [-1.0, 0.2], 0.5, ModelError, "W"),
    (np.ones((2, 3)), [-1.0, 0.2], 0.5, DimensionError, "W"),
    (np.ones(2), [-1.0, 0.2], 0.5, DimensionError, "W"),
    (np.eye(2), [-1.0, 0.2, 0.0], 0.5, DimensionError, "q"),
    (np.eye(2), [-1.0, np.nan], 0.5, ModelError, "q"),
    (np.eye(2), ["-1", "0"], 0.5, ModelError, "q"),
    (np.eye(2), [-1.0, 0.2], -0.5, ModelError, "mu"),
    (np.eye(2), [-1.0, 0.2], np.nan, ModelError, "mu"),
    (np.eye(2), [-1.0, 0.2], "0.5", ModelError, "mu"),                   # parsed before
    (np.eye(2), [-1.0, 0.2], True, ModelError, "mu"),
    (np.eye(2), [-1.0, 0.2], 0.5j, ModelError, "mu"),
    (np.eye(2), [-1.0, 0.2], [0.5, 0.5], DimensionError, "mu"),
    (np.eye(4), [-1.0, 0.2, -1.0, 0.0], [0.5, -0.1], ModelError, r"mu\[1\]"),
    (np.eye(4), [-1.0, 0.2, -1.0, 0.0], [0.5, np.nan], ModelError, "mu"),
])
def test_bad_problem_data_is_refused_with_the_argument_named(W, q, mu, error, name):
    for method in ("auto", "lcp", "nsgs"):
        with pytest.raises(error, match=f"^{name}: expected"):
            solve_friction_contact(W, q, mu, dim=2, method=method)
    with pytest.raises(error, match=f"^{name}: expected"):
        friction_residual(W, q, mu, np.zeros(len(q)), 2)


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"tol": -1.0}, "tol"), ({"tol": "1e-9"}, "tol"), ({"max_sweeps": 0}, "max_sweeps"),
    ({"max_sweeps": 2.5}, "max_sweeps"), ({"max_pivots": 0}, "max_pivots"),
    ({"max_local_iter": 0}, "max_local_iter"), ({"max_local_iter": "9"}, "max_local_iter"),
    ({"dim": 0}, "dim"), ({"dim": 4}, "dim"), ({"dim": True}, "dim"), ({"method": None}, "method"),
    ({"method": ["lcp"]}, "method"),
])
def test_bad_options_are_refused(kwargs, name):
    options = {"dim": 2, **kwargs}
    with pytest.raises(ModelError, match=f"^{name}: expected"):
        solve_friction_contact(np.eye(2), [-1.0, 0.2], 0.5, **options)


def test_the_helpers_check_their_input_too():
    with pytest.raises(ModelError, match="^dim: expected"):
        friction_residual(np.eye(2), [-1.0, 0.2], 0.5, [1.0, 0.0], 0)     # was ZeroDivision
    with pytest.raises(ModelError, match="^r: expected"):
        contact_states(["1", "0"], [0.0, 0.0], 2)                         # was parsed
    with pytest.raises(DimensionError, match="^u: expected a vector of length 2"):
        contact_states([1.0, 0.0], [0.0, 0.0, 0.0], 2)
    with pytest.raises(ModelError, match="^W: expected"):
        frictionless_impulses([["1", "0"], ["0", "1"]], [-1.0, 0.2], 2)
    with pytest.raises(DimensionError, match="^q: expected a length divisible"):
        frictionless_impulses(np.eye(3), [-1.0, 0.2, 0.0], 2)


# ----------------------------------------------------------------------------- verified status


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("dim", [2, 3])
def test_status_agrees_with_the_recomputed_residual_on_every_method(seed, dim):
    rng = np.random.default_rng(seed)
    cond = [1.0, 50.0, 1e6, 1e12][seed]            # up to nearly singular W
    W, q = _random_problem(rng, 8, dim, cond=cond)
    for method in (["auto", "lcp", "nsgs"] if dim == 2 else ["auto", "nsgs"]):
        try:
            res = solve_friction_contact(W, q, 0.4, dim=dim, method=method, max_sweeps=2000)
        except BudgetExceededError as err:
            res = err.partial
            assert err.budget == "max_sweeps" and res.status == "max_iter"
        # an independent round-off bound of u = W r + q, relative as the residual:
        # 2 k eps (1 + mu) sqrt(n) max(|W||r| + |q|) / scale, k = n + 1 terms (dense W)
        n = len(q)
        scale = max(np.linalg.norm(q), np.linalg.norm(res.r), np.linalg.norm(res.u))
        cancel = np.max(np.abs(W) @ np.abs(res.r) + np.abs(q)) / scale
        bound = 2 * (n + 1) * EPS * 1.4 * np.sqrt(n) * cancel
        # the residual is the one of r (recomputed in another summation order), and
        # "solved" means it passed a tolerance that is tol plus that bound
        independent = friction_residual(W, q, 0.4, res.r, dim)
        assert abs(res.residual - independent) <= 2 * bound
        assert res.success == (res.residual <= res.tolerance)
        assert res.tolerance <= 1e-12 + bound * (1 + 1e-12)


# ----------------------------------------------------------------------------- budgets


def _hard_spatial_contact():
    """One spatial contact whose slip direction has no bracketed root: the local solver
    falls back to the projected fixed point, which needs ~4500 steps from r = 0."""
    rng = np.random.default_rng(120)
    A = rng.standard_normal((3, 3))
    W = A @ A.T + 0.05 * np.eye(3)
    mu = float(rng.uniform(0.5, 3.0))
    q = rng.standard_normal(3)
    q[0] = -abs(q[0])
    return W, q, mu


def test_local_fixed_point_stops_at_its_budget():
    W, q, mu = _hard_spatial_contact()
    r = np.zeros(3)
    _, steps = kernels._local_fixed_point(W, q, mu, r, 10)
    assert steps == 10
    r = np.zeros(3)
    _, steps = kernels._local_fixed_point(W, q, mu, r, kernels.MAX_LOCAL_ITER)
    assert 10 < steps < kernels.MAX_LOCAL_ITER            # it converges within the default


def test_nsgs_sweep_and_local_budgets():
    W, q, mu = _hard_spatial_contact()
    full = solve_friction_contact(W, q, mu, dim=3, method="nsgs")
    assert full.success and full.iterations == 1
    # a small local budget: each sweep continues the fixed point from the last iterate
    res = solve_friction_contact(W, q, mu, dim=3, method="nsgs", max_local_iter=10)
    assert res.success and res.iterations > 1
    np.testing.assert_allclose(res.r, full.r, rtol=0, atol=1e-10 * np.abs(full.r).max())
    with pytest.raises(BudgetExceededError, match="^max_sweeps: ") as err:
        solve_friction_contact(W, q, mu, dim=3, method="nsgs", max_local_iter=10,
                               max_sweeps=3)
    e = err.value
    assert (e.budget, e.limit, e.used) == ("max_sweeps", 3, 3)
    assert e.partial.status == "max_iter" and e.partial.iterations == 3
    assert "budget max_sweeps = 3 sweeps spent" in str(e)


def test_lemke_pivot_budget_of_the_planar_lcp():
    W, q = _planar(6)
    with pytest.raises(BudgetExceededError, match="^max_pivots: ") as err:
        solve_friction_contact(W, q, 0.3, dim=2, method="lcp", max_pivots=1)
    assert (err.value.budget, err.value.limit, err.value.used) == ("max_pivots", 1, 1)
    assert solve_friction_contact(W, q, 0.3, dim=2, method="lcp").success


def test_a_result_is_an_immutable_record_read_by_name():
    res = solve_friction_contact(np.eye(3), np.array([-1.0, 1.0, 0.0]), 0.5, dim=3,
                                 method="nsgs")
    with pytest.raises(AttributeError):
        res.status = "max_iter"                          # type: ignore[misc]
    with pytest.raises(TypeError, match="by name"):
        _ = list(res)                                    # not a sequence of its fields
    back = pickle.loads(pickle.dumps(res))
    assert back.success and repr(back).startswith("FrictionContactResult(r=array(")
    for name in ("r", "u", "states"):
        np.testing.assert_array_equal(getattr(back, name), getattr(res, name))
    assert ((back.residual, back.iterations, back.method, back.status, back.tolerance,
             back.message) == (res.residual, res.iterations, res.method, res.status,
                               res.tolerance, res.message))
    made = FrictionContactResult(res.r, res.u, res.states, res.residual, res.iterations,
                                 res.method, res.status)     # the public constructor
    assert made.status == "solved" and np.isnan(made.tolerance) and made.message == ""

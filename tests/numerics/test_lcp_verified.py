"""Every LCP path decides "solved" from the residual of the z it returns (one test,
``_lcp_kernels.certify``), and every iterative loop has a budget that ends it with a status
or an error naming that budget."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nscontrol.errors import BudgetExceededError, DimensionError, ModelError, SolverError
from nscontrol.numerics import _lcp_kernels as kernels
from nscontrol.numerics.lcp import LCPResult, LCPSolver, residual, solve_lcp
from nscontrol.testing.lcp_problems import (
    degenerate_ties,
    no_solution,
    random_p_matrix,
    random_psd_matrix,
)

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(float).eps
TOL = 1e-12
PROPERTY = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def psd_family(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The family of the report: ``M = A A^T`` with ``A`` 9 x rank, rank < 9, ``q`` random.
    Many of its problems have no solution; Lemke ends on a ray there."""
    rng = np.random.default_rng(seed)
    rank = int(rng.integers(1, 9))
    A = rng.standard_normal((9, rank))
    return A @ A.T, rng.standard_normal(9)


def roundoff_bound(M, z, q) -> float:
    """An independent a-priori bound of the error of evaluating ``M z + q`` in float64,
    relative as the residual: ``gamma_{n+1} max(|M||z| + |q|) / (1 + max|q|)`` (Higham
    §3.1), with ``gamma_{n+1} <= 2 (n + 1) eps`` for any summation order."""
    Md = M.toarray() if sp.issparse(M) else M
    n = len(q)
    scale = 1.0 + np.abs(q).max(initial=0.0)
    return 2 * (n + 1) * EPS * float(np.max(np.abs(Md) @ np.abs(z) + np.abs(q),
                                            initial=0.0)) / scale


def assert_status_agrees_with_residual(res: LCPResult, M, q) -> None:
    """``solved`` exactly when the residual passes its tolerance, the residual is that of the
    returned z, and a solved z is a solution up to the round-off of evaluating M z + q."""
    assert res.success == (res.residual <= res.tolerance), res.message
    if not np.all(np.isfinite(res.z)):
        assert not res.success
        return
    bound = roundoff_bound(M, res.z, q)
    independent = residual(M, res.z, q)
    # both residuals evaluate M z + q from the same z, in different summation orders
    assert abs(independent - res.residual) <= 2 * bound + 1e-300, res.message
    if np.isfinite(res.tolerance):
        # the tolerance is the stated error estimate: tol plus that bound, taken with
        # max|M||z| + max|q| <= 2 max(|M||z| + |q|)
        assert res.tolerance <= TOL + 2 * bound * (1 + 1e-12)
    if res.success:
        assert independent <= TOL + 3 * bound
        assert res.z.min() >= -(TOL + bound) * (1 + np.abs(q).max())


def all_paths(M, q, methods=("auto", "lemke", "pgs", "banded")):
    """Every way a result is produced: ``solve_lcp`` per method (the fused compiled call of
    the first method, then ``auto``'s fallbacks), a reused ``LCPSolver`` cold and with a
    warm start (the Python runners), and ``M`` as a sparse matrix (Howard with sparse LU)."""
    n = len(q)
    for method in methods:
        yield f"solve_lcp {method}", solve_lcp(M, q, method=method, tol=TOL)
        solver = LCPSolver(M, method, tol=TOL)
        solver.solve(q)
        yield f"reused {method}", solver.solve(q)
        yield f"warm {method}", solver.solve(q, z0=np.zeros(n))
    yield "sparse auto", solve_lcp(sp.csr_matrix(M), q, tol=TOL)


# ----------------------------------------------------------------------------- item: wrong answer


@pytest.mark.parametrize("seed", [95, 213, 247, 337])
def test_reported_family_is_never_solved_with_a_large_residual(seed):
    # before: Lemke's ray, then PGS's polish solved a singular active block (|z| ~ 1e15)
    # and was accepted with residuals 0.14-0.92 because the round-off floor grew with |z|
    M, q = psd_family(seed)
    res = solve_lcp(M, q)
    assert not res.success, res.message
    assert res.status == "ray_termination"
    assert residual(M, res.z, q) > 1e-3       # indeed no solution: nothing small was hidden
    for _, r in all_paths(M, q):
        assert_status_agrees_with_residual(r, M, q)
        assert not r.success


def test_family_over_many_seeds_never_solved_above_tolerance():
    for seed in range(120):
        M, q = psd_family(seed)
        res = solve_lcp(M, q)
        assert_status_agrees_with_residual(res, M, q)


def test_certify_refuses_a_point_whose_residual_is_round_off():
    # a z on a near-ray: |M||z| ~ 1e16 (1 + |q|), where w = M z + q carries no digit
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    q = np.array([-1.0, 0.5])
    z = np.array([1e16, 1e16])
    w = np.empty(2)
    res, tolerance, ok = kernels.verify_dense(M, q, z, w, TOL)
    assert not ok and tolerance == -np.inf
    # an honest solution of the same size of entries passes
    z = np.array([1.0, 0.0])
    M2 = np.eye(2)
    res, tolerance, ok = kernels.verify_dense(M2, -z, z, w, TOL)
    assert ok and res == 0.0 and TOL <= tolerance <= TOL + 2 * 3 * EPS * 2


def _p_matrix(rng, n):
    return random_p_matrix(n, rng)


def _psd(rng, n):
    return random_psd_matrix(n, int(rng.integers(0, n + 1)), rng)


def _copositive(rng, n):
    # entrywise positive: strictly copositive, so the LCP has a solution for every q
    return np.abs(rng.standard_normal((n, n))) + 0.01


def _infeasible(rng, n):
    # PSD with M 1 = 0: with sum(q) < 0, y = 1 is a Farkas certificate of {z >= 0, Mz+q >= 0}
    # being empty
    B = rng.standard_normal((n, max(1, n - 2)))
    B -= B.mean(axis=0)
    return B @ B.T


FAMILIES = {"p-matrix": _p_matrix, "psd": _psd, "copositive": _copositive,
            "infeasible": _infeasible}


@PROPERTY
@given(family=st.sampled_from(sorted(FAMILIES)), n=st.integers(2, 10),
       seed=st.integers(0, 2**32 - 1))
def test_every_path_status_agrees_with_its_verified_residual(family, n, seed):
    rng = np.random.default_rng(seed)
    M = FAMILIES[family](rng, n)
    q = rng.standard_normal(n)
    if family == "infeasible":
        q -= q.mean() + 0.5                        # sum(q) = -n/2 < 0
    for path, res in all_paths(M, q):
        assert_status_agrees_with_residual(res, M, q)
        if family == "infeasible":
            assert not res.success, path
        if family in ("p-matrix", "copositive") and path.endswith(("auto", "lemke")):
            # Lemke solves every LCP with a P-matrix or a strictly copositive matrix
            assert res.success, f"{path}: {res.message}"


@PROPERTY
@given(n=st.integers(1, 12), seed=st.integers(0, 2**32 - 1))
def test_compiled_entries_report_solved_exactly_when_certified(n, seed):
    rng = np.random.default_rng(seed)
    M = np.ascontiguousarray(_psd(rng, n))
    q = rng.standard_normal(n)
    for run in (lambda z, w: kernels.lemke_verified(M, q, z, w, 0, TOL),
                lambda z, w: kernels.pgs_verified(M, q, z, w, TOL, 200, 1.0, True)):
        z, w = np.empty(n), np.empty(n)
        code, _, res, tolerance = run(z, w)
        assert (code == kernels.SOLVED) == (res <= tolerance)
        w2 = np.empty(n)
        again, tol2, ok = kernels.verify_dense(M, q, z, w2, TOL)
        assert ok == (code == kernels.SOLVED) and again == res and tol2 == tolerance


# ----------------------------------------------------------------------------- item: budgets


def test_lemke_budget_ends_a_degenerate_path_and_is_named():
    prob = degenerate_ties()
    res = solve_lcp(prob.M, prob.q, method="lemke", max_iter=1)
    assert res.status == "max_iter" and res.iterations == 1
    assert "budget max_iter = 1 pivots spent" in res.message
    with pytest.raises(BudgetExceededError, match="^max_iter: ") as err:
        solve_lcp(prob.M, prob.q, method="lemke", max_iter=1, strict=True)
    e = err.value
    assert (e.budget, e.limit, e.used, e.status) == ("max_iter", 1, 1, "budget")
    assert isinstance(e, SolverError) and e.partial.status == "max_iter"
    # the default cap 50 (n + 1) bounds any path: Lemke never runs unbounded
    full = solve_lcp(prob.M, prob.q, method="lemke")
    assert full.success and full.iterations <= 50 * (len(prob.q) + 1)


def test_pgs_budget_is_named_and_raises_when_strict():
    prob = no_solution()                   # PGS cannot converge: no solution exists
    res = solve_lcp(prob.M, prob.q, method="pgs", max_iter=7)
    assert res.status == "max_iter" and res.iterations == 7
    assert res.message == (f"pgs: max_iter (residual {res.residual:.3g}, budget max_iter = 7 "
                           "sweeps spent)")
    with pytest.raises(BudgetExceededError) as err:
        solve_lcp(prob.M, prob.q, method="pgs", max_iter=7, strict=True)
    assert (err.value.budget, err.value.limit, err.value.used) == ("max_iter", 7, 7)


def test_banded_budget_tridiagonal_and_sparse_paths():
    n = 40
    # the stack's Delassus matrix with an impact at one end: from z = 0 Howard needs one
    # iteration per contact the impact reaches (n), far beyond a budget of 3
    main = np.full(n, 2.0)
    main[-1] = 1.0
    M = sp.diags([-np.ones(n - 1), main, -np.ones(n - 1)], [-1, 0, 1], format="csr")
    q = np.full(n, 1e-3)
    q[0] = -1.0
    res = solve_lcp(M, q, method="banded", max_iter=3, z0=np.zeros(n))
    assert res.status == "max_iter" and res.iterations == 3
    assert "budget max_iter = 3 iterations spent" in res.message
    # a pentadiagonal matrix takes the Python Howard with sparse LU
    penta = sp.diags([np.full(n - 2, -0.5), -np.ones(n - 1), np.full(n, 4.0),
                      -np.ones(n - 1), np.full(n - 2, -0.5)], [-2, -1, 0, 1, 2], format="csr")
    res = solve_lcp(penta, q, method="banded", max_iter=1)
    assert res.status == "max_iter" and res.iterations == 1
    assert "budget max_iter = 1 iterations spent" in res.message


def test_auto_chain_is_bounded_and_names_every_budget():
    prob = no_solution()
    res = solve_lcp(prob.M, prob.q, max_iter=5)
    parts = res.message.split("; ")
    assert [p.split(":")[0] for p in parts] == ["lemke", "pgs", "banded"]
    assert "budget max_iter = 5 sweeps spent" in parts[1]
    assert res.status == "ray_termination" and not res.success


# ----------------------------------------------------------------------------- item: bad input


@pytest.mark.parametrize("strict", ["no", "yes", 1, None])
def test_strict_must_be_a_bool(strict):
    with pytest.raises(ModelError, match="^strict: expected True or False"):
        solve_lcp(np.eye(2), np.ones(2), strict=strict)
    with pytest.raises(ModelError, match="^strict: expected True or False"):
        LCPSolver(np.eye(2), strict=strict)


@pytest.mark.parametrize(("args", "error", "name"), [
    ((np.eye(2), ["1", "0"], [0.0, 0.0]), ModelError, "z"),           # was parsed
    ((np.eye(2), [1.0, 0.0], ["0", "0"]), ModelError, "q"),
    ((np.eye(2), [1.0, 0.0, 0.0], [0.0, 0.0]), DimensionError, "z"),
    ((np.eye(2), [1.0, 0.0], [0.0]), DimensionError, "q"),
    (([["1", "0"], ["0", "1"]], [1.0, 0.0], [0.0, 0.0]), ModelError, "M"),
    ((np.ones((2, 3)), [1.0, 0.0], [0.0, 0.0]), DimensionError, "M"),
])
def test_residual_checks_its_arguments(args, error, name):
    with pytest.raises(error, match=f"^{name}: expected"):
        residual(*args)

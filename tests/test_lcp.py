"""LCP solvers: conformance on problems with known answers, property tests on random
P-matrices and PSD matrices, the stack Delassus matrix, failures reported, bad input."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numba import njit
from scipy.optimize import linprog

from nscontrol.errors import DimensionError, ModelError, SolverError
from nscontrol.numerics._lcp_kernels import (
    lemke_kernel,
    pgs_kernel,
    tridiagonal_lcp_kernel,
)
from nscontrol.numerics.lcp import LCPResult, residual, solve_lcp
from nscontrol.testing.lcp_problems import (
    canonical_lcps,
    degenerate_ties,
    no_solution,
    random_p_matrix,
    random_psd_matrix,
    stack_delassus,
)

METHODS = ["auto", "lemke", "pgs", "banded"]
PROPERTY = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def assert_is_solution(res: LCPResult, M, q) -> None:
    """The properties every accepted result must have, recomputed independently."""
    assert res.success, res.message
    w = M @ res.z + q
    np.testing.assert_allclose(res.w, w, rtol=0, atol=1e-12 * (1 + np.abs(w).max()))
    assert res.residual <= 1e-10
    assert residual(M, res.z, q) <= 1e-10
    # Absolute 1e-12, widened only by the round-off of evaluating M z (|z| reaches 1e4 on
    # nearly singular PSD problems, where no float computation of M z + q is exact to 1e-12).
    norm_m = float(np.asarray(abs(M).sum(axis=1)).max())
    floor = max(1e-12, 16 * np.finfo(float).eps * (norm_m * np.abs(res.z).max()
                                                   + np.abs(q).max()))
    assert res.z.min() >= -1e-12 and res.w.min() >= -floor


def applies(method: str, problem) -> bool:
    """Whether a method is guaranteed to solve a (solvable) problem."""
    M = problem.M.toarray() if sp.issparse(problem.M) else problem.M
    symmetric_psd = np.allclose(M, M.T) and np.linalg.eigvalsh(M)[0] >= -1e-12
    if method == "pgs":
        return symmetric_psd and M.shape[0] <= 10
    if method == "banded":
        return problem.name.startswith("stack") or problem.name.startswith("2x2")
    return True


# ----------------------------------------------------------------------------- conformance


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("problem", canonical_lcps(), ids=lambda p: p.name)
def test_conformance_known_answers(problem, method):
    res = solve_lcp(problem.M, problem.q, method=method)
    if not problem.solvable:
        assert not res.success, "an infeasible LCP was reported solved"
        return
    if res.success:  # whichever method: a solution it reports must be right
        assert_is_solution(res, problem.M, problem.q)
        # PGS stops on the residual: its error in z is up to residual / lambda_min(M).
        atol = 1e-8 if res.method == "pgs" else 1e-12
        if problem.z is not None:
            np.testing.assert_allclose(res.z, problem.z, rtol=1e-10, atol=atol)
        if problem.w is not None:
            np.testing.assert_allclose(res.w, problem.w, atol=1e-10)
    if applies(method, problem):
        assert res.success, f"{method} failed on {problem.name}: {res.message}"


def test_degenerate_problem_terminates_with_the_solution():
    prob = degenerate_ties()
    res = solve_lcp(prob.M, prob.q, method="lemke", max_iter=100)
    assert res.status == "solved" and res.iterations < 100
    np.testing.assert_allclose(res.z, prob.z, atol=1e-14)


def test_no_solution_is_reported_and_strict_raises():
    prob = no_solution()
    res = solve_lcp(prob.M, prob.q, method="lemke")
    assert res.status == "ray_termination" and not res.success
    assert solve_lcp(prob.M, prob.q, method="pgs", max_iter=500).status == "max_iter"
    with pytest.raises(SolverError) as err:
        solve_lcp(prob.M, prob.q, strict=True)
    assert err.value.status == "ray_termination"
    assert "size 2" in str(err.value)


# ----------------------------------------------------------------------------- properties


@PROPERTY
@given(n=st.integers(1, 60), seed=st.integers(0, 2**32 - 1))
def test_random_p_matrices_are_solved(n, seed):
    rng = np.random.default_rng(seed)
    M = random_p_matrix(n, rng)
    q = rng.standard_normal(n)
    results = [solve_lcp(M, q, method=m) for m in ("lemke", "auto")]
    for res in results:
        assert_is_solution(res, M, q)
    # Unique solution: both agree.
    np.testing.assert_allclose(results[0].z, results[1].z, atol=1e-9)


@PROPERTY
@given(n=st.integers(1, 30), seed=st.integers(0, 2**32 - 1))
def test_all_methods_agree_on_symmetric_positive_definite(n, seed):
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((n, n))
    M = B @ B.T / n + np.eye(n)  # well conditioned: PGS converges quickly
    q = rng.standard_normal(n)
    ref = solve_lcp(M, q, method="lemke")
    assert_is_solution(ref, M, q)
    for method in ("pgs", "auto"):
        res = solve_lcp(M, q, method=method, max_iter=20_000)
        assert_is_solution(res, M, q)
        np.testing.assert_allclose(res.z, ref.z, atol=1e-9)


@PROPERTY
@given(n=st.integers(2, 60), seed=st.integers(0, 2**32 - 1))
def test_all_methods_agree_on_tridiagonal_m_matrices(n, seed):
    rng = np.random.default_rng(seed)
    off = -rng.uniform(0.0, 1.0, n - 1)
    diag = rng.uniform(0.1, 1.0, n) + np.abs(np.r_[off, 0]) + np.abs(np.r_[0, off])
    M = np.diag(diag) + np.diag(off, 1) + np.diag(off, -1)  # diagonally dominant Stieltjes
    q = rng.standard_normal(n)
    ref = solve_lcp(M, q, method="lemke")
    assert_is_solution(ref, M, q)
    for method, matrix in (("banded", M), ("banded", sp.csr_matrix(M)), ("auto", M)):
        res = solve_lcp(matrix, q, method=method)
        assert_is_solution(res, M, q)
        np.testing.assert_allclose(res.z, ref.z, atol=1e-10)
        # Howard's iteration on an M-matrix: at most n + 1 active-set solves (Bokanowski et al.)
        assert res.method == "lemke" or res.iterations <= n + 1


@PROPERTY
@given(n=st.integers(3, 40), seed=st.integers(0, 2**32 - 1))
def test_banded_on_pentadiagonal_m_matrices_uses_sparse_lu_and_agrees(n, seed):
    rng = np.random.default_rng(seed)
    off1, off2 = -rng.uniform(0, 1, n - 1), -rng.uniform(0, 1, n - 2)
    M = np.diag(off1, 1) + np.diag(off1, -1) + np.diag(off2, 2) + np.diag(off2, -2)
    M += np.diag(np.abs(M).sum(axis=1) + rng.uniform(0.1, 1.0, n))  # strictly dominant
    q = rng.standard_normal(n)
    ref = solve_lcp(M, q, method="lemke")
    res = solve_lcp(sp.csr_matrix(M), q, method="banded")
    assert_is_solution(res, M, q)
    np.testing.assert_allclose(res.z, ref.z, atol=1e-10)


def _infeasible(M, q) -> bool:
    """No z >= 0 with M z + q >= 0 (LP phase one)."""
    n = len(q)
    lp = linprog(np.zeros(n), A_ub=-M, b_ub=q, bounds=[(0, None)] * n, method="highs")
    return lp.status == 2


@PROPERTY
@given(n=st.integers(1, 40), rank=st.integers(0, 40), seed=st.integers(0, 2**32 - 1))
def test_random_psd_solved_or_certified_infeasible(n, rank, seed):
    rng = np.random.default_rng(seed)
    M = random_psd_matrix(n, rank, rng)
    q = rng.standard_normal(n)
    res = solve_lcp(M, q, method="lemke")
    if res.success:
        assert_is_solution(res, M, q)
    else:
        # PSD is copositive-plus: Lemke's ray means the LCP is infeasible.
        assert res.status == "ray_termination"
        assert _infeasible(M, q)


@pytest.mark.parametrize("n_masses", [1, 10, 1000, 10_000])
def test_stack_gives_the_analytic_impulses(n_masses):
    prob = stack_delassus(n_masses)
    for method in ("banded", "auto"):
        res = solve_lcp(prob.M, prob.q, method=method)
        # auto hands 1x1 and 2x2 problems to Lemke (no structure worth exploiting)
        assert res.success and res.method == ("lemke" if n_masses <= 2 and method == "auto"
                                              else "banded")
        np.testing.assert_allclose(res.z, prob.z, rtol=1e-10)
        assert np.abs(res.w).max() <= 1e-10


def test_banded_failure_falls_back_to_lemke():
    # A tridiagonal P-matrix that is not an M-matrix: Howard's Thomas sweep meets a
    # non-positive pivot, banded says so, auto hands over to Lemke.
    M = np.array([[1.1, -0.9, 0.0], [-1.1, 1.1, 1.7], [0.0, 1.1, 1.2]])
    q = np.array([0.1, -0.8, -1.3])
    banded = solve_lcp(M, q, method="banded")
    assert not banded.success
    res = solve_lcp(M, q)
    assert_is_solution(res, M, q)
    assert res.method == "lemke" and "banded" in res.message


def test_pgs_warm_start_converges_immediately():
    prob = stack_delassus(10, sparse=False)
    res = solve_lcp(prob.M, prob.q, method="pgs", z0=prob.z)
    assert res.success and res.iterations == 0


@njit(cache=True)
def _all_kernels_from_njit(M, q, lower, diag, upper):
    n = q.shape[0]
    z1, w1, z2, w2 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    s1, _ = lemke_kernel(M, q, z1, w1, 0)
    s2, _ = tridiagonal_lcp_kernel(lower, diag, upper, q, z2, w2, 0)
    z3, w3 = np.zeros(n), np.empty(n)
    s3, _ = pgs_kernel(M, q, z3, w3, 1e-12, 100_000, 1.5)
    return s1, s2, s3, z1, z2, z3


def test_kernels_are_callable_from_njit_code():
    both = _all_kernels_from_njit
    prob = stack_delassus(20, sparse=False)
    M = prob.M
    s1, s2, s3, z1, z2, z3 = both(M, prob.q, np.diagonal(M, -1).copy(), np.diagonal(M).copy(),
                                  np.diagonal(M, 1).copy())
    assert (s1, s2, s3) == (0, 0, 0)
    for z in (z1, z2, z3):
        np.testing.assert_allclose(z, prob.z, rtol=1e-9)


def test_result_is_frozen():
    res = solve_lcp(np.eye(2), [-1.0, 1.0])
    with pytest.raises(AttributeError):
        res.status = "x"  # type: ignore[misc]
    with pytest.raises(ValueError):
        res.z[0] = 5.0


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(("M", "q", "kwargs", "error", "names"), [
    (np.ones((2, 3)), np.ones(2), {}, DimensionError, "M"),
    (np.ones(3), np.ones(3), {}, DimensionError, "M"),
    (np.eye(3), np.ones(2), {}, DimensionError, "q"),
    (np.eye(2), np.ones((2, 1)), {}, DimensionError, "q"),
    (np.array([[1.0, np.nan], [0.0, 1.0]]), np.ones(2), {}, ModelError, "M"),
    (np.eye(2), np.array([1.0, np.inf]), {}, ModelError, "q"),
    (sp.csr_matrix(np.array([[1.0, np.inf], [0.0, 1.0]])), np.ones(2), {}, ModelError, "M"),
    (sp.csr_matrix(np.ones((2, 3))), np.ones(2), {}, DimensionError, "M"),
    (np.eye(2), np.ones(2), {"z0": np.ones(3)}, DimensionError, "z0"),
    (np.eye(2), np.ones(2), {"method": "simplex"}, ModelError, "method"),
    (np.eye(2), np.ones(2), {"tol": -1.0}, ModelError, "tol"),
    (np.eye(2), np.ones(2), {"omega": 2.5}, ModelError, "omega"),
    (np.eye(2), np.ones(2), {"max_iter": 0}, ModelError, "max_iter"),
    ([["a", "b"], ["c", "d"]], np.ones(2), {}, ModelError, "M"),
])
def test_bad_input_raises_its_specific_error(M, q, kwargs, error, names):
    with pytest.raises(error, match=f"^{names}: expected"):
        solve_lcp(M, q, **kwargs)

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

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

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
    # Non-symmetric and not a Z-matrix: of the methods only Lemke applies (and auto picks it).
    res = solve_lcp(M, q, method="lemke")
    assert_is_solution(res, M, q)
    auto = solve_lcp(M, q)
    assert_is_solution(auto, M, q)
    assert auto.method == "lemke"


@PROPERTY
@given(n=st.integers(1, 30), seed=st.integers(0, 2**32 - 1))
def test_lemke_and_pgs_agree_on_symmetric_positive_definite(n, seed):
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((n, n))
    M = B @ B.T / n + np.eye(n)  # well conditioned: PGS converges quickly
    q = rng.standard_normal(n)
    lemke = solve_lcp(M, q, method="lemke")
    pgs = solve_lcp(M, q, method="pgs", max_iter=20_000)
    for res in (lemke, pgs):
        assert_is_solution(res, M, q)
    assert (lemke.method, pgs.method) == ("lemke", "pgs")
    # unique solution (P-matrix); PGS's z carries the polish's round-off only
    np.testing.assert_allclose(pgs.z, lemke.z, atol=1e-9)


@PROPERTY
@given(n=st.integers(2, 60), seed=st.integers(0, 2**32 - 1))
def test_lemke_pgs_and_banded_agree_on_tridiagonal_m_matrices(n, seed):
    rng = np.random.default_rng(seed)
    off = -rng.uniform(0.0, 1.0, n - 1)
    diag = rng.uniform(0.1, 1.0, n) + np.abs(np.r_[off, 0]) + np.abs(np.r_[0, off])
    M = np.diag(diag) + np.diag(off, 1) + np.diag(off, -1)  # diagonally dominant Stieltjes
    q = rng.standard_normal(n)
    ref = solve_lcp(M, q, method="lemke")
    assert_is_solution(ref, M, q)
    runs = {"banded dense": solve_lcp(M, q, method="banded"),
            "banded sparse": solve_lcp(sp.csr_matrix(M), q, method="banded"),
            "pgs": solve_lcp(M, q, method="pgs", max_iter=100_000)}
    for label, res in runs.items():
        assert_is_solution(res, M, q)
        assert res.method == label.split()[0]
        np.testing.assert_allclose(res.z, ref.z, atol=1e-9 if label == "pgs" else 1e-10)
    # Howard's iteration on an M-matrix: at most n + 1 active-set solves (Bokanowski et al.)
    assert runs["banded dense"].iterations <= n + 1
    if n > 2:
        assert solve_lcp(M, q).method == "banded"


@PROPERTY
@given(n=st.integers(3, 40), seed=st.integers(0, 2**32 - 1))
def test_banded_on_pentadiagonal_m_matrices_uses_sparse_lu_and_agrees(n, seed):
    rng = np.random.default_rng(seed)
    off1, off2 = -rng.uniform(0, 1, n - 1), -rng.uniform(0, 1, n - 2)
    M = np.diag(off1, 1) + np.diag(off1, -1) + np.diag(off2, 2) + np.diag(off2, -2)
    M += np.diag(np.abs(M).sum(axis=1) + rng.uniform(0.1, 1.0, n))  # strictly dominant
    q = rng.standard_normal(n)
    ref = solve_lcp(M, q, method="lemke")
    banded = solve_lcp(sp.csr_matrix(M), q, method="banded")
    pgs = solve_lcp(M, q, method="pgs", max_iter=100_000)
    auto = solve_lcp(sp.csr_matrix(M), q)
    for res in (ref, banded, pgs, auto):
        assert_is_solution(res, M, q)
    assert (banded.method, pgs.method, auto.method) == ("banded", "pgs", "banded")
    np.testing.assert_allclose(banded.z, ref.z, atol=1e-10)
    np.testing.assert_allclose(pgs.z, ref.z, atol=1e-9)


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


def _propagating_impact(n: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """Stack Delassus matrix with an impact at one end and small positive gaps elsewhere:
    Howard's iteration from z = 0 adds one contact per iteration (n iterations for
    n <= 1000, where the impact reaches the end of the chain)."""
    M = stack_delassus(n).M
    q = np.full(n, 1e-3)
    q[0] = -1.0
    return M, q


@pytest.mark.parametrize("n", [10, 1000, 10_000])
def test_banded_starting_sweeps_solve_a_propagating_impact_without_iterating(n):
    M, q = _propagating_impact(n)
    res = solve_lcp(M, q, method="banded")
    assert_is_solution(res, M, q)
    assert res.iterations == 0                     # from z = 0 Howard needs n iterations
    z0 = solve_lcp(M, q, method="banded", z0=np.zeros(n))   # the plain iteration, warm start 0
    # one contact per iteration, as deep as the impact reaches (about 1 / 1e-3 contacts)
    assert z0.success and z0.iterations == min(n, 1000)
    # two direct solves of one system whose condition number grows like n^2
    np.testing.assert_allclose(res.z, z0.z, rtol=1e-15 * n ** 2, atol=1e-15)
    # the impact at the other end, and in the middle
    # the impact at the other end, and in the middle: exact starts while the impact reaches
    # an end of the chain (one free boundary); a region inside a long chain has two, and
    # costs about half its depth in iterations (documented in docs/lcp.md)
    for where in (n - 1, n // 2):
        q2 = np.full(n, 1e-3)
        q2[where] = -1.0
        res2 = solve_lcp(M, q2, method="banded")
        assert_is_solution(res2, M, q2)
        assert res2.iterations <= (1 if where == n - 1 or n <= 1000 else 600)


def test_howard_does_not_stop_at_a_feasible_but_not_complementary_start():
    prob = stack_delassus(20, sparse=False)
    z0 = 2.0 * prob.z                        # feasible: w = -q >= 0, but z0[0] w[0] > 0
    assert np.all(prob.M @ z0 + prob.q >= -1e-15) and (prob.M @ z0 + prob.q)[0] > 0.0
    for M in (prob.M, sp.csr_matrix(prob.M) + sp.diags(np.full(18, -1e-3), 2)
              + sp.diags(np.full(18, -1e-3), -2)):
        res = solve_lcp(M, prob.q, method="banded", z0=z0)
        assert_is_solution(res, M, prob.q)
        assert res.iterations >= 1


def test_sparse_howard_detects_a_cycle_and_auto_falls_back():
    # Pentadiagonal matrices that are not Z-matrices: Howard's iteration may cycle between
    # active sets; the repetition is detected at once (not after max_iter sparse
    # factorisations) and reported as max_iter; auto hands over to Lemke.
    rng = np.random.default_rng(4)
    cycles = 0
    for _ in range(300):
        n = int(rng.integers(3, 9))
        M = np.eye(n) * rng.uniform(0.5, 2.0)
        for k in (1, 2):
            M += np.diag(rng.uniform(-2, 2, n - k), k) + np.diag(rng.uniform(-2, 2, n - k), -k)
        q = rng.standard_normal(n)
        res = solve_lcp(sp.csr_matrix(M), q, method="banded", max_iter=1000)
        if res.status != "max_iter":
            continue
        cycles += 1
        assert res.iterations <= 2 ** n             # stopped at the first repeated set
        auto = solve_lcp(sp.csr_matrix(M), q)
        assert auto.message.startswith("banded: max_iter")
        if auto.success:
            assert auto.method == "lemke"
            assert_is_solution(auto, M, q)
    assert cycles >= 10


def test_auto_dispatch_by_structure():
    rng = np.random.default_rng(2)
    n = 300
    off1, off2 = -rng.uniform(0, 1, n - 1), -rng.uniform(0, 1, n - 2)
    P = np.diag(off1, 1) + np.diag(off1, -1) + np.diag(off2, 2) + np.diag(off2, -2)
    P += np.diag(np.abs(P).sum(axis=1) + 0.5)
    q = rng.standard_normal(n)
    assert solve_lcp(sp.csr_matrix(P), q).method == "banded"    # sparse: no densifying
    assert solve_lcp(P, q).method == "banded"                   # dense with a narrow band
    B = rng.standard_normal((500, 500))
    S = B @ B.T / 500 + np.eye(500)
    qs = rng.standard_normal(500)
    res = solve_lcp(S, qs)
    assert_is_solution(res, S, qs)
    assert res.method == "pgs" and res.message.startswith("pgs: solved")
    # symmetric, positive diagonal, but indefinite and PGS does not converge: Lemke takes over
    A = rng.standard_normal((450, 450))
    Ind = np.diag(np.full(450, 1.0)) + 3.0 * (A + A.T)
    Ind[np.diag_indices(450)] = np.abs(np.diag(Ind)) + 0.1
    qi = -np.abs(rng.standard_normal(450))
    res = solve_lcp(Ind, qi)
    assert res.message.split(";")[0].startswith("pgs: ")
    if res.success:
        assert_is_solution(res, Ind, qi)


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
    (np.eye(2) * (1 + 1j), np.ones(2), {}, ModelError, "M"),
    (np.eye(2), np.array([1.0, 1.0j]), {}, ModelError, "q"),
    (sp.csr_matrix(np.eye(2) * 1j), np.ones(2), {}, ModelError, "M"),
    (np.eye(2), np.ones(2), {"z0": [1j, 0.0]}, ModelError, "z0"),
    (np.eye(2), np.ones(2), {"tol": "small"}, ModelError, "tol"),
    (np.eye(2), np.ones(2), {"tol": None}, ModelError, "tol"),
    (np.eye(2), np.ones(2), {"omega": "fast"}, ModelError, "omega"),
    (np.eye(2), np.ones(2), {"omega": 0.0}, ModelError, "omega"),
    (np.eye(2), np.ones(2), {"max_iter": 2.7}, ModelError, "max_iter"),
    (np.eye(2), np.ones(2), {"max_iter": "10"}, ModelError, "max_iter"),
    (np.eye(2), np.ones(2), {"max_iter": True}, ModelError, "max_iter"),
])
def test_bad_input_raises_its_specific_error(M, q, kwargs, error, names):
    with pytest.raises(error, match=f"^{names}: expected"):
        solve_lcp(M, q, **kwargs)

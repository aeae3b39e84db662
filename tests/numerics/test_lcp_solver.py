"""The reusable LCP solver: one code path with solve_lcp, reuse over many q, bad q refused
with the argument named; auto's fallbacks (Murty's triangular family); overflow reported."""

import numpy as np
import pytest
import scipy.sparse as sp

from nscontrol.errors import DimensionError, ModelError, SolverError
from nscontrol.numerics.lcp import LCPResult, LCPSolver, solve_lcp
from nscontrol.testing.lcp_problems import no_solution, random_p_matrix

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(np.float64).eps


def spd_matrix(n: int, rng: np.random.Generator) -> np.ndarray:
    B = rng.standard_normal((n, n))
    return B @ B.T / n + np.eye(n)


def tridiagonal_m_matrix(n: int, rng: np.random.Generator) -> np.ndarray:
    off = -rng.uniform(0.0, 1.0, n - 1)
    M = np.diag(off, 1) + np.diag(off, -1)
    return M + np.diag(np.abs(M).sum(axis=1) + rng.uniform(0.1, 1.0, n))


def pentadiagonal_m_matrix(n: int, rng: np.random.Generator) -> sp.csr_matrix:
    M = np.zeros((n, n))
    for k in (1, 2):
        off = -rng.uniform(0.0, 1.0, n - k)
        M += np.diag(off, k) + np.diag(off, -k)
    return sp.csr_matrix(M + np.diag(np.abs(M).sum(axis=1) + 0.5))


def assert_matches_active_set_solve(res: LCPResult, M, q) -> None:
    """Compare ``res.z`` with an independent LAPACK solve of ``M[a, a] z_a = -q_a`` on its
    active set ``a = {z > w}`` (the unique solution for these P-matrices if ``z_a >= 0``
    and ``w >= 0`` off ``a``).

    Tolerance: both are backward stable (Lemke refined against the exact basis, banded's
    Thomas/LU, PGS's polish), so each is within ``cond(M_aa) * c n eps * ||z||`` of the
    exact solution (forward error <= condition number x backward error, with the backward
    error of a dense solve <= c n eps, c = 8 taken generously).
    """
    dense = M.toarray() if sp.issparse(M) else M
    assert res.success, res.message
    active = np.flatnonzero(res.z > res.w)
    z_ref = np.zeros_like(res.z)
    if active.size:
        block = dense[np.ix_(active, active)]
        z_ref[active] = np.linalg.solve(block, -q[active])
        cond = np.linalg.cond(block, p=np.inf)
    else:
        cond = 1.0
    n = len(q)
    # both errors add up: 2 x (8 n eps) x cond x ||z||; an empty active set means z = 0
    # exactly on both sides (tol = 0)
    tol = 2 * 8 * n * EPS * cond * np.abs(z_ref).max()
    np.testing.assert_allclose(res.z, z_ref, rtol=0, atol=tol)
    w_ref = dense @ z_ref + q
    # the solution conditions of the reference itself, to the round-off of M z + q
    floor = 8 * n * EPS * (np.abs(dense).sum(axis=1).max() * np.abs(z_ref).max()
                           + np.abs(q).max())
    assert z_ref.min() >= 0.0 and w_ref.min() >= -floor


def assert_same_result(a: LCPResult, b: LCPResult) -> None:
    """One code path: bit-identical results, not merely close ones."""
    np.testing.assert_array_equal(a.z, b.z)
    np.testing.assert_array_equal(a.w, b.w)
    assert (a.status, a.iterations, a.residual, a.method, a.message) == (
        b.status, b.iterations, b.residual, b.method, b.message)


# ----------------------------------------------------------------------------- agreement


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("family", ["p-matrix", "spd", "spd-pgs", "tridiagonal",
                                    "tridiagonal-sparse", "pentadiagonal-sparse"])
def test_solver_agrees_with_solve_lcp_and_with_a_direct_solve(family, seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 80))
    method = "auto"
    if family == "p-matrix":
        M = random_p_matrix(n, rng)
    elif family.startswith("spd"):
        M = spd_matrix(n, rng)
        method = "pgs" if family == "spd-pgs" else "auto"
    elif family.startswith("tridiagonal"):
        M = tridiagonal_m_matrix(n, rng)
        M = sp.csr_matrix(M) if family.endswith("sparse") else M
    else:
        M = pentadiagonal_m_matrix(max(n, 3), rng)
        n = M.shape[0]
    solver = LCPSolver(M, method)
    expected_first = {"p-matrix": "lemke", "spd": "lemke", "spd-pgs": "pgs"}.get(family,
                                                                                "banded")
    assert solver.first_method == expected_first
    for _ in range(3):
        q = rng.standard_normal(n)
        res = solver.solve(q)
        assert_same_result(res, solve_lcp(M, q, method=method))
        assert res.method == expected_first
        assert_matches_active_set_solve(res, M, q)


def test_one_solver_reused_over_many_q():
    rng = np.random.default_rng(11)
    n = 20
    M = random_p_matrix(n, rng)
    solver = LCPSolver(M)
    qs = rng.standard_normal((200, n))
    results = [solver.solve(q) for q in qs]
    for q, res in zip(qs, results, strict=True):
        # later calls did not overwrite an earlier result (no shared buffers)
        assert_same_result(res, solve_lcp(M, q))
        assert_matches_active_set_solve(res, M, q)
    # solving again gives the same answer: the solver keeps no state between calls
    assert_same_result(solver.solve(qs[0]), results[0])


def test_solver_accepts_any_vector_like_q_and_warm_starts():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    solver = LCPSolver(M)
    expected = solver.solve(np.array([-5.0, -6.0]))
    strided = np.array([-5.0, 0.0, -6.0])[::2]             # not contiguous
    frozen = np.array([-5.0, -6.0])
    frozen.setflags(write=False)                            # e.g. an earlier result's z
    for q in ([-5, -6], (-5.0, -6.0), strided, frozen, np.array([-5, -6], dtype=np.int32)):
        assert_same_result(solver.solve(q), expected)
    pgs = LCPSolver(M, "pgs")
    assert pgs.solve(np.array([-5.0, -6.0]), z0=expected.z).iterations == 0


@pytest.mark.parametrize(("q", "kwargs", "error"), [
    (np.ones(3), {}, DimensionError),
    (np.ones((2, 1)), {}, DimensionError),
    (np.ones((1, 2)), {}, DimensionError),
    (np.array([1.0, np.nan]), {}, ModelError),
    (np.array([np.inf, 1.0]), {}, ModelError),
    (["a", "b"], {}, ModelError),
    ("12", {}, ModelError),
    (np.array([1.0, 1.0j]), {}, ModelError),
    ([1.0, None], {}, ModelError),
    (np.ones(2), {"z0": np.ones(3)}, DimensionError),
    (np.ones(2), {"z0": [np.nan, 0.0]}, ModelError),
])
@pytest.mark.parametrize("method", ["auto", "lemke", "pgs", "banded"])
def test_bad_q_raises_with_the_argument_named(q, kwargs, error, method):
    name = "z0" if kwargs else "q"
    for M in (np.array([[2.0, -1.0], [-1.0, 2.0]]),
              sp.csr_matrix(np.array([[2.0, -1.0], [-1.0, 2.0]]))):
        solver = LCPSolver(M, method)
        with pytest.raises(error, match=f"^{name}: expected"):
            solver.solve(q, **kwargs)


@pytest.mark.parametrize("method", ["auto", "lemke", "pgs", "banded"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_q_refused_by_every_kernel_path(method, bad):
    # 3x3 tridiagonal: auto and banded take the fused Thomas kernel, which checks q itself
    q = np.array([1.0, bad, -1.0])
    for M in (np.diag(np.full(3, 2.0)), sp.csr_matrix(np.diag(np.full(3, 2.0))),
              np.array([[2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [1.0, 0.0, 2.0]])):
        with pytest.raises(ModelError, match="^q: expected finite entries"):
            LCPSolver(M, method).solve(q)


@pytest.mark.parametrize(("M", "kwargs", "error", "name"), [
    (np.ones((2, 3)), {}, DimensionError, "M"),
    (np.array([[1.0, np.nan], [0.0, 1.0]]), {}, ModelError, "M"),
    (np.eye(2), {"method": "simplex"}, ModelError, "method"),
    (np.eye(2), {"tol": 0.0}, ModelError, "tol"),
    (np.eye(2), {"tol": float("nan")}, ModelError, "tol"),
    (np.eye(2), {"omega": 2.0}, ModelError, "omega"),
    (np.eye(2), {"max_iter": 1.5}, ModelError, "max_iter"),
])
def test_bad_matrix_or_options_refused_at_construction(M, kwargs, error, name):
    with pytest.raises(error, match=f"^{name}: expected"):
        LCPSolver(M, **kwargs)


# ----------------------------------------------------------------------------- fallbacks


def murty_matrix(n: int) -> np.ndarray:
    """Unit lower-triangular with 2 below the diagonal: a P-matrix on which Lemke's path
    from ``q = -1`` takes exactly 2^n pivots (Murty 1978)."""
    return np.eye(n) + np.tril(np.full((n, n), 2.0), -1)


@pytest.mark.parametrize("n", range(9, 31))
def test_auto_falls_back_on_murty_triangular_family(n):
    M, q = murty_matrix(n), -np.ones(n)
    lemke = solve_lcp(M, q, method="lemke")   # 50 (n + 1) pivots < 2^n for n >= 9
    assert lemke.status == "max_iter"
    res = solve_lcp(M, q)
    e1 = np.zeros(n)
    e1[0] = 1.0
    # the unique solution z = e1 (w = (0, 1, ..., 1)): integers, exact in floating point
    np.testing.assert_array_equal(res.z, e1)
    assert res.success and res.method == "pgs"
    assert res.message.startswith("lemke: max_iter") and "pgs: solved" in res.message
    assert_same_result(LCPSolver(M).solve(q), res)


@pytest.mark.parametrize("n", [3, 9, 12])
def test_lemke_path_on_murty_family_is_2_to_the_n(n):
    # the reason for the fallback: Lemke does solve it, after 2^n pivots
    res = solve_lcp(murty_matrix(n), -np.ones(n), method="lemke", max_iter=2 ** n)
    assert res.success and res.iterations == 2 ** n


def test_when_every_method_fails_the_message_lists_them_and_ray_is_kept():
    prob = no_solution()
    res = solve_lcp(prob.M, prob.q)
    assert res.status == "ray_termination" and res.method == "lemke"
    tried = [part.split(":")[0] for part in res.message.split("; ")]
    assert tried == ["lemke", "pgs", "banded"]
    with pytest.raises(SolverError, match="lemke: ray_termination") as err:
        LCPSolver(prob.M, strict=True).solve(prob.q)
    assert err.value.status == "ray_termination"


def test_fixed_method_does_not_fall_back():
    n = 12
    res = solve_lcp(murty_matrix(n), -np.ones(n), method="lemke")
    assert res.status == "max_iter" and res.message == (
        f"lemke: max_iter (residual {0.5:.3g}, budget max_iter = {50 * (n + 1)} pivots spent)")


# ----------------------------------------------------------------------------- overflow


def test_overflowing_solution_is_reported_as_overflow_not_infeasible():
    res = solve_lcp([[0.5]], [-1.7e308])
    assert res.status == "overflow" and not res.success
    assert res.message.startswith("q: the solution overflows float64")
    assert "max|q| = 1.7e+308" in res.message and "Rescale" in res.message
    assert np.isinf(res.z[0]) and res.z[0] > 0
    with pytest.raises(SolverError, match="overflows") as err:
        solve_lcp([[0.5]], [-1.7e308], strict=True)
    assert err.value.status == "overflow"
    # tiny M: the solution 1e10 / 1e-300 overflows as well, whatever the method
    for method in ("auto", "lemke", "banded", "pgs"):
        assert solve_lcp([[1e-300]], [-1e10], method=method).status == "overflow"


def test_extreme_but_representable_scales_are_solved():
    # z = 3.4e300 fits in float64: solved, exactly 2 * 1.7e300 (powers of two are exact)
    res = solve_lcp([[0.5]], [-1.7e300])
    assert res.success and res.z[0] == 2 * 1.7e300
    # an infeasible problem stays infeasible at any scale
    prob = no_solution()
    assert solve_lcp(prob.M, prob.q * 1e300).status == "ray_termination"


def test_solver_pickles_and_keeps_solving():
    import pickle

    rng = np.random.default_rng(3)
    M, q = random_p_matrix(8, rng), rng.standard_normal(8)
    for matrix in (M, tridiagonal_m_matrix(8, rng), sp.csr_matrix(tridiagonal_m_matrix(8, rng))):
        solver = LCPSolver(matrix)
        solver.solve(q)                      # caches filled before pickling
        clone = pickle.loads(pickle.dumps(solver))
        assert_same_result(clone.solve(q), solver.solve(q))
        assert repr(clone) == repr(solver)


def test_every_form_of_m_takes_the_same_path():
    # the fast path (writeable C-contiguous float64) and the general conversion agree
    rng = np.random.default_rng(5)
    M, q = random_p_matrix(6, rng), rng.standard_normal(6)
    frozen = M.copy()
    frozen.setflags(write=False)
    expected = solve_lcp(M, q)
    for form in (M.tolist(), np.asfortranarray(M), frozen, M[:, ::-1][:, ::-1]):
        assert_same_result(solve_lcp(form, q), expected)
    integer = np.array([[2, 1], [1, 2]])
    assert_same_result(solve_lcp(integer, [-5.0, -6.0]),
                       solve_lcp(integer.astype(float), np.array([-5.0, -6.0])))

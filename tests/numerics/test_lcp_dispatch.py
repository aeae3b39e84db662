"""The compiled dispatch of the LCP methods: ``solve_lcp``, ``LCPSolver`` and the compiled
entry ``solve_lcp_kernel`` give the same answers from the same analysis and chain; ``auto``'s
fallbacks run in compiled code; the order of the fallbacks is decided in one place; bad
input is refused with the argument named."""

import pickle

import numpy as np
import pytest
import scipy.sparse as sp
from numba import njit

from nscontrol.errors import DimensionError, ModelError, SolverError
from nscontrol.numerics import _lcp_dispatch_kernels as dispatch
from nscontrol.numerics import lcp
from nscontrol.numerics.lcp import LCPResult, LCPSolver, solve_lcp, solve_lcp_kernel
from nscontrol.testing.lcp_problems import random_p_matrix

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(np.float64).eps

#: A bimatrix game ``[[0, A], [B, 0]]`` with positive ``A``, ``B`` and ``q = -1`` (the
#: game's equilibria are its solutions, Cottle, Pang & Stone 1992, §1.2): Lemke's path with
#: the covering vector ``d = 1`` ends on a ray at once, so ``auto`` must fall back (no PGS:
#: the diagonal is zero; Howard's iteration solves it).
GAME = np.block([[np.zeros((2, 2)), np.array([[1.0, 3.0], [2.0, 1.0]])],
                 [np.array([[3.0, 1.0], [1.0, 2.0]]), np.zeros((2, 2))]])
#: No solution: ``M`` is skew-symmetric (copositive-plus) and ``w_2 = -z_1 - 1 < 0`` for
#: every ``z >= 0``. Lemke ends on a ray (for copositive-plus ``M``: infeasible), and so
#: must the result be after every fallback failed.
INFEASIBLE = (np.array([[0.0, 1.0], [-1.0, 0.0]]), np.array([-1.0, -1.0]))


def independent_residual(M, q, z):
    """``max|min(z, Mz + q)| / (1 + max|q|)`` in numpy, and its round-off bound
    ``2 (n + 1) eps (max(|M||z|) + max|q|) / (1 + max|q|)`` (Higham §3.1, the bound of
    evaluating ``M z + q`` in float64, doubled for the evaluation here)."""
    n = len(q)
    scale = 1.0 + np.abs(q).max()
    res = np.abs(np.minimum(z, M @ z + q)).max() / scale
    bound = 2 * (n + 1) * EPS * ((np.abs(M) @ np.abs(z)).max() + np.abs(q).max()) / scale
    return res, bound


def assert_same(a: LCPResult, b: LCPResult) -> None:
    assert (a.status, a.method, a.iterations, a.message) == (
        b.status, b.method, b.iterations, b.message)
    np.testing.assert_array_equal(a.z, b.z)     # same analysis, same chain: bit for bit
    np.testing.assert_array_equal(a.w, b.w)
    assert a.residual == b.residual and a.tolerance == b.tolerance


@njit(cache=False)
def kernel_author_loop(M, Q, Z, codes):
    """What a kernel author writes: solve one LCP per row of Q inside compiled code."""
    n = M.shape[0]
    w = np.empty(n)
    for k in range(Q.shape[0]):
        status, method, its, res, tol = solve_lcp_kernel(M, Q[k], Z[k], w, 1e-12, 0)
        codes[k, 0] = status
        codes[k, 1] = method
        codes[k, 2] = its


@pytest.mark.parametrize("n", [1, 2, 3, 5, 10, 30])
def test_solve_lcp_and_a_reused_solver_agree_bit_for_bit(n):
    rng = np.random.default_rng(100 + n)
    M = random_p_matrix(n, rng)
    solver = LCPSolver(M)
    for _ in range(20):
        q = rng.standard_normal(n)
        assert_same(solve_lcp(M, q), solver.solve(q))


@pytest.mark.parametrize(("M", "q"), [(GAME, -np.ones(4)), INFEASIBLE])
def test_auto_falls_back_in_compiled_code_and_both_entries_agree(M, q):
    res = solve_lcp(M, q)
    assert_same(res, LCPSolver(M).solve(q))
    assert res.message.startswith("lemke: ray_termination")
    if M is GAME:                 # the fallback (Howard's iteration) finds a solution
        assert res.success and res.method == "banded", res.message
        r, bound = independent_residual(M, q, res.z)
        assert r <= 1e-12 + bound
        assert np.all(res.z >= 0) and np.all(res.w >= -bound * (1 + np.abs(q).max()))
    else:                         # nothing solves it: Lemke's ray is the answer
        assert res.status == "ray_termination" and res.method == "lemke", res.message
        assert "; banded: " in res.message


def test_the_compiled_entry_called_from_a_kernel_gives_solve_lcps_answers():
    rng = np.random.default_rng(7)
    n = 6
    M = random_p_matrix(n, rng)
    Q = rng.standard_normal((25, n))
    Z = np.empty((25, n))
    codes = np.zeros((25, 3), dtype=np.int64)
    kernel_author_loop(M, Q, Z, codes)
    for k in range(25):
        res = solve_lcp(M, Q[k])
        assert codes[k, 0] == 0 and dispatch.RUN_NAMES[codes[k, 1]] == res.method
        assert codes[k, 2] == res.iterations
        np.testing.assert_array_equal(Z[k], res.z)


@pytest.mark.parametrize(("M", "q", "status", "method"), [
    (GAME, -np.ones(4), 0, dispatch.BANDED),
    (INFEASIBLE[0], INFEASIBLE[1], 1, dispatch.LEMKE),
])
def test_the_compiled_entry_runs_the_fallbacks_and_keeps_lemkes_ray(M, q, status, method):
    n = len(q)
    z, w = np.empty(n), np.empty(n)
    got = solve_lcp_kernel(M, q, z, w, 1e-12, 0)
    res = solve_lcp(M, q)
    assert got[:2] == (status, method)
    np.testing.assert_array_equal(z, res.z)
    np.testing.assert_array_equal(w, res.w)


def test_the_compiled_entry_reports_non_finite_input_as_a_failure():
    z, w = np.empty(2), np.empty(2)
    assert solve_lcp_kernel(np.array([[1.0, np.nan], [0.0, 1.0]]), -np.ones(2), z, w,
                            1e-12, 0)[0] == 3
    assert solve_lcp_kernel(np.eye(2), np.array([np.inf, 1.0]), z, w, 1e-12, 0)[0] == 3


def test_fallback_order_is_decided_in_one_place():
    auto = dispatch.AUTO
    order = []
    tried = dispatch.family(dispatch.BANDED)
    run = dispatch.next_run(auto, tried, 500, True, True, True)
    while run != dispatch.NO_RUN:
        order.append(dispatch.RUN_NAMES[run])
        tried |= dispatch.family(run)
        run = dispatch.next_run(auto, tried, 500, True, True, True)
    assert order == ["pgs_auto", "lemke"]          # banded then PGS's probe, then Lemke
    # a small dense matrix with a zero on the diagonal: Lemke, then Howard (no PGS)
    tried = dispatch.family(dispatch.LEMKE)
    assert dispatch.next_run(auto, tried, 4, False, False, False) == dispatch.BANDED
    assert dispatch.next_run(auto, tried, 4, False, False, True) == dispatch.PGS_FALLBACK
    assert dispatch.next_run(auto, 7, 4, False, False, True) == dispatch.NO_RUN
    assert dispatch.next_run(dispatch.LEMKE, 1, 4, False, False, True) == dispatch.NO_RUN
    assert dispatch.next_run(auto, 1, 201, False, False, False) == dispatch.NO_RUN


def test_results_of_the_per_call_path_are_read_only_and_do_not_share_memory():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    a, b = solve_lcp(M, np.array([-5.0, -6.0])), solve_lcp(M, np.array([-5.0, 6.0]))
    for res in (a, b):
        assert not res.z.flags.writeable and not res.w.flags.writeable
        with pytest.raises(ValueError):
            res.z[0] = 1.0
    assert not np.shares_memory(a.z, b.z) and not np.shares_memory(a.z, a.w)
    np.testing.assert_allclose(a.z, [4 / 3, 7 / 3], rtol=0, atol=8 * EPS)
    # the message formats the verified residual (here at round-off: <= (n + 1) eps)
    assert a.message == f"lemke: solved (residual {a.residual:.3g})"
    assert a.residual <= 3 * EPS and isinstance(a, LCPResult)
    # a read-only result passed back as q takes the general path, with the same answer
    assert_same(solve_lcp(M, -a.z), solve_lcp(M, -a.z.copy()))


@pytest.mark.parametrize("entry", ["solve_lcp", "LCPSolver"])
@pytest.mark.parametrize(("M", "q", "error", "start"), [
    (np.ones((2, 3)), np.ones(2), DimensionError, "M: expected"),
    (np.array([[1.0, np.nan], [0.0, 1.0]]), np.ones(2), ModelError, "M: "),
    (np.array([["1", "a"], ["0", "1"]], dtype=object), np.ones(2), ModelError, "M: expected"),
    (np.array([["1", "a"], ["0", "1"]]), np.ones(2), ModelError, "M: expected"),
    (sp.csr_matrix(np.ones((3, 2))), np.ones(3), DimensionError, "M: expected"),
    (np.eye(2), np.array([1.0, np.nan]), ModelError, "q: "),
    (np.eye(2), np.array(["1", "x"]), ModelError, "q: expected"),
    (np.eye(2), np.ones(3), DimensionError, "q: expected"),
])
def test_bad_input_is_refused_naming_the_argument(entry, M, q, error, start):
    with pytest.raises(error, match=f"^{start}"):
        if entry == "solve_lcp":
            solve_lcp(M, q)
        else:
            LCPSolver(M).solve(q)


# ----------------------------------------------------------------------------- per-call path
# solve_lcp and LCPSolver.solve leave the type checks of their per-call path to a compiled
# entry of one exact signature (numba's dispatcher raises TypeError for any other kind of
# argument, which sends it to the general path) and the shapes and options to its first
# line. Whatever kind of array the same numbers come in, the answer is the same, bit for bit.


def _kinds(a):
    """The same numbers as a clean array, a Fortran-ordered one, a read-only one, a
    non-contiguous view and a list."""
    ro = a.copy()
    ro.setflags(write=False)
    strided = np.empty((2,) + a.shape)[0] if a.ndim == 1 else np.empty(
        (a.shape[0], 2 * a.shape[1]))[:, ::2]
    strided[...] = a
    return [a.copy(), np.asfortranarray(a), ro, strided, a.tolist()]


@pytest.mark.parametrize("n", [2, 5, 12])
def test_every_kind_of_array_gets_the_answer_of_the_clean_one(n):
    rng = np.random.default_rng(300 + n)
    M, q = random_p_matrix(n, rng), rng.standard_normal(n)
    ref = solve_lcp(M, q)
    assert ref.success
    solver = LCPSolver(M)
    for Mk in _kinds(M):
        assert_same(solve_lcp(Mk, q), ref)
    for qk in _kinds(q):
        assert_same(solve_lcp(M, qk), ref)
        assert_same(solver.solve(qk), ref)
    # a Fortran-ordered matrix kept by a solver (copied to C order once) gives it too
    assert_same(LCPSolver(np.asfortranarray(M)).solve(q), ref)


@pytest.mark.parametrize("entry", ["solve_lcp", "LCPSolver"])
@pytest.mark.parametrize(("kwargs", "start"), [
    ({"max_iter": 0}, "max_iter: "), ({"max_iter": 2.5}, "max_iter: "),
    ({"tol": 0.0}, "tol: "), ({"tol": float("nan")}, "tol: "), ({"tol": -1e-9}, "tol: "),
    ({"omega": 2.0}, "omega: "), ({"omega": 0.0}, "omega: "), ({"method": "simplex"}, "method: "),
    ({"strict": "no"}, "strict: "),
])
def test_options_the_compiled_entry_does_not_take_are_refused_by_name(entry, kwargs, start):
    M, q = np.array([[2.0, 1.0], [1.0, 2.0]]), np.array([-5.0, -6.0])
    with pytest.raises(ModelError, match=f"^{start}"):
        if entry == "solve_lcp":
            solve_lcp(M, q, **kwargs)
        else:
            LCPSolver(M, **kwargs).solve(q)


@pytest.mark.parametrize("n", [47, 48, 49, 50])
def test_lemke_on_the_full_tableau_and_on_the_basis_inverse_solves_to_round_off(n):
    # up to n = 48 Lemke pivots the full tableau B^-1 [I, -M, -1], above it B^-1 alone; both
    # end on a solution whose residual, recomputed here, is within the round-off bound of
    # evaluating M z + q (independent_residual), and ties are broken the same way: the
    # degenerate q = 0 rows (lexicographic rule) do not cycle
    rng = np.random.default_rng(500 + n)
    M = random_p_matrix(n, rng)
    q = rng.standard_normal(n)
    q[: n // 4] = 0.0
    z, w = np.empty(n), np.empty(n)
    from nscontrol.numerics import _lcp_kernels as kernels
    code, pivots = kernels.lemke_kernel(M, q, z, w, 0)
    assert code == kernels.SOLVED and pivots >= 1
    res, bound = independent_residual(M, q, z)
    assert res <= bound and np.all(z >= 0.0)
    assert_same(solve_lcp(M, q, method="lemke"), LCPSolver(M, "lemke").solve(q))


def _lemke_cases():
    """Problems whose Lemke paths end every way: solved (P-matrix, with degenerate rows
    q_i = 0), on a ray (the skew-symmetric infeasible LCP, the bimatrix game), out of
    pivots (Murty's exponential family at n = 9 with a budget of 20), trivially (q >= 0)."""
    rng = np.random.default_rng(77)
    for n in (1, 3, 10, 48):
        M = random_p_matrix(n, rng)
        q = rng.standard_normal(n)
        q[: n // 3] = 0.0
        yield M, q, 0
    yield INFEASIBLE[0], INFEASIBLE[1], 0
    yield GAME, -np.ones(4), 0
    murty = np.eye(9) + 2.0 * np.tril(np.ones((9, 9)), -1)
    yield murty, -np.ones(9), 20
    yield np.eye(3), np.ones(3), 0


@pytest.mark.parametrize("case", list(range(8)))
def test_lemke_in_a_given_workspace_is_lemke_kernel_bit_for_bit(case):
    # the per-call path of a small LCP runs Lemke in the caller's buffer (no allocation, no
    # reference counting); it must be the same pivots: status, count, z and w identical
    from nscontrol.numerics import _lcp_kernels as kernels
    M, q, limit = list(_lemke_cases())[case]
    n = q.shape[0]
    z1, w1, z2, w2 = (np.full(n, np.nan) for _ in range(4))
    work = np.full(kernels.lemke_work_size(n), np.nan)     # no entry read before written
    first = kernels.lemke_kernel(M, q, z1, w1, limit)
    assert kernels.lemke_into(M, q, z2, w2, limit, work) == first
    np.testing.assert_array_equal(z1, z2)
    np.testing.assert_array_equal(w1, w2)
    if first[0] == kernels.SOLVED:          # and it is a solution, to round-off
        res, bound = independent_residual(M, q, z1)
        assert res <= bound


def _pgs_cases():
    """Problems whose PGS runs end every way: solved (random SPD, its active set polished),
    out of sweeps (a tiny budget; a PSD LCP without solution, ``M = a a^T``, ``q = (-1,
    1)``), a zero diagonal (numerical failure), trivially (q >= 0), with ``omega`` 1 and
    1.5."""
    rng = np.random.default_rng(78)
    for n in (1, 4, 10, 48):
        A = rng.standard_normal((n, n))
        yield A @ A.T / n + np.eye(n), rng.standard_normal(n) - 1.0, 0, 1.0
    A = rng.standard_normal((10, 10))
    yield A @ A.T / 10 + 0.01 * np.eye(10), rng.standard_normal(10), 3, 1.5
    yield np.array([[1.0, -1.0], [-1.0, 1.0]]), np.array([-1.0, -1.0]), 50, 1.0
    yield GAME, -np.ones(4), 0, 1.0
    yield np.eye(3), np.ones(3), 0, 1.0


@pytest.mark.parametrize("case", list(range(8)))
def test_pgs_in_the_buffer_is_the_allocating_pgs_bit_for_bit(case):
    # a first PGS run (method="pgs") runs in the per-call buffer with its scratch there (no
    # allocation); it must be the same sweeps and the same polish as pgs_verified, which
    # allocates: status, count, residual, z and w identical, through solve_lcp and a
    # reusable solver alike
    from nscontrol.numerics import _lcp_kernels as kernels
    M, q, limit, omega = list(_pgs_cases())[case]
    n = q.shape[0]
    z, w = np.full(n, np.nan), np.full(n, np.nan)
    code, its, res, tolerance = kernels.pgs_verified(M, q, z, w, 1e-12, limit or 10_000,
                                                     omega, True)
    ours = solve_lcp(M, q, method="pgs", max_iter=limit or None, omega=omega)
    assert_same(ours, LCPSolver(M, "pgs", max_iter=limit or None, omega=omega).solve(q))
    assert (ours.status, ours.iterations) == (lcp.STATUSES[code], its)
    assert ours.residual == res and ours.tolerance == tolerance
    np.testing.assert_array_equal(ours.z, z)
    np.testing.assert_array_equal(ours.w, w)
    work = np.full(kernels.pgs_work_size(n), np.nan)    # no entry read before written
    z2, w2 = np.full(n, np.nan), np.full(n, np.nan)
    assert kernels._pgs_verified_in(M, q, z2, w2, 1e-12, limit or 10_000, omega, True,
                                    work)[:2] == (code, its)
    np.testing.assert_array_equal(z2, z)


@pytest.mark.parametrize(("M", "q"), [(GAME, -np.ones(4)), INFEASIBLE])
def test_fallbacks_after_the_first_lemke_run_in_the_buffer_match_the_solver(M, q):
    # the first Lemke run in the buffer fails (a ray), the chain goes on from it: the same
    # runs, the same log (message) and the same answer as the reusable solver and as the
    # compiled entry, which report the ray of the infeasible LCP and the game's solution
    res = solve_lcp(M, q)
    assert_same(res, LCPSolver(M).solve(q))
    assert res.message.startswith("lemke: ray_termination")
    n = q.shape[0]
    z, w = np.empty(n), np.empty(n)
    code, run, _, _, _ = solve_lcp_kernel(M, q, z, w, 1e-12, 0)
    assert dispatch.RUN_NAMES[run] == res.method and code == ("solved", "ray_termination",
                                                              ).index(res.status)
    np.testing.assert_array_equal(z, res.z)
    np.testing.assert_array_equal(w, res.w)


@pytest.mark.parametrize("n", [2, 3])
def test_a_reusable_solver_of_a_small_tridiagonal_matrix_keeps_writeable_bands(n):
    # the bands of a 2 x 2 M have one entry each: numpy's diagonal view of one entry is
    # contiguous and read-only, which the solver's exact-signature entry refuses (every
    # solve then took the general path); the bands must be writeable copies, and the
    # answers the same as solve_lcp's
    M = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    q = -np.arange(1.0, n + 1.0)
    solver = LCPSolver(M)
    bands = solver._packed[1:4]
    assert all(b.flags.writeable and b.flags.c_contiguous for b in bands)
    assert all(not np.shares_memory(b, M) for b in bands)
    assert_same(solver.solve(q), solve_lcp(M, q))
    assert solver.solve(q).success


#: Siconos's ``lcp_Pang_isolated_sol_perturbed`` (no solution: Lemke's ray, then Howard's
#: iteration cycles) and ``lcp_CPS_3`` (a bimatrix game: Lemke's ray, then Howard's
#: iteration solves it), the two problems of its suite where ``auto`` falls back.
PANG_PERTURBED = (np.array([[0.0, -1.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]),
                  np.array([-1e-4, -1.0, 1.0]))
CPS_3 = (np.array([[0.0, 0.0, 10.0, 20.0], [0.0, 0.0, 30.0, 15.0], [10.0, 20.0, 0.0, 0.0],
                   [30.0, 15.0, 0.0, 0.0]]), -np.ones(4))


@pytest.mark.parametrize(("M", "q"), [(GAME, -np.ones(4)), INFEASIBLE, PANG_PERTURBED, CPS_3])
def test_a_chain_read_from_the_compiled_log_is_the_result_assembled_run_by_run(M, q):
    # solve_lcp and LCPSolver.solve read a chain that needs nothing more from Python from
    # its buffer (the result chosen as _choose does, the message formatted when read); a
    # warm start from z0 = 0 (the same runs: Lemke ignores z0, dense Howard starts from it)
    # goes through the Python assembly of the runs (_finish, _choose): the same result
    n = q.shape[0]
    assembled = LCPSolver(M).solve(q, z0=np.zeros(n))
    for res in (solve_lcp(M, q), LCPSolver(M).solve(q)):
        assert_same(res, assembled)
        assert not res.z.flags.writeable and not res.w.flags.writeable
    assert solve_lcp(M, q).message.count(";") == 1      # Lemke, then Howard's iteration
    if M is PANG_PERTURBED[0] or M is INFEASIBLE[0]:
        with pytest.raises(SolverError, match="ray_termination") as err:
            solve_lcp(M, q, strict=True)
        assert assembled.message in str(err.value)


def test_a_result_is_an_immutable_record_read_by_name():
    res = solve_lcp(*INFEASIBLE)
    with pytest.raises(AttributeError):
        res.status = "solved"                            # type: ignore[misc]
    with pytest.raises(TypeError, match="by name"):
        _ = list(res)                                    # not a sequence of its fields
    back = pickle.loads(pickle.dumps(res))
    assert_same(back, res)
    assert back.success is False and repr(back).startswith("LCPResult(z=array(")
    # the public constructor, as the Python paths call it
    made = LCPResult(res.z, res.w, res.status, res.iterations, res.residual, res.method,
                     res.message, res.tolerance)
    assert_same(made, res)


def _tridiagonal_m_matrix(n: int, rng: np.random.Generator) -> np.ndarray:
    """A random tridiagonal M-matrix (positive diagonal dominating non-positive
    off-diagonals): Howard's iteration solves its LCP exactly in at most n iterations."""
    off = -rng.uniform(0.1, 1.0, n - 1)
    M = np.diag(2.5 + rng.uniform(0.0, 1.0, n)) + np.diag(off, -1) + np.diag(off[::-1], 1)
    return M


@pytest.mark.parametrize("kind", [sp.csr_matrix, sp.csr_array])
@pytest.mark.parametrize("n", [3, 10, 57])
def test_a_tridiagonal_csr_matrix_is_solved_by_one_compiled_call_as_by_the_solver(kind, n):
    """solve_lcp's compiled CSR path (bands read, Howard's tridiagonal iteration, its
    verification) gives LCPSolver's answer bit for bit (the same bands, the same run), and
    a solution to round-off of the dense matrix's LCP."""
    rng = np.random.default_rng(n)
    dense = _tridiagonal_m_matrix(n, rng)
    q = rng.standard_normal(n)
    M = kind(dense)
    solve_lcp(M, q)                                  # the general path records the CSR type
    res = solve_lcp(M, q)
    assert res.status == "solved" and res.method == "banded"
    assert_same(res, lcp._solve_csr(M, q, 1e-12, 0))   # the compiled path took it
    assert_same(res, LCPSolver(M).solve(q))
    got, bound = independent_residual(dense, q, res.z)
    assert got <= bound
    assert not res.z.flags.writeable and not np.shares_memory(res.z, res.w)


def test_csr_matrices_the_compiled_path_does_not_take_get_the_general_answer():
    """A CSR ``M`` that is not tridiagonal, has int64 indices, duplicate entries, a NaN,
    or is not square: the general path's answer or error, named."""
    rng = np.random.default_rng(7)
    n = 8
    dense = _tridiagonal_m_matrix(n, rng)
    q = rng.standard_normal(n)
    wide = dense.copy()
    wide[0, 3] = -0.1                                 # beyond the first off-diagonals
    M = sp.csr_matrix(wide)
    assert_same(solve_lcp(M, q), LCPSolver(M).solve(q))
    M64 = sp.csr_matrix(dense)
    M64.indices, M64.indptr = M64.indices.astype(np.int64), M64.indptr.astype(np.int64)
    assert_same(solve_lcp(M64, q), LCPSolver(M64).solve(q))
    # duplicates are summed, as scipy reads them: the answer of the summed matrix
    rows, cols = np.nonzero(dense)
    vals = dense[rows, cols]
    twice = sp.csr_matrix((np.r_[vals / 2, vals / 2], (np.r_[rows, rows], np.r_[cols, cols])),
                          shape=(n, n))
    twice.has_canonical_format = False
    np.testing.assert_allclose(solve_lcp(twice, q).z, solve_lcp(dense, q).z, rtol=0,
                               atol=64 * n * EPS * np.abs(solve_lcp(dense, q).z).max())
    bad = sp.csr_matrix(dense)
    bad.data[2] = np.nan
    with pytest.raises(ModelError, match="M"):
        solve_lcp(bad, q)
    with pytest.raises(DimensionError, match="M"):
        solve_lcp(sp.csr_matrix(np.hstack([dense, np.zeros((n, 1))])), q)


def test_a_csr_matrix_whose_banded_run_fails_gets_autos_fallbacks():
    """A tridiagonal CSR ``M`` that is no M-matrix (a positive off-diagonal), where Howard's
    iteration fails: the compiled path hands the problem to the general one, whose
    fallbacks solve it (Lemke; the result is the solver's, bit for bit)."""
    M = sp.csr_matrix(np.array([[1.39, -1.83, 0.0], [-0.37, 1.77, 1.29], [0.0, 1.64, 0.72]]))
    q = np.array([-0.36, -1.9, -0.11])
    res = solve_lcp(M, q)
    assert_same(res, LCPSolver(M).solve(q))
    assert res.status == "solved" and res.message.startswith("banded: numerical_failure")
    assert res.method == "lemke"
    got, bound = independent_residual(M.toarray(), q, res.z)
    assert got <= bound

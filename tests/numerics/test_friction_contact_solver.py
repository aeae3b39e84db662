"""The reusable frictional-contact solver: closed-form single contacts (take-off, stick,
slip), agreement with ``solve_friction_contact`` and between dense and sparse ``W``, warm
starts, and bad input refused with the argument named."""

import numpy as np
import pytest
import scipy.sparse as sp

from nscontrol.errors import DimensionError, ModelError
from nscontrol.numerics import (
    FrictionContactSolver,
    friction_residual,
    solve_friction_contact,
    solve_lcp,
)

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(float).eps


def _spd(rng, n, cond=50.0):
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    W = Q @ np.diag(np.geomspace(1.0, cond, n)) @ Q.T
    return 0.5 * (W + W.T)


def _chain(rng, m, dim):
    """A block-sparse Delassus matrix ``H M⁻¹ Hᵀ``: contact ``i`` touches bodies ``i`` and
    ``i + 1`` (block tridiagonal), and a random ``q``."""
    n_body = 3
    rows = []
    for i in range(m):
        block = np.zeros((dim, n_body * (m + 1)))
        block[:, n_body * i:n_body * (i + 2)] = rng.standard_normal((dim, 2 * n_body))
        rows.append(block)
    H = np.vstack(rows)
    minv = np.diag(rng.uniform(0.5, 2.0, n_body * (m + 1)))
    W = H @ minv @ H.T
    W[np.abs(W) < 1e-300] = 0.0
    return 0.5 * (W + W.T), rng.standard_normal(m * dim)


# ----------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("tangent", [0.3, 3.0])            # stick, then slip
@pytest.mark.parametrize("angle", [0.0, 2.1])              # slip direction off the axes
def test_one_contact_with_diagonal_w_matches_the_closed_form(dim, tangent, angle):
    # W = diag(wn, wt, wt): the normal impulse r_N = -q_N / wn does not depend on friction;
    # stick (r_T = -q_T / wt) exactly when |q_T| / wt <= mu r_N, otherwise slip with
    # r_T = -mu r_N q_T / |q_T| and u_T = q_T (1 - mu r_N wt / |q_T|), along q_T
    wn, wt, mu, qn = 2.0, 0.5, 0.4, -1.3
    direction = np.array([np.cos(angle), np.sin(angle)])[:dim - 1]
    direction /= np.linalg.norm(direction)
    qt = tangent * direction
    W = np.diag([wn] + [wt] * (dim - 1))
    q = np.concatenate([[qn], qt])
    rn = -qn / wn
    sticks = np.linalg.norm(qt) / wt <= mu * rn
    if sticks:
        r = np.concatenate([[rn], -qt / wt])
        u = np.zeros(dim)
    else:
        r = np.concatenate([[rn], -mu * rn * direction])
        u = np.concatenate([[0.0], qt * (1.0 - mu * rn * wt / np.linalg.norm(qt))])
    res = FrictionContactSolver(W, mu, dim=dim).solve(q)
    assert res.success and res.states.tolist() == [1 if sticks else 2]
    # the slip angle is a root to machine resolution (a few ulps of 2 pi) and every entry
    # a few operations on numbers of order |q| / w: 64 eps of the largest is ample
    scale = np.abs(q).max() / min(wn, wt)
    np.testing.assert_allclose(res.r, r, rtol=0, atol=64 * EPS * scale)
    np.testing.assert_allclose(res.u, u, rtol=0, atol=64 * EPS * scale * max(wn, wt))
    # the one-call function gives the same numbers (it is the same solver)
    once = solve_friction_contact(W, q, mu, dim=dim, method="nsgs")
    np.testing.assert_array_equal(once.r, res.r)


def test_one_contact_that_takes_off_has_no_impulse():
    res = FrictionContactSolver(np.diag([2.0, 0.5, 0.5]), 0.4, dim=3).solve(
        np.array([0.1, -5.0, 2.0]))
    assert res.r.tolist() == [0.0, 0.0, 0.0] and res.states.tolist() == [0]
    assert res.u.tolist() == [0.1, -5.0, 2.0]


def test_frictionless_contacts_solve_the_normal_lcp():
    rng = np.random.default_rng(3)
    W, q = _spd(rng, 6), rng.standard_normal(6)
    res = FrictionContactSolver(W, 0.0, dim=1).solve(q, tol=1e-14)
    lcp = solve_lcp(W, q)
    # W SPD: the LCP's solution is unique, |dz| <= cond(W) x residual x scale
    scale = max(np.linalg.norm(q), np.linalg.norm(lcp.z))
    assert np.max(np.abs(res.r - lcp.z)) <= 50 * 1e-14 * scale * 10


# ----------------------------------------------------------------------------- agreement


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_the_solver_agrees_with_solve_friction_contact(dim, seed):
    rng = np.random.default_rng(seed)
    W, q = _spd(rng, 8 * dim), rng.standard_normal(8 * dim)
    mu = rng.uniform(0.1, 0.8, 8)
    solver = FrictionContactSolver(W, mu, dim=dim)
    res = solver.solve(q, tol=1e-12)
    ref = solve_friction_contact(W, q, mu, dim=dim, method="nsgs", tol=1e-12)
    # the same sweeps from the same start: the same iterates
    assert res.success and res.iterations == ref.iterations
    np.testing.assert_array_equal(res.r, ref.r)
    # the residual is that of r, recomputed elsewhere in another summation order: the two
    # differ by at most twice the round-off bound the tolerance adds to tol
    independent = friction_residual(W, q, mu, res.r, dim)
    assert abs(res.residual - independent) <= 2 * (res.tolerance - 1e-12)
    # a list W and an F-ordered W take the checked path: the same answer
    for other in (W.tolist(), np.asfortranarray(W)):
        again = solve_friction_contact(other, q.tolist(), mu, dim=dim, method="nsgs",
                                       tol=1e-12)
        np.testing.assert_array_equal(again.r, ref.r)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_dense_and_sparse_w_give_the_same_answer(dim, seed):
    rng = np.random.default_rng(10 + seed)
    W, q = _chain(rng, 12, dim)
    tol = 1e-13
    dense = FrictionContactSolver(W, 0.5, dim=dim).solve(q, tol=tol)
    assert dense.success
    for Ws in (sp.csr_matrix(W), sp.csc_matrix(W), sp.coo_matrix(W)):
        solver = FrictionContactSolver(Ws, 0.5, dim=dim)
        assert "sparse" in repr(solver)
        res = solver.solve(q, tol=tol)
        assert res.success and res.states.tolist() == dense.states.tolist()
        # both reach tol: each r is within cond(W) x tol x scale of the solution (unique
        # for these diagonally dominant blocks), so of each other within twice that
        cond = np.linalg.cond(W)
        scale = max(np.linalg.norm(q), np.linalg.norm(dense.r), np.linalg.norm(dense.u))
        assert np.max(np.abs(res.r - dense.r)) <= 2 * cond * tol * scale


def test_a_sparse_w_from_solve_friction_contact_takes_the_same_solver():
    rng = np.random.default_rng(4)
    W, q = _chain(rng, 10, 3)
    res = solve_friction_contact(sp.csr_matrix(W), q, 0.5, dim=3, tol=1e-12)
    ref = FrictionContactSolver(sp.csc_matrix(W), 0.5, dim=3).solve(q, tol=1e-12)
    np.testing.assert_array_equal(res.r, ref.r)


# ----------------------------------------------------------------------------- warm starts


@pytest.mark.parametrize("dim", [2, 3])
def test_a_warm_start_from_the_solution_takes_one_sweep(dim):
    rng = np.random.default_rng(7)
    W, q = _spd(rng, 20 * dim), rng.standard_normal(20 * dim)
    solver = FrictionContactSolver(W, 0.5, dim=dim)
    cold = solver.solve(q, tol=1e-12)
    assert cold.iterations > 1
    warm = solver.solve(q, cold.r, tol=1e-12)
    assert warm.success and warm.iterations == 1
    # one sweep from a point within tol: it stays within cond x tol x scale
    scale = max(np.linalg.norm(q), np.linalg.norm(cold.r), np.linalg.norm(cold.u))
    assert np.max(np.abs(warm.r - cold.r)) <= 50 * 1e-12 * scale * 2
    # r0 is copied, not written
    start = cold.r.copy()
    solver.solve(q, start)
    np.testing.assert_array_equal(start, cold.r)


def test_a_warm_start_from_a_nearby_load_saves_sweeps():
    # the use in a time-stepping loop: the next step's q is close to this one's
    rng = np.random.default_rng(8)
    W, q = _spd(rng, 60), rng.standard_normal(60)
    solver = FrictionContactSolver(W, 0.5, dim=3)
    first = solver.solve(q, tol=1e-10)
    q2 = q + 1e-6 * rng.standard_normal(60)
    cold, warm = solver.solve(q2, tol=1e-10), solver.solve(q2, first.r, tol=1e-10)
    assert cold.success and warm.success
    assert warm.iterations < cold.iterations


def test_the_sweep_budget_is_reported_not_raised():
    rng = np.random.default_rng(9)
    W, q = _spd(rng, 30), rng.standard_normal(30)
    res = FrictionContactSolver(W, 0.5, dim=3).solve(q, tol=1e-14, max_sweeps=2)
    assert res.status == "max_iter" and res.iterations == 2
    assert res.message == "budget max_sweeps = 2 sweeps spent"


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(("W", "mu", "dim", "error", "name"), [
    (np.ones((3, 4)), 0.5, 3, DimensionError, "W: expected shape a square matrix"),
    (np.ones(3), 0.5, 3, DimensionError, "W: expected a 2-d array"),
    (np.eye(4), 0.5, 3, DimensionError, "W: expected a size divisible by dim = 3"),
    (np.array([[np.nan, 0.0], [0.0, 1.0]]), 0.5, 2, ModelError, "W: expected finite"),
    (sp.csr_matrix(np.array([[1.0, np.inf], [0.0, 1.0]])), 0.5, 2, ModelError,
     "W: expected finite"),
    (np.eye(2) * 1j, 0.5, 2, ModelError, "W: expected real"),
    (np.diag([0.0, 1.0]), 0.5, 2, ModelError, "W: the normal diagonal entry of contact 0"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), 0.5, 2, ModelError,
     "W: the normal diagonal entry of contact 1"),
    (np.eye(2), -0.5, 2, ModelError, "mu: expected a finite number >= 0"),
    (np.eye(2), np.nan, 2, ModelError, "mu: expected a finite number >= 0"),
    (np.eye(4), [0.5, -0.1], 2, ModelError, r"mu\[1\]: expected a finite number >= 0"),
    (np.eye(4), [0.5, np.nan], 2, ModelError, "mu: expected finite"),
    (np.eye(4), [0.5, 0.5, 0.5], 2, DimensionError, "mu: expected a vector of length 2"),
    (np.eye(2), 0.5, 0, ModelError, "dim: expected"),
    (np.eye(2), 0.5, 4, ModelError, "dim: expected"),
])
def test_bad_problems_are_refused_with_the_argument_named(W, mu, dim, error, name):
    with pytest.raises(error, match=f"^{name}"):
        FrictionContactSolver(W, mu, dim=dim)


@pytest.mark.parametrize(("q", "r0", "error", "name"), [
    (np.zeros(3), None, DimensionError, "q: expected a vector of length 4"),
    (np.zeros((2, 2)), None, DimensionError, "q: expected a vector"),
    (np.array([-1.0, np.nan, 0.0, 0.0]), None, ModelError, "q: expected finite"),
    ([-1.0, np.inf, 0.0, 0.0], None, ModelError, "q: expected finite"),
    (["-1", "0", "0", "0"], None, ModelError, "q: expected a real numeric array"),
    (np.zeros(4), np.zeros(5), DimensionError, "r0: expected a vector of length 4"),
    (np.zeros(4), np.array([1.0, np.nan, 0.0, 0.0]), ModelError, "r0: expected finite"),
])
def test_bad_loads_and_starts_are_refused_with_the_argument_named(q, r0, error, name):
    solver = FrictionContactSolver(np.eye(4), 0.5, dim=2)
    with pytest.raises(error, match=f"^{name}"):
        solver.solve(q, r0)


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"tol": 0.0}, "tol"), ({"tol": "1e-9"}, "tol"), ({"max_sweeps": 0}, "max_sweeps"),
    ({"max_sweeps": 1.5}, "max_sweeps"),
])
def test_bad_solve_options_are_refused(kwargs, name):
    solver = FrictionContactSolver(np.eye(2), 0.5, dim=2)
    with pytest.raises(ModelError, match=f"^{name}: expected"):
        solver.solve(np.array([-1.0, 0.2]), **kwargs)


def test_the_short_path_refuses_what_the_checked_path_refuses():
    # solve_friction_contact's one-call path on small dense problems hands refusals to the
    # checked path: the same errors as before it existed
    W, q = np.eye(3), np.array([-1.0, 0.2, 0.0])
    with pytest.raises(ModelError, match=r"^mu\[0\]: expected a finite number >= 0"):
        solve_friction_contact(W, q, np.array([-0.5]), dim=3)
    with pytest.raises(ModelError, match="^mu: expected finite"):
        solve_friction_contact(W, q, np.array([np.nan]), dim=3)
    with pytest.raises(ModelError, match="^W: expected finite"):
        solve_friction_contact(np.diag([1.0, np.nan, 1.0]), q, 0.5, dim=3)
    with pytest.raises(ModelError, match="^q: expected finite"):
        solve_friction_contact(W, np.array([-1.0, np.inf, 0.0]), 0.5, dim=3)
    with pytest.raises(ModelError, match="^r0: expected finite"):
        solve_friction_contact(W, q, 0.5, dim=3, r0=np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ModelError, match="^W: the normal diagonal entry of contact 0"):
        solve_friction_contact(np.diag([0.0, 1.0, 1.0]), q, 0.5, dim=3)


@pytest.mark.parametrize("kind", [sp.csr_matrix, sp.csc_matrix, sp.csr_array, sp.csc_array])
def test_the_short_path_of_a_sparse_w_gives_the_checked_solvers_answer(kind):
    # solve_friction_contact runs a CSR or CSC W with int32 indices in one compiled call
    # (its blocks built there); the reusable solver builds the same blocks and runs the same
    # sweep: the same r bit for bit, verified to its tolerance (recomputed here), and
    # int64 indices (the general path) give it too
    rng = np.random.default_rng(7)
    W, q = _chain(rng, 6, 3)
    Ws = kind(W)
    assert Ws.indices.dtype == np.int32
    res = solve_friction_contact(Ws, q, 0.5, dim=3, tol=1e-12)
    ref = FrictionContactSolver(Ws, 0.5, dim=3).solve(q, tol=1e-12)
    assert res.success and ref.success
    np.testing.assert_array_equal(res.r, ref.r)
    np.testing.assert_array_equal(res.u, ref.u)
    assert friction_residual(W, q, 0.5, res.r, 3) <= res.tolerance
    wide = kind(W)
    wide.indices = wide.indices.astype(np.int64)
    wide.indptr = wide.indptr.astype(np.int64)
    np.testing.assert_array_equal(solve_friction_contact(wide, q, 0.5, dim=3, tol=1e-12).r,
                                  res.r)


def test_the_short_path_of_a_sparse_w_refuses_what_the_checked_path_refuses():
    q = np.array([-1.0, 0.2, 0.0])
    bad = sp.csr_matrix(np.diag([1.0, np.nan, 1.0]))
    with pytest.raises(ModelError, match="^W: expected finite"):
        solve_friction_contact(bad, q, 0.5, dim=3)
    with pytest.raises(ModelError, match="^W: the normal diagonal entry of contact 0"):
        solve_friction_contact(sp.csc_matrix(np.diag([0.0, 1.0, 1.0])), q, 0.5, dim=3)
    with pytest.raises(DimensionError, match="^W: expected shape"):
        solve_friction_contact(sp.csr_matrix(np.eye(6)), q, 0.5, dim=3)


def test_the_short_path_hands_other_kinds_of_arrays_to_the_general_path():
    # the short path's compiled entry takes writeable C-contiguous float64 arrays only (its
    # signature raises TypeError for others); a Fortran-ordered W, a read-only q or μ, an
    # integer start go through the general path, to the same sweeps and the same r
    rng = np.random.default_rng(11)
    W, q = _spd(rng, 9), rng.standard_normal(9)
    mu = np.array([0.3, 0.5, 0.8])
    ref = solve_friction_contact(W, q, mu, dim=3, tol=1e-12)
    assert ref.success and friction_residual(W, q, mu, ref.r, 3) <= ref.tolerance
    q_ro, mu_ro = q.copy(), mu.copy()
    q_ro.setflags(write=False)
    mu_ro.setflags(write=False)
    for args in ((np.asfortranarray(W), q, mu), (W, q_ro, mu), (W, q, mu_ro)):
        np.testing.assert_array_equal(solve_friction_contact(*args, dim=3, tol=1e-12).r, ref.r)
    zero_start = solve_friction_contact(W, q, mu, dim=3, tol=1e-12, r0=np.zeros(9, int))
    np.testing.assert_array_equal(zero_start.r, ref.r)


# ------------------------------------------------------------------ the planar compiled path


def _planar_lcp_impulses(W, q, mu):
    """The planar problem solved independently: its LCP reformulation
    (:func:`planar_friction_lcp`) by Lemke's method, ``r_T = r_T⁺ - r_T⁻``."""
    from nscontrol.numerics import planar_friction_lcp

    M, qq = planar_friction_lcp(W, q, mu)
    res = solve_lcp(M, qq, method="lemke")
    assert res.success
    m = q.size // 2
    r = np.empty(2 * m)
    r[0::2] = res.z[:m]
    r[1::2] = res.z[m:2 * m] - res.z[2 * m:3 * m]
    return r


@pytest.mark.parametrize("seed", range(3))
def test_the_planar_compiled_paths_agree_with_the_lcp_reformulation(seed):
    rng = np.random.default_rng(30 + seed)
    m, mu, tol, cond = 15, 0.3, 1e-12, 50.0
    W, q = _spd(rng, 2 * m, cond), rng.standard_normal(2 * m)
    exact = _planar_lcp_impulses(W, q, mu)
    # W positive definite: the solution is unique, and a point whose relative natural-map
    # error is at most tol lies within about cond(W) x tol x scale of it (factor 4 for the
    # scale's own spread between the two points and the round-off added to tol)
    scale = max(np.linalg.norm(q), np.linalg.norm(exact))
    bound = 4 * cond * tol * scale
    results = {
        "one call, dense": solve_friction_contact(W, q, mu, dim=2, method="nsgs", tol=tol),
        "one call, CSR": solve_friction_contact(sp.csr_matrix(W), q, mu, dim=2,
                                                method="nsgs", tol=tol),
        "solver, dense": FrictionContactSolver(W, mu, dim=2).solve(q, tol=tol),
        "solver, CSC": FrictionContactSolver(sp.csc_matrix(W), mu, dim=2).solve(q, tol=tol),
    }
    for name, res in results.items():
        assert res.success, name
        assert np.max(np.abs(res.r - exact)) <= bound, name


def test_a_planar_dense_w_that_is_not_symmetric_is_read_by_its_columns():
    # W block lower triangular: contact 0 does not feel contact 1, contact 1 feels contact
    # 0's impulse through C. Gauss-Seidel in contact order then solves it exactly in its
    # first sweep: contact 0 alone (diagonal block: the closed form of one contact), then
    # contact 1 with q1 + C r0. Reading W's rows for its columns would couple them the
    # other way and give another r.
    wn, wt, mu = 2.0, 0.5, 0.4
    C = np.array([[0.3, -0.2], [0.7, 0.1]])
    W = np.zeros((4, 4))
    W[0:2, 0:2] = np.diag([wn, wt])
    W[2:4, 2:4] = np.diag([wn, wt])
    W[2:4, 0:2] = C
    q = np.array([-1.3, 3.0, -0.9, 0.2])

    def one_contact(qn, qt):   # diagonal block: stick if |q_T| / wt <= mu r_N, else slip
        rn = -qn / wn
        rt = -qt / wt if abs(qt) / wt <= mu * rn else -mu * rn * np.sign(qt)
        return np.array([rn, rt])

    r0 = one_contact(q[0], q[1])
    r1 = one_contact(*(q[2:4] + C @ r0))
    expected = np.concatenate([r0, r1])
    for res in (solve_friction_contact(W, q, mu, dim=2, method="nsgs", tol=1e-14),
                FrictionContactSolver(W, mu, dim=2).solve(q, tol=1e-14),
                FrictionContactSolver(sp.csr_matrix(W), mu, dim=2).solve(q, tol=1e-14)):
        assert res.success
        # a few operations on numbers of order 1: a few ulps of the largest impulse
        np.testing.assert_allclose(res.r, expected, rtol=0, atol=8 * EPS * np.abs(expected).max())
        np.testing.assert_allclose(res.u, W @ res.r + q, rtol=0, atol=8 * EPS * 4)


# ------------------------------------------------------------------ a whole call at its budget
@pytest.mark.parametrize("kind", ["dense", "csr", "csc"])
def test_a_whole_call_that_spends_its_sweeps_raises_without_solving_again(kind, monkeypatch):
    """The short path's sweeps ran out: the error is the one the general path raises (same
    message, same partial result), and the general path, which would run the same sweeps
    from the same start again, is not entered."""
    from nscontrol.errors import BudgetExceededError
    from nscontrol.numerics import friction_contact as fc

    rng = np.random.default_rng(7)
    m = 5
    W = _spd(rng, 3 * m)
    q = rng.standard_normal(3 * m)
    mu = np.full(m, 0.5)
    Wk = W if kind == "dense" else (sp.csr_matrix(W) if kind == "csr" else sp.csc_matrix(W))
    # the general path's error, reached with q given as a list (not the short path's kind)
    with pytest.raises(BudgetExceededError) as general:
        solve_friction_contact(Wk, q.tolist(), mu, dim=3, method="nsgs", max_sweeps=2)

    def general_path(*args, **kwargs):
        raise AssertionError("the general path ran")

    monkeypatch.setattr(fc.FrictionContactSolver, "_checked", general_path)
    with pytest.raises(BudgetExceededError) as short:
        solve_friction_contact(Wk, q, mu, dim=3, method="nsgs", max_sweeps=2)
    assert str(short.value) == str(general.value)
    assert short.value.budget == "max_sweeps" and short.value.used == 2
    np.testing.assert_array_equal(short.value.partial.r, general.value.partial.r)
    assert short.value.partial.status == "max_iter"


# ------------------------------------------------------------------ checks of the error
@pytest.mark.parametrize("seed", range(4))
def test_the_sweeps_run_past_the_first_that_reaches_tol_are_at_most_an_eighth(seed):
    """The checks of the error are spaced so that a solve stops at most ``max(1, k // 8)``
    sweeps after the first sweep ``k`` whose error is ``<= tol`` (found by solving with
    ``max_sweeps`` 1, 2, ...: the last sweep is always checked)."""
    rng = np.random.default_rng(seed)
    W, q = _chain(rng, 30, 3)
    solver = FrictionContactSolver(sp.csr_matrix(W), 0.5, dim=3)
    tol = 1e-10
    done = solver.solve(q, tol=tol, max_sweeps=20_000)
    assert done.success
    first = next(k for k in range(1, done.iterations + 1)
                 if solver.solve(q, tol=tol, max_sweeps=k).residual <= tol)
    assert done.iterations - first <= max(1, first // 8)

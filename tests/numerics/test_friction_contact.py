"""The one-step frictional contact problem: known answers, the two planar methods agree,
and every solution satisfies Coulomb's law (cone, maximal dissipation)."""

import numpy as np
import pytest

from nscontrol.errors import DimensionError, ModelError
from nscontrol.numerics import friction_residual, planar_friction_lcp, solve_friction_contact

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
    with pytest.raises(ModelError, match=r"mu\[0\]"):
        solve_friction_contact(np.eye(2), [-1.0, 0.0], -0.5, dim=2)
    with pytest.raises(DimensionError, match="W"):
        solve_friction_contact(np.eye(3), [-1.0, 0.0], 0.5, dim=2)
    with pytest.raises(ModelError, match="method"):
        solve_friction_contact(np.eye(3), [-1.0, 0.0, 0.0], 0.5, dim=3, method="lcp")

"""Newton's multi-contact impact law (the impact law of Moreau–Jean): complementarity, the
exact kinetic-energy identity, and redundant contacts (m > n)."""

import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.laws.impact import NewtonImpactLaw, delassus_matrix, impact_energy_change

EPS = np.finfo(float).eps


def _spd(n, rng):
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


@pytest.mark.parametrize("seed", range(3))
def test_complementarity_and_energy_identity_on_random_impacts(seed):
    """§5 check 1: 1-3 contacts, m <= n, e in [0, 1], all contacts in the index set."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        n = int(rng.integers(2, 6))
        k = int(rng.integers(1, min(3, n) + 1))
        M, G = _spd(n, rng), rng.standard_normal((k, n))
        e = float(rng.uniform())
        v_minus = rng.standard_normal(n)
        res = NewtonImpactLaw(e).apply(M, G.T, v_minus)
        P, U_minus, U_plus = res.impulse, G @ v_minus, res.normal_velocity
        D = delassus_matrix(M, G.T)
        kappa = np.linalg.cond(D) * np.linalg.cond(M)
        scale = np.abs(U_minus).max() + 1.0
        # the LCP solve and v+ = v- + M⁻¹GᵀP are backward stable: errors of order
        # n ε κ(Δ) κ(M) relative to the data; a factor 100 of margin
        tol = 100 * n * EPS * kappa
        assert P.min() >= 0.0
        assert (U_plus + e * U_minus).min() >= -tol * scale
        assert np.abs(P * (U_plus + e * U_minus)).max() <= tol * scale * (P.max() + 1.0)
        T_change = 0.5 * (res.v_plus @ M @ res.v_plus - v_minus @ M @ v_minus)
        T0 = 0.5 * v_minus @ M @ v_minus
        assert abs(T_change - impact_energy_change(D, P, e)) <= tol * T0
        assert T_change <= tol * T0                     # never gains energy


def test_energy_identity_closed_form_one_contact():
    # unit mass at -2 m/s on a wall, e = 1/2: v+ = 1, T+ - T- = 0.5 - 2 exactly
    res = NewtonImpactLaw(0.5).apply(np.eye(1), [1.0], [-2.0])
    assert res.v_plus[0] == 1.0
    assert impact_energy_change(np.eye(1), res.impulse, 0.5) == -1.5


def test_elastic_impact_keeps_energy_and_inelastic_projects():
    rng = np.random.default_rng(7)
    M, G = _spd(4, rng), rng.standard_normal((2, 4))
    v = -np.linalg.solve(M, G.T @ np.array([0.5, 0.8]))   # approaching on both
    D = delassus_matrix(M, G.T)
    res1 = NewtonImpactLaw(1.0).apply(M, G.T, v)
    assert impact_energy_change(D, res1.impulse, 1.0) == 0.0
    T0 = 0.5 * v @ M @ v
    # e = 1: T is conserved to the round-off of the solve (cond(M) cond(Δ) n ε, factor 100)
    tol = 100 * 4 * EPS * np.linalg.cond(M) * np.linalg.cond(D)
    assert abs(0.5 * res1.v_plus @ M @ res1.v_plus - T0) <= tol * T0
    res0 = NewtonImpactLaw(0.0).apply(M, G.T, v)
    # e = 0: v+ is the M-projection of v- on {G w >= 0}: M (v+ - v-) ⟂ v+ (complementarity)
    assert abs((res0.v_plus - v) @ M @ res0.v_plus) <= tol * T0


def test_redundant_contacts_more_than_coordinates():
    """m > n: the Delassus matrix is singular (PSD); Lemke still returns a complementary
    solution and the identity holds with a looser tolerance."""
    rng = np.random.default_rng(3)
    M = _spd(2, rng)
    G = rng.standard_normal((3, 2))
    v = -np.linalg.solve(M, G.T @ np.array([1.0, 1.0, 1.0]))
    if np.any(G @ v >= 0):
        v = -v
    res = NewtonImpactLaw(0.3).apply(M, G.T, v)
    D = delassus_matrix(M, G.T)
    assert np.linalg.matrix_rank(D) == 2
    w = res.normal_velocity + 0.3 * (G @ v)
    # Lemke on a PSD matrix: pivots amplify round-off by about the pivots' condition; 1e-9
    # relative is 1e6 n ε (a singular Δ has no condition number to quote)
    assert res.impulse.min() >= 0.0 and w.min() >= -1e-9 * np.abs(G @ v).max()
    T_change = 0.5 * (res.v_plus @ M @ res.v_plus - v @ M @ v)
    assert abs(T_change - impact_energy_change(D, res.impulse, 0.3)) <= 1e-9 * (v @ M @ v)


def test_delassus_refuses_indefinite_mass():
    with pytest.raises(ModelError, match="M"):
        delassus_matrix([[1.0, 2.0], [2.0, 1.0]], [[1.0], [0.0]])

"""Chapter 8, spec §6 check 6: the one-step inclusion ``w ∈ -φ(a + D w)`` against brute-force
active-set enumeration (200 random positive definite, non-symmetric ``D``, ``m = 3``) and the
scalar closed forms of spec §3.1."""

import itertools

import numpy as np
import pytest

from nscontrol.laws.set_valued import Complementarity, Relay, solve_inclusion


def _random_pd(rng, m):
    """Positive definite in the sense xᵀDx > 0, deliberately non-symmetric."""
    R = rng.normal(size=(m, m))
    S = rng.normal(size=(m, m))
    return R @ R.T + 0.1 * np.eye(m) + (S - S.T)


def _relay_enumeration(D, a, c):
    """All sign patterns (z_i = 0 with |w_i| <= c_i, or z_i ≷ 0 with w_i = ∓c_i)."""
    m = a.size
    found = []
    for pattern in itertools.product((0, 1, -1), repeat=m):
        pattern = np.array(pattern)
        free = pattern == 0
        w = -c * pattern.astype(float)
        if free.any():
            rhs = -(a[free] + D[np.ix_(free, ~free)] @ w[~free])
            w[free] = np.linalg.solve(D[np.ix_(free, free)], rhs)
        z = a + D @ w
        ok = (np.all(np.abs(w[free]) <= c[free] + 1e-12)
              and np.all(z[~free] * pattern[~free] > -1e-12))
        if ok:
            found.append((z, w))
    return found


def _complementarity_enumeration(D, a):
    """All index sets: w_i > 0 with z_i = 0, or w_i = 0 with z_i >= 0."""
    m = a.size
    found = []
    for active in itertools.product((False, True), repeat=m):
        act = np.array(active)
        w = np.zeros(m)
        if act.any():
            w[act] = np.linalg.solve(D[np.ix_(act, act)], -a[act])
        z = a + D @ w
        if np.all(w >= -1e-12) and np.all(z[~act] >= -1e-12):
            found.append((z, w))
    return found


def test_relay_one_step_matches_enumeration(rng):
    law = Relay([1.0, 0.5, 2.0])
    worst = 0.0
    for _ in range(200):
        D, a = _random_pd(rng, 3), rng.normal(scale=2.0, size=3)
        sol = solve_inclusion(law, D, a, method="lcp")
        brute = _relay_enumeration(D, a, law.bound)
        assert len(brute) >= 1
        worst = max(worst, min(np.linalg.norm(sol.w - w) for _, w in brute))
        assert law.contains(sol.z, -sol.w, tol=1e-9)
        np.testing.assert_allclose(sol.z, a + D @ sol.w, atol=1e-12)
    assert worst <= 1e-9


def test_complementarity_one_step_matches_enumeration(rng):
    law = Complementarity(3)
    worst = 0.0
    for _ in range(200):
        D, a = _random_pd(rng, 3), rng.normal(scale=2.0, size=3)
        sol = solve_inclusion(law, D, a, method="lcp")
        brute = _complementarity_enumeration(D, a)
        assert len(brute) == 1  # D is a P-matrix: exactly one solution
        worst = max(worst, np.linalg.norm(sol.w - brute[0][1]))
        assert law.contains(sol.z, -sol.w, tol=1e-9)
    assert worst <= 1e-9


@pytest.mark.parametrize("method", ["lcp", "closed_form"])
def test_scalar_closed_forms(rng, method):
    relay, comp = Relay(1.5), Complementarity(1)
    for _ in range(100):
        d, a = float(rng.uniform(0.01, 3.0)), float(rng.normal(scale=3.0))
        w_relay = -np.clip(a / d, -1.5, 1.5)
        w_comp = max(0.0, -a / d)
        s_relay = solve_inclusion(relay, [[d]], [a], method=method)
        s_comp = solve_inclusion(comp, [[d]], [a], method=method)
        assert abs(s_relay.w[0] - w_relay) <= 1e-9 * max(1.0, abs(w_relay))
        assert abs(s_comp.w[0] - w_comp) <= 1e-9 * max(1.0, abs(w_comp))

"""Nonsmooth laws: resolvents land in their graphs, monotonicity, complementarity encodings,
Stribeck's loop transformation, Newton restitution (single and multi-contact), bad input."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nscontrol.errors import DimensionError, InadmissibleStateError, ModelError
from nscontrol.laws.impact import NewtonImpactLaw, restitution_matrix
from nscontrol.laws.set_valued import (
    AsymmetricStribeck,
    Complementarity,
    Coulomb,
    MonotoneFunction,
    NormalConeBox,
    NormalConeInterval,
    PiecewiseLinearFunction,
    Product,
    Relay,
    SetValuedLaw,
    Stribeck,
    require_monotone,
    solve_inclusion,
)

SETTINGS = settings(max_examples=60, deadline=None)


def _law_zoo(seed: int) -> list[SetValuedLaw]:
    """One instance of every law, with random parameters (bounds in [0, 5])."""
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-3.0, 0.0, 3)
    hi = lo + rng.uniform(0.0, 3.0, 3)
    lo[2], hi[1] = -np.inf, np.inf
    stribeck = Stribeck(static=[0.3, 1.0], coulomb=[0.1, 0.6], stribeck_velocity=[1.0, 0.2],
                        delta=[2.0, 1.0], viscous=[0.01, 0.05])
    asym = AsymmetricStribeck(Stribeck(0.3, 0.1, 1.0), Stribeck(0.5, 0.2, 0.5, viscous=0.1))
    return [
        Relay(rng.uniform(0.0, 5.0, 3)),
        Relay(0.0),
        Coulomb(rng.uniform(0.0, 1.0, 2), rng.uniform(0.0, 5.0, 2)),
        NormalConeBox(lo, hi),
        NormalConeInterval(-1.0, 1.0, dim=2),
        Complementarity(3),
        MonotoneFunction(np.tanh, lambda z: 1.0 - np.tanh(z) ** 2, dim=2),
        MonotoneFunction(lambda z: z ** 3, dim=1),
        stribeck,
        stribeck.loop_transformation().monotone_part,
        asym,
        asym.loop_transformation().monotone_part,
        Product(Relay([1.0, 2.0]), Complementarity(1), MonotoneFunction(np.arctan)),
        PiecewiseLinearFunction.saturation(rng.uniform(0.5, 3.0), rng.uniform(0.2, 4.0), dim=2),
        PiecewiseLinearFunction(np.cumsum(rng.uniform(0.1, 2.0, 4)) - 3.0,
                                np.cumsum([0.0, 1.0, 0.0, 0.5]), slope_left=rng.uniform(0, 2),
                                slope_right=0.3, dim=3),
        Product(PiecewiseLinearFunction([-1.0, 1.0], [0.0, 0.0], 1.0, 1.0), Relay(1.0)),
    ]


def _graph_point(law: SetValuedLaw, x: np.ndarray, gamma: np.ndarray):
    z = law.resolvent(x, gamma)
    return z, (x - z) / gamma


def _gamma_for(law: SetValuedLaw, rng: np.random.Generator) -> np.ndarray:
    gamma = rng.uniform(0.05, 20.0, law.dim) if law.componentwise else np.full(law.dim, 1.3)
    # the non-monotone resolvent needs gamma sigma_tan < 1
    if isinstance(law, (Stribeck, AsymmetricStribeck)):
        gamma = np.minimum(gamma, 0.9 / np.maximum(law.sigma_tan, 1e-300))
    return gamma


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_every_resolvent_lands_in_the_graph(seed):
    rng = np.random.default_rng(seed)
    for law in _law_zoo(seed):
        x = rng.uniform(-10.0, 10.0, law.dim)
        # also hit the flat parts of the graphs (|x| small relative to gamma c)
        x[rng.random(law.dim) < 0.3] *= 1e-3
        z, v = _graph_point(law, x, _gamma_for(law, rng))
        assert law.graph_residual(z, v) <= 1e-12, (law, x, z, v)
        assert law.contains(z, v)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_monotone_laws_are_monotone_on_random_pairs(seed):
    rng = np.random.default_rng(seed)
    for law in _law_zoo(seed):
        if not law.monotone:
            continue
        pairs = []
        for _ in range(2):
            x = rng.uniform(-10.0, 10.0, law.dim)
            pairs.append(_graph_point(law, x, _gamma_for(law, rng)))
        (z1, v1), (z2, v2) = pairs
        assert (z1 - z2) @ (v1 - v2) >= -1e-12
        # minimum-norm selections on the resolvent's (admissible) points, too
        s1, s2 = law.select(z1), law.select(z2)
        assert (z1 - z2) @ (s1 - s2) >= -1e-12
        assert law.graph_residual(z1, s1) <= 1e-12


def test_closed_forms_of_the_piecewise_linear_laws():
    relay = Relay([1.0, 2.0, 0.5])
    np.testing.assert_array_equal(relay.resolvent([3.0, -1.0, -2.0], 1.0), [2.0, 0.0, -1.5])
    np.testing.assert_array_equal(relay.select([0.0, -3.0, 2.0]), [0.0, -2.0, 0.5])
    # distance from the graph: exact Euclidean distance to the polyline
    assert relay.graph_residual([0.0, 0.0, 0.0], [3.0, 0.0, 0.0]) == pytest.approx(2.0)
    assert relay.graph_residual([0.5, 0.0, 0.0], [0.0, 0.0, 0.0]) == pytest.approx(0.5)
    assert relay.graph_residual([3.0, 0.0, 0.0], [0.0, 0.0, 0.0]) == pytest.approx(1.0)
    box = NormalConeBox([0.0, -1.0], [1.0, np.inf])
    np.testing.assert_array_equal(box.resolvent([2.0, -5.0], 7.0), [1.0, -1.0])
    assert box.contains([1.0, -1.0], [5.0, -3.0])     # outward normals at the faces
    assert not box.contains([1.0, -1.0], [-5.0, 0.0])
    assert box.graph_residual([2.0, 0.0], [0.0, 0.0]) == pytest.approx(1.0)
    comp = Complementarity(2)
    np.testing.assert_array_equal(comp.resolvent([-1.0, 2.0]), [0.0, 2.0])
    assert comp.contains([0.0, 3.0], [-4.0, 0.0]) and not comp.contains([1.0, 0.0], [-1.0, 0.0])
    assert Coulomb(0.5, [2.0, 4.0]).bound.tolist() == [1.0, 2.0]


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_inclusion_lcp_matches_closed_form_for_diagonal_steps(seed):
    rng = np.random.default_rng(seed)
    law = Product(Relay(rng.uniform(0.0, 3.0, 2)),
                  NormalConeBox([-1.0, 0.0, -np.inf], [1.0, np.inf, 0.5]), Coulomb(0.3, 2.0))
    M = np.diag(rng.uniform(0.1, 5.0, law.dim))
    q = rng.uniform(-5.0, 5.0, law.dim)
    closed = solve_inclusion(law, M, q)
    via_lcp = solve_inclusion(law, M, q, method="lcp")
    assert closed.method == "closed_form" and via_lcp.method == "lcp"
    np.testing.assert_allclose(via_lcp.z, closed.z, atol=1e-10)
    np.testing.assert_allclose(via_lcp.w, closed.w, atol=1e-10)
    assert closed.residual <= 1e-12


def _pieces(law):
    """The pieces of a scalar law's Lur'e graph ``w in -phi(z)``: (fixed variable, value, check
    on the other variable)."""
    if isinstance(law, Relay):
        c = law.bound[0]
        return [("z", 0.0, lambda w: -c <= w <= c), ("w", -c, lambda z: z >= 0.0),
                ("w", c, lambda z: z <= 0.0)]
    lo, hi = law.lower[0], law.upper[0]
    pieces = [("z", lo, lambda w: w >= 0.0), ("w", 0.0, lambda z: lo <= z <= hi)]
    if np.isfinite(hi):
        pieces.append(("z", hi, lambda w: w <= 0.0))
    return pieces


def _brute_force(parts, M, q, tol=1e-9):
    """All solutions of ``z = M w + q, w in -phi(z)`` by enumerating the graphs' pieces."""
    m = len(parts)
    found = []
    for choice in itertools.product(*(_pieces(p) for p in parts)):
        K = np.zeros((2 * m, 2 * m))
        rhs = np.zeros(2 * m)
        K[:m, :m], K[:m, m:], rhs[:m] = np.eye(m), -M, q          # z - M w = q
        for i, (var, value, _) in enumerate(choice):
            K[m + i, i if var == "z" else m + i], rhs[m + i] = 1.0, value
        try:
            sol = np.linalg.solve(K, rhs)
        except np.linalg.LinAlgError:
            continue
        z, w = sol[:m], sol[m:]
        if all(_check_tol(check, w[i] if var == "z" else z[i], tol)
               for i, (var, _, check) in enumerate(choice)):
            found.append(z)
    return found


def _check_tol(check, value, tol):
    return check(value) or check(value + tol) or check(value - tol)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 5))
def test_inclusion_with_coupled_positive_definite_step(seed, m):
    rng = np.random.default_rng(seed)
    kinds = [lambda: Relay(rng.uniform(0.0, 3.0)), lambda: Complementarity(1),
             lambda: NormalConeInterval(-0.5, 1.0), lambda: Coulomb(0.4, 1.5)]
    parts = [kinds[i]() for i in rng.integers(0, len(kinds), m)]
    law = Product(*parts)
    A = rng.normal(size=(m, m))
    M = A @ A.T + 0.2 * np.eye(m) + (A - A.T)      # positive definite, not symmetric
    q = rng.uniform(-5.0, 5.0, m)
    sol = solve_inclusion(law, M, q, method="lcp")
    np.testing.assert_allclose(sol.z, M @ sol.w + q, atol=1e-12)
    assert law.graph_residual(sol.z, -sol.w) <= 1e-9
    # strongly monotone inclusion: unique solution; brute-force enumeration agrees
    found = _brute_force(parts, M, q)
    assert found
    for z in found:
        np.testing.assert_allclose(sol.z, z, atol=1e-8)


def _pwl_pieces(law):
    """Affine pieces ``(z_lo, z_hi, slope, offset)`` of a PiecewiseLinearFunction:
    ``f(z) = offset + slope z`` on ``[z_lo, z_hi]``."""
    b, v = law.breakpoints, law.values
    pieces = [(-np.inf, b[0], law.slope_left, v[0] - law.slope_left * b[0])]
    for j in range(b.size - 1):
        s = (v[j + 1] - v[j]) / (b[j + 1] - b[j])
        pieces.append((b[j], b[j + 1], s, v[j] - s * b[j]))
    pieces.append((b[-1], np.inf, law.slope_right, v[-1] - law.slope_right * b[-1]))
    return pieces


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 3))
def test_piecewise_linear_function_lcp_form_is_exact(seed, m):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 5))
    law = PiecewiseLinearFunction(np.cumsum(rng.uniform(0.2, 2.0, k)) - 2.0,
                                  np.cumsum(np.where(rng.random(k) < 0.3, 0.0,
                                                     rng.uniform(0.0, 2.0, k))),
                                  slope_left=rng.choice([0.0, 1.5]),
                                  slope_right=rng.choice([0.0, 0.7]), dim=m)
    A = rng.normal(size=(m, m))
    M = A @ A.T + 0.2 * np.eye(m) + (A - A.T)      # positive definite, not symmetric
    q = rng.uniform(-6.0, 6.0, m)
    sol = solve_inclusion(law, M, q, method="lcp")
    np.testing.assert_allclose(sol.z, M @ sol.w + q, atol=1e-12)
    assert law.graph_residual(sol.z, -sol.w) <= 1e-12
    np.testing.assert_allclose(sol.w, -law.select(sol.z), atol=1e-12)
    # unique solution: enumerate the affine pieces (w = -(offset + slope z) on each)
    found = []
    for choice in itertools.product(_pwl_pieces(law), repeat=m):
        S = np.diag([c[2] for c in choice])
        off = np.array([c[3] for c in choice])
        z = np.linalg.solve(np.eye(m) + M @ S, q - M @ off)   # z = M(-(off + S z)) + q
        if all(lo - 1e-9 <= zi <= hi + 1e-9 for zi, (lo, hi, _, _) in zip(z, choice,
                                                                           strict=True)):
            found.append(z)
    assert found
    for z in found:
        np.testing.assert_allclose(sol.z, z, atol=1e-8)
    # diagonal step: the closed-form resolvent and the LCP path agree
    Md = np.diag(rng.uniform(0.1, 5.0, m))
    closed, via_lcp = solve_inclusion(law, Md, q), solve_inclusion(law, Md, q, method="lcp")
    assert closed.method == "closed_form"
    np.testing.assert_allclose(via_lcp.z, closed.z, atol=1e-10)


def test_saturation_closed_forms():
    sat = PiecewiseLinearFunction.saturation(level=2.0, slope=4.0, dim=3)
    np.testing.assert_array_equal(sat.select([-1.0, 0.25, 7.0]), [-2.0, 1.0, 2.0])
    # z + 0.5 sat(z) = x: on the linear part z (1 + 2) = x, beyond it z = x - 1
    np.testing.assert_allclose(sat.resolvent([0.6, 5.0, -5.0], 0.5), [0.2, 4.0, -4.0])
    # (0, 3) is nearest to the corner (0.5, 2) of the polyline; (1, 0) to the segment v = 4 z
    assert sat.graph_residual([0.0, 0.0, 0.0], [0.0, 3.0, 0.0]) == pytest.approx(np.sqrt(1.25))
    assert sat.graph_residual([0.0, 0.2, 0.0], [0.0, 0.0, 0.0]) == pytest.approx(
        0.8 / np.hypot(1.0, 4.0))
    form = sat.complementarity_form()
    assert form.n_complementarity == 6          # one rising segment per component: 2 each


def test_stribeck_slope_constants_match_the_closed_forms_of_ch07():
    law = Stribeck(0.3, 0.1, 1.0, delta=2.0, viscous=0.01)
    # the constants are quoted to 6 digits: rounding 5e-7 x 0.2 / 0.16 = 6e-7 relative
    assert law.sigma_tan[0] == pytest.approx(0.857764 * 0.2 - 0.01, rel=1e-6)
    assert law.sigma_tan[0] == pytest.approx(0.161553, rel=1e-5)      # ch08 §5.7
    assert law.sigma_sec[0] == pytest.approx(0.638173 * 0.2 - 0.01, rel=1e-6)
    assert Stribeck(2.0, 1.0, 1.0, delta=1.0).sigma_tan[0] == pytest.approx(1.0)
    assert Stribeck(2.0, 1.0, 1.0, delta=3.0).sigma_tan[0] == pytest.approx(1.17543, rel=1e-5)
    assert np.isinf(Stribeck(2.0, 1.0, 1.0, delta=0.5).sigma_tan[0])
    # the bound is the true steepest descent of f: check on a fine grid
    s = np.linspace(1e-6, 5.0, 200001)
    f = law.coulomb + (law.static - law.coulomb) * np.exp(-s ** 2) + law.viscous * s
    # a difference quotient at the midpoint and a grid maximum, both O(h^2) with h = 2.5e-5:
    # ~1e-9 relative; rounding of f over h, u |f| / h = 4e-12
    assert np.max(-np.diff(f) / np.diff(s)) == pytest.approx(law.sigma_tan[0], rel=1e-6)
    assert Stribeck(0.5, 0.5, 1.0, viscous=0.1).monotone      # Coulomb + viscous


def test_stribeck_is_refused_until_loop_transformed():
    law = Stribeck(0.3, 0.1, 1.0, delta=2.0, viscous=0.01)
    assert not law.monotone
    # a pair on the falling branch violates monotonicity
    z1, z2 = np.array([1.0]), np.array([0.5])
    assert (z1 - z2) @ (law.select(z1) - law.select(z2)) < 0.0
    with pytest.raises(ModelError, match="loop_transformation"):
        require_monotone(law, who="design_lure_observer")
    lt = law.loop_transformation()
    phi_m = require_monotone(law, who="design_lure_observer", loop_transformation=lt)
    assert phi_m is lt.monotone_part and phi_m.monotone
    np.testing.assert_allclose(lt.slope, law.sigma_tan)
    # phi = phi_m - sigma id on the branches, and phi_m is monotone on a dense grid
    v = np.linspace(-4.0, 4.0, 8001)
    v = v[v != 0.0]
    phi = np.array([law.select([x])[0] for x in v])
    phim = np.array([phi_m.select([x])[0] for x in v])
    np.testing.assert_allclose(phim, phi + lt.slope[0] * v, atol=1e-14)
    assert np.all(np.diff(phim[v > 0]) >= -1e-15) and np.all(np.diff(phim[v < 0]) >= -1e-15)
    with pytest.raises(ModelError, match="sigma_tan"):
        law.loop_transformation(0.5 * law.sigma_tan)
    # ch08 §5.7: the slope moves into A as + sigma G H
    J_u, J_l, k, b_u = 0.5, 0.05, 0.08, 2.0
    A = np.array([[0, 1, -1], [-k / J_u, -b_u / J_u, 0], [k / J_l, 0, 0]])
    G, H = np.array([[0], [0], [1 / J_l]]), np.array([[0.0, 0.0, 1.0]])
    assert lt.transform_A(A, G, H)[2, 2] == pytest.approx(0.161553 / J_l, rel=1e-5)
    # a product with a non-monotone part is non-monotone, and transforms blockwise
    prod = Product(Relay(1.0), law)
    assert not prod.monotone
    plt_ = prod.loop_transformation()
    assert plt_.monotone_part.monotone
    np.testing.assert_allclose(plt_.slope, [0.0, law.sigma_tan[0]])


def test_stribeck_resolvent_refuses_steps_with_several_solutions():
    law = Stribeck(0.3, 0.1, 1.0)
    with pytest.raises(ModelError, match="gamma"):
        law.resolvent([1.0], gamma=1.0 / law.sigma_tan[0])
    assert law.resolvent([0.15], gamma=0.5)[0] == 0.0     # |x| <= gamma T_s: sticks
    z = law.resolvent([0.25], gamma=0.5)[0]               # slips: z + gamma f(z) = x
    assert 0.0 < z < 0.25
    assert z + 0.5 * law.magnitude([z])[0] == pytest.approx(0.25, abs=1e-15)


@SETTINGS
@given(m1=st.floats(0.01, 100.0), m2=st.floats(0.01, 100.0), e=st.floats(0.0, 1.0),
       v1=st.floats(-10.0, 10.0), dv=st.floats(1e-3, 10.0))
def test_restitution_conserves_momentum_and_never_adds_energy(m1, m2, e, v1, dv):
    v_minus = np.array([v1, v1 - dv])            # body 1 (left) approaches body 2
    R = restitution_matrix(m1, m2, e)
    v_plus = R @ v_minus
    masses = np.array([m1, m2])
    scale = masses @ np.abs(v_minus)
    assert masses @ v_plus == pytest.approx(masses @ v_minus, abs=1e-12 * scale)
    assert v_plus[1] - v_plus[0] == pytest.approx(-e * (v_minus[1] - v_minus[0]),
                                                  abs=1e-12 * (1 + np.abs(v_minus).max()))
    ke = lambda v: 0.5 * masses @ v ** 2   # noqa: E731
    assert ke(v_plus) <= ke(v_minus) * (1 + 1e-12)
    # the multi-contact law reduces to the same map for one contact
    res = NewtonImpactLaw(e).apply(np.diag(masses), np.array([-1.0, 1.0]), v_minus)
    np.testing.assert_allclose(res.v_plus, v_plus, atol=1e-12 * (1 + np.abs(v_minus).max()))
    assert res.impulse[0] >= 0.0


def test_newtons_cradle_simultaneous_impact():
    # three equal balls touching, the first arrives with speed 1: simultaneous Newton law
    W = np.array([[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]])
    res = NewtonImpactLaw(1.0).apply(np.eye(3), W, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(res.v_plus, [-1 / 3, 2 / 3, 2 / 3], atol=1e-12)
    np.testing.assert_allclose(res.impulse, [4 / 3, 2 / 3], atol=1e-12)
    assert 0.5 * res.v_plus @ res.v_plus == pytest.approx(0.5, abs=1e-12)   # e = 1: conserved
    # only the first contact active: the classic two-ball exchange
    one = NewtonImpactLaw(1.0).apply(np.eye(3), W, [1.0, 0.0, 0.0], active=[0])
    np.testing.assert_allclose(one.v_plus, [0.0, 1.0, 0.0], atol=1e-12)
    assert one.impulse[1] == 0.0


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 12), e=st.floats(0.0, 1.0))
def test_chain_impact_satisfies_newton_complementarity(seed, n, e):
    rng = np.random.default_rng(seed)
    masses = rng.uniform(0.1, 10.0, n)
    W = np.zeros((n, n - 1))
    W[np.arange(n - 1), np.arange(n - 1)] = -1.0
    W[np.arange(1, n), np.arange(n - 1)] = 1.0
    v_minus = rng.uniform(-3.0, 3.0, n)
    res = NewtonImpactLaw(e).apply(np.diag(masses), W, v_minus)
    u_minus = W.T @ v_minus
    slack = res.normal_velocity + e * u_minus
    tol = 1e-10 * (1 + np.abs(v_minus).max())
    assert np.all(res.impulse >= 0.0) and np.all(slack >= -tol)
    assert np.abs(res.impulse @ slack) <= tol * (1 + res.impulse.sum())
    assert masses @ res.v_plus == pytest.approx(masses @ v_minus, abs=tol * masses.sum())
    ke = lambda v: 0.5 * masses @ v ** 2   # noqa: E731
    assert ke(res.v_plus) <= ke(v_minus) + tol * masses.sum()


_W3 = np.array([[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]])
_RELAY2 = Relay([1.0, 1.0])
_LAW2 = NewtonImpactLaw([0.5, 0.9])

BAD_INPUT = [
    (lambda: Relay(-1.0), ModelError, r"^bound: expected relay bounds c >= 0"),
    (lambda: Relay([1.0, np.nan]), ModelError, r"^bound: expected real entries, got NaN"),
    (lambda: Relay([1.0, 2.0], dim=3), DimensionError,
     r"^bound: expected a scalar or a vector of length dim=3, got length 2"),
    (lambda: Relay(1.0, dim=0), DimensionError, r"^dim: expected an integer >= 1, got 0"),
    (lambda: Relay(1.0, dim=2.5), DimensionError, r"^dim: expected an integer >= 1, got 2.5"),
    (lambda: Relay(1.0j), ModelError, r"^bound: expected real entries, got a complex array"),
    (lambda: Coulomb(0.3, 1.0, dim=0), DimensionError, r"^dim: expected an integer >= 1"),
    (lambda: Stribeck(0.3, 0.1, 1.0, dim=1.5), DimensionError, r"^dim: expected an integer"),
    (lambda: NormalConeBox([0.0, 2.0], [1.0, 1.0]), ModelError,
     r"^lower, upper: expected lower <= upper componentwise, got lower\[1\] = 2.0"),
    (lambda: NormalConeInterval([0.0, 1.0], 2.0), ModelError,
     r"^lower, upper: NormalConeInterval takes scalar bounds"),
    (lambda: Complementarity(0), DimensionError, r"^dim: expected an integer >= 1, got 0"),
    (lambda: Coulomb(-0.1, 1.0), ModelError, r"^mu: expected finite friction coefficients >= 0"),
    (lambda: Coulomb(0.3, -2.0), ModelError, r"^normal_force: expected finite normal forces"),
    (lambda: Stribeck(static=0.1, coulomb=0.3, stribeck_velocity=1.0), ModelError,
     r"^static: expected static levels T_s >= coulomb T_c"),
    (lambda: Stribeck(0.3, 0.1, 0.0), ModelError,
     r"^stribeck_velocity, delta: expected positive values"),
    (lambda: MonotoneFunction(lambda z: -z), ModelError,
     r"^f: expected a nondecreasing function, but it decreases near"),
    (lambda: MonotoneFunction(lambda z: z + 1j).resolvent([1.0]), ModelError,
     r"^f: expected real entries, got a complex array"),
    (lambda: PiecewiseLinearFunction([0.0, 0.0], [0.0, 1.0]), ModelError,
     r"^breakpoints: expected strictly increasing values"),
    (lambda: PiecewiseLinearFunction([0.0, 1.0], [1.0, 0.0]), ModelError,
     r"^values: expected nondecreasing values"),
    (lambda: PiecewiseLinearFunction([0.0, 1.0], [0.0]), DimensionError,
     r"^values: expected a vector of length 2, got length 1"),
    (lambda: PiecewiseLinearFunction([0.0], [0.0], slope_left=-1.0), ModelError,
     r"^slope_left: expected a finite slope >= 0"),
    (lambda: PiecewiseLinearFunction.saturation(level=0.0), ModelError,
     r"^level: expected a finite saturation level > 0"),
    (lambda: Product(), ModelError, r"^laws: Product needs at least one law, got none"),
    (lambda: Product(Relay(1.0), "relay"), ModelError, r"^laws\[1\]: expected a SetValuedLaw"),
    (lambda: _RELAY2.resolvent([1.0, 2.0, 3.0]), DimensionError,
     r"^x: expected a vector of length 2, got length 3"),
    (lambda: _RELAY2.resolvent([1.0, 2.0], gamma=0.0), ModelError,
     r"^gamma: expected positive weights"),
    (lambda: _RELAY2.graph_residual([0.0, 0.0], [1.0]), DimensionError,
     r"^v: expected a vector of length 2, got length 1"),
    (lambda: NormalConeBox(0.0, 1.0).select([2.0]), InadmissibleStateError,
     r"^z: the normal cone is empty outside the box"),
    (lambda: solve_inclusion(MonotoneFunction(np.tanh, dim=2), [[2.0, 1.0], [0.0, 2.0]],
                             [1.0, 1.0]), ModelError,
     r"^MonotoneFunction\(f='tanh', dim=2\) has no complementarity \(LCP\) form: an LCP "
     r"encodes only graphs made of finitely many straight pieces"),
    (lambda: solve_inclusion(_RELAY2, np.eye(3), [1.0, 1.0]), DimensionError,
     r"^M: expected shape \(2, 2\), got \(3, 3\)"),
    (lambda: NewtonImpactLaw(1.2), ModelError, r"^e: expected restitution coefficients in "
                                               r"\[0, 1\], got \[1.2\]"),
    (lambda: NewtonImpactLaw(-0.1), ModelError, r"^e: expected restitution coefficients"),
    (lambda: NewtonImpactLaw(np.nan), ModelError, r"^e: expected restitution coefficients"),
    (lambda: NewtonImpactLaw("a"), ModelError, r"^e: expected a real numeric array, got "
                                               r"strings"),
    (lambda: NewtonImpactLaw([[0.5]]), DimensionError, r"^e: expected a scalar or a vector"),
    (lambda: restitution_matrix(1.0, 1.0, 1.5), ModelError,
     r"^e: expected a value in \[0.0, 1.0\], got 1.5"),
    (lambda: restitution_matrix(0.0, 1.0, 0.5), ModelError,
     r"^m1: expected a finite number > 0, got 0.0"),
    (lambda: _LAW2.apply([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], _W3,
                         [1.0, 0.0, 0.0]), ModelError, r"^M: expected a symmetric matrix"),
    (lambda: _LAW2.apply(np.diag([1.0, -1.0, 1.0]), _W3, [1.0, 0.0, 0.0]), ModelError,
     r"^M: expected a symmetric positive definite mass matrix"),
    (lambda: _LAW2.apply(np.eye(3), _W3[:2], [1.0, 0.0, 0.0]), DimensionError,
     r"^W: expected 3 rows, got shape \(2, 2\)"),
    (lambda: NewtonImpactLaw(0.5).apply(np.eye(3), [1.0, -1.0], [1.0, 0.0, 0.0]),
     DimensionError, r"^W: expected a vector of length 3, got length 2"),
    (lambda: NewtonImpactLaw([0.5, 0.5, 0.5]).apply(np.eye(3), _W3, [1.0, 0.0, 0.0]),
     DimensionError, r"^e: expected one coefficient or 2 \(one per contact"),
    (lambda: _LAW2.apply(np.eye(3), _W3, [1.0, 0.0, 0.0], active=[0, 5]), DimensionError,
     r"^active: expected distinct indices in \[0, 2\), got \[0, 5\]"),
    (lambda: _LAW2.apply(np.eye(3), _W3, [1.0, 0.0j, 0.0]), ModelError,
     r"^v_minus: expected real entries, got a complex array"),
]


@pytest.mark.parametrize(("make", "error", "pattern"), BAD_INPUT,
                         ids=[f"case{i}" for i in range(len(BAD_INPUT))])
def test_bad_input_raises_specific_errors(make, error, pattern):
    with pytest.raises(error, match=pattern):
        make()


def test_domains_and_product_blocks():
    box = NormalConeBox([0.0, -1.0], [1.0, np.inf])
    assert box.in_domain([0.5, 10.0]) and not box.in_domain([1.5, 0.0])
    assert box.in_domain([1.0 + 1e-10, 0.0], tol=1e-9)
    assert Relay(1.0).in_domain([1e9])
    prod = Product(Relay(1.0), Product(Complementarity(2), Coulomb(0.5, 2.0)))
    assert prod.dim == 4 and len(prod.parts) == 3            # nested products flatten
    assert not prod.in_domain([0.0, -1.0, 0.0, 0.0])
    np.testing.assert_array_equal(prod.resolvent([3.0, -1.0, 2.0, -4.0], [1.0, 1.0, 1.0, 2.0]),
                                  [2.0, 0.0, 2.0, -2.0])
    with pytest.raises(AttributeError):
        prod.dim = 5


def test_laws_are_cheap_to_vary_with_replace():
    import dataclasses

    c = dataclasses.replace(Coulomb(0.5, [1.0, 2.0]), mu=0.1)
    np.testing.assert_allclose(c.bound, [0.1, 0.2])
    s = dataclasses.replace(Stribeck(0.3, 0.1, 1.0), static=0.1)
    assert s.monotone and s.sigma_tan[0] == 0.0          # T_s = T_c: Coulomb + viscous
    with pytest.raises(ModelError, match="bound"):
        dataclasses.replace(Relay(1.0), bound=-1.0)


def test_graph_residual_is_the_euclidean_distance_for_polyline_graphs(rng):
    # dense samples of the graphs of 1.5 Sign and N_[-1, 2] in the box [-6, 6]^2
    t = np.linspace(-6.0, 6.0, 120001)
    relay_graph = np.concatenate([
        np.stack([np.zeros_like(t), np.clip(t, -1.5, 1.5)], 1),
        np.stack([np.abs(t), np.full_like(t, 1.5)], 1),
        np.stack([-np.abs(t), np.full_like(t, -1.5)], 1)])
    cone_graph = np.concatenate([
        np.stack([np.clip(t, -1.0, 2.0), np.zeros_like(t)], 1),
        np.stack([np.full_like(t, -1.0), -np.abs(t)], 1),
        np.stack([np.full_like(t, 2.0), np.abs(t)], 1)])
    for law, graph in ((Relay(1.5), relay_graph), (NormalConeInterval(-1.0, 2.0), cone_graph)):
        for point in rng.uniform(-3.0, 3.0, (30, 2)):
            sampled = np.min(np.hypot(*(graph - point).T))
            # the nearest sample lies within half a grid step h of the nearest graph point:
            # sampled - true <= sqrt(d^2 + (h/2)^2) - d <= h/2 (plus rounding, ~u)
            assert law.graph_residual([point[0]], [point[1]]) == pytest.approx(
                sampled, abs=0.5 * (t[1] - t[0]) + 1e-12)


def test_asymmetric_stribeck_uses_each_side_and_the_worse_slope():
    plus, minus = Stribeck(0.3, 0.1, 1.0), Stribeck(0.5, 0.2, 0.5, viscous=0.1)
    law = AsymmetricStribeck(plus, minus)
    assert not law.monotone
    np.testing.assert_allclose(law.sigma_tan, max(plus.sigma_tan[0], minus.sigma_tan[0]))
    assert law.contains([0.0], [-0.5]) and law.contains([0.0], [0.3])
    assert not law.contains([0.0], [0.4])                # above T_s_plus
    assert law.select([2.0])[0] == pytest.approx(plus.magnitude([2.0])[0])
    assert law.select([-2.0])[0] == pytest.approx(-minus.magnitude([2.0])[0])
    assert law.resolvent([-0.2], gamma=0.5)[0] == 0.0      # |x| <= gamma T_s_minus = 0.25
    assert law.resolvent([0.2], gamma=0.5)[0] > 0.0        # x > gamma T_s_plus = 0.15
    lt = law.loop_transformation()
    assert lt.monotone_part.monotone
    with pytest.raises(ModelError, match="dimensions"):
        AsymmetricStribeck(plus, Stribeck([0.3, 0.3], 0.1, 1.0))


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), e=st.floats(0.0, 1.0))
def test_impact_with_a_full_mass_matrix(seed, e):
    rng = np.random.default_rng(seed)
    n, k = 4, 3
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    W = rng.normal(size=(n, k))
    v_minus = rng.uniform(-2.0, 2.0, n)
    res = NewtonImpactLaw(e).apply(M, W, v_minus)
    np.testing.assert_allclose(M @ (res.v_plus - v_minus), W @ res.impulse, atol=1e-10)
    slack = W.T @ res.v_plus + e * (W.T @ v_minus)
    assert np.all(res.impulse >= 0.0) and np.all(slack >= -1e-10)
    assert abs(res.impulse @ slack) <= 1e-9
    ke = lambda v: 0.5 * v @ M @ v   # noqa: E731
    assert ke(res.v_plus) <= ke(v_minus) + 1e-9


def test_require_monotone_and_loop_transformation_edge_cases():
    law = Stribeck(0.3, 0.1, 1.0)
    relay = Relay(1.0)
    assert require_monotone(relay, who="x") is relay
    with pytest.raises(ModelError, match="SetValuedLaw"):
        require_monotone("relay", who="x")
    fake = law.loop_transformation()
    fake = type(fake)(monotone_part=law, slope=fake.slope)    # not monotone: refused
    with pytest.raises(ModelError, match="monotone_part"):
        require_monotone(law, who="x", loop_transformation=fake)
    with pytest.raises(ModelError, match="already monotone"):
        relay.loop_transformation(0.3)
    with pytest.raises(ModelError, match="finite"):
        Stribeck(2.0, 1.0, 1.0, delta=0.5).loop_transformation()
    lt = Product(relay, law).loop_transformation([0.0, 2 * law.sigma_tan[0]])
    np.testing.assert_allclose(lt.slope, [0.0, 2 * law.sigma_tan[0]])
    assert lt.monotone_part.monotone
    with pytest.raises(DimensionError, match="G"):
        lt.transform_A(np.eye(3), np.ones((3, 1)), np.ones((2, 3)))

"""Chapter 2, linear-algebra side: restitution, Theorem 1, Jury test, high-gain placement,
the eps search, and the specific errors for bad input (spec ch02 §7)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nscontrol.analysis.observability import (
    alpha_limit,
    jury_second_order,
    reconstructibility,
    search_epsilon,
    theorem1_test,
)
from nscontrol.design.impact_observer import (
    design_impact_observer,
    impact_plant,
    observer_jump,
    place_scaled,
)
from nscontrol.errors import (
    DimensionError,
    InadmissibleStateError,
    InfeasibleDesignError,
    ModelError,
)
from nscontrol.systems.impacting_bodies import ImpactingBodies

LAMBDA1 = [-0.5, -0.6, -0.7, -0.8]


def example_bodies(m3=1.0, e=1.0, E=None, k12=6.0):
    """Spec §6: masses 1-2 joined by k12, mass 1 tied by k11, mass 3 tied by k33 > 0."""
    return ImpactingBodies.from_springs([1.0, 1.0], [m3], {(0, 0): 4.0, (0, 1): k12},
                                        {(0, 0): 4.0 * m3}, E=E, restitution=e)


def test_docstring_examples():
    import doctest

    import nscontrol.analysis.observability as obs

    failures, tried = doctest.testmod(obs, optionflags=doctest.ELLIPSIS)
    assert tried >= 4 and failures == 0


# -- restitution (Newton, Remark 1) ----------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(m1=st.floats(0.05, 20.0), m2=st.floats(0.05, 20.0), e=st.floats(0.0, 1.0),
       v1=st.floats(-10.0, 10.0), dv=st.floats(0.01, 10.0))
def test_restitution_conserves_momentum_and_scales_relative_velocity(m1, m2, e, v1, dv):
    bodies = ImpactingBodies([m1], [[1.0]], [m2], [[1.0]], restitution=e)
    M = bodies.restitution_matrix
    v_minus = np.array([v1, v1 - dv])          # approaching: v_left > v_right
    v_plus = M @ v_minus
    p_minus, p_plus = m1 * v_minus[0] + m2 * v_minus[1], m1 * v_plus[0] + m2 * v_plus[1]
    assert abs(p_plus - p_minus) <= 1e-12 * (abs(m1 * v1) + abs(m2 * v_minus[1]) + 1.0)
    rel_minus, rel_plus = v_minus[1] - v_minus[0], v_plus[1] - v_plus[0]
    assert rel_plus == pytest.approx(-e * rel_minus, rel=1e-12, abs=1e-12)
    kin = lambda v: 0.5 * (m1 * v[0] ** 2 + m2 * v[1] ** 2)  # noqa: E731
    if e == 1.0:
        assert kin(v_plus) == pytest.approx(kin(v_minus), rel=1e-12, abs=1e-12)
    else:
        assert kin(v_plus) < kin(v_minus) + 1e-12 * kin(v_minus)
    assert abs(M[1, 1]) < 1.0 or e == 0.0 and m1 == m2


# -- Theorem 1 -------------------------------------------------------------------------------
def test_theorem1_yes_for_the_example():
    res = theorem1_test(*_mats(example_bodies()))
    assert res.observable and res.transfer_nonzero and res.pair_observable
    assert res.markov_relative > 1e-3 and res.pbh_margin > 1e-3
    assert "observable" in res.reason


def test_theorem1_no_when_input_cannot_reach_the_contact_mass():
    # force on mass 1 but no spring between masses 1 and 2: W(s) = 0 and (C_a, A_a)
    # unobservable; condition (1) is reported first
    res = theorem1_test(*_mats(example_bodies(k12=0.0)))
    assert not res.observable and not res.transfer_nonzero
    assert res.markov_relative == 0.0
    assert "condition (1)" in res.reason


def test_theorem1_no_when_pair_unobservable():
    # force on mass 2, no spring 1-2: the input moves mass 2 (W != 0) but y = q1 never sees it
    res = theorem1_test(*_mats(example_bodies(k12=0.0, E=[0.0, 1.0])))
    assert res.transfer_nonzero and not res.pair_observable and not res.observable
    assert len(res.unobservable_modes) == 2            # the +-2i... modes of mass 2 alone
    assert "condition (2)" in res.reason and res.pbh_margin < 1e-12


def _mats(bodies):
    p = impact_plant(bodies)
    return p.A_a, p.B_a, p.C_a, p.C_contact


def test_reconstructibility_needs_an_impact_and_an_observable_pair():
    p = impact_plant(example_bodies())
    assert not reconstructibility(p.A_a, p.C_a, [], (0.0, 10.0)).reconstructible
    ok = reconstructibility(p.A_a, p.C_a, [1.0, 3.0], (0.0, 10.0))
    assert ok.reconstructible and ok.n_impacts == 2 and ok.min_dwell == pytest.approx(2.0)
    zeno = reconstructibility(p.A_a, p.C_a, [1.0, 1.0 + 1e-12], (0.0, 10.0))
    assert not zeno.reconstructible and "accumulate" in zeno.reason
    q = impact_plant(example_bodies(k12=0.0, E=[0.0, 1.0]))
    assert not reconstructibility(q.A_a, q.C_a, [1.0], (0.0, 10.0)).reconstructible


# -- Jury-type test (our restatement of (11a)-(11b)) -------------------------------------------
def test_jury_second_order_matches_root_moduli(rng):
    disagreements = 0
    for _ in range(4000):
        c1, c0 = rng.uniform(-2.0, 2.0, size=2)
        rho = rng.uniform(0.1, 1.5)
        radius = np.max(np.abs(np.roots([1.0, -c1, -c0])))
        if abs(radius - rho) < 1e-9:
            continue
        disagreements += jury_second_order(c1, c0, rho) != (radius < rho)
    assert disagreements == 0


# -- high-gain placement -----------------------------------------------------------------------
@pytest.mark.parametrize("eps", [1.0, 0.1, 0.01])
def test_place_scaled_spectrum_and_scaled_realisation(eps):
    p = impact_plant(example_bodies())
    sp = place_scaled(p.A_a, p.C_a, LAMBDA1, eps)
    # the scaled flow matrix is exactly companion(Lambda1)/eps and similar to A_a - G C_a
    A_O = p.A_a - np.outer(sp.G, p.C_a)
    similar = np.linalg.solve(sp.T, A_O @ sp.T)
    assert np.max(np.abs(similar - sp.F / eps)) <= 1e-9 * np.max(np.abs(sp.F / eps))
    assert np.allclose(np.sort(np.linalg.eigvals(sp.F)).real, np.sort(LAMBDA1), atol=1e-12)
    assert np.allclose(np.linalg.solve(sp.T, sp.G), sp.g_scaled, rtol=1e-9)
    assert sp.conditioning.spectrum_error_scaled < 1e-12
    assert sp.conditioning.spectrum_error_original < 1e-8


def test_gain_grows_like_eps_to_minus_N():
    p = impact_plant(example_bodies())
    norms = [place_scaled(p.A_a, p.C_a, LAMBDA1, e).conditioning.gain_norm
             for e in (1e-2, 1e-3)]
    assert norms[1] / norms[0] == pytest.approx(1e4, rel=0.02)   # N = 4, lower terms


def test_observer_jump_equal_masses_swaps_the_velocity_estimates():
    M = example_bodies().restitution_matrix
    xa, xb = observer_jump([1.0, 2.0, 3.0, 4.0], [5.0, 6.0], y=-7.0, M=M)
    assert np.array_equal(xa, [-7.0, 2.0, 3.0, 6.0])     # q1 <- y, v2 <- v3 (swap)
    assert np.array_equal(xb, [2.0, 4.0])                 # q3 <- q2, v3 <- v2


# -- eps search (Theorems 3, 4) ----------------------------------------------------------------
def _scaled(p):
    sp = place_scaled(p.A_a, p.C_a, LAMBDA1, 1.0)
    return sp.F, sp.P


def test_search_epsilon_equal_masses_certifies_and_shrinks_with_alpha():
    p = impact_plant(example_bodies())
    c1 = search_epsilon(*_scaled(p), p.A_b, p.M, 0.3, 3.6, 0.2)
    c2 = search_epsilon(*_scaled(p), p.A_b, p.M, 0.3, 3.6, 0.6)
    assert c1.condition == "theorem3" and c1.alpha_L == np.inf
    assert 0 < c2.eps < c1.eps <= 1.0
    for c in (c1, c2):
        assert jury_second_order(c.b1, c.b0, c.rho) and c.spectral_radius < c.rho


def test_search_epsilon_unequal_masses_caps_alpha():
    p = impact_plant(example_bodies(m3=0.7))
    alpha_L = alpha_limit(p.M[1, 1], 2.3)
    assert alpha_L == pytest.approx(-np.log(0.3 / 1.7) / 2.3)
    cert = search_epsilon(*_scaled(p), p.A_b, p.M, 0.6, 2.3, 0.5 * alpha_L)
    assert cert.condition == "theorem4" and cert.spectral_radius < cert.rho
    with pytest.raises(InfeasibleDesignError, match="alpha_L") as info:
        search_epsilon(*_scaled(p), p.A_b, p.M, 0.6, 2.3, 1.01 * alpha_L)
    assert info.value.status == "alpha_unreachable"


def test_design_with_target_rate_reports_certificate():
    d = design_impact_observer(example_bodies(m3=0.7), LAMBDA1, alpha=0.3, delta_min=0.6,
                               delta_max=2.3)
    assert d.certificate is not None and d.eps == d.certificate.eps
    assert d.alpha_L == pytest.approx(alpha_limit(d.plant.M[1, 1], 2.3))
    assert d.observability.observable


# -- bad input ---------------------------------------------------------------------------------
def test_bad_lambda_and_eps_raise_specific_errors():
    b = example_bodies()
    with pytest.raises(DimensionError, match="Lambda1"):
        design_impact_observer(b, [-1.0, -2.0, -3.0], 0.5)
    with pytest.raises(ModelError, match="negative real part"):
        design_impact_observer(b, [-1.0, -2.0, 0.0, -3.0], 0.5)
    with pytest.raises(ModelError, match="conjugation"):
        design_impact_observer(b, [-1 + 1j, -1 + 1j, -2.0, -3.0], 0.5)
    for eps in (0.0, -0.1, 1.5, np.nan):
        with pytest.raises(ModelError, match=r"eps: expected a value in \(0, 1\]"):
            design_impact_observer(b, LAMBDA1, eps)


def test_unobservable_pair_is_an_infeasible_design():
    with pytest.raises(InfeasibleDesignError, match="unobservable") as info:
        design_impact_observer(example_bodies(k12=0.0, E=[0.0, 1.0]), LAMBDA1, 0.5)
    assert info.value.status == "unobservable"


def test_inadmissible_initial_state_is_rejected():
    d = design_impact_observer(example_bodies(), LAMBDA1, 0.5)
    with pytest.raises(InadmissibleStateError, match="penetrates"):
        d.initial_state([0.0, 1.0, 0, 0, 0.5, 0.0], np.zeros(6))     # q2 > q3
    with pytest.raises(InadmissibleStateError, match="approach"):
        d.initial_state([0.0, 0.5, 0, 1.0, 0.5, 0.0], np.zeros(6))   # touching, closing


def test_certified_eps_is_the_largest_independent_recheck():
    """Re-derive the Theorem-4 comparison matrix in the original coordinates (scipy expm of
    A_a - G_eps C_a): it certifies just below the returned eps and fails just above it."""
    from scipy.linalg import expm

    p = impact_plant(example_bodies(m3=0.7))
    d_min, d_max = 0.6, 2.3
    alpha = 0.3
    cert = search_epsilon(*_scaled(p), p.A_b, p.M, d_min, d_max, alpha)
    deltas = np.linspace(d_min, d_max, 64)
    Phis = [expm(p.A_b * d) for d in deltas]
    r = max(np.hypot(P[1, 0], P[1, 1] * p.M[1, 0]) for P in Phis)
    gamma = abs(p.M[1, 1]) * max(abs(P[1, 1]) for P in Phis)

    def radius(eps):
        G = place_scaled(p.A_a, p.C_a, LAMBDA1, eps).G
        A_O = p.A_a - np.outer(G, p.C_a)
        beta = max(np.linalg.norm(expm(A_O * d), 2) for d in deltas)
        comp = np.array([[beta, beta * abs(p.M[0, 1])], [r, gamma]])
        return np.max(np.abs(np.linalg.eigvals(comp)))

    rho = np.exp(-alpha * d_max)
    assert cert.rho == pytest.approx(rho)
    assert radius(0.97 * cert.eps) < rho < radius(1.03 * cert.eps)

"""Chapter 2, linear-algebra side: restitution, Theorem 1, Jury test, high-gain placement,
the eps search, and the specific errors for bad input (spec ch02 §7)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nscontrol.analysis.observability import (
    alpha_limit,
    certified_rate,
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


@pytest.mark.parametrize("module, minimum", [
    ("nscontrol.analysis.observability", 15),
    ("nscontrol.design.impact_conditions", 25),
    ("nscontrol.numerics.observability", 5),
    ("nscontrol.design.impact_observer", 25),
    ("nscontrol.systems.impacting_bodies", 4),
])
def test_docstring_examples(module, minimum):
    import doctest
    import importlib

    failures, tried = doctest.testmod(importlib.import_module(module),
                                      optionflags=doctest.ELLIPSIS)
    assert tried >= minimum and failures == 0


# -- restitution (Newton, Remark 1) ----------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(m1=st.floats(0.05, 20.0), m2=st.floats(0.05, 20.0),
       e=st.floats(0.0, 1.0, exclude_min=True), v1=st.floats(-10.0, 10.0),
       dv=st.floats(0.01, 10.0))
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
    assert abs(M[1, 1]) < 1.0


# -- Theorem 1 -------------------------------------------------------------------------------
def test_theorem1_yes_for_the_example():
    res = theorem1_test(*_mats(example_bodies()))
    assert res.observable and res.transfer_nonzero and res.pair_observable
    assert res.krylov_dimension == 4                     # the input reaches every state
    assert res.contact_projection == pytest.approx(1.0, abs=1e-12)
    assert res.pbh_margin > 0.1                          # measured 0.339
    assert "observable" in res.reason
    # W(s) at a test point, from the Markov parameters' own definition: not zero
    p = impact_plant(example_bodies())
    s0 = 0.37 + 1.1j
    W = p.C_contact @ np.linalg.solve(s0 * np.eye(4) - p.A_a, p.B_a)
    assert abs(W) > 1e-2


def test_theorem1_no_when_no_input_reaches_the_contact_mass():
    # E = 0 with k12 != 0: W(s) = 0 while (C_a, A_a) IS observable -- condition (1) alone
    res = theorem1_test(*_mats(example_bodies(E=[0.0, 0.0])))
    assert not res.observable and not res.transfer_nonzero and res.pair_observable
    assert res.krylov_dimension == 0 and res.contact_projection == 0.0
    assert res.reason.startswith("condition (1) fails")


def test_theorem1_no_when_input_cannot_reach_the_contact_mass():
    # force on mass 1 but no spring between masses 1 and 2: W(s) = 0 and (C_a, A_a)
    # unobservable; condition (1) is reported first
    res = theorem1_test(*_mats(example_bodies(k12=0.0)))
    assert not res.observable and not res.transfer_nonzero
    assert res.krylov_dimension == 2 and res.contact_projection == 0.0   # mass 1 only
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


def _chain(n_a, k=10.0):
    springs = {(0, 0): k}
    springs.update({(i, i + 1): k for i in range(n_a - 1)})
    return ImpactingBodies.from_springs([1.0] * n_a, [1.0], springs, {(0, 0): k})


def _rescaled(c, how, m3=1.0, k12=6.0, **kw):
    """The example with time scaled by 1/c: springs x c^2, or masses x 1/c^2."""
    k, m = (c * c, 1.0) if how == "springs" else (1.0, 1.0 / (c * c))
    return ImpactingBodies.from_springs([m, m], [m3 * m], {(0, 0): 4.0 * k, (0, 1): k12 * k},
                                        {(0, 0): 4.0 * m3 * k}, **kw)


@pytest.mark.parametrize("c", [1e2, 1e3, 1e-2])
@pytest.mark.parametrize("how", ["springs", "masses"])
def test_theorem1_verdict_does_not_depend_on_units(c, how):
    """Springs x 1e4 / 1e6 (or masses x 1e-4 / 1e-6) are the worked example in other units:
    same verdict, same margins up to the powers of two of the balancing."""
    ref = theorem1_test(*_mats(example_bodies()))
    res = theorem1_test(*_mats(_rescaled(c, how)))
    assert res.observable and res.krylov_dimension == 4
    assert res.contact_projection == pytest.approx(ref.contact_projection, rel=1e-9)
    assert 0.5 < res.pbh_margin / ref.pbh_margin < 2.0
    # the truly unobservable cases stay unobservable, with their reasons
    no_w = theorem1_test(*_mats(_rescaled(c, how, E=[0.0, 0.0])))
    assert not no_w.transfer_nonzero and no_w.pair_observable
    assert no_w.reason.startswith("condition (1) fails")
    no_pair = theorem1_test(*_mats(_rescaled(c, how, k12=0.0, E=[0.0, 1.0])))
    assert no_pair.transfer_nonzero and not no_pair.pair_observable
    assert no_pair.reason.startswith("condition (2) fails") and len(no_pair.unobservable_modes) == 2


@pytest.mark.parametrize("n_a", [5, 12])
def test_theorem1_long_chain_is_observable(n_a):
    # force on mass 1 of an n_a-mass chain (all springs k = 10): W(s) != 0 (the first non-zero
    # Markov parameter is ~ k^(n_a-1) against ||A||^(2 n_a - 1), which the old relative test
    # called zero for n_a = 5) and (C_a, A_a) observable
    res = theorem1_test(*_mats(_chain(n_a)))
    assert res.observable and res.krylov_dimension == 2 * n_a
    assert res.contact_projection > 0.5 and res.pbh_margin > 1e-3   # 0.033 (5), 0.0052 (12)


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


# -- error estimates for the realised observer spectrum --------------------------------------
U = np.finfo(float).eps / 2                                 # unit roundoff


def _eigenvalue_bound(M, perturbation):
    """First-order bound on ``max_i |mu_i - w_i| / |w_i|``: ``w`` the eigenvalues of ``M``,
    ``mu`` those ``eigvals`` computes of ``M`` perturbed by at most ``perturbation``
    (entrywise).

    In the coordinates ``D`` that balance ``M`` (LAPACK balances before QR), the perturbation
    plus the eigensolver's backward error ``N u ||B||_F``: ``|mu_i - w_i| <= kappa_i (N u
    ||B||_F + ||D^-1 perturbation D||_F)``, ``kappa_i = 1 / |y_i^H x_i|`` (unit left/right
    eigenvectors of the balanced ``B``).
    """
    from scipy.linalg import eig, matrix_balance

    n = M.shape[0]
    B, (d, _) = matrix_balance(M, permute=False, separate=True)
    moved = np.linalg.norm(perturbation * (d[None, :] / d[:, None]))
    w, left, right = eig(B, left=True, right=True)
    kappa = 1.0 / np.abs(np.sum(left.conj() * right, axis=0))
    return float(np.max(kappa * (n * U * np.linalg.norm(B) + moved) / np.abs(w)))


def _error_factor(sp, n_products):
    """``k`` of the entrywise bound ``k u |X| |Y|..`` on the error of a product of stored
    factors of the placement.

    Forming a product of ``n_products + 1`` factors of size ``N`` rounds by ``gamma_{n N}``
    (Higham, *Accuracy and Stability*, section 3.5: ``|fl(X Y) - X Y| <= gamma_N |X| |Y|``,
    ``gamma_k ~ k u``). The stored ``T``, ``T^-1``, ``g`` themselves come from orthogonal
    factors and a triangular substitution of condition ``cond_P`` (reported by the
    placement), so they are off by up to ``N cond_P u`` relative (Higham, chapter 8).
    """
    n = sp.F.shape[0]
    return n_products * n + 1 + n * sp.conditioning.cond_P


def _realised_spectrum_bound(sp, A, C, eps):
    """Bounds for the error matrix ``R = T^-1 A T - g (C T)`` the scaled realisation runs,
    which stands for ``F / eps`` exactly, whatever the gain.

    Returns ``(spectrum_bound, residual, residual_bound)``:

    * ``residual = ||D^-1 (R - F / eps) D||_F`` (``D`` balancing ``F / eps``) and its a priori
      bound, ``R`` being off by at most ``k u (|T^-1| |A| |T| + |g| |C T|)`` entrywise with
      ``k`` from :func:`_error_factor`: this is where an inaccurate placement shows;
    * the bound on ``conditioning.spectrum_error`` given that residual
      (:func:`_eigenvalue_bound` of ``F / eps`` perturbed by ``|R - F / eps|`` and the
      rounding of that difference).
    """
    from scipy.linalg import matrix_balance

    A, C = np.asarray(A, float), np.ravel(C).astype(float)
    F = sp.F / eps
    realised = sp.T_inv @ A @ sp.T - np.outer(sp.g_scaled, C @ sp.T)
    magnitude = (np.abs(sp.T_inv) @ np.abs(A) @ np.abs(sp.T)
                 + np.outer(np.abs(sp.g_scaled), np.abs(C) @ np.abs(sp.T)))
    _, (d, _) = matrix_balance(F, permute=False, separate=True)
    to_balanced = d[None, :] / d[:, None]                   # D^-1 X D, entrywise
    residual = np.linalg.norm((realised - F) * to_balanced)
    residual_bound = _error_factor(sp, 2) * U * np.linalg.norm(magnitude * to_balanced)
    moved = np.abs(realised - F) + U * (np.abs(realised) + np.abs(F))
    return _eigenvalue_bound(F, moved), float(residual), float(residual_bound)


def _original_spectrum_bound(sp, A, C):
    """A priori bound on ``conditioning.spectrum_error_original``: ``A - G C`` with ``G = T g``
    is off by at most ``k u (|A| + |T| |g| |C|)`` (:func:`_error_factor`,
    :func:`_eigenvalue_bound`)."""
    A, C = np.asarray(A, float), np.ravel(C).astype(float)
    magnitude = np.abs(A) + np.outer(np.abs(sp.T) @ np.abs(sp.g_scaled), np.abs(C))
    moved = (_error_factor(sp, 1) + 1) * U * magnitude
    return _eigenvalue_bound(A - np.outer(sp.G, C), moved)


# -- high-gain placement -----------------------------------------------------------------------
@pytest.mark.parametrize("eps", [1.0, 0.1, 0.01])
def test_place_scaled_spectrum_and_scaled_realisation(eps):
    p = impact_plant(example_bodies())
    sp = place_scaled(p.A_a, p.C_a, LAMBDA1, eps)
    # the scaled flow matrix is companion(Lambda1)/eps and similar to A_a - G C_a
    A_O = p.A_a - np.outer(sp.G, p.C_a)
    similar = np.linalg.solve(sp.T, A_O @ sp.T)
    assert np.max(np.abs(similar - sp.F / eps)) <= 1e-9 * np.max(np.abs(sp.F / eps))
    assert np.allclose(np.sort(np.linalg.eigvals(sp.F)).real, np.sort(LAMBDA1), atol=1e-12)
    assert np.allclose(np.linalg.solve(sp.T, sp.G), sp.g_scaled, rtol=1e-9)
    assert np.allclose(sp.T_inv @ sp.T, np.eye(4), atol=1e-12)
    # canonical form: P^-1 A P = companion(a), C P = e1, a = char. poly of A_a
    Pinv_A_P = np.linalg.solve(sp.P, p.A_a @ sp.P)
    assert np.allclose(Pinv_A_P[:, 0], -sp.a, rtol=1e-12, atol=1e-12)
    assert np.allclose(p.C_a @ sp.P, [1.0, 0.0, 0.0, 0.0], atol=1e-14)
    assert np.allclose(sp.a, np.poly(p.A_a)[1:], rtol=1e-12)
    # the realised error matrix T^-1 A_a T - g C_a T, recomputed here
    realised = sp.T_inv @ p.A_a @ sp.T - np.outer(sp.g_scaled, p.C_a @ sp.T)
    mu = np.sort_complex(np.linalg.eigvals(realised))
    # bounds (_realised_spectrum_bound, _original_spectrum_bound): 1.7e-10 / 2.1e-9 at eps = 1,
    # 5.3e-12 / 1.7e-11 below; measured 2.9e-11 / 4.1e-11 (eps = 1) .. 1.3e-13. A T wrong by
    # 1e-9 relative gives a residual 8e3 x its bound.
    bound, residual, residual_bound = _realised_spectrum_bound(sp, p.A_a, p.C_a, eps)
    assert residual <= residual_bound
    assert np.allclose(mu.real, np.sort(LAMBDA1) / eps, rtol=bound, atol=0)
    assert np.allclose(mu.imag, 0, atol=bound * np.max(np.abs(LAMBDA1)) / eps)
    assert sp.conditioning.spectrum_error <= bound
    assert sp.conditioning.spectrum_error_original <= _original_spectrum_bound(sp, p.A_a, p.C_a)


def _long_chain(n_a):
    springs = {(0, 0): 4.0}
    springs.update({(i, i + 1): 6.0 for i in range(n_a - 1)})
    return ImpactingBodies.from_springs([1.0] * n_a, [1.0], springs, {(0, 0): 4.0})


@pytest.mark.parametrize("n_a, eps", [(4, 0.1), (4, 0.01), (6, 0.1), (6, 0.01)])
def test_place_scaled_realised_spectrum_of_longer_chains(n_a, eps):
    """The true error matrix of the realisation, T^-1 A_a T - g C_a T, against the bounds of
    _realised_spectrum_bound: its residual against companion(Lambda1)/eps within the rounding
    of its stored factors (cond_P = 193, 1.3e4), and its spectrum error within 7.5e-8 (n_a = 4;
    1.5e-6 with OpenBLAS's Nehalem kernels, whose residual is 600x larger) and 2.1e-4 (n_a =
    6), set by the eigenvalue condition numbers of the balanced companion matrix (5.6e6,
    7.6e9). Measured: 3.5e-10 / 1.0e-9 (1.6e-9 / 1.04e-8 on Nehalem kernels) and 4.4e-7 /
    2.2e-7 at eps = 0.1 / 0.01; with P = O^-1 O_c from matrix powers it was 1.8e-8 / 2.1e-4
    and 6.5e-2 / 5.0 (a T wrong by 1e-9 relative already gives a residual 25x its bound)."""
    import warnings

    from nscontrol.design.impact_observer import SPECTRUM_RTOL
    from nscontrol.errors import InaccurateCertificateWarning

    lam = -(0.5 + 0.1 * np.arange(2 * n_a))
    p = impact_plant(_long_chain(n_a))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sp = place_scaled(p.A_a, p.C_a, lam, eps)
    bound, residual, residual_bound = _realised_spectrum_bound(sp, p.A_a, p.C_a, eps)
    assert residual <= residual_bound
    realised = sp.T_inv @ p.A_a @ sp.T - np.outer(sp.g_scaled, p.C_a @ sp.T)
    mu = np.linalg.eigvals(realised)
    err = max(np.min(np.abs(mu - w)) / abs(w) for w in lam / eps)
    assert err <= bound and sp.conditioning.spectrum_error <= bound
    # the warning is the user-facing promise SPECTRUM_RTOL: exactly when it is broken; where
    # the bound is below it (n_a = 4 with most kernels), it can never be
    warned = [w for w in caught if issubclass(w.category, InaccurateCertificateWarning)]
    assert len(caught) == len(warned)
    assert bool(warned) == (sp.conditioning.spectrum_error > SPECTRUM_RTOL)
    if bound < SPECTRUM_RTOL:
        assert not warned


def test_place_scaled_warns_when_the_realised_spectrum_is_inaccurate():
    from nscontrol.design.impact_observer import SPECTRUM_RTOL
    from nscontrol.errors import InaccurateCertificateWarning

    p = impact_plant(_long_chain(4))
    lam = -(0.5 + 0.005 * np.arange(8))                    # clustered
    # the first-order error of a backward-stable eigensolver, kappa_i u ||B||_F / |w_i| (the
    # bound of _eigenvalue_bound without its factor N), is 0.26 here: 2.6e5 x SPECTRUM_RTOL,
    # so no CPU's rounding can land under the threshold (measured error 7e-3, companion
    # floor 6e-3)
    with pytest.warns(InaccurateCertificateWarning, match="misses Lambda1/eps") as rec:
        sp = place_scaled(p.A_a, p.C_a, lam, 0.1)
    assert sp.conditioning.spectrum_error > SPECTRUM_RTOL
    assert sp.conditioning.spectrum_error_companion > SPECTRUM_RTOL
    assert "companion form of Lambda1 alone" in str(rec[0].message)


@pytest.mark.parametrize("how", ["springs", "masses"])
def test_design_behaviour_does_not_depend_on_units(how):
    """Time scaled by 1/c (c = 1e3): Lambda1, alpha x c, dwell bounds / c. Same placement
    accuracy, same certified eps, alpha_L x c; at k = 1e6 the old PBH test said
    'unobservable' and the design raised."""
    c = 1e3
    lam = np.array(LAMBDA1)
    for m3, alpha in ((1.0, 0.3), (0.7, 0.3)):
        ref = design_impact_observer(example_bodies(m3=m3), lam, alpha=alpha, delta_min=0.6,
                                     delta_max=2.3)
        new = design_impact_observer(_rescaled(c, how, m3=m3), lam * c, alpha=alpha * c,
                                     delta_min=0.6 / c, delta_max=2.3 / c)
        assert new.eps == pytest.approx(ref.eps, rel=1e-6)
        assert new.certificate.spectral_radius == pytest.approx(ref.certificate.spectral_radius,
                                                                rel=1e-6)
        if m3 != 1.0:
            assert new.alpha_L == pytest.approx(c * ref.alpha_L, rel=1e-12)
        p_new = impact_plant(_rescaled(c, how, m3=m3))
        bound, _, _ = _realised_spectrum_bound(new.placement, p_new.A_a, p_new.C_a, new.eps)
        assert new.conditioning.spectrum_error <= bound     # bound ~5e-12, measured ~1e-13
        assert new.observability.observable
        for eps in (0.25, 0.01):
            a = design_impact_observer(example_bodies(m3=m3), lam, eps).placement
            b = design_impact_observer(_rescaled(c, how, m3=m3), lam * c, eps).placement
            bound, _, _ = _realised_spectrum_bound(b, p_new.A_a, p_new.C_a, eps)
            assert b.conditioning.spectrum_error <= bound
            assert 0.5 < b.conditioning.cond_P / a.conditioning.cond_P < 2.0


def test_gain_grows_like_eps_to_minus_N():
    p = impact_plant(example_bodies())
    norms = [place_scaled(p.A_a, p.C_a, LAMBDA1, e).conditioning.gain_norm
             for e in (1e-2, 1e-3)]
    # G ~ eps^-N (1 + O(eps)): the lower powers change the ratio by O(1e-2), stated as 2 eps
    assert norms[1] / norms[0] == pytest.approx(1e4, rel=2 * 1e-2)


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
    for eps in (True, "0.5", 0.5 + 0j, [0.5, 0.25]):
        with pytest.raises(ModelError, match="eps: expected a real number"):
            design_impact_observer(b, LAMBDA1, eps)
    with pytest.raises(DimensionError, match=r"Lambda1: expected a 1-D .* shape \(2, 2\)"):
        design_impact_observer(b, [[-0.5, -0.6], [-0.7, -0.8]], 0.5)


def test_restitution_zero_is_refused():
    with pytest.raises(ModelError, match=r"restitution: expected a value in \(0, 1\], got 0.*"
                                         "sustained contact"):
        example_bodies(e=0.0)


def test_unobservable_pair_is_an_infeasible_design():
    with pytest.raises(InfeasibleDesignError, match="unobservable") as info:
        design_impact_observer(example_bodies(k12=0.0, E=[0.0, 1.0]), LAMBDA1, 0.5)
    assert info.value.status == "unobservable"


def test_inadmissible_initial_state_is_rejected():
    d = design_impact_observer(example_bodies(), LAMBDA1, 0.5)
    with pytest.raises(InadmissibleStateError, match="^x_plant0: body a penetrates"):
        d.initial_state([0.0, 1.0, 0, 0, 0.5, 0.0], np.zeros(6))     # q2 > q3
    with pytest.raises(InadmissibleStateError, match="^x_plant0: the bodies touch and approach"):
        d.initial_state([0.0, 0.5, 0, 1.0, 0.5, 0.0], np.zeros(6))   # touching, closing


@pytest.mark.parametrize("velocity_scale", [1.0, 2.0])
def test_certified_eps_is_the_largest_independent_recheck(velocity_scale):
    """Re-derive the Theorem-4 comparison matrix in the original coordinates (scipy expm of
    A_a - G_eps C_a, norms of [q; v / velocity_scale]): it certifies just below the returned
    eps and fails just above it."""
    from scipy.linalg import expm

    p = impact_plant(example_bodies(m3=0.7))
    d_min, d_max = 0.6, 2.3
    alpha = 0.3
    cert = search_epsilon(*_scaled(p), p.A_b, p.M, d_min, d_max, alpha,
                          velocity_scale=velocity_scale)
    assert cert.velocity_scale == velocity_scale
    deltas = np.linspace(d_min, d_max, 64)
    wb, wa = np.array([1.0, 1.0 / velocity_scale]), np.repeat([1.0, 1.0 / velocity_scale], 2)
    Phis = [wb[:, None] * expm(p.A_b * d) / wb[None, :] for d in deltas]
    r = max(np.hypot(P[1, 0], P[1, 1] * p.M[1, 0]) for P in Phis)
    gamma = abs(p.M[1, 1]) * max(abs(P[1, 1]) for P in Phis)

    def radius(eps):
        G = place_scaled(p.A_a, p.C_a, LAMBDA1, eps).G
        A_O = p.A_a - np.outer(G, p.C_a)
        beta = max(np.linalg.norm(wa[:, None] * expm(A_O * d) / wa[None, :], 2)
                   for d in deltas)
        comp = np.array([[beta, beta * abs(p.M[0, 1])], [r, gamma]])
        return np.max(np.abs(np.linalg.eigvals(comp)))

    rho = np.exp(-alpha * d_max)
    assert cert.rho == pytest.approx(rho)
    assert radius(0.97 * cert.eps) < rho < radius(1.03 * cert.eps)


def test_certified_rate_is_the_converse_of_search_epsilon():
    """At the eps search_epsilon returns for alpha, certified_rate gives back alpha (the
    certificate's boundary), for both theorems."""
    for m3 in (1.0, 0.7):
        p = impact_plant(example_bodies(m3=m3))
        F, P = _scaled(p)
        cert = search_epsilon(F, P, p.A_b, p.M, 0.6, 2.3, 0.3)
        assert certified_rate(F, P, p.A_b, p.M, 0.6, 2.3, cert.eps) == pytest.approx(0.3,
                                                                                     rel=1e-3)
        assert certified_rate(F, P, p.A_b, p.M, 0.6, 2.3, 1.0) == 0.0     # nothing certified
    p = impact_plant(example_bodies(m3=0.7))
    alpha_L = alpha_limit(p.M[1, 1], 2.3)
    assert 0.0 < certified_rate(*_scaled(p), p.A_b, p.M, 0.6, 2.3, 1e-3) <= alpha_L

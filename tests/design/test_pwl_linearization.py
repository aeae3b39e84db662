"""PWL feedback linearization: verdicts and reasons (acceptance check 1), the construction of
Ex 9.2 (check 2), robust rejections (check 6), the bimodal corollary on random systems, the
matched multi-input case and the refusals."""

import numpy as np
import pytest

from nscontrol.design import (
    FEEDBACK_CLASSES,
    linearize_or_raise,
    pwl_feedback_linearize,
)
from nscontrol.errors import InfeasibleDesignError, ModelError, SlidingError
from nscontrol.examples.ch09_pwl_linearization import (
    EXPECTED_VERDICTS,
    ex9_2_one_layer,
    ex9_4_pwl_gain,
    random_bimodal,
)
from nscontrol.systems import ConewiseLinearSystem

EPS = np.finfo(float).eps


@pytest.mark.parametrize("exact", [False, True], ids=["float", "exact"])
@pytest.mark.parametrize("name", list(EXPECTED_VERDICTS))
def test_verdicts_and_reasons_of_the_examples(name, exact):
    (builder, args), expected, words = EXPECTED_VERDICTS[name]
    res = pwl_feedback_linearize(builder(*args), exact=exact)
    assert tuple(res.verdict[c] for c in FEEDBACK_CLASSES) == expected
    for cls, ok in zip(FEEDBACK_CLASSES, expected, strict=True):
        assert bool(res.reasons[cls]) is not ok      # a "no" always says why
    first_no = next((c for c in FEEDBACK_CLASSES if not res.verdict[c]), None)
    if first_no is not None:
        assert words in res.reasons[first_no][0]
    assert (res.transform is not None) is res.verdict["pwl_gain"]


@pytest.mark.parametrize("name", [n for n, (_, v, _) in EXPECTED_VERDICTS.items() if v[2]])
def test_float_and_exact_modes_build_the_same_transformation(name):
    (builder, args), _, _ = EXPECTED_VERDICTS[name]
    system = builder(*args)
    f = pwl_feedback_linearize(system).transform
    x = pwl_feedback_linearize(system, exact=True).transform
    # data of a few digits: the float pieces are exact up to a few roundoffs of |T_i| <= 3
    for a, b in zip(f.T_modes + f.K_modes, x.T_modes + x.K_modes, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=10 * EPS * 3)
    np.testing.assert_allclose(f.gammas, x.gammas, rtol=10 * EPS)


def test_one_layer_example_matches_its_closed_forms():
    lin = pwl_feedback_linearize(ex9_2_one_layer()).transform
    # integer data: every entry is computed exactly (sums and products of 0 and 1)
    np.testing.assert_array_equal(lin.w, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(lin.L, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_array_equal(lin.rows[0], [1.0, 0.0, 1.0])
    np.testing.assert_array_equal(lin.rows[1], [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(lin.gammas, [1.0, 1.0])
    rng = np.random.default_rng(92)
    for x, v in zip(rng.standard_normal((100, 3)), rng.standard_normal(100), strict=True):
        T_ref = [x[0], x[1], x[2] + max(x[0], 0.0)]
        u_ref = v - (x[1] if x[0] >= 0 else 0.0)
        # one rounding of a sum of two O(1) numbers: 1e-12 is far above 4 × 2.2e-16
        np.testing.assert_allclose(lin.T(x), T_ref, rtol=0, atol=1e-12)
        assert lin.feedback(x, [v])[0] == pytest.approx(u_ref, abs=1e-12)
        np.testing.assert_allclose(lin.T_inv(lin.T(x)), x, rtol=0, atol=1e-12)


def test_perturbed_two_layer_example_stays_rejected():
    rng = np.random.default_rng(6)
    A2, b, c = np.eye(3, k=1), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    for _ in range(200):
        d = 1e-3   # the chain residual stays O(1) (it is |e1ᵀ| = 1 unperturbed) ≫ tol 1e-9
        A2p = A2 + d * rng.standard_normal((3, 3))
        cp = c + d * rng.standard_normal(3)
        sysp = ConewiseLinearSystem.bimodal(A2p + np.outer(c + d * rng.standard_normal(3), cp),
                                            A2p, b + d * rng.standard_normal(3), cp)
        res = pwl_feedback_linearize(sysp)
        assert not any(res.verdict.values())
        assert "chain broken at k = 1" in res.reasons["pwl_gain"][0]


def test_a_kink_one_integrator_too_deep_by_1e_3_is_reported_not_accepted():
    res = pwl_feedback_linearize(ex9_2_one_layer(1e-3))
    assert res.verdict == {c: False for c in FEEDBACK_CLASSES}
    assert "chain broken at k = 1 in mode 1" in res.reasons["pwl_gain"][0]
    (i, k, r), = [t for t in res.chain_residuals if t[1] == 1]
    # |1e-3 e1| / |e2 + 1e-3 e1| = 1e-3 / sqrt(1 + 1e-6), computed to a few roundoffs
    assert r == pytest.approx(1e-3 / np.sqrt(1 + 1e-6), rel=1e-12)
    assert "residual 0.001" in res.reasons["pwl_gain"][0]


def _bimodal_oracle(system, A2, b, c):
    """Verdicts of the bimodal corollary: e = A_1 - A_2 column over the Krylov basis of
    (A_2, b); F2 iff e in span{b, A_2 b} and 1 + β_1 cᵀb > 0; F1 iff also β_1 cᵀb = 0; F0
    iff e in span{b}."""
    n = len(b)
    e = (system.A[0] - A2) @ c / (c @ c)
    K = np.column_stack([np.linalg.matrix_power(A2, k) @ b for k in range(n)])
    beta = np.linalg.solve(K, e)
    small = 1e-8 * np.linalg.cond(K) * (1 + np.linalg.norm(e))
    in_span2 = bool(np.all(np.abs(beta[2:]) <= small))
    ratio = 1 + beta[1] * (c @ b)
    f2 = in_span2 and ratio > 0
    f1 = f2 and abs(beta[1] * (c @ b)) <= small
    f0 = in_span2 and abs(beta[1]) <= small
    return (f0, f1, f2), ratio, np.linalg.cond(K)


def test_bimodal_corollary_on_random_systems():
    rng = np.random.default_rng(33)
    checked = {True: 0, False: 0}
    for trial in range(300):
        n = 2 + trial % 4
        kind = trial % 5
        beta = (rng.normal(), rng.normal() if kind in (0, 1, 2) else 0.0,
                0.0 if kind in (0, 1, 3) else rng.choice([-1, 1]) * rng.uniform(0.2, 1.0))
        system = random_bimodal(rng, n, beta)
        A2, b = system.A[1], system.B[:, 0]
        c = system.facets[0].normal
        if kind == 1:   # c ⟂ b: the F1 case with β_1 ≠ 0 (rebuild with a projected c)
            c = c - (c @ b) / (b @ b) * b
            e = beta[0] * b + beta[1] * A2 @ b
            system = ConewiseLinearSystem.bimodal(A2 + np.outer(e, c), A2, b, c)
            c = system.facets[0].normal
        expected, ratio, cond = _bimodal_oracle(system, A2, b, c)
        if abs(ratio) < 0.05 or cond > 1e6:
            continue   # too close to a boundary of the corollary for a float verdict
        res = pwl_feedback_linearize(system)
        assert tuple(res.verdict[cl] for cl in FEEDBACK_CLASSES) == expected, (trial, beta)
        checked[expected[2]] += 1
        if expected[2]:
            # γ_0/γ_1 = 1 + β_1 cᵀb; both sides carry relative errors of about cond(ctrb) × u
            # (the flat output solves a system with that matrix): 100 n cond u
            g = res.gammas
            assert g[0] / g[1] == pytest.approx(ratio, rel=100 * n * cond * EPS)
    assert min(checked.values()) >= 60     # both verdicts well represented


def test_matched_multi_input_system_is_linearized_by_continuous_feedback():
    rng = np.random.default_rng(5)
    # small integers: A_1 is exact in floating point, so the exact mode sees a matched system
    B = rng.integers(-3, 4, (4, 2)).astype(float)
    c = rng.integers(-3, 4, 4).astype(float)
    A2 = rng.integers(-3, 4, (4, 4)).astype(float)
    A1 = A2 + np.outer(B @ [1.0, -2.0], c)        # matched: the kink enters through im B
    system = ConewiseLinearSystem.bimodal(A1, A2, B, c)
    assert np.linalg.matrix_rank(B) == 2 and np.linalg.matrix_rank(
        np.column_stack([np.linalg.matrix_power(A1, k) @ B for k in range(4)])) == 4
    for exact in (False, True):
        res = pwl_feedback_linearize(system, "continuous", exact=exact)
        assert res.verdict == {cl: True for cl in FEEDBACK_CLASSES}
    lin = res.transform
    for A, K in zip(system.A, lin.K_modes, strict=True):
        # B⁺ applied to B k cᵀ: exact up to cond(B) roundoffs of |A|
        np.testing.assert_allclose(A + B @ K, lin.A_target, rtol=0,
                                   atol=100 * np.linalg.cond(B) * EPS * np.abs(A).max())
    unmatched = ConewiseLinearSystem.bimodal(A2 + np.outer(rng.standard_normal(4), c), A2, B, c)
    for exact in (False, True):
        res = pwl_feedback_linearize(unmatched, exact=exact)
        assert res.verdict == {"continuous": False, "pwl_feedback": None, "pwl_gain": None}
        assert "unmatched" in res.reasons["continuous"][0]
        assert "not decided" in res.reasons["pwl_gain"][0]


def test_exact_mode_decides_for_the_stored_doubles():
    # A_2 + B k cᵀ rounded in floating point is matched only up to roundoff: the float mode
    # accepts it (residual ~1e-16 ≪ tol), the exact mode sees the rounding and says no
    rng = np.random.default_rng(5)
    B, c, A2 = rng.standard_normal((4, 2)), rng.standard_normal(4), rng.standard_normal((4, 4))
    system = ConewiseLinearSystem.bimodal(A2 + np.outer(B @ [0.1, -0.3], c), A2, B, c)
    assert pwl_feedback_linearize(system, "continuous").verdict["continuous"]
    assert not pwl_feedback_linearize(system, "continuous", exact=True).verdict["continuous"]


def test_uncontrollable_mode_and_bad_arguments():
    A = np.diag([1.0, 2.0])                    # b = e1: e2 unreachable in either mode
    system = ConewiseLinearSystem.bimodal(A, A, [1.0, 0.0], [0.0, 1.0])
    res = pwl_feedback_linearize(system)
    assert not any(res.verdict.values()) and "not controllable" in res.reasons["pwl_gain"][0]
    with pytest.raises(ModelError, match="^feedback_class: expected one of"):
        pwl_feedback_linearize(system, "smooth")
    with pytest.raises(ModelError, match="^system: expected a ConewiseLinearSystem"):
        pwl_feedback_linearize(system.pwa)
    with pytest.raises(InfeasibleDesignError, match="not feedback linearizable in class "
                                                    "'pwl_gain' .no.: mode 0 is not"):
        linearize_or_raise(system)


def test_forced_feedback_with_sign_changing_gains_is_refused_before_the_run():
    res = pwl_feedback_linearize(ex9_4_pwl_gain(-1.0, 1.0), force=True)
    assert res.verdict["pwl_gain"] is False and res.transform.forced
    with pytest.raises(SlidingError, match="^closed_loop: the feedback is not well posed on "
                                           "the facet between cones 0 and 1.*= -1 < 0"):
        res.transform.closed_loop(-0.5)
    assert pwl_feedback_linearize(ex9_4_pwl_gain(-1.0, 1.0)).transform is None  # not forced


def _planar_fan(rng, n_cones, linear_first_row):
    """A continuous planar fan built from the field's values on its rays:
    ``A_i = [f(d_i), f(d_i+1)] [d_i, d_i+1]⁻¹`` (continuous by construction: the two cones
    sharing a ray agree on it). Gaps between rays stay below π so every cone is pointed (so at
    least three cones; two make half-planes, the bimodal case tested above)."""
    while True:
        gaps = rng.dirichlet(np.ones(n_cones)) * 2 * np.pi
        if np.all(gaps < 0.9 * np.pi) and np.all(gaps > 0.1):
            break
    angles = rng.uniform(0, 2 * np.pi) + np.concatenate([[0.0], np.cumsum(gaps)[:-1]])
    rays = [np.array([np.cos(a), np.sin(a)]) for a in angles]
    p = rng.standard_normal(2)
    values = [np.array([p @ d if linear_first_row else rng.standard_normal(),
                        rng.standard_normal()]) for d in rays]
    A, cones = [], []
    rot = np.array([[0.0, -1.0], [1.0, 0.0]])             # +90°: inward normal of the first ray
    for i in range(n_cones):
        d0, d1 = rays[i], rays[(i + 1) % n_cones]
        A.append(np.column_stack([values[i], values[(i + 1) % n_cones]])
                 @ np.linalg.inv(np.column_stack([d0, d1])))
        cones.append(np.vstack([rot @ d0, -(rot @ d1)]))
    return ConewiseLinearSystem(A, [0.0, 1.0], cones)


def test_planar_corollary_on_random_fans():
    # b = e2: the verdicts are read off (A_i)_12 = ∂(x1')/∂x2 per cone and the first rows
    rng = np.random.default_rng(34)
    seen = set()
    for trial in range(12):   # each fan costs the partition check's LPs (~0.2 s)
        system = _planar_fan(rng, 3 + trial % 3, linear_first_row=trial % 4 == 0)
        a12 = np.array([A[0, 1] for A in system.A])
        if np.min(np.abs(a12)) < 1e-3:
            continue                      # too close to the orientation boundary for floats
        f2 = bool(np.all(a12 > 0) or np.all(a12 < 0))
        # first rows equal up to the roundoff of the construction (cond of [d_i, d_i+1] ≤ ~10)
        f0 = f2 and all(np.allclose(A[0], system.A[0][0], rtol=0, atol=1e-12)
                        for A in system.A)
        res = pwl_feedback_linearize(system)
        assert res.verdict["pwl_gain"] == f2 and res.verdict["continuous"] == f0, trial
        seen.add((f0, f2))
    assert {(False, True), (False, False), (True, True)} <= seen

"""The chapter-6 beam surrogate "beam2" (acceptance checks 1 and 2) and the validation of
MechanicalPWL / OneSidedSpring / Unbalance."""

import numpy as np
import pytest

from nscontrol.errors import DimensionError, ModelError
from nscontrol.systems.beam import MechanicalPWL, OneSidedSpring, Unbalance, two_mode_beam

EPS = np.finfo(float).eps

A1_REF = np.array([[0, 0, 1, 0], [0, 0, 0, 1],
                   [-15791.367, 0, -5.02655, 0], [0, -394784.176, 0, -25.1327]])
A2_LOWER_LEFT = np.array([[-91711.40, -75920.03], [-75920.03, -470704.21]])


def test_matrices_match_the_reference_values():
    beam = two_mode_beam()
    A1, A2 = beam.state_matrix(False), beam.state_matrix(True)
    om, zeta = 2 * np.pi * np.array([20.0, 100.0]), 0.02
    exact = np.block([[np.zeros((2, 2)), np.eye(2)],
                      [-np.diag(om**2), -np.diag(2 * zeta * om)]])
    # from the defining formulas: a few roundings of entries up to 4e5 (1e-9 relative is far
    # above the 8 ε of two products and a division)
    assert np.allclose(A1, exact, rtol=1e-9, atol=0)
    # the printed values have 6 significant digits: half a unit in the last place of
    # -25.1327 is 2e-6 relative, the loosest of them
    assert np.allclose(A1, A1_REF, rtol=2e-6, atol=0)
    assert np.allclose(A2[2:, :2], A2_LOWER_LEFT, rtol=2e-7, atol=0)
    assert np.array_equal(A2[:, 2:], A1[:, 2:])
    assert np.allclose(beam.B.ravel(), [0, 0, 0.2, 0.2], rtol=4 * EPS, atol=0)
    assert np.array_equal(beam.D, beam.B) and np.array_equal(beam.H, [1, 1, 0, 0])
    # k_mid = (Σ 1/k_i)⁻¹: a few roundings of numbers ~1e5, far below 0.1 N/m
    assert abs(beam.support_static_stiffness - 75920.0) < 0.1
    assert abs(beam.support.k / beam.support_static_stiffness - 5.0) < 8 * EPS


def test_modes_are_hurwitz_with_a_rank_one_difference_and_continuous():
    pwa = two_mode_beam().to_pwa()
    contact, free = pwa.A
    assert all(np.max(np.linalg.eigvals(A).real) < 0 for A in (contact, free))
    s = np.linalg.svd(contact - free, compute_uv=False)
    # rank one: the second singular value is zero up to the roundoff of entries ~4e5
    assert s[1] <= 16 * EPS * s[0]
    rng = np.random.default_rng(6)
    for _ in range(20):   # random points of the switching plane Hx = 0
        x = rng.standard_normal(4)
        x[1] = -x[0]
        jump = pwa.field(0, x) - pwa.field(1, x)
        # the two fields differ by k_s g (Hx), Hx = 0 exactly here: roundoff of |A||x| only
        assert np.linalg.norm(jump) <= 16 * EPS * np.linalg.norm(contact, 2) * np.linalg.norm(x)


def test_natural_frequencies():
    beam = two_mode_beam()
    f_free, z_free = beam.frequencies(contact=False)
    f_contact, z_contact = beam.frequencies(contact=True)
    # |λ|/2π of each mode; ±0.01 Hz is the precision the values are quoted to
    assert np.allclose(f_free, [20.0, 100.0], atol=0.01, rtol=0)
    assert np.allclose(z_free, [0.02, 0.02], atol=1e-12, rtol=0)
    assert abs(f_contact[0] - 44.18) < 0.01
    # |λ|/2π of the second contact mode is 110.876 Hz; its damped frequency Im λ/2π is the
    # 110.86 Hz quoted with the reference model (non-proportional damping couples the modes)
    assert abs(f_contact[1] - 110.876) < 0.01
    lam = np.linalg.eigvals(beam.state_matrix(True))
    assert abs(np.sort(lam.imag[lam.imag > 0])[1] / (2 * np.pi) - 110.86) < 0.01
    assert np.allclose(z_contact, [0.0104, 0.0175], atol=5e-5, rtol=0)
    # bilinear estimate of the harmonic resonance, half a period in each linear mode
    f_b = 2 * f_free[0] * f_contact[0] / (f_free[0] + f_contact[0])
    assert abs(f_b - 27.53) < 0.01


def test_homogeneous_without_gap_and_affine_with_one():
    assert two_mode_beam().to_pwa().is_pwl
    gapped = two_mode_beam(gap=1e-3).to_pwa()
    assert not gapped.is_pwl
    # continuity across Hx = δ with the offset k_s δ g on the contact side
    x = np.array([6e-4, 4e-4, 0.3, -0.1])
    assert np.allclose(gapped.field(0, x), gapped.field(1, x), rtol=1e-12, atol=0)


def test_unbalance_amplitude_grows_with_the_square_of_the_speed():
    ub = Unbalance(1e-4)
    w = 2 * np.pi * 27.5
    assert ub(w) == pytest.approx(1e-4 * w * w, rel=4 * EPS)
    assert abs(ub(2 * np.pi * 70) - 19.34) < 0.01
    assert np.allclose(ub.force(w).u(0.25 / 27.5), [ub(w)], rtol=1e-12)


@pytest.mark.parametrize("kwargs, exc, word", [
    ({"alpha": -1.0}, ModelError, "alpha"),
    ({"f1": 120.0}, ModelError, "f1"),
    ({"zeta": (0.02, -0.01)}, ModelError, "zeta[1]"),
    ({"m": (5.0,)}, DimensionError, "m"),
    ({"gap": float("nan")}, ModelError, "gap"),
])
def test_bad_beam_parameters_are_refused(kwargs, exc, word):
    with pytest.raises(exc, match=word.replace("[", r"\[").replace("]", r"\]")):
        two_mode_beam(**kwargs)


def test_bad_mechanical_models_are_refused():
    good = two_mode_beam()
    base = dict(M=good.M, Cd=good.Cd, K=good.K, support=good.support, h_F=good.h_F,
                h_u=good.h_u, C_m=good.C_m)
    for key, value, exc in (("M", -good.M, ModelError), ("K", [[1.0, 2.0], [0.0, 1.0]], ModelError),
                            ("Cd", -good.Cd, ModelError), ("h_F", [1.0, 1.0, 1.0], DimensionError),
                            ("C_m", np.ones((1, 3)), DimensionError),
                            ("support", "spring", ModelError)):
        with pytest.raises(exc, match=key):
            MechanicalPWL(**{**base, key: value})
    with pytest.raises(ModelError, match="k"):
        OneSidedSpring([1.0, 1.0], k=0.0)
    with pytest.raises(ModelError, match="h"):
        OneSidedSpring([0.0, 0.0], k=1.0)
    with pytest.raises(ModelError, match="me_r"):
        Unbalance(0.0)

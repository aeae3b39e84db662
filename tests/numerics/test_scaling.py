"""numerics/scaling and the Lyapunov re-check: the one balancing routine, the one Scaling, the
one certificate re-check, with the properties the designs and analyses rely on."""

import numpy as np
import pytest
import scipy.linalg

from nscontrol.errors import DimensionError, ModelError
from nscontrol.numerics.lmi import LYAPUNOV_RECHECK_RTOL, recheck_lyapunov
from nscontrol.numerics.scaling import Scaling, balance, balanced_unit_norm

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

U = np.finfo(float).eps  # unit roundoff (x2)


def _badly_scaled(rng, n):
    A = rng.standard_normal((n, n)) * 10.0 ** rng.integers(-6, 7, (n, n))
    A[rng.random((n, n)) < 0.3] = 0.0
    return A


def test_balance_of_one_matrix_is_lapack_balancing_of_it(rng):
    # gebal reads only the moduli of the entries, so balancing Σ|A_i| = |A| gives the very
    # same powers of two as balancing A: exact equality, no tolerance
    for _ in range(50):
        A = _badly_scaled(rng, int(rng.integers(1, 7)))
        d, _ = balance([A])
        _, (d_lapack, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
        np.testing.assert_array_equal(d, d_lapack)
        assert np.all(np.log2(d) == np.round(np.log2(d)))      # powers of two


def test_balanced_matrices_have_unit_norm(rng):
    for _ in range(50):
        n = int(rng.integers(1, 7))
        As = [_badly_scaled(rng, n) for _ in range(3)]
        sc = Scaling.balanced(As)
        norms = [np.linalg.norm(sc.matrix(A), 2) for A in As]
        if not any(np.any(A) for A in As):
            continue
        # omega is the largest of these norms, recomputed: the SVD's relative error is a few
        # n·u, bounded here by 10·n·u
        assert max(norms) == pytest.approx(1.0, rel=10 * n * U)
        An, d, omega = balanced_unit_norm(As[0])
        expected = 1.0 if np.any(As[0]) else 0.0          # the zero matrix stays zero
        assert np.linalg.norm(An, 2) == pytest.approx(expected, rel=10 * n * U)
        # the similarity by powers of two is exact; dividing by omega and multiplying back
        # rounds twice: at most 2u = eps relative per entry (checked with 2·eps)
        np.testing.assert_allclose(An * omega, As[0] / d[:, None] * d[None, :], rtol=2 * U,
                                   atol=0)


def test_zero_matrices_keep_unit_time_scale():
    d, omega = balance([np.zeros((3, 3))])
    assert omega == 1.0 and np.all(d == 1.0)
    assert balance([np.zeros((0, 0))])[1] == 1.0


def test_quadratic_forms_map_back_and_forth(rng):
    P = rng.standard_normal((4, 4))
    P = P @ P.T + np.eye(4)
    sc = Scaling.balanced([_badly_scaled(rng, 4)])
    # diagonal powers of two: exact both ways
    np.testing.assert_array_equal(sc.quadratic_scaled(sc.quadratic_back(P)), P)
    x = rng.standard_normal(4)
    xs = sc.S @ x
    assert xs @ P @ xs == pytest.approx(x @ sc.quadratic_back(P) @ x, rel=100 * U)
    # a full S: round trip within cond(S)² · u (two solves with S), times a factor 100
    S = np.eye(4) + 0.3 * rng.standard_normal((4, 4))
    full = Scaling(S, omega=2.0)
    cond = np.linalg.cond(S)
    np.testing.assert_allclose(full.quadratic_scaled(full.quadratic_back(P)), P,
                               rtol=0, atol=100 * cond**2 * U * np.abs(P).max())
    A = rng.standard_normal((4, 4))
    np.testing.assert_allclose(full.matrix(A), S @ A @ np.linalg.inv(S) / 2.0,
                               rtol=0, atol=100 * cond**2 * U * np.abs(A).max())


def test_auto_scaling_normalises_input_and_output():
    A = np.array([[0.0, 1.0], [-4e5, -20.0]])
    B, C = np.array([[0.0], [3e5]]), np.array([[2e-3, 0.0]])
    sc = Scaling.auto([A], B, C)
    # ‖B̃‖ = ‖S B f/ω‖ = 1 and ‖C̃‖ = ‖C S⁻¹/g‖ = 1, each to a few roundings of a 2-norm
    assert np.linalg.norm(sc.S @ B * sc.input_unit / sc.omega, 2) == pytest.approx(1, rel=10 * U)
    assert (np.linalg.norm(C @ np.linalg.inv(sc.S), 2) / sc.output_unit
            == pytest.approx(1, rel=10 * U))


def test_bad_scalings_are_refused():
    with pytest.raises(ModelError, match="Scaling.S"):
        Scaling(np.zeros((2, 2)))
    with pytest.raises(ModelError, match="Scaling.omega"):
        Scaling(np.eye(2), omega=0.0)
    with pytest.raises(ModelError, match="As"):
        balance([])
    with pytest.raises(DimensionError):
        balance([np.eye(2), np.eye(3)])


def test_lyapunov_recheck_numbers_and_verdicts():
    A = -np.eye(2)
    # AᵀP + PA + 2σP = (2σ - 2) I for P = I: exact in floating point
    chk = recheck_lyapunov([A, 2 * A], np.eye(2), decay=0.25)
    assert (chk.P_min_eig, chk.lyap_max_eig, chk.P_norm) == (1.0, -1.5, 1.0)
    assert chk.holds() and chk.residual == -1.5
    assert not recheck_lyapunov([A], np.eye(2), decay=1.5).holds(LYAPUNOV_RECHECK_RTOL)
    assert not recheck_lyapunov([A], -np.eye(2)).holds()              # P not positive
    with pytest.raises(ModelError, match="P"):
        recheck_lyapunov([A], np.full((2, 2), np.nan))
    with pytest.raises(DimensionError, match=r"As\[0\]"):
        recheck_lyapunov([np.eye(3)], np.eye(2))
    with pytest.raises(ModelError, match="decay"):
        recheck_lyapunov([A], np.eye(2), decay="0.1")

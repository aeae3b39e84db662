"""The foot + body and wall-mass models: mass matrix, Christoffel structure, derivatives."""

import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.numerics.differences import central_difference_jacobian
from nscontrol.systems.foot_body import (
    ActuatedContactModel,
    foot_body_model,
    foot_body_points,
    wall_mass_model,
)

EPS = np.finfo(float).eps
# central differences with step 1e-6 (1 + |x|): truncation O(δ²) ~ 1e-12 times the third
# derivative, round-off ε/δ ~ 2e-10 times the value: 1e-7 relative covers both with margin
FD_RTOL = 1e-7


@pytest.fixture
def model():
    return foot_body_model()


def _random_states(rng, k=5):
    return [(rng.uniform(-1, 1, 4) * [0.1, 0.1, 0.5, 1.0], rng.standard_normal(4))
            for _ in range(k)]


def test_mass_matrix_is_spd_and_christoffel_consistent(model):
    rng = np.random.default_rng(0)
    for q, v in _random_states(rng):
        M = model.mass(q)
        assert np.array_equal(M, M.T) and np.linalg.eigvalsh(M).min() > 0
        # C(q, v) v equals the Christoffel form ∂(Mv)/∂q v - ½ ∂(vᵀMv)/∂q
        dMv = central_difference_jacobian(lambda x, v=v: model.mass(x) @ v, q)
        grad_T = central_difference_jacobian(lambda x, v=v: np.array([0.5 * v @ model.mass(x) @ v]),
                                             q)[0]
        expected = dMv @ v - grad_T
        scale = np.abs(expected).max() + 1.0
        assert np.allclose(model.coriolis_force(q, v), expected, atol=FD_RTOL * scale)


def test_force_and_gap_derivatives_match_central_differences(model):
    rng = np.random.default_rng(1)
    for q, v in _random_states(rng):
        Jq, Jv = model.smooth_force_jacobian(0.0, q, v)
        fd_q = central_difference_jacobian(lambda x, v=v: model.smooth_force(0.0, x, v), q)
        fd_v = central_difference_jacobian(lambda x, q=q: model.smooth_force(0.0, q, x), v)
        scale = np.abs(fd_q).max() + np.abs(fd_v).max() + 1.0
        assert np.allclose(Jq, fd_q, atol=FD_RTOL * scale)
        assert np.allclose(Jv, fd_v, atol=FD_RTOL * scale)
        assert np.allclose(model.gap_jacobian(q), central_difference_jacobian(
            lambda x: np.r_[model.gaps(x), 0.0, 0.0], q)[:2], atol=FD_RTOL)
        for a in range(2):
            H = central_difference_jacobian(lambda x, a=a: model.gap_jacobian(x)[a], q)
            assert np.allclose(model.gap_hessians(q)[a], H, atol=FD_RTOL)
        assert np.allclose(model.potential_gradient(q), central_difference_jacobian(
            lambda x: np.r_[model.potential(x), 0, 0, 0], q)[0], atol=FD_RTOL * 200)
        assert np.allclose(model.potential_hessian(q), central_difference_jacobian(
            model.potential_gradient, q), atol=FD_RTOL * 200)


def test_points_and_symmetry(model):
    q = np.array([0.3, 0.05, 0.0, -0.1])
    pts = foot_body_points(model, q)
    assert np.allclose(pts["heel"], [0.3 - 0.08, 0.0]) and np.allclose(pts["toe"], [0.47, 0.0])
    # x is cyclic: gaps and potential do not see it
    shifted = q + [1.0, 0, 0, 0]
    assert np.array_equal(model.gaps(q), model.gaps(shifted))
    assert model.potential(q) == model.potential(shifted)


def test_lagrangian_system_runs_the_model(model):
    system = model.lagrangian(0.0)
    assert system.n_dof == 4 and system.n_contacts == 2
    assert system.actuation.shape == (4, 1)


def test_wall_mass_and_bad_actuation():
    wall = wall_mass_model(2.0)
    assert wall.mass(np.zeros(1))[0, 0] == 2.0 and wall.gaps(np.array([-0.1]))[0] == 0.1
    with pytest.raises(ModelError, match="actuation"):
        ActuatedContactModel(2, wall.mass, wall.coriolis_force, wall.coriolis_jacobians,
                             wall.potential, wall.potential_gradient, wall.potential_hessian,
                             wall.gaps, wall.gap_jacobian, wall.gap_hessians,
                             actuation=[[1.0, 0.0], [2.0, 0.0]], symmetry=None,
                             names=("a", "b"), contact_names=("c",))


def test_parameters_are_a_named_record_and_a_short_q_is_refused(model):
    """The compiled model's parameters read back by name; the callables (compiled kernels,
    which do not bounds-check) refuse a configuration of the wrong size."""
    from nscontrol.errors import DimensionError
    from nscontrol.systems._foot_body_kernels import FOOT_BODY

    p = model.compiled_model().params.view(FOOT_BODY)[0]
    assert (p["m"], p["m_b"], p["L"], p["a"], p["b"], p["d"]) == (21.0, 20.0, 0.8, 0.08, 0.17,
                                                                  0.05)
    with pytest.raises(DimensionError, match=r"^q: expected 4 coordinates"):
        model.mass(np.zeros(3))
    with pytest.raises(DimensionError, match=r"^v: expected 4 coordinates"):
        model.coriolis_force(np.zeros(4), np.zeros(5))

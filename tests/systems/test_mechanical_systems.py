"""Model validation of the mechanical systems: every bad input its specific error."""

import numpy as np
import pytest

from nscontrol.errors import DimensionError, InadmissibleStateError, ModelError
from nscontrol.laws.impact import restitution_matrix
from nscontrol.simulate import simulate
from nscontrol.systems.hybrid import LinearHybridSystem
from nscontrol.systems.impacting_bodies import ImpactingBodies
from nscontrol.systems.lagrangian import LagrangianSystem


def test_inadmissible_initial_states() -> None:
    ball = LagrangianSystem.bouncing_ball()
    with pytest.raises(InadmissibleStateError, match="penetrated"):
        simulate(ball, [-0.1, 0.0], (0.0, 1.0))
    with pytest.raises(InadmissibleStateError, match="approaching"):
        simulate(ball, [0.0, -1.0], (0.0, 1.0), method="moreau_jean", h=1e-3)
    bodies = ImpactingBodies([1.0], np.eye(1), [1.0], np.eye(1))
    with pytest.raises(InadmissibleStateError, match="penetrates"):
        bodies.check_state([0.2, 0.0, 0.1, 0.0])
    with pytest.raises(InadmissibleStateError, match="approach"):
        bodies.check_state([0.1, 1.0, 0.1, 0.0])
    bodies.check_state([0.1, -1.0, 0.1, 0.0])  # touching and separating is fine


@pytest.mark.parametrize("mass", [[[1.0, 0.0], [0.0, -1.0]], [[1.0, 2.0], [0.0, 1.0]]])
def test_mass_matrix_must_be_symmetric_positive_definite(mass) -> None:
    with pytest.raises(ModelError, match="mass"):
        LagrangianSystem(mass, gap_matrix=[[1.0, 0.0]])


def test_configuration_dependent_mass_checked_at_q0() -> None:
    bad = LagrangianSystem(lambda q: np.array([[q[0]]]), gap=lambda q: q + 1.0,
                           jacobian=lambda q: np.eye(1), names=("x",))
    with pytest.raises(ModelError, match="mass"):
        simulate(bad, [-0.5, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3)


def test_wrong_shapes() -> None:
    with pytest.raises(DimensionError, match="jacobian"):
        LagrangianSystem(np.eye(2), gap=lambda q: q[:1], jacobian=lambda q: np.eye(2))
    with pytest.raises(DimensionError, match="gap_matrix"):
        LagrangianSystem(np.eye(2), gap_matrix=np.ones((1, 3)))
    with pytest.raises(DimensionError, match="x0"):
        simulate(LagrangianSystem.bouncing_ball(), [1.0, 0.0, 0.0], (0.0, 1.0))
    with pytest.raises(DimensionError):
        LinearHybridSystem(np.eye(2), np.ones((1, 3)), [0.0], lambda t, x, i: x)


def test_missing_jacobian_warns_and_differences_are_accurate() -> None:
    with pytest.warns(UserWarning, match="jacobian"):
        s = LagrangianSystem(np.eye(2), gap=lambda q: np.array([q[0] ** 2 + q[1]]))
    J = s.gap_jacobian(np.array([0.7, 0.1]))
    assert J == pytest.approx(np.array([[1.4, 1.0]]), rel=1e-8)


def test_step_and_options() -> None:
    ball = LagrangianSystem.bouncing_ball()
    with pytest.raises(ModelError, match="h"):
        simulate(ball, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=-1e-3)
    with pytest.raises(ModelError, match="needs a step"):
        simulate(ball, [1.0, 0.0], (0.0, 1.0), method="moreau_jean")
    with pytest.raises(ModelError, match="theta"):
        simulate(ball, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3, theta=0.2)
    with pytest.raises(ModelError, match="t_span"):
        simulate(ball, [1.0, 0.0], (1.0, 0.0))
    # an unknown option is the driver's one ModelError, listing what the method accepts
    with pytest.raises(ModelError, match=r"^moreau_jean: unknown option\(s\) \['bogus'\]; "
                                         r"accepted: \['activation'"):
        simulate(ball, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3, bogus=1)


@pytest.mark.parametrize("e", [-0.1, 1.5])
def test_restitution_outside_unit_interval(e: float) -> None:
    with pytest.raises(ModelError, match="restitution"):
        LagrangianSystem.bouncing_ball(restitution=e)
    with pytest.raises(ModelError, match="restitution"):
        ImpactingBodies([1.0], np.eye(1), [1.0], np.eye(1), restitution=e)


def test_impacting_bodies_matrices_and_checks() -> None:
    plant = ImpactingBodies.from_springs([1.0, 2.0], [3.0], {(0, 0): 1.0, (0, 1): 0.5},
                                        {(0, 0): -0.2}, restitution=0.7)
    Ka = np.array([[1.5, -0.5], [-0.5, 0.5]])
    assert np.allclose(plant.K_a, Ka)
    assert np.allclose(plant.A_a[2:, :2], -np.diag([1.0, 0.5]) @ Ka)
    assert np.allclose(plant.B_a[:, 0], [0.0, 0.0, 1.0, 0.0])
    assert np.allclose(plant.A_b, [[0.0, 1.0], [0.2 / 3.0, 0.0]])  # negative stiffness allowed
    assert np.allclose(plant.C_a, [[1.0, 0.0, 0.0, 0.0]])
    assert np.allclose(plant.restitution_matrix, restitution_matrix(2.0, 3.0, 0.7))
    with pytest.raises(ModelError, match="symmetric"):
        ImpactingBodies([1.0, 1.0], [[1.0, 1.0], [0.0, 1.0]], [1.0], np.eye(1))
    with pytest.raises(ModelError, match="H_b"):
        ImpactingBodies([1.0], np.eye(1), [0.0], np.eye(1))


def test_structure_detection() -> None:
    assert LagrangianSystem.stack(5).pairwise_contacts() is not None
    assert LagrangianSystem.newtons_cradle(5).is_linear
    arm = LagrangianSystem.two_link_arm()
    assert not arm.is_linear
    M = arm.mass_matrix(np.array([0.3, -1.0]))
    assert np.allclose(M, M.T) and np.all(np.linalg.eigvalsh(M) > 0)


def test_two_link_coriolis_is_in_christoffel_form() -> None:
    from nscontrol.systems.lagrangian import two_link_arm_coriolis, two_link_arm_mass

    p = dict(l1=0.5, l2=0.5, m1=1.0, m2=1.0, I1=1.0, I2=1.0)
    q, v = np.array([0.4, -1.1]), np.array([0.7, -0.3])
    eps = 1e-6
    Mdot = (two_link_arm_mass(q + eps * v, **p) - two_link_arm_mass(q - eps * v, **p)) / (2 * eps)
    S = Mdot - 2 * two_link_arm_coriolis(q, v, **p)
    assert np.max(np.abs(S + S.T)) < 1e-8

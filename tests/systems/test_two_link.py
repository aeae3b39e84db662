"""The two-link arm of chapter 3 and its task map: the properties the controller relies on."""

import numpy as np
import pytest

from nscontrol.errors import InadmissibleStateError
from nscontrol.systems.two_link import OneDofMass, TwoLinkArm, TwoLinkParams

EPS = np.finfo(float).eps
ARM = TwoLinkArm()
RNG = np.random.default_rng(3)
# configurations on the elbow branch, away from the stretched/folded arm (|sin θ2| >= 0.29)
CONFIGS = [np.array([RNG.uniform(0.0, np.pi), RNG.uniform(-np.pi + 0.3, -0.3)])
           for _ in range(20)]


@pytest.mark.parametrize("theta", CONFIGS[:8])
def test_mass_is_symmetric_positive_definite(theta):
    M = ARM.mass(theta)
    assert np.array_equal(M, M.T)
    assert np.linalg.eigvalsh(M).min() > 0.0


@pytest.mark.parametrize("theta", CONFIGS)
def test_mdot_minus_2c_is_skew_in_joint_and_task_coordinates(theta):
    w = RNG.normal(size=2)
    d = 1e-5   # central differences: truncation ~d² |M'''| ~ 1e-10, roundoff ~ε/d ~ 2e-11
    Mdot = (ARM.mass(theta + d * w) - ARM.mass(theta - d * w)) / (2 * d)
    N = Mdot - 2 * ARM.coriolis(theta, w)
    assert np.abs(N + N.T).max() <= 1e-5 * np.abs(Mdot).max()
    Mq_dot = (ARM.task_dynamics(theta + d * w, w)[0] - ARM.task_dynamics(theta - d * w, w)[0]) \
        / (2 * d)
    Nq = Mq_dot - 2 * ARM.task_dynamics(theta, w)[1]
    # the same differences through J⁻¹ (cond J <= 12 here): still far below 1e-5
    assert np.abs(Nq + Nq.T).max() <= 1e-5 * np.abs(Mq_dot).max()


@pytest.mark.parametrize("theta", CONFIGS)
def test_task_inertia_maps_back_to_joint_inertia(theta):
    Mq, _, gq, J = ARM.task_dynamics(theta, np.zeros(2))
    M = ARM.mass(theta)
    # ~16 roundings through J⁻¹ and back, amplified by cond(J) <= 12; factor 10 of margin
    bound = 12 * 16 * 10 * EPS
    assert np.abs(J.T @ Mq @ J - M).max() <= bound * np.abs(M).max()
    G = ARM.gravity(theta)
    assert np.abs(J.T @ gq - G).max() <= bound * np.abs(G).max()


def test_forward_kinematics_matches_the_published_initial_points():
    y, x = ARM.position(np.array([0.9, -1.6]))
    assert (round(x, 6), round(y, 6)) == (0.693226, 0.069555)
    y, x = ARM.position(np.array([1.0, -1.5]))
    assert (round(x, 6), round(y, 6)) == (0.708942, 0.181023)


@pytest.mark.parametrize("theta", CONFIGS)
def test_inverse_returns_the_elbow_branch(theta):
    back = ARM.inverse(ARM.position(theta))
    # arccos near ±1 loses digits: error ~ ε / |sin θ2| <= 4 ε, times the O(1) angles
    assert np.allclose(np.angle(np.exp(1j * (back - theta))), 0.0, atol=1e-12)


def test_inverse_refuses_a_point_out_of_reach():
    with pytest.raises(InadmissibleStateError, match="out of the arm's reach"):
        ARM.inverse(np.array([0.0, 1.2]))


@pytest.mark.parametrize("theta", CONFIGS[:6])
def test_jacobian_and_its_rate_match_differences(theta):
    w = RNG.normal(size=2)
    d = 1e-6   # truncation ~d² ≈ 1e-12, roundoff ~ε/d ≈ 2e-10
    fd = np.column_stack([(ARM.position(theta + d * e) - ARM.position(theta - d * e)) / (2 * d)
                          for e in np.eye(2)])
    assert np.abs(fd - ARM.jacobian(theta)).max() <= 1e-8
    fd_rate = (ARM.jacobian(theta + d * w) - ARM.jacobian(theta - d * w)) / (2 * d)
    assert np.abs(fd_rate - ARM.jacobian_rate(theta, w)).max() <= 1e-8


def test_plant_gap_is_the_task_height_and_gravity_is_compensable():
    arm = TwoLinkArm(TwoLinkParams(g=9.8))
    plant = arm.system(0.7)
    theta = np.array([0.9, -1.6])
    assert plant.gaps(theta)[0] == pytest.approx(arm.position(theta)[0], abs=4 * EPS)
    assert np.allclose(plant.gap_jacobian(theta), arm.jacobian(theta)[:1], atol=4 * EPS)
    # at rest the plant's force is -G(θ): the controller's g_q (through Jᵀ) cancels it
    f = plant.forces(0.0, theta, np.zeros(2))
    G = arm.gravity(theta)
    assert np.abs(f + G).max() <= 16 * EPS * np.abs(G).max()   # the same formula, a few roundings


def test_one_dof_mass_is_the_identity_task_map():
    plant = OneDofMass(m=2.0, g=9.81)
    M, C, g, J = plant.task_dynamics(np.array([0.1]), np.array([0.3]))
    assert (M[0, 0], C[0, 0], g[0], J[0, 0]) == (2.0, 0.0, 2.0 * 9.81, 1.0)
    sys = plant.system(0.5)
    assert sys.forces(0.0, np.array([0.1]), np.array([0.0]))[0] == -2.0 * 9.81


def test_plants_are_kept_per_parameters_and_never_mixed():
    """``system()`` returns the same immutable plant for the same parameters (the integrators
    keep their set-ups per system) and a different one as soon as a parameter differs."""
    from nscontrol.systems.lagrangian import affine_compiled_model

    a, b = OneDofMass(), OneDofMass()
    assert a.system(0.7) is b.system(0.7)
    assert a.system(0.5) is not a.system(0.7)
    assert a.system(0.5).restitution[0] == 0.5 and a.system(0.7).restitution[0] == 0.7
    heavy = OneDofMass(m=2.0).system(0.7)
    assert heavy.mass_matrix()[0, 0] == 2.0 and a.system(0.7).mass_matrix()[0, 0] == 1.0
    # the compiled model of the affine plant: kept per parameters too
    assert affine_compiled_model(a.system(0.7)) is affine_compiled_model(b.system(0.5))
    assert affine_compiled_model(heavy) is not affine_compiled_model(a.system(0.7))
    assert affine_compiled_model(heavy).mass(np.zeros(1), affine_compiled_model(heavy).params
                                             )[0, 0] == 2.0
    arm = TwoLinkArm()
    assert arm.system(0.7) is TwoLinkArm().system(0.7)
    long_arm = TwoLinkArm(TwoLinkParams(l1=0.6))
    theta = np.array([0.9, -1.6])
    assert long_arm.system(0.7).gaps(theta)[0] == pytest.approx(
        long_arm.position(theta)[0], abs=4 * EPS)
    assert long_arm.system(0.7).gaps(theta)[0] != arm.system(0.7).gaps(theta)[0]

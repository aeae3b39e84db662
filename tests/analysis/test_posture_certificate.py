"""The strict-minimum certificate of a regulated posture (§5 check 7), the gain threshold,
the kinetic-angle condition (§5 check 2) and the constrained minimiser (A7)."""

import numpy as np
import pytest

from nscontrol.analysis.posture_certificate import (
    constrained_minimum,
    gain_threshold,
    kinetic_angle_condition,
    posture_certificate,
)
from nscontrol.design.contact_posture import ContactRegulator, static_contact_forces
from nscontrol.errors import ModelError
from nscontrol.laws.impact import NewtonImpactLaw
from nscontrol.systems.foot_body import foot_body_model, wall_mass_model

EPS = np.finfo(float).eps
Q_STAR = np.array([0.0, 0.05, 0.0, -0.1])


@pytest.fixture(scope="module")
def model():
    return foot_body_model()


@pytest.fixture(scope="module")
def design(model):
    return static_contact_forces(model, Q_STAR, [0, 1])


def test_nominal_gains_certify_a_strict_minimum(model, design):
    c = posture_certificate(model, Q_STAR, [0, 1], 400.0, design.tau_star)
    assert c.kkt_ok and c.strictly_complementary and c.sosc_ok and c.is_strict_min
    assert c.kkt_residual <= c.kkt_tolerance and not c.failed
    # KKT multipliers are the design's forces (lstsq on a 4x2 system, κ(G) < 10)
    assert np.allclose(c.multipliers, design.lam_star, rtol=1e3 * EPS)
    # reduced space = θ only (x removed as symmetry): eigenvalue k_p - m_b g L cos θ*
    p = model.parameters
    expected = 400.0 - p.m_b * p.g * p.L * np.cos(Q_STAR[3])
    assert c.reduced_hessian_eigs.shape == (1,)
    assert abs(c.reduced_hessian_eigs[0] - expected) <= 1e3 * EPS * 400.0


def test_soft_joint_fails_the_second_order_condition(model, design):
    c = posture_certificate(model, Q_STAR, [0, 1], 120.0, design.tau_star)
    assert c.kkt_ok and not c.sosc_ok and c.failed == "sosc"
    p = model.parameters
    assert abs(c.margin - (120.0 - p.m_b * p.g * p.L * np.cos(-0.1))) <= 1e3 * EPS * 400.0
    assert "second-order" in c.verdict


def test_lean_beyond_the_toe_fails_kkt_with_a_negative_heel_multiplier(model):
    q = np.array([0.0, 0.05, 0.0, -0.25])
    d = static_contact_forces(model, q, [0, 1], require_positive=False)
    c = posture_certificate(model, q, [0, 1], 400.0, d.tau_star)
    assert not c.kkt_ok and c.failed == "multiplier_sign" and c.margin < 0
    assert "heel" in c.verdict and c.multipliers[0] < 0


def test_wrong_feed_forward_is_not_an_equilibrium(model, design):
    c = posture_certificate(model, Q_STAR, [0, 1], 400.0, design.tau_star + 1.0,
                            theta_star=[0.2])
    assert c.failed == "kkt_residual" and not c.is_strict_min


def test_degenerate_multiplier_is_flagged(model):
    # lean with the centre of mass exactly above the toe: λ_heel = 0
    p = model.parameters
    theta = -np.arcsin(p.total_mass * p.b / (p.m_b * p.L))
    q = np.array([0.0, 0.05, 0.0, theta])
    d = static_contact_forces(model, q, [0, 1], require_positive=False)
    assert abs(d.lam_star[0]) <= 1e-10 * d.lam_star[1]
    c = posture_certificate(model, q, [0, 1], 400.0, d.tau_star)
    assert c.degenerate and not c.strictly_complementary


def test_gain_threshold_is_mb_g_L_cos_theta(model, design):
    p = model.parameters
    k = gain_threshold(model, Q_STAR, [0, 1], design.lam_star)
    # bisection to rtol 1e-12
    assert abs(k - p.m_b * p.g * p.L * np.cos(-0.1)) <= 1e-11 * k
    assert abs(k - 156.176) <= 1e-4 * 156.176


def test_gain_threshold_refuses_an_unstable_unactuated_motion():
    wall = wall_mass_model()
    from dataclasses import replace

    # a 2-DOF toy: coordinate 1 unactuated, free, with a negative potential curvature
    toy = replace(wall, n_dof=2, mass=lambda q: np.eye(2),
                  potential_hessian=lambda q: np.diag([0.0, -1.0]),
                  gaps=lambda q: np.array([-q[0]]), gap_jacobian=lambda q: np.array([[-1.0, 0]]),
                  gap_hessians=lambda q: np.zeros((1, 2, 2)), actuation=np.array([[1.0, 0.0]]),
                  symmetry=np.zeros((0, 2)), names=("a", "b"))
    with pytest.raises(ModelError, match="no joint stiffness"):
        gain_threshold(toy, np.zeros(2), [], np.zeros(0))


def test_kinetic_angle_helper_and_sequential_impacts():
    """§5 check 2: e = 0, W_12 <= 0 -> sequential (contact 1, then both) equals simultaneous;
    the helper's verdict matches the sign of W_12."""
    rng = np.random.default_rng(11)
    law = NewtonImpactLaw(0.0)
    agreed = 0
    for _ in range(400):
        n = int(rng.integers(2, 5))
        A = rng.standard_normal((n, n))
        M = A @ A.T + n * np.eye(n)
        G = rng.standard_normal((2, n))
        v = -np.linalg.solve(M, G.T @ rng.uniform(0.1, 1.0, 2))
        if np.any(G @ v >= 0):
            continue
        r = kinetic_angle_condition(M, G)
        W12 = r.delassus[0, 1]
        assert r.holds == (W12 <= 0.0)
        if W12 <= 0.0:
            seq = law.apply(M, G.T, law.apply(M, G.T, v, active=[0]).v_plus).v_plus
            sim = law.apply(M, G.T, v).v_plus
            # two projections in the M metric, each backward stable: n ε κ(M), factor 100
            assert np.abs(seq - sim).max() <= 100 * n * EPS * np.linalg.cond(M) * np.abs(v).max()
            agreed += 1
    assert agreed > 50


def test_kinetic_angle_of_the_foot_is_not_obtuse(model):
    r = kinetic_angle_condition(model.mass(Q_STAR), model.gap_jacobian(Q_STAR))
    assert r.holds and r.worst < 0


def test_constrained_minimum_with_a_mis_estimated_mass(model):
    """A7: τ* computed with m_b x 1.2; the true W has its minimum with the foot flat and
    both forces positive, at dW/dθ = 0 on the contact manifold."""
    p = model.parameters
    d = static_contact_forces(foot_body_model(m_b=1.2 * p.m_b), Q_STAR, [0, 1])
    reg = ContactRegulator(model, d, 400.0, 30.0)
    cm = constrained_minimum(model, reg.total_potential, reg.total_potential_gradient, Q_STAR)
    assert cm.success and cm.active == (0, 1) and np.all(cm.multipliers > 0)
    th = cm.q[3]
    # stationarity along θ: -m_b g L sin θ + k_p (θ - θ*) - τ* = 0 (Newton-polished to
    # round-off of W's gradient, about 1e3 ε |τ*|)
    resid = -p.m_b * p.g * p.L * np.sin(th) + 400.0 * (th - Q_STAR[3]) - d.tau_star[0]
    assert abs(resid) <= 1e3 * EPS * 400.0
    assert abs(th - Q_STAR[3]) > 1e-2

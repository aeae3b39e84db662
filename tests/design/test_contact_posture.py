"""The posture regulator of ch04: static design (§5 check 6), infeasible postures, the
Controller protocol and the folded (implicit) form."""

import warnings

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.design.contact_posture import (
    ContactRegulator,
    design_contact_regulator,
    static_contact_forces,
)
from nscontrol.errors import DimensionError, InfeasibleDesignError, ModelError, NscontrolWarning
from nscontrol.systems.feedback import Controller, Measurement
from nscontrol.systems.foot_body import foot_body_model, wall_mass_model
from nscontrol.systems.lagrangian import LagrangianSystem

EPS = np.finfo(float).eps
Q_STAR = np.array([0.0, 0.05, 0.0, -0.1])


@pytest.fixture(scope="module")
def model():
    return foot_body_model()


def test_static_design_matches_closed_forms(model):
    """§5 check 6: τ* = -m_b g L sin θ*, λ* = ((m g b - τ*), (m g a + τ*)) / (a + b),
    ZMP offset τ*/(m g); equilibrium residual at round-off."""
    p = model.parameters
    d = static_contact_forces(model, Q_STAR, [0, 1])
    m, th = p.total_mass, Q_STAR[3]
    tau = -p.m_b * p.g * p.L * np.sin(th)
    lam = np.array([m * p.g * p.b - tau, m * p.g * p.a + tau]) / (p.a + p.b)
    # the design solves 3x2 and 1x1 well-conditioned systems (κ < 10): a few ε of the forces
    assert np.allclose(d.tau_star, tau, rtol=100 * EPS)
    assert np.allclose(d.lam_star, lam, rtol=100 * EPS)
    assert abs(d.center_of_pressure - tau / (m * p.g)) <= 100 * EPS
    # the published-to-4-digits reference values of the acceptance list
    assert abs(d.tau_star[0] - 15.6699) <= 1e-4 * 15.6699
    assert np.allclose(d.lam_star, [77.4074, 128.6026], rtol=1e-4)
    f_eq = (model.smooth_force(0.0, Q_STAR, np.zeros(4)) + model.actuation.T @ d.tau_star
            + model.gap_jacobian(Q_STAR).T @ d.lam_star)
    # forces of size m g ≈ 200 N summed in a few terms: 1e-10 is 1e-12 relative (≈ 5000 ε)
    assert np.abs(f_eq).max() <= 1e-10
    assert d.feasible and d.support == (-0.08, 0.17)


def test_posture_outside_the_support_is_refused_with_the_reason(model):
    with pytest.raises(InfeasibleDesignError, match="centre of pressure") as err:
        design_contact_regulator(model, [0.0, 0.05, 0.0, -0.25], [0, 1], 400.0, 30.0)
    assert err.value.status == "negative_contact_force"
    assert "heel" in str(err.value) and "0.17" in str(err.value)
    d = static_contact_forces(model, [0.0, 0.05, 0.0, -0.25], [0, 1], require_positive=False)
    assert not d.feasible and d.lam_star[0] < 0 and d.center_of_pressure > 0.17


def test_one_contact_cannot_balance_the_foot(model):
    # toe alone, foot tilted onto it: the unactuated rotation is not balanced
    phi = -0.3
    p = model.parameters
    q = np.array([0.0, p.d * np.cos(phi) - p.b * np.sin(phi), phi, -0.1])
    with pytest.raises(InfeasibleDesignError, match="balance") as err:
        static_contact_forces(model, q, [1])
    assert err.value.status == "unbalanced"


def test_bad_contact_sets(model):
    with pytest.raises(ModelError, match="should be closed"):
        static_contact_forces(model, [0.0, 0.06, 0.0, -0.1], [0, 1])
    with pytest.raises(ModelError, match="not in active"):
        static_contact_forces(model, Q_STAR, [0])
    with pytest.raises(DimensionError, match="active"):
        static_contact_forces(model, Q_STAR, [0, 2])


def test_redundant_contacts_warn_and_pick_a_distribution():
    """More contacts than coordinates (m > n): dependent gradients, forces not unique."""
    wall = wall_mass_model()
    # the same wall twice: 2 contacts on 1 coordinate
    from dataclasses import replace

    two = replace(wall, gaps=lambda q: np.r_[-q, -q], gap_jacobian=lambda q: np.array(
        [[-1.0], [-1.0]]), gap_hessians=lambda q: np.zeros((2, 1, 1)),
        contact_names=("wall a", "wall b"))
    with pytest.warns(NscontrolWarning, match="linearly dependent"):
        d = static_contact_forces(two, [0.0], [0, 1], lam_ref=[2.0, 3.0])
    assert np.allclose(d.lam_star, [2.0, 3.0], atol=1e-8) and np.allclose(d.tau_star, 5.0)


def test_fully_actuated_force_regulation_uses_the_requested_force():
    reg = design_contact_regulator(wall_mass_model(), [0.0], [0], 100.0, 2.0, lam_ref=[5.0])
    assert np.allclose(reg.design.lam_star, 5.0, atol=1e-9)
    assert np.allclose(reg.torque([0.01], [0.0]), -1.0 + 5.0)


def test_regulator_is_a_controller_and_its_forms_agree(model):
    reg = design_contact_regulator(model, Q_STAR, [0, 1], 400.0, 30.0)
    assert isinstance(reg, Controller) and reg.n_outputs == 1 and reg.n_states == 0
    rng = np.random.default_rng(0)
    q, v = Q_STAR + 0.01 * rng.standard_normal(4), rng.standard_normal(4)
    x = np.r_[q, v]
    tau = reg.output(0.0, np.zeros(0), Measurement(0.0, y=x, x=x))
    fb = reg.state_feedback()
    assert np.allclose(tau, fb.K @ x + fb.k, rtol=0, atol=1e-12)
    plant = model.lagrangian(0.0)
    folded = reg.folded(plant)
    # the folded model's forces are the plant's plus Sᵀ τ
    assert np.allclose(folded.forces(0.0, q, v), plant.forces(0.0, q, v, u=tau), atol=1e-11)
    # its energy is E = ½vᵀMv + W up to the constant ½ θ*ᵀ K_p θ*
    const = 0.5 * 400.0 * Q_STAR[3] ** 2
    assert abs(folded.energy(x) - (reg.energy(q, v) - const)) <= 1e-12 * abs(reg.energy(q, v))
    # ∇W at q* is G_Iᵀ λ* (the design's KKT point)
    assert np.allclose(reg.total_potential_gradient(Q_STAR),
                       model.gap_jacobian(Q_STAR).T @ reg.design.lam_star, atol=1e-12)


def test_gains_are_checked(model):
    d = static_contact_forces(model, Q_STAR, [0, 1])
    with pytest.raises(ModelError, match="Kp"):
        ContactRegulator(model, d, -1.0, 30.0)
    with pytest.raises(ModelError, match="Kd"):
        ContactRegulator(model, d, 400.0, -1.0)


def test_mass_matrix_losing_definiteness_along_the_motion_stops_the_run():
    """Bad input: M(q) = 0.5 + q is SPD at q0 = 0.2 but not past q = -0.5; the regulator
    pushes the mass towards the wall at q = -0.6: Moreau–Jean stops with ModelError."""
    plant = LagrangianSystem(lambda q: np.array([[0.5 + q[0]]]), gap_matrix=[[1.0]],
                             gap_offset=[0.6], actuation=[[1.0]], names=("q",))
    wall = wall_mass_model()
    from dataclasses import replace

    model = replace(wall, gaps=lambda q: q + 0.6, gap_jacobian=lambda q: np.array([[1.0]]))
    reg = design_contact_regulator(model, [-0.6], [0], 10.0, 1.0, lam_ref=[1.0])
    with pytest.raises(ModelError, match="not positive definite") as err:
        nsc.simulate(reg.folded(plant), [0.2, 0.0], (0.0, 3.0), method="moreau_jean",
                     h=1e-3, progress=False)
    assert err.value.trajectory is not None and err.value.trajectory.t[-1] > 0.0


def test_regulator_block_runs_in_closed_loop_and_reads_contacts(model):
    reg = design_contact_regulator(model, Q_STAR, [0, 1], 400.0, 30.0)
    loop = nsc.closed_loop(model.lagrangian(0.0), reg)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr = nsc.simulate(loop, np.r_[Q_STAR, np.zeros(4)], (0.0, 0.05), method="moreau_jean",
                          h=1e-3, progress=False)
    # at rest at q*: the law's output is τ*, the contacts carry λ* (the design's balance,
    # reached by the LCP to its round-off: 1e-9 relative is 1e6 ε on forces of 100 N)
    assert np.allclose(tr.signals["u"][-1], reg.design.tau_star, rtol=1e-12)
    assert np.allclose(tr.signals["impulse"][-1] / 1e-3, reg.design.lam_star, rtol=1e-9)

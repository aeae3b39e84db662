"""event_driven with sensitivity=True: the state transition of nonlinear mechanics (DOP853
with the variational equation, Newton-impact saltation with M(q) and a nonlinear gap)
against central differences of the flow."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import ModelError, SolverError
from nscontrol.numerics.differences import central_difference_jacobian
from nscontrol.numerics.saltation import impact_jump_jacobian
from nscontrol.systems.hybrid import LinearHybridSystem
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.testing.mechanics_problems import ImpactingPendulum

# DOP853's global error over one run: at most (steps <= 200, about 30 here) local errors of
# rtol·|x| each, carried by |Φ| <= 5: 1e3·rtol·max(1, |x|)
STEP_BOUND = 1e3


def _end(system, x0, tf, **opts):
    return simulate(system, x0, (0.0, tf), dt=tf, **opts).x[-1]


def _flow_differences(system, x0, tf, **opts):
    """Fourth-order central differences of the flow, step d = ε^{1/5}(1 + |x_k|) >= 7.4e-4:
    truncation d⁴/30·|P⁽⁵⁾| (<= 1e4 at an impact speed ~1: 1e-9) plus 3/2 of the runs'
    error over d."""
    return central_difference_jacobian(lambda x: _end(system, x, tf, **opts), x0, order=4)


@pytest.mark.parametrize("variant", [
    {},                                   # analytic force Jacobian
    {"force_jacobian": False},            # the field differenced (fourth order)
    {"callable_mass": True},              # M(q) given as a callable: differenced too
], ids=["analytic", "differenced", "callable_mass"])
def test_pendulum_transition_over_an_impact_matches_differences_of_the_flow(variant):
    p = ImpactingPendulum(**variant)
    s, x0, T = p.system(), np.array(p.x_guess), p.period
    opts = dict(rtol=1e-13, atol=1e-15, progress=False)
    tr = simulate(s, x0, (0.0, T), dt=T, sensitivity=True, **opts)
    assert [e.kind for e in tr.events] == ["impact"]
    Phi = tr.stats["state_transition"]
    assert tr.stats["saltation_matrices"].shape == (1, 2, 2)
    fd = _flow_differences(s, x0, T, **opts)
    # runs' error STEP_BOUND·rtol·max(1, |x|) = 1e-10 (|x| <= 1): 1.5·1e-10/7.4e-4 = 2e-7,
    # plus the truncation 1e-9: below 1e-6
    assert np.max(np.abs(Phi - fd)) <= 1e-6 * max(1.0, np.max(np.abs(Phi)))
    # one impact: det Φ = e² e^{-cT} (Liouville and det S = e²); each of the 2 columns off
    # by STEP_BOUND·rtol relative
    assert np.linalg.det(Phi) == pytest.approx(p.monodromy_determinant(),
                                               rel=2 * STEP_BOUND * 1e-13)


def test_two_link_arm_saltation_with_mass_matrix_and_nonlinear_gap():
    """M(q), a gap y(q) = l1 sin θ1 + l2 sin(θ1 + θ2): the jump's dv+/dq block matters."""
    arm = LagrangianSystem.two_link_arm(restitution=0.5)
    x0 = np.array([0.6, -0.3, 0.0, 0.0])          # falls under gravity, hits at t ≈ 0.53
    tf = 0.6
    opts = dict(rtol=1e-12, atol=1e-14, progress=False)
    tr = simulate(arm, x0, (0.0, tf), dt=tf, sensitivity=True, **opts)
    assert [e.kind for e in tr.events] == ["impact"]
    Phi = tr.stats["state_transition"]
    fd = _flow_differences(arm, x0, tf, **opts)
    # runs' error STEP_BOUND·rtol·max|x| = 3e-9 (|x| <= 3): 1.5·3e-9/7.4e-4 = 6e-6, plus the
    # truncation: below 1e-5 relative to |Φ| ~ 3.6
    assert np.max(np.abs(Phi - fd)) <= 1e-5 * max(1.0, np.max(np.abs(Phi)))
    ev = tr.events[0]
    J = impact_jump_jacobian(arm.mass_matrix, lambda q: arm.gap_jacobian(q)[0], 0.5,
                             state=ev.pre)
    # the turning normal and M(q) give dv+/dq ~ 0.3: a transition without it would miss the
    # differences by ~0.3·|Φ| >> the tolerance above
    assert np.max(np.abs(J[2:, :2])) > 0.1


def test_refusals():
    p = ImpactingPendulum()
    with pytest.raises(ModelError, match="^sensitivity: expected True or False"):
        simulate(p.system(), p.x_guess, (0.0, 1.0), sensitivity="yes")
    hybrid = LinearHybridSystem([[0, 1, 0], [0, 0, -9.81], [0, 0, 0]], [[1, 0, 0]], [0.0],
                                np.diag([1.0, -0.5, 1.0]))
    with pytest.raises(ModelError, match="^sensitivity: event_driven computes the state "
                                         "transition of a LagrangianSystem"):
        simulate(hybrid, [1.0, 0.0, 1.0], (0.0, 1.0), sensitivity=True)
    # two contacts closing at the same instant: the jump is not differentiable there
    twin = LagrangianSystem(np.eye(1), force=lambda t, q, v: np.zeros(1),
                            gap_matrix=[[-1.0], [-1.0]], gap_offset=[0.5, 0.5],
                            restitution=0.5)
    with pytest.raises(SolverError, match="^sensitivity: contacts \\[0, 1\\] close together"):
        simulate(twin, [0.0, 1.0], (0.0, 1.0), sensitivity=True, progress=False)

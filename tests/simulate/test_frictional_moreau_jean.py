"""Moreau–Jean with Coulomb friction and with the position projection: the known answers
of the inclined plane, the pushed block, the disk and sphere thrown with backspin, the brick
stack at rest, and the bouncing ball without penetration."""

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.systems import (
    LagrangianSystem,
    brick_stack,
    brick_stack_rest_state,
    inclined_block,
    rolling_disk,
    rolling_sphere,
)

EPS = np.finfo(float).eps
G = 9.81
H = 1e-3


def _run(system, x0, tf, **kw):
    return nsc.simulate(system, x0, (0.0, tf), method="moreau_jean", h=H, progress=False, **kw)


def test_block_sticks_when_the_slope_is_below_the_friction_angle():
    traj = _run(inclined_block(0.5, 0.4), [0.0, 0.0, 0.0, 0.0], 1.0)
    # each step's stick impulse cancels h g sin α to a few ulps; 1000 steps accumulate them
    assert np.max(np.abs(traj.x[:, [0, 2]])) <= 1000 * 4 * EPS * G * H
    assert np.all(traj.signals["contact_state"][1:] == 1)   # stick at every step


@pytest.mark.parametrize("angle", [0.6, 0.9])
def test_block_slides_with_the_coulomb_acceleration(angle):
    mu, T = 0.5, 1.0
    a = G * (np.sin(angle) - mu * np.cos(angle))
    traj = _run(inclined_block(mu, angle), [0.0, 0.0, 0.0, 0.0], T)
    n = traj.t.size - 1
    # v_k = k h a exactly; x by the trapezoidal rule, exact on a linear v: round-off of n
    # additions of terms of size |v| (n eps |v| each), a factor 4 for the products
    assert abs(traj.x[-1, 2] - a * T) <= 4 * n * EPS * a * T
    assert abs(traj.x[-1, 0] - a * T**2 / 2) <= 4 * n * EPS * a * T * T
    assert np.all(traj.signals["contact_state"][1:] == 2)   # slip at every step
    # the friction impulse is on the cone's edge, opposite to the slip
    assert np.allclose(traj.signals["friction_impulse"][1:, 0],
                       -mu * traj.signals["impulse"][1:, 0], rtol=4 * EPS, atol=0)


def test_stick_slip_transition_at_tan_theta_equal_mu():
    mu = 0.5
    below, above = np.arctan(mu * (1 - 1e-6)), np.arctan(mu * (1 + 1e-6))
    stick = _run(inclined_block(mu, below), [0.0] * 4, 0.2)
    slide = _run(inclined_block(mu, above), [0.0] * 4, 0.2)
    a = G * (np.sin(above) - mu * np.cos(above))   # ~ 4e-6 g: tiny but positive
    assert np.max(np.abs(stick.x[:, 2])) <= 200 * 4 * EPS * G * H
    assert abs(slide.x[-1, 2] - a * 0.2) <= 4 * 200 * EPS * G * 0.2


def test_pushed_block_stops_at_the_closed_form_time_and_distance():
    mu, v0 = 0.5, 2.0
    t_stop, d_stop = v0 / (mu * G), v0**2 / (2 * mu * G)
    traj = _run(inclined_block(mu), [0.0, 0.0, v0, 0.0], 0.6)
    k = int(np.argmax(traj.x[:, 2] == 0.0))
    # v decreases by μ g h a step and is set to 0 in the step containing t_stop
    assert t_stop <= traj.t[k] < t_stop + H
    # the trapezoidal positions are exact on the linear decrease except in the last step,
    # whose error is at most μ g h² / 2
    assert abs(traj.x[-1, 0] - d_stop) <= mu * G * H**2 / 2
    assert np.all(traj.x[k:, 2] == 0.0)


def test_sphere_with_backspin_rolls_after_the_closed_form_time():
    mu, R, v0, w0 = 0.3, 0.1, 2.0, 10.0   # ω_y = 10: slip s0 = v0 - R ω_y = 1
    s0 = v0 - R * w0
    t_roll, v_roll = 2 * s0 / (7 * mu * G), v0 - 2 * s0 / 7
    x0 = [0.0, 0.0, R, 0.0, 0.0, 0.0, v0, 0.0, 0.0, 0.0, w0, 0.0]
    traj = _run(rolling_sphere(mu, radius=R), x0, 0.3)
    slip = traj.x[:, 6] - R * traj.x[:, 10]
    k = int(np.argmax(np.abs(slip) <= 1e-12 * v0))
    assert t_roll <= traj.t[k] < t_roll + H   # the slip decreases by 7 μ g h / 2 a step
    # the angular momentum about the contact point is conserved: the rolling velocity is
    # exact up to the round-off of the steps (n steps, a few ulps of v0 each)
    n = traj.t.size - 1
    assert abs(traj.x[-1, 6] - v_roll) <= 4 * n * EPS * v0
    # NSGS stops at a relative residual 1e-12: the rolling slip is that small
    assert np.max(np.abs(slip[k:])) <= 1e-12 * v0 * 10
    assert np.all(traj.signals["contact_state"][1:k] == 2)
    assert np.all(traj.signals["contact_state"][k + 1:] == 1)


def test_planar_disk_with_backspin_rolls_after_the_closed_form_time():
    mu, R, v0, w0 = 0.2, 0.1, 1.0, 5.0    # slip s0 = v0 + R θ' = 1.5
    s0 = v0 + R * w0
    t_roll, v_roll = s0 / (3 * mu * G), v0 - s0 / 3
    traj = _run(rolling_disk(mu, radius=R), [0.0, R, 0.0, v0, 0.0, w0], 0.5)
    slip = traj.x[:, 3] + R * traj.x[:, 5]
    k = int(np.argmax(np.abs(slip) <= 1e-12 * s0))
    assert t_roll <= traj.t[k] < t_roll + H
    assert abs(traj.x[-1, 3] - v_roll) <= 4 * (traj.t.size - 1) * EPS * s0


def test_energy_balance_splits_into_normal_and_friction_work():
    x0 = [0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 2.0, 0.5, 0.0, 1.0, 10.0, 0.0]
    traj = _run(rolling_sphere(0.3), x0, 0.3)
    E = traj.signals["energy"]
    work = traj.signals["friction_work"] + traj.signals["normal_work"]
    # θ = ½ on linear forces: E_{k+1} - E_k = r · (u_k + u_{k+1})/2 exactly; round-off of n
    # steps on energies of size max|E|
    assert np.max(np.abs(E - E[0] - work)) <= 4 * (E.size - 1) * EPS * np.max(np.abs(E))
    # friction only dissipates (maximal dissipation), and it does here
    assert np.all(np.diff(traj.signals["friction_work"]) <= 4 * EPS * np.max(np.abs(E)))
    assert traj.signals["friction_work"][-1] < -0.1


def test_brick_stack_stays_at_rest_for_ten_thousand_steps_with_impulses_in_the_cone():
    n, mu, angle = 10, 0.5, 0.1   # tan α = 0.1: below μ and below the tipping ratio w/(n h)
    system = brick_stack(n, mu, angle=angle)
    x0 = brick_stack_rest_state(n)
    traj = _run(system, x0, 10.0, record_every=10)
    steps = traj.stats["steps"]
    assert steps == 10_000
    # drift: per step, the velocity left by a contact solve at relative tolerance 1e-12 (on
    # local velocities of size h g sqrt(2n)), and the round-off of adding to |q| <= 1
    tol = traj.stats["max_contact_residual"]
    assert tol <= 1e-12
    bound = steps * (H * 10 * 1e-12 * H * G * np.sqrt(2 * n) + 4 * EPS * 1.0)
    assert np.max(np.abs(traj.x - x0)) <= bound
    pn, pt = traj.signals["impulse"][1:], traj.signals["friction_impulse"][1:]
    assert np.all(np.abs(pt) <= mu * pn * (1 + 1e-12))   # in the cone, to NSGS's tolerance
    assert np.all(traj.signals["contact_state"][1:] == 1)  # every contact sticks
    # the ground holds the whole stack against the tilt: Σ P_t = n m g h sin α (split in
    # any way between the two corners: the two tangent rows are equal), to NSGS's tolerance
    assert abs(pt[-1, :2].sum() - n * G * H * np.sin(angle)) <= 10 * 1e-12 * n * G * H


def test_bouncing_ball_with_projection_has_no_penetration_and_the_same_impacts():
    ball = LagrangianSystem.bouncing_ball(0.9)
    plain = _run(ball, [1.0, 0.0], 3.0)
    proj = _run(ball, [1.0, 0.0], 3.0, projection=True)
    assert plain.stats["max_penetration"] > 1e-3          # O(h |u-|) without projection
    assert proj.stats["max_penetration"] <= 1e-12
    assert np.min(proj.signals["gap"]) >= -1e-12
    t_plain, t_proj = plain.event_times("impact"), proj.event_times("impact")
    assert t_plain.size == t_proj.size == 4
    # each projection lifts the ball by d <= h|u|/2 and gives the lift's potential energy
    # back from the velocity: the following flight is the plain one advanced by d/|u| <= h/2,
    # and both runs locate an impact inside the same step: no drift, each within h
    assert np.all(np.abs(t_proj - t_plain) <= H)
    # the lifts would cost m g times the penetrations; the velocity gives it back, so the
    # net change is round-off of energies of size m g q0 = G (a few ulps per projection)
    assert 0.0 < proj.stats["projection_lift_energy"] <= 4 * G * proj.stats[
        "max_penetration_before_projection"]
    assert abs(proj.stats["projection_energy"]) <= proj.stats["projections"] * 16 * EPS * G


def test_friction_refuses_a_controller_and_nonlinear_models():
    class Push(nsc.systems.StaticLaw):
        n_outputs, period = 2, None

        def output(self, t, xc, m):
            return np.zeros(2)

    with pytest.raises(ModelError, match="^controller: a closed loop's Python blocks"):
        nsc.simulate(nsc.closed_loop(inclined_block(0.5), Push()), [0.0] * 4, (0.0, 0.01),
                     method="moreau_jean", h=H)
    with pytest.raises(ModelError, match="^listeners: not supported yet with friction"):
        nsc.simulate(inclined_block(0.5), [0.0] * 4, (0.0, 0.01), method="moreau_jean", h=H,
                     listeners=[lambda *args: None])
    arm = LagrangianSystem.two_link_arm()
    with pytest.raises(ModelError, match="projection"):
        nsc.simulate(arm, [0.5, 0.0, 0.0, 0.0], (0.0, 0.01), method="moreau_jean", h=H,
                     projection=True)

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


def test_friction_refuses_nonlinear_models():
    # (a closed loop's Python blocks and the listeners run: test_frictional_blocks.py)
    arm = LagrangianSystem.two_link_arm()
    with pytest.raises(ModelError, match="projection"):
        nsc.simulate(arm, [0.5, 0.0, 0.0, 0.0], (0.0, 0.01), method="moreau_jean", h=H,
                     projection=True)


# -- the one compiled step: every configuration, the warm start, the checked fallback --------
def _chain(T_span=1.0):
    """Two blocks on the ground joined by a spring (``K`` not diagonal, so neither is ``M̂``),
    thrown apart: they slide, stick and oscillate."""
    k = 50.0
    K = np.array([[k, -k, 0, 0], [-k, k, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0.0]])
    system = LagrangianSystem(np.array([1.0, 2.0, 1.0, 2.0]), stiffness=K,
                              constant_force=[0, 0, -G, -2 * G],
                              gap_matrix=[[0, 0, 1, 0], [0, 0, 0, 1.0]], friction=[0.3, 0.3],
                              tangent_matrix=[[1, 0, 0, 0], [0, 1, 0, 0.0]])
    return system, [0.1, -0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("tf", [1.0, 1.0 - H / 2])   # the second ends on a shortened step
def test_energy_balance_holds_with_a_coupling_stiffness_and_a_short_last_step(tf):
    system, x0 = _chain()
    traj = _run(system, x0, tf)
    assert traj.t[-1] == tf and traj.stats["contact_fallback_steps"] == 0
    assert set(np.unique(traj.signals["contact_state"][1:])) >= {1.0, 2.0}   # stick, slip
    E = traj.signals["energy"]
    work = traj.signals["friction_work"] + traj.signals["normal_work"]
    # θ = ½, linear forces: exact balance up to round-off (n steps, energies of size max|E|)
    assert np.max(np.abs(E - E[0] - work)) <= 4 * (E.size - 1) * EPS * np.max(np.abs(E))
    assert traj.signals["friction_work"][-1] < -0.1


def test_a_change_of_coordinates_gives_the_same_motion():
    """The disk of the closed-form test in coordinates ``q = P z`` (mass ``Pᵀ M P``, not
    diagonal): the same discrete motion, mapped back by ``P``."""
    mu, R, v0, w0 = 0.2, 0.1, 1.0, 5.0
    disk = rolling_disk(mu, radius=R)
    x0 = np.array([0.0, R, 0.0, v0, 0.0, w0])
    P = np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.2], [0.1, 0.0, 1.0]])
    tangent = np.asarray(disk.tangent_matrix.todense() if hasattr(disk.tangent_matrix, "todense")
                         else disk.tangent_matrix)
    moved = LagrangianSystem(P.T @ disk.mass_matrix() @ P,
                             constant_force=P.T @ disk.constant_force,
                             gap_matrix=disk.dense_gap_matrix() @ P, gap_offset=disk.gap_offset,
                             friction=disk.friction, tangent_matrix=tangent @ P)
    plain = _run(disk, x0, 0.5)
    z = _run(moved, np.concatenate([np.linalg.solve(P, x0[:3]), np.linalg.solve(P, x0[3:])]),
             0.5)
    n = plain.t.size - 1
    # per step: round-off of the transformation (cond P ε |v|, a factor 4) and the two
    # contact solves at relative tolerance 1e-12 on impulses of size |r| (a factor 10)
    r = np.max(np.abs(plain.signals["impulse"])) + np.max(np.abs(
        plain.signals["friction_impulse"]))
    bound = n * (4 * np.linalg.cond(P) * EPS * max(v0, R * w0, w0) + 10 * 1e-12 * r)
    assert np.max(np.abs(z.x[:, 3:] @ P.T - plain.x[:, 3:])) <= bound
    assert np.max(np.abs(z.x[:, :3] @ P.T - plain.x[:, :3])) <= bound * 0.5
    slip = plain.x[:, 3] + R * plain.x[:, 5]
    k = int(np.argmax(np.abs(slip) <= 1e-12))
    assert np.all(z.signals["contact_state"][1:k] == 2)


def _frictional(system, x0, tf, **kw):
    """The frictional run itself (its warm-start switch is not a ``simulate`` option)."""
    from nscontrol.simulate.moreau_jean._frictional_run import integrate_frictional
    from nscontrol.simulate.moreau_jean._options import MoreauJeanOptions

    warm = kw.pop("warm_start", True)
    x0 = system.check_state(x0)
    opts = MoreauJeanOptions.checked(
        system, x0, h=H, theta=0.5, gamma=1.0, activation=None, u=None, forces="implicit",
        mass_at="start", projection=False, contact_tol=1e-12, record_every=1, signals=None,
        progress=False)
    return integrate_frictional(system, x0, 0.0, tf, opts, warm_start=warm)


def _agreement_bound(system, a, steps):
    """Two runs that each stick at every contact and solve each step to the relative
    natural-map error ``tol = 1e-12``: at a stuck contact that error bounds ``|u|``, scaled
    by ``max(|q|, |r|, |u|) <= max(1, |W|) |r|`` (``q = u - W r``); the velocities are
    ``v = H⁺ u`` (``H`` of full column rank), so each run's ``v`` is within
    ``tol max(1, |W|) |r| / σ_min(H)`` of rest at every step (a factor 4 for the per-contact
    sums), and the positions gather ``h`` times that per step."""
    T = system.tangent_matrix
    Hm = np.vstack([system.dense_gap_matrix(),
                    np.asarray(T.todense() if hasattr(T, "todense") else T)])
    W = Hm @ np.linalg.solve(system.mass_matrix(), Hm.T)
    r = np.max(np.linalg.norm(np.hstack([a.signals["impulse"], a.signals["friction_impulse"]]),
                              axis=1))
    dv = 2 * 4 * 1e-12 * max(1.0, np.linalg.norm(W, 2)) * r / np.linalg.svd(
        Hm, compute_uv=False).min()
    return dv, steps * H * dv


def test_the_warm_start_saves_sweeps_on_a_resting_stack_and_keeps_the_answer():
    n, steps = 3, 200
    system, x0 = brick_stack(n, 0.5, angle=0.1), brick_stack_rest_state(n)
    warm = _frictional(system, x0, steps * H)
    cold = _frictional(system, x0, steps * H, warm_start=False)
    assert warm.stats["warm_start"] and not cold.stats["warm_start"]
    assert warm.stats["contact_fallback_steps"] == cold.stats["contact_fallback_steps"] == 0
    # from the last step's impulses a resting stack needs a few sweeps a step; from zero,
    # NSGS spreads the load through the stack again every step (hundreds)
    assert warm.stats["contact_sweeps"] <= 5 * steps
    assert cold.stats["contact_sweeps"] >= 20 * warm.stats["contact_sweeps"]
    for traj in (warm, cold):
        assert np.all(traj.signals["contact_state"][1:] == 1)   # both stick everywhere
        assert traj.stats["max_contact_residual"] <= 1e-12
    dv, dq = _agreement_bound(system, warm, steps)
    nd = system.n_dof
    assert np.max(np.abs(warm.x[:, nd:] - cold.x[:, nd:])) <= dv
    assert np.max(np.abs(warm.x[:, :nd] - cold.x[:, :nd])) <= dq


def test_a_step_the_sweeps_cannot_finish_is_taken_with_the_checked_solvers_impulses(
        monkeypatch):
    from nscontrol.simulate.moreau_jean import _frictional_run

    n, steps = 3, 50
    system, x0 = brick_stack(n, 0.5, angle=0.1), brick_stack_rest_state(n)
    ref = _frictional(system, x0, steps * H)
    monkeypatch.setattr(_frictional_run, "MAX_SWEEPS", 5)   # from zero, no step converges
    fallback = _frictional(system, x0, steps * H, warm_start=False)
    assert fallback.stats["contact_fallback_steps"] == steps
    assert np.all(fallback.signals["contact_state"][1:] == 1)
    assert fallback.stats["max_contact_residual"] <= 1e-12   # recomputed by the kernel
    dv, dq = _agreement_bound(system, ref, steps)
    nd = system.n_dof
    assert np.max(np.abs(fallback.x[:, nd:] - ref.x[:, nd:])) <= dv
    assert np.max(np.abs(fallback.x[:, :nd] - ref.x[:, :nd])) <= dq


class SensorFault(RuntimeError):
    """The user's own exception type."""


def test_an_input_that_raises_keeps_every_step_before_it():
    """A block pushed along the ground by ``u(t) = 20 sin t`` that fails from t = 0.5 on: the
    run ends at the last step before, with the samples of a run stopped there."""
    t_fail = 0.5

    def u(t):
        t = np.atleast_1d(np.asarray(t, float))
        if np.any(t >= t_fail - 0.5 * H):
            raise SensorFault("u: sensor unplugged")
        return 20 * np.sin(t)[:, None]

    block = LagrangianSystem(np.ones(2), constant_force=[0.0, -G], gap_matrix=[[0.0, 1.0]],
                             friction=0.3, tangent_matrix=[[1.0, 0.0]],
                             actuation=[[1.0], [0.0]])
    with pytest.raises(SensorFault) as info:
        _run(block, [0.0] * 4, 1.0, u=u)
    partial = info.value.trajectory
    assert partial.status == -1
    # u is read at a step's start: the last step taken is the one starting before t_fail
    assert t_fail - 1e-12 <= partial.t[-1] <= t_fail + 1e-12
    reference = _run(block, [0.0] * 4, float(partial.t[-1]), u=u)
    assert set(np.unique(reference.signals["contact_state"][1:])) >= {1.0, 2.0}
    # the same steps on the same grid, bit for bit
    np.testing.assert_array_equal(partial.t, reference.t)
    np.testing.assert_array_equal(partial.x, reference.x)

"""The switching tracking controller: its reference pieces and its laws."""

import math

import numpy as np
import pytest

from nscontrol.design.complementarity_tracking import (
    CircleTask,
    HalfSineTask,
    PBCGains,
    SwitchingTrackingController,
    TransitionDesign,
    liftoff_blend,
    lyapunov_decay_rate,
    slotine_li_force,
    virtual_dive,
)
from nscontrol.errors import ModelError
from nscontrol.systems.two_link import OneDofMass, TwoLinkArm

EPS = np.finfo(float).eps


def test_dive_starts_at_rest_and_ends_at_rest_below_the_surface():
    q10, d, delta, Delta = 0.01, 0.005, 0.4, 1.0
    start = virtual_dive(delta, 0.0, q10, d, delta, Delta)
    end = virtual_dive(delta + Delta - 1e-12, 0.0, q10, d, delta, Delta)
    # a cubic between two rests ends with acceleration +6(q10 + d)/Δ²; then it is held
    assert end[2] == pytest.approx(6 * (q10 + d) / Delta**2, rel=1e-9)
    end = virtual_dive(delta + Delta + 1e-9, 0.0, q10, d, delta, Delta)
    assert start == pytest.approx((q10, 0.0, -6 * (q10 + d) / Delta**2), abs=4 * EPS)
    assert end == (-d, 0.0, 0.0)
    assert virtual_dive(delta - 1e-9, 0.0, q10, d, delta, Delta) is None
    # derivatives agree with central differences (cubic: truncation zero up to roundoff/δ)
    t, h = delta + 0.3, 1e-6
    pos = lambda s: virtual_dive(s, 0.0, q10, d, delta, Delta)[0]  # noqa: E731
    assert virtual_dive(t, 0.0, q10, d, delta, Delta)[1] == pytest.approx(
        (pos(t + h) - pos(t - h)) / (2 * h), abs=1e-9)


def test_liftoff_blend_leaves_with_zero_velocity_and_acceleration():
    assert liftoff_blend(0.0) == (0.0, 0.0, 0.0)
    assert liftoff_blend(1.0) == (1.0, 0.0, 0.0)
    assert liftoff_blend(0.5)[0] == pytest.approx(0.5, abs=4 * EPS)


def test_circle_task_transition_start_is_where_the_circle_reaches_the_threshold():
    task = CircleTask()
    tau0 = task.tau0(0)
    assert task.nominal(tau0)[0][0] == pytest.approx(task.y_threshold, abs=16 * EPS)
    assert task.nominal(tau0)[1][0] < 0.0                      # descending
    assert tau0 == pytest.approx(4.84, abs=0.01)
    assert task.t_detach(2) == 30.0


def test_half_sine_task_transition_start():
    task = HalfSineTask()
    tau0 = task.tau0(1)
    assert task.nominal(tau0)[0][0] == pytest.approx(task.threshold, abs=16 * EPS)
    assert task.nominal(tau0)[1][0] < 0.0


def test_decay_rate_formula():
    assert lyapunov_decay_rate(PBCGains(8.0, 7.0), 2.0) == pytest.approx(56 / 22, rel=EPS)


def test_slotine_li_closed_loop_is_m_sdot_plus_c_s_plus_gamma1_s():
    """With the exact model the law gives M ṡ + C s + γ1 s = 0: check the acceleration it
    produces against that identity at a random state of the arm."""
    arm = TwoLinkArm()
    rng = np.random.default_rng(1)
    theta, dtheta = np.array([0.9, -1.6]), rng.normal(size=2)
    q, dq = arm.task_state(theta, dtheta)
    Mq, Cq, gq, _ = arm.task_dynamics(theta, dtheta)
    qd, dqd, ddqd = rng.normal(size=2), rng.normal(size=2), rng.normal(size=2)
    gains = PBCGains(8.0, 7.0)
    tau = slotine_li_force(Mq, Cq, gq, q, dq, qd, dqd, ddqd, gains)
    ddq = np.linalg.solve(Mq, tau - Cq @ dq - gq)        # free motion in task coordinates
    s = dq - dqd + 7.0 * (q - qd)
    sdot = ddq - ddqd + 7.0 * (dq - dqd)
    residual = Mq @ sdot + Cq @ s + 8.0 * s
    # cond(M_q) ~ 10, O(10) terms of size |τ|: 1e3 ε |τ|
    assert np.abs(residual).max() <= 1e3 * EPS * np.abs(tau).max()


def test_pressing_force_after_the_first_impact():
    """U_t with q* = q_d - d e1 is U_nc plus the constant γ1 γ2 d along the inward normal."""
    M, C, g = np.eye(2), np.zeros((2, 2)), np.zeros(2)
    q, dq = np.array([0.002, 0.6]), np.array([-0.01, 0.0])
    qd = np.array([0.0, 0.6])
    gains, d = PBCGains(8.0, 7.0), 0.005
    u_nc = slotine_li_force(M, C, g, q, dq, qd, np.zeros(2), np.zeros(2), gains)
    u_t = slotine_li_force(M, C, g, q, dq, qd, np.zeros(2), np.zeros(2), gains,
                           q_star=qd - np.array([d, 0.0]))
    assert u_t - u_nc == pytest.approx([-8.0 * 7.0 * d, 0.0], abs=64 * EPS)


def test_depth_law_clips():
    tr = TransitionDesign()
    assert tr.depth(0.0) == tr.depth_min
    assert tr.depth(1.0) == tr.depth_max
    assert tr.depth(1e-7) == pytest.approx(100 * math.sqrt(1e-7), rel=4 * EPS)   # inside the clip
    assert TransitionDesign(depth_law="linear", phi=1e5, depth_min=0.0).depth(3e-12) == \
        pytest.approx(3e-7, rel=4 * EPS)


def test_bad_options_are_refused():
    with pytest.raises(ModelError, match="depth_law"):
        TransitionDesign(depth_law="cubic")
    with pytest.raises(ModelError, match="switching"):
        SwitchingTrackingController(OneDofMass(), HalfSineTask(), switching="maybe")
    with pytest.raises(ModelError, match="depth_max"):
        TransitionDesign(depth_min=0.1, depth_max=0.01)
    # the impact-triggered logic reads q2: a one-coordinate model cannot run it
    with pytest.raises(ModelError, match="switching"):
        SwitchingTrackingController(OneDofMass(), HalfSineTask(), switching="impact-triggered")


def test_a_model_the_kernels_do_not_know_is_refused():
    # the law runs as compiled kernels that know the two task maps and the two tasks: a
    # look-alike model (right methods, other formulas) would be silently ignored
    class Heavier(OneDofMass):
        def task_dynamics(self, theta, dtheta):
            return (np.array([[2.0]]), np.zeros((1, 1)), np.array([19.62]), np.eye(1))

    with pytest.raises(ModelError, match="model, task") as info:
        SwitchingTrackingController(Heavier(), HalfSineTask())
    assert "OneDofMass" in str(info.value)


def test_warp_is_continuous_with_the_nominal_path_at_the_transition_start():
    from nscontrol.design import _complementarity_tracking_kernels as kern

    ctrl = SwitchingTrackingController(OneDofMass(), HalfSineTask(), PBCGains(5.0, 5.0))
    task, delta = ctrl.task, ctrl.transition.delta
    rec = ctrl._kernel_params().view(kern.PARAMS)[0]
    tau0 = task.tau0(0)

    def warped(t):
        p, v, a = np.empty(1), np.empty(1), np.empty(1)
        kern.warp(t, tau0, delta, rec, p, v, a)
        return p, v, a
    p, v, _ = warped(tau0)
    pn, vn, _ = task.nominal(tau0)
    assert p[0] == pytest.approx(pn[0], abs=4 * EPS)
    assert v[0] == pytest.approx(vn[0], abs=4 * EPS)
    # at τ0 + δ the warp has brought the path back to rest where it started
    p, v, _ = warped(tau0 + delta - 1e-12)
    assert v[0] == pytest.approx(0.0, abs=1e-9)
    assert p[0] == pytest.approx(pn[0], abs=1e-9)
    assert math.isfinite(p[0])


def test_controller_works_compiled_and_as_python_blocks():
    """The same law through nscontrol.closed_loop run compiled (inside the compiled model's
    loop) and as Python blocks (its output method, fed λ̂, before each step of the plant's
    step loop): the same torques, hence the same trajectory."""
    import nscontrol as nsc

    plant = OneDofMass()
    runs = []
    for compiled in (True, False):
        ctrl = SwitchingTrackingController(plant, HalfSineTask(), PBCGains(5.0, 5.0))
        system = nsc.closed_loop(plant.system(0.7), ctrl, compiled=compiled)
        traj = nsc.simulate(system, [0.05, 0.0], (0.0, 0.5), method="moreau_jean", h=1e-3,
                            progress=False)
        assert (traj.stats["path"] == "compiled_model") == compiled
        # compiled, the block's log is read back from the run's block state
        runs.append((traj.x[:, :2], ctrl.signals(traj if compiled else None)["V"]))
    assert np.array_equal(runs[0][0], runs[1][0])
    assert np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][1][-1] < runs[0][1][0]            # V decays in free motion

"""Chapter 5 example: robustness maps of the chapter 3 tracking controller.

The fast tests run one cycle of the two-link task per new robustness parameter (detection
delay, measurement noise) at h = 1e-3 and assert exact properties (bit-identical prefixes,
reproducibility), so no tolerance is involved; the full example (about 20 sweep points) is
slow-marked.
"""

import numpy as np
import pytest

from nscontrol import sweep
from nscontrol.errors import ModelError
from nscontrol.examples import get_example
from nscontrol.examples.ch03_two_link_tracking import robustness_point, two_link_tracking
from nscontrol.examples.ch05_robustness import (
    MODEL_SCALES,
    critical_model_scale,
    crossing_speed,
    ground_force_offset,
    model_error_bound,
    robustness_maps,
    sensor_force_ratio,
)
from nscontrol.sweep import PointError, SweepResult

H = 1e-3


@pytest.fixture(scope="module")
def nominal():
    return two_link_tracking(cycles=1, h=H)


def _first_index(run, phase):
    return int(np.flatnonzero(run.traj.signals["phase"] == phase)[0])


def test_registered_with_claim_and_captions():
    ex = get_example("ch05-robustness")
    assert ex.claim and ex.key_figure in ex.captions
    assert set(ex.captions) == {"ch05_map_restitution_model", "ch05_map_delay_noise",
                                "ch05_curve_step_size", "ch05_curve_ground_offset",
                                "ch05_curve_force_sensor"}


def test_zero_delay_and_zero_noise_reproduce_the_nominal_run_exactly(nominal):
    run = two_link_tracking(cycles=1, h=H, detection_delay=0, position_noise=0.0,
                            noise_seed=7)
    # σ = 0 draws no noise and delay 0 reads the last step: the same floating-point operations
    assert np.array_equal(run.traj.x, nominal.traj.x)
    assert np.array_equal(run.traj.signals["V"], nominal.traj.signals["V"])


def test_detection_delay_switches_exactly_k_steps_late(nominal):
    k = 3
    run = two_link_tracking(cycles=1, h=H, detection_delay=k)
    i0 = _first_index(nominal, 2)            # first sample in the impacts phase
    assert _first_index(run, 2) == i0 + k
    # until the nominal switch both runs apply the same torques: identical states
    assert np.array_equal(run.traj.x[:i0 + 1], nominal.traj.x[:i0 + 1])
    # the recorded first impact is the true one, not the late detection
    assert run.controller.cycles[0].t_first_impact == nominal.controller.cycles[0].t_first_impact
    # after the switch the runs differ (the dive pressed k steps longer); both still settle
    assert np.isfinite(run.controller.cycles[0].t_constrained)


def test_position_noise_is_seeded_and_the_log_holds_the_true_state(nominal):
    a = two_link_tracking(cycles=1, h=H, position_noise=1e-3, noise_seed=1)
    b = two_link_tracking(cycles=1, h=H, position_noise=1e-3, noise_seed=1)
    assert np.array_equal(a.traj.x, b.traj.x)            # deterministic
    assert not np.array_equal(a.traj.x, nominal.traj.x)   # the noise acts
    n = a.model.n_dof
    q_true = np.array([a.model.task_state(x[:n], x[n:])[0] for x in a.traj.x[::500]])
    # the logged q_task is the plant's (same function of the same x), not the measurement
    assert np.array_equal(a.traj.signals["q_task"][::500], q_true)


def test_a_moved_ground_changes_nothing_before_the_first_contact(nominal):
    """The controller is not told where the ground is: until the arm first touches the
    higher ground, plant and controller run the same operations as in the nominal run, and
    the logged gap is the height above the real ground."""
    c = 0.003
    run = two_link_tracking(cycles=1, h=H, ground_offset=c)
    # a moved ground has no compiled model: that run takes the Python path (the same
    # controller kernels on Moreau–Jean's Python loop), so compare with the nominal run
    # on that path, operation for operation
    assert run.traj.stats["path"] == "python"
    python = two_link_tracking(cycles=1, h=H, compiled=False)
    P = run.traj.signals["impulse"][:, 0]
    first = int(np.flatnonzero(P > 0.0)[0])        # sample after the first contact step
    assert np.array_equal(run.traj.x[:first], python.traj.x[:first])
    # the ground is reached earlier than in the nominal run, higher up
    assert first < int(np.flatnonzero(nominal.traj.signals["impulse"][:, 0] > 0.0)[0])
    # gap and task height come from the same sines: equal up to a few roundings of 0.5 m
    y = run.traj.signals["q_task"][:, 0]
    assert np.allclose(run.traj.signals["gap"][:, 0], y - c, rtol=0.0, atol=8 * 2.2e-16)


def test_force_sensor_model_is_what_the_force_loop_reads(nominal):
    """λ̂ = min(a P/h + b, λ_sat) at every step (one step old, as designed), while the
    contact detection and the motion before the constrained phase are untouched."""
    a, b = 1.5, 0.2
    run = two_link_tracking(cycles=1, h=H, force_scale=a, force_bias=b)
    sig = run.traj.signals
    lam_raw = sig["impulse"][:-1, 0] / H           # row k reads the impulse of step k - 1
    expected = np.minimum(a * lam_raw + b, run.controller.contact.lam_sat)
    assert np.array_equal(sig["lam_hat"][1:-1], expected[1:])
    i3 = _first_index(nominal, 3)                  # the force loop starts acting here
    assert _first_index(run, 3) == i3
    assert np.array_equal(run.traj.x[:i3 + 1], nominal.traj.x[:i3 + 1])


def test_exact_force_sensor_and_zero_noise_reproduce_the_nominal_run(nominal):
    run = two_link_tracking(cycles=1, h=H, force_scale=1.0, force_bias=0.0, force_noise=0.0,
                            ground_offset=0.0, noise_seed=3)
    assert np.array_equal(run.traj.x, nominal.traj.x)
    a = two_link_tracking(cycles=1, h=H, force_noise=0.5, noise_seed=2)
    b = two_link_tracking(cycles=1, h=H, force_noise=0.5, noise_seed=2)
    assert np.array_equal(a.traj.signals["lam_hat"], b.traj.signals["lam_hat"])


def test_invalid_robustness_parameters_are_refused():
    with pytest.raises(ModelError, match="detection_delay"):
        two_link_tracking(cycles=1, h=H, detection_delay=-1)
    with pytest.raises(ModelError, match="position_noise"):
        two_link_tracking(cycles=1, h=H, position_noise=-1e-3)
    with pytest.raises(ModelError, match="force_scale"):
        two_link_tracking(cycles=1, h=H, force_scale=-1.0)
    with pytest.raises(ModelError, match="force_noise"):
        two_link_tracking(cycles=1, h=H, force_noise=-1.0)
    with pytest.raises(ModelError, match="ground_offset"):
        two_link_tracking(cycles=1, h=H, ground_offset=float("nan"))


def test_a_failed_point_is_nan_in_its_map_with_its_error():
    failed = sweep.run(robustness_point, [{"detection_delay": -1}], executor="serial",
                       progress=False)
    good = {"cycles_completed": 2, "worst_tau0_error": 1e-4, "worst_V_growth": 0.01,
            "penetration": 1e-5, "weakly_stable": True, "gap_before_first_takeoff": 0.0}
    result = SweepResult(grid=({}, {"detection_delay": -1}), values=(good, None),
                         errors=(None, PointError(1, failed.errors[0].type,
                                                  failed.errors[0].message)))
    maps = robustness_maps(result, (1, 2))
    assert maps["worst_tau0_error"][0, 0] == 1e-4 and maps["weakly_stable"][0, 0]
    assert np.isnan(maps["worst_tau0_error"][0, 1]) and not maps["weakly_stable"][0, 1]
    assert maps["errors"][0]["index"] == 1
    assert "ModelError" in maps["errors"][0]["error"]
    assert "detection_delay" in maps["errors"][0]["error"]


def test_model_grid_straddles_the_predicted_critical_scale():
    s_crit = critical_model_scale()
    assert min(MODEL_SCALES) < 1.0 < s_crit < max(MODEL_SCALES)
    assert model_error_bound(1.0) == 0.0       # exact model: no model-error force


def test_crossing_speed_is_the_dive_speed_at_the_ground():
    """The closed-form crossing of ``y = c`` against the controller's own dive function."""
    from nscontrol.design.complementarity_tracking import (
        CircleTask,
        TransitionDesign,
        virtual_dive,
    )
    task, tr = CircleTask(), TransitionDesign()
    tau0 = task.tau0(0)
    q10 = float(task.nominal(tau0)[0][0])
    for c in (-0.003, 0.0, 0.006):
        u = crossing_speed(c, depth=0.05)
        lo, hi = tau0 + tr.delta, tau0 + tr.delta + tr.Delta
        for _ in range(80):                  # bisection on the monotone dive to 2^-80 s
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if virtual_dive(mid, tau0, q10, 0.05, tr.delta,
                                               tr.Delta)[0] > c else (lo, mid)
        speed = -virtual_dive(lo, tau0, q10, 0.05, tr.delta, tr.Delta)[1]
        # both locate θ to rounding; the speed's slope in θ is at most 6 (q10 + d) / Δ
        assert speed == pytest.approx(u, rel=1e-12)
    assert np.isnan(crossing_speed(-0.06, depth=0.05))   # below the deepest dive
    assert sensor_force_ratio(1.0) == 1.0 and np.isnan(sensor_force_ratio(2.5))
    assert ground_force_offset(0.003) == pytest.approx(8 * 7 * 0.003 / 1.5, rel=1e-15)


@pytest.mark.slow
def test_example_run_passes_every_check(tmp_path):
    """Both sweeps (about 20 points of 2 cycles at h = 1e-3) with the figures."""
    result = get_example("ch05-robustness").run(tmp_path)
    failed = [(c.name, c.value, c.threshold) for c in result.checks if not c.passed]
    assert not failed
    assert len(result.figures) == 5
    assert result.metrics["failed_points"] == []

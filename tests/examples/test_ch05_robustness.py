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
    model_error_bound,
    robustness_maps,
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
    assert set(ex.captions) == {"ch05_map_restitution_model", "ch05_map_delay_noise"}


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


def test_invalid_robustness_parameters_are_refused():
    with pytest.raises(ModelError, match="detection_delay"):
        two_link_tracking(cycles=1, h=H, detection_delay=-1)
    with pytest.raises(ModelError, match="position_noise"):
        two_link_tracking(cycles=1, h=H, position_noise=-1e-3)


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


@pytest.mark.slow
def test_example_run_passes_every_check(tmp_path):
    """Both sweeps (about 20 points of 2 cycles at h = 1e-3) with the figures."""
    result = get_example("ch05-robustness").run(tmp_path)
    failed = [(c.name, c.value, c.threshold) for c in result.checks if not c.passed]
    assert not failed
    assert len(result.figures) == 2
    assert result.metrics["failed_points"] == []

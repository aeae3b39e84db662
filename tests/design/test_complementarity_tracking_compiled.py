"""The compiled form of the switching tracking controller against its Python methods (which
call the same kernels on Moreau–Jean's Python loop): the same closed-loop run (trajectory,
impacts, phases, logged V) on the 1-DOF mass and the two-link arm, for both switching logics
and the force-sensor model, and the settings that have no compiled form (the noise)."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.design import _complementarity_tracking_kernels as kern
from nscontrol.design.complementarity_tracking import (
    CircleTask,
    ContactPhaseDesign,
    HalfSineTask,
    PBCGains,
    SwitchingTrackingController,
    TransitionDesign,
)
from nscontrol.systems.two_link import OneDofMass, TwoLinkArm

U = np.finfo(float).eps
# Both paths run the same controller kernels; Moreau–Jean's Python loop and its compiled loop
# group some products of the plant step differently (a few ulps per step), and the loop
# carries such differences forward without amplifying them by more than a modest factor
# over a step of the contracting closed loop: 100 ulps per step, accumulated over the run.
FACTOR = 100.0


def _state(rows, name):
    """A field of the phase logic's record in logged block-state rows."""
    return np.ascontiguousarray(rows[:, :kern.N_STATE]).view(kern.STATE)[name][:, 0]


def _both_paths(model, ctrl, x0, T, h):
    """The Python run (the closed loop on Moreau–Jean's Python loop) and the compiled
    closed-loop run; returns them with the Python log."""
    plant = model.system(0.7)
    ctrl.reset_run()
    ref = nsc.simulate(nsc.closed_loop(plant, ctrl, compiled=False), x0, (0.0, T),
                       method="moreau_jean", h=h, theta=0.5, signals=("impulse", "gap"),
                       progress=False)
    assert ref.stats["path"] != "compiled_model"
    log = ctrl.signals()
    fast = nsc.simulate(nsc.closed_loop(plant, ctrl), x0, (0.0, T), method="moreau_jean",
                        h=h, theta=0.5, progress=False)
    assert fast.stats["path"] == "compiled_model"
    return ref, fast, log


def _impact_times(traj):
    return traj.t[1:][traj.signals["impulse"][1:, 0] > 0.0]


def _assert_same_run(ref, fast, log):
    n_steps = ref.t.size - 1
    bound = n_steps * U * FACTOR
    assert np.array_equal(ref.t, fast.t)
    assert np.abs(fast.x - ref.x).max() <= bound * max(1.0, np.abs(ref.x).max())
    assert np.array_equal(_impact_times(fast), _impact_times(ref))
    rows = fast.signals["xc"][1:]          # sample k + 1 shows the row of step start k
    assert np.array_equal(_state(rows, "phase"), log["phase"])
    assert np.array_equal(_state(rows, "cycle"), log["cycle"])
    assert np.abs(_state(rows, "V") - log["V"]).max() <= bound * np.abs(log["V"]).max()


@pytest.mark.parametrize("delay", [0, 2])
def test_one_dof_compiled_run_is_the_python_run(delay):
    model, task = OneDofMass(), HalfSineTask(omega=2 * np.pi / 8)
    ctrl = SwitchingTrackingController(model, task, PBCGains(5.0, 5.0, 0.5),
                                       TransitionDesign(), ContactPhaseDesign(lam_rate=1.5),
                                       detection_delay=delay)
    ref, fast, log = _both_paths(model, ctrl, np.array([0.05, 0.0]), 9.0, 1e-3)
    # the run goes through every phase, an impact and a take-off
    assert set(log["phase"]) == {0.0, 1.0, 2.0, 3.0} and log["cycle"].max() == 1.0
    _assert_same_run(ref, fast, log)


def test_two_link_compiled_run_is_the_python_run():
    arm = TwoLinkArm()
    ctrl = SwitchingTrackingController(arm, CircleTask(period=10.0), PBCGains(8.0, 7.0, 0.5),
                                       TransitionDesign(), ContactPhaseDesign(lam_rate=1.5))
    ref, fast, log = _both_paths(arm, ctrl, np.array([0.9, -1.6, 0.0, 0.0]), 10.5, 1e-3)
    assert set(log["phase"]) == {0.0, 1.0, 2.0, 3.0} and log["cycle"].max() == 1.0
    _assert_same_run(ref, fast, log)


@pytest.mark.parametrize("option", [{"force_bias": 0.3}, {"force_scale": 0.9}])
def test_force_sensor_model_runs_compiled_as_in_python(option):
    # the sensor's scale and bias act from the constrained phase on: run past its start
    model, task = OneDofMass(), HalfSineTask(omega=2 * np.pi / 8)
    ctrl = SwitchingTrackingController(model, task, PBCGains(5.0, 5.0, 0.5),
                                       TransitionDesign(), ContactPhaseDesign(lam_rate=1.5),
                                       **option)
    ref, fast, log = _both_paths(model, ctrl, np.array([0.05, 0.0]), 7.0, 1e-3)
    assert 3.0 in set(log["phase"])
    _assert_same_run(ref, fast, log)


def test_impact_triggered_switching_runs_compiled_as_in_python():
    # the 2007 logic (chapter 3's "siconos-2007" set-up) on the arm: one period of 3 s
    arm = TwoLinkArm()
    h = 5e-3
    ctrl = SwitchingTrackingController(arm, CircleTask(period=3.0), PBCGains(25.0, 30.0, 3.0),
                                       TransitionDesign(), ContactPhaseDesign(lam_rate=4.0),
                                       switching="impact-triggered",
                                       force_feedback_scale=h)
    ref, fast, log = _both_paths(arm, ctrl, np.array([1.0, -1.5, 0.0, 0.0]), 4.0, h)
    # it reaches the constrained phase and takes off: every branch of the logic ran
    assert {0.0, 2.0, 3.0} <= set(log["phase"]) and log["cycle"].max() >= 1.0
    _assert_same_run(ref, fast, log)


@pytest.mark.parametrize("option", [{"position_noise": 1e-4}, {"force_noise": 0.1}])
def test_settings_without_a_compiled_form_run_python(option):
    ctrl = SwitchingTrackingController(OneDofMass(), HalfSineTask(), **option)
    assert ctrl.compiled() is None and "noise" in ctrl.compiled_reason()
    loop = nsc.closed_loop(OneDofMass().system(0.7), ctrl)
    traj = nsc.simulate(loop, np.array([0.05, 0.0]), (0.0, 0.01), method="moreau_jean",
                        h=1e-3, theta=0.5, progress=False)
    assert traj.stats["path"] != "compiled_model"
    # the Python methods keep the phase logic in the loop's block state, as compiled
    assert np.array_equal(ctrl.signals(traj)["V"], ctrl.signals()["V"])


def test_block_state_is_finite_before_a_run():
    # the compiled loops reject a non-finite block state: "no such instant yet" is a
    # finite sentinel
    ctrl = SwitchingTrackingController(OneDofMass(), HalfSineTask(), detection_delay=3)
    assert ctrl.x0.shape == (ctrl.n_states,) == (kern.state_size(3),)
    assert np.isfinite(ctrl.x0).all()


def test_signals_read_back_from_a_compiled_run_are_the_python_log():
    model, task = OneDofMass(), HalfSineTask(omega=2 * np.pi / 8)
    ctrl = SwitchingTrackingController(model, task, PBCGains(5.0, 5.0, 0.5),
                                       TransitionDesign(), ContactPhaseDesign(lam_rate=1.5))
    ref, fast, log = _both_paths(model, ctrl, np.array([0.05, 0.0]), 9.0, 1e-3)
    back = ctrl.signals(fast)
    assert set(back) == set(log)
    bound = (ref.t.size - 1) * U * FACTOR
    for key, rows in log.items():
        scale = max(1.0, np.nanmax(np.abs(rows)))
        assert np.array_equal(np.isnan(back[key]), np.isnan(rows)), key
        assert np.nanmax(np.abs(back[key] - rows)) <= bound * scale, key


def _same_cycles(python, compiled, bound):
    assert len(python) == len(compiled)
    for a, b in zip(python, compiled, strict=True):
        assert a.index == b.index
        for name in ("tau0", "V_tau0", "V1_tau0", "depth", "q10", "t_first_impact",
                     "t_constrained", "t_detach", "t_star", "u_star"):
            x, y = getattr(a, name), getattr(b, name)
            assert (np.isnan(x) and np.isnan(y)) or abs(x - y) <= bound * max(1.0, abs(x)), \
                (a.index, name, x, y)
        assert a.q2_star.shape == b.q2_star.shape
        assert np.abs(a.q2_star - b.q2_star).max(initial=0.0) <= bound


@pytest.mark.parametrize("arm", [False, True])
def test_cycles_read_back_from_a_compiled_run_are_the_python_cycles(arm):
    if arm:
        model = TwoLinkArm()
        ctrl = SwitchingTrackingController(model, CircleTask(period=10.0),
                                           PBCGains(8.0, 7.0, 0.5), TransitionDesign(),
                                           ContactPhaseDesign(lam_rate=1.5))
        x0, T = np.array([0.9, -1.6, 0.0, 0.0]), 10.5
    else:
        model = OneDofMass()
        ctrl = SwitchingTrackingController(model, HalfSineTask(omega=2 * np.pi / 8),
                                           PBCGains(5.0, 5.0, 0.5), TransitionDesign(),
                                           ContactPhaseDesign(lam_rate=1.5))
        x0, T = np.array([0.05, 0.0]), 9.0
    ref, fast, log = _both_paths(model, ctrl, x0, T, 1e-3)
    _same_cycles(ctrl.cycles, ctrl.cycles_of(fast), (ref.t.size - 1) * U * FACTOR)


def test_load_run_gives_the_python_run_state():
    # after load_run, the object answers as after the Python run: log, cycles, and the
    # Lyapunov function at the final state (which reads the phase state)
    model, task = OneDofMass(), HalfSineTask(omega=2 * np.pi / 8)
    ctrl = SwitchingTrackingController(model, task, PBCGains(5.0, 5.0, 0.5),
                                       TransitionDesign(), ContactPhaseDesign(lam_rate=1.5))
    ref, fast, log = _both_paths(model, ctrl, np.array([0.05, 0.0]), 9.0, 1e-3)
    V_python = ctrl.lyapunov(float(ref.t[-1]), ref.x[-1])
    cycles = ctrl.cycles
    ctrl.load_run(fast)
    bound = (ref.t.size - 1) * U * FACTOR
    assert np.array_equal(ctrl.signals()["phase"], log["phase"])
    _same_cycles(cycles, ctrl.cycles, bound)
    V_loaded = ctrl.lyapunov(float(fast.t[-1]), fast.x[-1, :2])
    assert np.allclose(V_loaded, V_python, rtol=bound, atol=0.0)
    ctrl.reset_run()
    assert ctrl.signals() == {}


def test_example_runs_compiled_by_default_with_the_python_signals():
    from nscontrol.examples.ch03_two_link_tracking import two_link_tracking

    slow = two_link_tracking(cycles=1, h=1e-3, compiled=False)
    fast = two_link_tracking(cycles=1, h=1e-3)
    assert slow.traj.stats["path"] == "python"
    assert slow.traj.stats["path_reason"] == "compiled=False"
    assert fast.traj.stats["path"] == "compiled_model"
    # a moved ground has no compiled model: the Python path, said so
    moved = two_link_tracking(cycles=1, h=1e-3, ground_offset=1e-3)
    assert moved.traj.stats["path"] == "python"
    assert moved.traj.stats["path_reason"].startswith("ground_offset")
    bound = (slow.traj.t.size - 1) * U * FACTOR
    assert np.abs(fast.traj.x - slow.traj.x).max() <= bound
    assert set(fast.traj.signals) == set(slow.traj.signals)
    for key in ("phase", "cycle"):
        assert np.array_equal(fast.traj.signals[key], slow.traj.signals[key])
    assert np.abs(fast.traj.signals["V"] - slow.traj.signals["V"]).max() \
        <= bound * np.abs(slow.traj.signals["V"]).max()


def test_compiled_blocks_are_shared_only_between_equal_settings():
    """The compiled block is kept per parameter record: two controllers of the same setting
    share it, a different gain gets its own (and each block carries its own gains)."""
    def make(gamma1):
        return SwitchingTrackingController(OneDofMass(), HalfSineTask(), PBCGains(gamma1, 5.0))
    a, b, c = make(5.0), make(5.0), make(6.0)
    assert a.compiled() is b.compiled()
    assert c.compiled() is not a.compiled()
    gamma1 = [kern.PARAMS.names.index("gamma1")]
    assert a.compiled().params[gamma1] == 5.0 and c.compiled().params[gamma1] == 6.0


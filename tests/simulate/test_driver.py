"""The integrator family behind one driver: names and classes, a user's own integrator, one
option check, one failure policy, partial trajectories whatever ends the run."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import (
    BudgetExceededError,
    ModelError,
    NscontrolWarning,
    ZenoError,
    ZenoWarning,
)
from nscontrol.simulate import METHODS, Integrator, Trajectory, register_method
from nscontrol.simulate.methods import (
    EventDriven,
    ImplicitEuler,
    MoreauJean,
    SampledZOH,
    Switching,
)
from nscontrol.simulate.trajectory import Recorder
from nscontrol.systems.feedback import StaticLaw
from nscontrol.systems.lagrangian import LagrangianSystem

G = 9.81


@pytest.fixture
def ball():
    return LagrangianSystem.bouncing_ball(restitution=0.9)


def test_methods_map_names_to_classes_and_a_class_is_a_method(ball):
    assert {k: METHODS[k] for k in METHODS} == {
        "event_driven": EventDriven, "moreau_jean": MoreauJean,
        "implicit_euler": ImplicitEuler, "switching": Switching, "sampled_zoh": SampledZOH}
    by_name = nsc.simulate(ball, [1.0, 0.0], (0.0, 3.0), method="moreau_jean", h=1e-3)
    by_class = nsc.simulate(ball, [1.0, 0.0], (0.0, 3.0), method=MoreauJean, h=1e-3)
    # the same code runs both ways: bitwise equal
    np.testing.assert_array_equal(by_name.x, by_class.x)
    for cls in (EventDriven, MoreauJean, ImplicitEuler, Switching, SampledZOH):
        assert cls.capabilities, cls


class ExplicitEuler(Integrator):
    """A user's integrator of ``x' = A x``: the smallest thing that keeps the contract."""

    name = "user_explicit_euler"
    capabilities = frozenset()
    options = frozenset({"h"})

    @classmethod
    def supports(cls, system):
        return isinstance(system, LinearODE)

    @classmethod
    def systems(cls):
        return "LinearODE"

    def integrate(self, system, x0, t_span, *, h=1e-3, record_every=1, signals=None,
                  progress=None):
        rec = Recorder(len(x0), every=record_every, signals=signals, offered=("norm",))
        t0, tf = t_span
        x = np.asarray(x0, float)
        n = int(round((tf - t0) / h))
        for k in range(n + 1):
            rec.sample(t0 + k * h, x, force=k == n, norm=np.linalg.norm(x))
            if system.on_step is not None:
                system.on_step(t0 + k * h)
            x = x + h * (system.A @ x)
        return rec.finish(method=self.name)


class LinearODE:
    default_method = None

    def __init__(self, A, on_step=None):
        self.A = np.asarray(A, float)
        self.on_step = on_step


def test_a_user_integrator_plugs_in_by_class_and_by_registered_name():
    rot = LinearODE([[0.0, 1.0], [-1.0, 0.0]])
    h = 1e-4
    tr = nsc.simulate(rot, [1.0, 0.0], (0.0, 1.0), method=ExplicitEuler, h=h,
                      t_eval=[0.25, 0.5, 1.0])
    # explicit Euler's global error on the rotation is <= t h |A|^2 e^{t|A|} |x0| / 2 (+ the
    # O(h^2) interpolation, zero at grid points): 1 * 1e-4 * e / 2 < 1.4e-4
    exact = np.array([[np.cos(t), -np.sin(t)] for t in (0.25, 0.5, 1.0)])
    assert np.max(np.abs(tr.x - exact)) < 0.5 * h * np.e
    assert tr.stats["t_eval"] == "interpolated"
    register_method(ExplicitEuler)
    try:
        by_name = nsc.simulate(rot, [1.0, 0.0], (0.0, 1.0), method="user_explicit_euler", h=h)
        assert by_name.method == "user_explicit_euler"
    finally:
        METHODS._paths.pop("user_explicit_euler")
        METHODS._classes.pop("user_explicit_euler")
    with pytest.raises(ModelError, match=r"^method: expected a method name or an Integrator"):
        nsc.simulate(rot, [1.0, 0.0], (0.0, 1.0), method=object)
    with pytest.raises(ModelError, match=r"^user_explicit_euler: integrates LinearODE, got"):
        nsc.simulate(LagrangianSystem.bouncing_ball(), [1.0, 0.0], (0.0, 1.0),
                     method=ExplicitEuler)


@pytest.mark.parametrize("method, system_kind", [
    ("event_driven", "ball"), ("moreau_jean", "ball"), ("implicit_euler", "lure"),
    ("switching", "pwa"), ("sampled_zoh", "smc")])
def test_every_method_refuses_an_unknown_option_with_one_message(method, system_kind, ball):
    from nscontrol.design import FirstOrderSMC
    from nscontrol.systems import SlidingModePlant
    from nscontrol.testing.setvalued_problems import bimodal_oscillator, relay_feedback

    smc = SlidingModePlant.double_integrator()
    system, x0 = {"ball": (ball, [1.0, 0.0]),
                  "lure": (relay_feedback().system, [1.0, 0.0]),
                  "pwa": (bimodal_oscillator().system, bimodal_oscillator().x0),
                  "smc": (nsc.closed_loop(smc, FirstOrderSMC(smc, 1.0, 1e-2)), [1.0, 0.0]),
                  }[system_kind]
    with pytest.raises(ModelError, match=rf"^{method}: unknown option\(s\) \['stepsize'\]; "
                                         r"accepted: \[.*'on_failure'.*'t_eval'"):
        nsc.simulate(system, x0, (0.0, 1.0), method=method, stepsize=1e-3)


def test_feedback_given_as_an_option_is_told_to_be_a_closed_loop():
    """``controller=`` is no option of a method: feedback is a closed loop, a system too.
    The same message from ``simulate`` and from the up-front checks of a sweep."""
    from nscontrol.simulate.driver import CAPABILITIES, check_run
    from nscontrol.systems.feedback import StateFeedback
    from nscontrol.testing.setvalued_problems import relay_feedback

    plant = relay_feedback().system
    message = (r"^controller: unknown option of simulate; feedback is a closed loop.*"
               r"simulate\(closed_loop\(plant, block\), x0, t_span, ...\)")
    with pytest.raises(ModelError, match=message):
        nsc.simulate(plant, [1.0, 0.0], (0.0, 1.0), h=1e-2, controller=lambda t, x: [0.0])
    with pytest.raises(ModelError, match=message):
        check_run(plant, "implicit_euler", {"h": 1e-2, "controller": StateFeedback([[0.0]])})
    assert "controller" not in CAPABILITIES


class WholeLoop(Integrator):
    """A user's integrator that says it runs a closed loop as it is."""

    name = "user_whole_loop"
    seen: list = []

    @classmethod
    def supports(cls, system):
        from nscontrol.simulate.closed_loop import ClosedLoop

        return isinstance(system, ClosedLoop)

    def integrate(self, system, x0, t_span, *, record_every=1, signals=None, progress=None):
        self.seen.append(system)
        rec = Recorder(len(x0))
        rec.sample(t_span[0], np.asarray(x0, float))
        rec.sample(t_span[1], np.asarray(x0, float), force=True)
        return rec.finish(method=self.name)


def test_a_method_that_claims_a_closed_loop_is_handed_the_lowered_model_only(ball):
    from nscontrol.systems.feedback import StateFeedback

    # feedback reaches an integrator one way: the loop is lowered whatever the method's
    # supports() says (here the feedback folds into the ball's forces, a LagrangianSystem),
    # so a method that takes closed loops only is never handed one: it is refused
    loop = nsc.closed_loop(ball, StateFeedback([[-1.0, -1.0]]))
    WholeLoop.seen.clear()
    with pytest.raises(ModelError, match=r"^user_whole_loop: lowered by fold state feedback, "
                                         r"this system is a LagrangianSystem"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), method=WholeLoop)
    assert WholeLoop.seen == []
    lowered = nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-2)
    assert "u" in lowered.signals          # the lowering's own signals: it was lowered


def test_a_user_callback_error_keeps_the_run_so_far(ball):
    class Controller(nsc.systems.StaticLaw):
        n_outputs, period = 1, None

        def output(self, t, xc, m):
            if t > 0.5:
                raise RuntimeError("sensor unplugged")
            return np.zeros(1)

    with pytest.raises(RuntimeError, match="sensor unplugged") as info:
        nsc.simulate(nsc.closed_loop(ball, Controller()), [1.0, 0.0], (0.0, 1.0),
                     method="moreau_jean", h=1e-3)
    partial = info.value.trajectory
    assert isinstance(partial, Trajectory) and partial.status == -1
    # the controller is called at each step's start: the last recorded step ends at 0.501
    assert 0.5 <= partial.t[-1] <= 0.5 + 2e-3
    assert "err.trajectory" in info.value.__notes__[0]


def test_keyboard_interrupt_keeps_the_run_so_far():
    def stop(t):
        if t >= 0.3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as info:
        nsc.simulate(LinearODE(np.zeros((1, 1)), on_step=stop), [1.0], (0.0, 1.0),
                     method=ExplicitEuler, h=0.1)
    assert info.value.trajectory.t[-1] == pytest.approx(0.3)


class _Saturating(StaticLaw):
    """A law written in Python that fails once the ball is below 0.5."""

    n_outputs, period = 1, None

    def output(self, t, xc, m):
        if m.x[0] < 0.5:
            raise ValueError("actuator saturated")
        return np.zeros(1)


def test_a_user_force_error_on_the_event_driven_path_keeps_the_run(ball):
    # a law written in Python: the DOP853 path
    with pytest.raises(ValueError) as info:
        nsc.simulate(nsc.closed_loop(ball, _Saturating()), [1.0, 0.0], (0.0, 2.0),
                     method="event_driven")
    assert info.value.trajectory.x[-1, 0] >= 0.5 - 1e-9 and len(info.value.trajectory.t) > 1


def _zeno_run(ball, **kw):
    return nsc.simulate(ball, [1.0, 0.0], (0.0, 10.0), max_events=10, **kw)


def test_one_failure_policy_for_every_method(ball):
    with pytest.raises(BudgetExceededError) as info:   # the event budget spent
        _zeno_run(ball)
    assert info.value.budget == "max_events" and info.value.limit == 10
    assert info.value.trajectory.status == -1
    returned = _zeno_run(ball, on_failure="return")
    assert returned.status == -1 and len(returned.events_of("impact")) == 10
    np.testing.assert_array_equal(returned.t, info.value.trajectory.t)
    with pytest.warns(NscontrolWarning, match="max_events"):
        warned = _zeno_run(ball, on_failure="warn")
    assert warned.status == -1
    with pytest.raises(ModelError, match=r"^on_failure: expected 'raise', 'return' or 'warn'"):
        _zeno_run(ball, on_failure="ignore")
    assert issubclass(ZenoWarning, NscontrolWarning) and issubclass(BudgetExceededError,
                                                                      ZenoError) is False


def test_a_model_error_is_raised_whatever_the_failure_policy(ball):
    with pytest.raises(nsc.InadmissibleStateError):
        nsc.simulate(ball, [-0.1, 0.0], (0.0, 1.0), on_failure="return")


def test_capabilities_are_asked_for_not_assumed(ball):
    with pytest.raises(ModelError, match=r"^sensitivity: method 'moreau_jean' does not "
                                         r"compute sensitivities; use one of "
                                         r"\[.*'event_driven'.*'switching'.*\]"):
        nsc.simulate(ball, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3,
                     sensitivity=True)
    from nscontrol.analysis.periodic import periodic_steady_state

    with pytest.raises(ModelError, match="shooting needs sensitivities"):
        periodic_steady_state(ball, 1.0, method="moreau_jean", h=1e-3)


def test_t_eval_on_a_time_stepping_method_is_within_the_interpolation_bound(ball):
    """Free fall before the first impact: Moreau–Jean with theta = 1/2 is exact at the steps
    for a constant force (the trapezoid rule on a linear velocity), so the only error at
    t_eval is linear interpolation of the parabola between steps: g h^2 / 8."""
    h = 1e-2
    t_eval = np.linspace(0.0, 0.4, 37)      # off the step grid
    tr = nsc.simulate(ball, [1.0, 0.0], (0.0, 0.4), method="moreau_jean", h=h, theta=0.5,
                      t_eval=t_eval)
    np.testing.assert_array_equal(tr.t, t_eval)
    exact_q = 1.0 - 0.5 * G * t_eval ** 2
    # bound g h^2 / 8, plus 10 ulps of the positions for the arithmetic
    assert np.max(np.abs(tr.x[:, 0] - exact_q)) <= G * h * h / 8 + 10 * np.finfo(float).eps
    np.testing.assert_allclose(tr.x[:, 1], -G * t_eval, rtol=0, atol=1e-12)  # v is linear
    with pytest.raises(ModelError, match=r"^t_eval: times must lie in the simulated span"):
        nsc.simulate(ball, [1.0, 0.0], (0.0, 0.4), method="moreau_jean", h=h,
                     t_eval=[0.5])


def test_record_every_and_signals_mean_the_same_for_every_method():
    from nscontrol.testing.setvalued_problems import bimodal_oscillator

    p = bimodal_oscillator()
    full = nsc.simulate(p.system, p.x0, (0.0, 5.0))
    thin = nsc.simulate(p.system, p.x0, (0.0, 5.0), record_every=10)
    np.testing.assert_array_equal(thin.t[:-1], full.t[::10][:len(thin.t) - 1])
    assert thin.t[-1] == full.t[-1]
    with pytest.raises(ModelError, match=r"^signals: unknown name"):
        nsc.simulate(p.system, p.x0, (0.0, 5.0), signals=["gap"])


def test_listeners_are_called_by_every_method():
    from nscontrol.testing.setvalued_problems import bimodal_oscillator

    p = bimodal_oscillator()
    seen = []
    tr = nsc.simulate(p.system, p.x0, (0.0, 5.0),
                      listeners=[lambda t, xm, xp, idx, imp: seen.append(t)])
    assert seen == list(tr.event_times()) and len(seen) > 0
    with pytest.raises(ModelError, match=r"^listeners: expected a sequence of callables"):
        nsc.simulate(p.system, p.x0, (0.0, 5.0), listeners=print)


def test_no_recorder_no_partial_but_the_error_still_reaches_the_caller():
    class Broken(Integrator):
        name = "broken"

        def integrate(self, system, x0, t_span, **options):
            raise ArithmeticError("before any sample")

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ArithmeticError) as info:
            nsc.simulate(LinearODE(np.eye(1)), [1.0], (0.0, 1.0), method=Broken)
    assert getattr(info.value, "trajectory", None) is None


@pytest.mark.parametrize("method, opts", [("event_driven", {}), ("moreau_jean", {"h": 1e-3})])
def test_a_user_error_on_impacting_bodies_keeps_the_partial_run_in_their_state_order(
        method, opts):
    """ImpactingBodies run through their Lagrangian form (another state order): a partial
    run comes back in the bodies' own order [x_a; x_b], as a finished one does."""
    from nscontrol.systems.impacting_bodies import ImpactingBodies

    bodies = ImpactingBodies.from_springs([1.0, 2.0], [3.0], {(0, 0): 1.0, (0, 1): 0.5},
                                          {(0, 0): -0.2}, restitution=0.7)
    x0 = np.array([0.0, 0.1, 0.3, 0.0, 1.0, -0.5])
    full = nsc.simulate(bodies, x0, (0.0, 0.5), method=method, **opts)

    def stop(t, x_minus, x_plus, contacts, impulse):
        raise RuntimeError("stop at the first impact")

    try:
        nsc.simulate(bodies, x0, (0.0, 5.0), method=method, listeners=[stop], **opts)
    except RuntimeError as err:
        partial = err.trajectory
    else:   # no impact in the span: nothing to test with this configuration
        pytest.fail("expected an impact within 5 s")
    assert partial.state_names == full.state_names
    np.testing.assert_array_equal(partial.x[0], x0)

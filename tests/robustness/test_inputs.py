"""The remaining bad-input classes of issue 29: blocks, laws, designs, trajectories and
frequency sweeps.

Each case was accepted silently, gave NaN with an ok status, or crashed with a raw
``AttributeError`` (or a vague message) on the code before the fix; each must now raise a
specific error from :mod:`nscontrol.errors` whose message starts with the argument's name,
says what is wrong (with the value received) and what to do. Every check here is exact: no
numerical tolerance is involved.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.analysis.periodic import frequency_sweep
from nscontrol.errors import DimensionError, ModelError


def refused(call, name: str, exc: type[Exception] = ModelError, *, says=()) -> str:
    """``call()`` raises ``exc`` whose message starts with ``name``; every string of
    ``says`` appears in it. Returns the message."""
    with pytest.raises(exc) as info:
        call()
    msg = str(info.value)
    assert msg.startswith(name), msg
    for part in says:
        assert part in msg, (part, msg)
    return msg


# ------------------------------------------------------------------------------- blocks

@pytest.fixture(scope="module")
def mass():
    from nscontrol.systems.lagrangian import LagrangianSystem

    return LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0], actuation=[[1.0]])


class _Block:
    """A Python controller ``u = -q`` (or a fixed output), sampled with ``period``."""

    n_states, n_outputs = 0, 1

    def __init__(self, period=None, out=None):
        self.period, self.out = period, out

    def output(self, t, xc, m):
        return -m.x[:1] if self.out is None else self.out

    def update(self, t, xc, m):
        return xc

    def reset(self, t, xc, jump):
        return xc


def test_linear_controller_needs_a_square_A():
    from nscontrol.systems.feedback import LinearController

    # a 2x3 A used to give a controller with n_states = 2 whose update A xc cannot run
    refused(lambda: LinearController(np.ones((2, 3)), np.ones((2, 1)), np.ones((1, 2)),
                                     np.ones((1, 1))), "A", DimensionError,
            says=["square", "(2, 3)"])


@pytest.mark.parametrize("period", [0.0, math.nan, -0.1, math.inf, "0.1"])
def test_block_period_is_refused_when_the_loop_is_built(mass, period):
    msg = refused(lambda: nsc.closed_loop(mass, _Block(period)), "controller.period",
                  says=[repr(period)])
    assert isinstance(period, str) or "None (continuous-time)" in msg
    refused(lambda: nsc.closed_loop(mass, observer=_Block(period)), "observer.period")


@pytest.mark.parametrize("out", ["1.0", ["1.0"], np.array(["1.0"]), b"1"])
def test_block_output_that_is_not_numeric_is_refused(mass, out):
    loop = nsc.closed_loop(mass, _Block(None, out))
    refused(lambda: nsc.simulate(loop, [0.2, 0.0], (0.0, 0.05), h=1e-2, progress=False),
            "controller", says=["string", "t = 0", "numeric arrays"])


def test_block_reset_of_the_wrong_length_is_refused(mass):
    class Grows(_Block):
        n_states = 1

        def reset(self, t, xc, jump):
            return np.zeros(2)

    loop = nsc.closed_loop(mass, Grows())
    refused(lambda: nsc.simulate(loop, [0.05, -1.0], (0.0, 0.2), h=1e-2, progress=False),
            "controller", DimensionError, says=["returned 2 values", "has 1"])


@pytest.mark.parametrize(("params", "says"), [(["1.0"], ["strings"]),
                                               ([1.0, math.nan], ["NaN", "[1]"]),
                                               (np.array([[math.nan]]), ["NaN"])])
def test_compiled_block_params_are_numbers(params, says):
    from nscontrol.systems._feedback_kernels import affine_output, static_update
    from nscontrol.systems.feedback import CompiledBlock

    refused(lambda: CompiledBlock(affine_output, static_update, params), "params", says=says)


def test_compiled_block_params_may_hold_an_infinite_bound():
    from nscontrol.systems._feedback_kernels import affine_output, static_update
    from nscontrol.systems.feedback import CompiledBlock

    form = CompiledBlock(affine_output, static_update, [1.0, math.inf])
    assert form.params.tolist() == [1.0, math.inf]


# --------------------------------------------------------------------------------- laws

@pytest.mark.parametrize(("args", "name"), [((3.0, -1.0, 1.0), "a"), ((3.0, 1.0, -0.5), "b"),
                                            ((3.0, [1.0, -1.0], 1.0), "a"),
                                            ((math.nan, 1.0, 1.0), "x"),
                                            ((math.inf, 1.0, 1.0), "x"),
                                            ((1.0, math.nan, 1.0), "a"),
                                            (("3.0", 1.0, 1.0), "x")])
def test_super_twisting_resolvent_refuses_negative_weights_and_nan(args, name):
    from nscontrol.laws import super_twisting_resolvent

    refused(lambda: super_twisting_resolvent(*args), name)


def test_super_twisting_resolvent_refuses_shapes_that_do_not_broadcast():
    from nscontrol.laws import super_twisting_resolvent

    refused(lambda: super_twisting_resolvent([1.0, 2.0], [1.0, 1.0, 1.0], 0.0), "x, a, b",
            DimensionError)


def test_super_twisting_resolvent_still_solves_its_inclusion():
    # the checked entry returns the root of z + a sqrt|z| sign z = x - b sign x (|x| > b)
    from nscontrol.laws import super_twisting_resolvent

    z = super_twisting_resolvent(np.array([3.0, -7.0, 0.5]), 1.0, 1.0)
    assert z.tolist() == [1.0, -4.0, 0.0]      # r^2 + r = 2 -> r = 1; r^2 + r = 6 -> r = 2


# ------------------------------------------------------------------ tracking controller

@pytest.mark.parametrize(("task", "name"), [
    (dict(radius=-0.1), "radius"), (dict(radius=0.0), "radius"), (dict(period=0.0), "period"),
    (dict(period=math.nan), "period"), (dict(centre=math.inf), "centre"),
    (dict(centre="0.65"), "centre"), (dict(y_threshold=0.2), "y_threshold"),
    (dict(y_threshold=-0.01), "y_threshold")])
def test_circle_task_parameters(task, name):
    from nscontrol.design.complementarity_tracking import CircleTask

    refused(lambda: CircleTask(**task), name, says=[repr(next(iter(task.values())))])


@pytest.mark.parametrize(("task", "name"), [(dict(amplitude=-0.1), "amplitude"),
                                            (dict(omega=0.0), "omega"),
                                            (dict(threshold=0.5), "threshold")])
def test_half_sine_task_parameters(task, name):
    from nscontrol.design.complementarity_tracking import HalfSineTask

    refused(lambda: HalfSineTask(**task), name)


@pytest.mark.parametrize("centre", [5.0, 1.0, 0.05, -0.95])
def test_circle_out_of_the_arms_reach_is_refused(centre):
    # the arm reaches |l1 - l2| <= |p| <= l1 + l2 = 1 m from its base; a circle of centre
    # (c, 0) and radius r spans the distances [|c| - r, |c| + r]
    from nscontrol.design.complementarity_tracking import CircleTask, SwitchingTrackingController
    from nscontrol.systems.two_link import TwoLinkArm

    refused(lambda: SwitchingTrackingController(TwoLinkArm(), CircleTask(centre=centre)),
            "task", says=["reach [0, 1]", f"{abs(centre) + 0.1:.6g}"])


def test_circle_in_reach_is_accepted():
    from nscontrol.design.complementarity_tracking import CircleTask, SwitchingTrackingController
    from nscontrol.systems.two_link import TwoLinkArm

    ctrl = SwitchingTrackingController(TwoLinkArm(), CircleTask(centre=0.85, radius=0.15))
    assert ctrl.n_outputs == 2


@pytest.mark.parametrize("model", ["arm", np.eye(2), None])
def test_tracking_controller_needs_a_task_space_model(model):
    from nscontrol.design.complementarity_tracking import CircleTask, SwitchingTrackingController

    refused(lambda: SwitchingTrackingController(model, CircleTask()), "model",
            says=["TaskSpaceModel", "TwoLinkArm()"])


def test_tracking_controller_needs_a_task_of_the_models_dimension():
    from nscontrol.design.complementarity_tracking import (
        CircleTask,
        HalfSineTask,
        SwitchingTrackingController,
    )
    from nscontrol.systems.two_link import OneDofMass, TwoLinkArm

    refused(lambda: SwitchingTrackingController(OneDofMass(), CircleTask()), "task",
            DimensionError, says=["2 coordinate(s), the model 1"])
    refused(lambda: SwitchingTrackingController(TwoLinkArm(), HalfSineTask()), "task",
            DimensionError)
    refused(lambda: SwitchingTrackingController(TwoLinkArm(), "circle"), "task",
            says=["CyclicTask"])
    refused(lambda: SwitchingTrackingController(TwoLinkArm(), CircleTask(), gains=(5.0, 5.0)),
            "gains", says=["PBCGains", "tuple"])


# --------------------------------------------------------------------------- trajectory

@pytest.mark.parametrize("t", [1e9, -1.0, 2.0 + 1e-9, [0.5, 3.0]])
def test_trajectory_at_refuses_times_outside_the_run(t):
    from nscontrol.simulate.trajectory import Trajectory

    traj = Trajectory(t=[0.0, 1.0, 2.0], x=np.arange(3.0)[:, None])
    refused(lambda: traj.at(t), "t", says=["[0, 2]", "simulate over a longer span"])


def test_trajectory_at_accepts_the_end_times_to_round_off():
    from nscontrol.simulate.trajectory import Trajectory

    traj = Trajectory(t=[0.0, 1.0, 2.0], x=np.arange(3.0)[:, None])
    # 2 + 2 ulp(2) is round-off of the end time (the span check allows 1e-12 relative)
    t_end = np.nextafter(np.nextafter(2.0, 3.0), 3.0)
    assert traj.at(t_end).tolist() == [2.0] and traj.at(0.5).tolist() == [0.5]


# ---------------------------------------------------------------------- frequency sweep

@pytest.fixture(scope="module")
def oscillator():
    from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator

    return one_sided_oscillator(0.1)


SWEEP = dict(n_transient=2, n_record=2, executor="serial", progress=False,
             directions=("up",))


@pytest.mark.parametrize(("change", "name", "says"), [
    (dict(n_record=0), "n_record", [">= 1", "0"]),
    (dict(n_transient=-1), "n_transient", [">= 0"]),
    (dict(n_harmonics=0), "n_harmonics", [">= 1"]),
    (dict(n_harmonics=2.5), "n_harmonics", ["2.5"]),
    (dict(samples_per_period=1), "samples_per_period", [">= 11", "lower n_harmonics"]),
    (dict(samples_per_period=10), "samples_per_period", [">= 11"]),
    (dict(nosuch=1), "switching", ["unknown option(s) ['nosuch']", "accepted"]),
    (dict(method="nosuch"), "method", ["'nosuch'"]),
    (dict(progress="no"), "progress", ["string 'no'"]),
    (dict(directions="up"), "directions", ["string"]),
])
def test_frequency_sweep_refuses_what_every_point_would_fail_on(oscillator, change, name,
                                                                says):
    kw = {**SWEEP, **change}
    refused(lambda: frequency_sweep(oscillator, [2.8], **kw), name,
            says=says)


def test_frequency_sweep_accepts_the_least_samples_per_period(oscillator):
    # 5 samples per period resolve harmonic 2 (5 > 2·2): the point is measured, no error
    res = frequency_sweep(oscillator, [2.8], samples_per_period=5,
                                                n_harmonics=2, **SWEEP)
    assert res["up"].errors[0] is None and np.isfinite(res["up"].gamma[0])


def test_frequency_sweep_refuses_a_system_its_method_does_not_integrate(mass):
    refused(lambda: frequency_sweep(mass, [2.8], **SWEEP), "switching",
            says=["got LagrangianSystem", "use method='event_driven'"])


# ---------------------------------------------------------------------------- designs

def test_design_zad_refuses_a_model_that_is_not_a_converter():
    from nscontrol.design.converter_regulation import design_zad

    for bad in ("buck", {"u_on": 1.0}, None):
        refused(lambda bad=bad: design_zad(bad, T=0.18, x_ref=0.8), "system",
                says=["BuckConverter", type(bad).__name__])


@pytest.mark.parametrize("duty_margin", [0.7, -0.1, math.nan, "0.01"])
def test_design_zad_names_duty_margin(duty_margin):
    from nscontrol.design.converter_regulation import design_zad
    from nscontrol.systems.buck import BuckConverter

    # 0.7 used to report an inverted interval [0.7, 0.3] against x_ref
    refused(lambda: design_zad(BuckConverter.normalized(0.35), T=0.18, x_ref=0.8,
                               duty_margin=duty_margin), "duty_margin")


@pytest.fixture(scope="module")
def corner_case():
    from nscontrol.analysis.orbits import find_cycle
    from nscontrol.testing.cycle_problems import polar_normal_form

    plant, _ = polar_normal_form((-0.08, 0.0, 0.1, 0.0, -0.02), omega=1.0)
    return plant, find_cycle(plant, [1.0, 0.0], 2 * np.pi, normal=[0.0, 1.0])


@pytest.mark.parametrize("which", ["plant", "cycle", "section"])
def test_corner_design_refuses_wrong_object_types(corner_case, which):
    from nscontrol.design.limit_cycle_switching import corner_site, design_corner_controller

    plant, cyc = corner_case
    args = {"plant": plant, "cycle": cyc, "section": None}
    args[which] = [1.0, 0.0]
    expected = {"plant": "NonlinearSystem", "cycle": "find_cycle", "section": "Section"}
    refused(lambda: design_corner_controller(
        args["plant"], args["cycle"], b=[1.0, 0.0], target_multiplier=-0.5,
        target_offset=0.01, anchor=[1.0, 0.0], section=args["section"], allow_sliding=True),
        which, says=[expected[which], "list"])
    refused(lambda: corner_site(args["plant"], args["cycle"], b=[1.0, 0.0],
                                section=args["section"]), which)


def test_posture_design_refuses_wrong_object_types():
    from nscontrol.analysis.posture_certificate import gain_threshold, posture_certificate
    from nscontrol.design.contact_posture import (
        ContactRegulator,
        design_contact_regulator,
        static_contact_forces,
    )
    from nscontrol.systems.foot_body import foot_body_model

    q = [0.0, 0.05, 0.0, -0.1]
    for call in (lambda: static_contact_forces("robot", q, [0, 1]),
                 lambda: design_contact_regulator(None, q, [0, 1], 400.0, 30.0),
                 lambda: posture_certificate("robot", q, [0, 1], 120.0, [1.0]),
                 lambda: gain_threshold(q, q, [0, 1], [1.0, 1.0])):
        refused(call, "model", says=["ActuatedContactModel"])
    refused(lambda: ContactRegulator(foot_body_model(), {"lam_star": 1.0}, 400.0, 30.0),
            "design", says=["StaticPostureDesign", "static_contact_forces"])


# ------------------------------------------------------------------------- boolean options

def _mod(name: str):
    import importlib

    return importlib.import_module(name)


def _pwl():
    return _mod("nscontrol.examples.ch09_pwl_linearization").ex9_4_pwl_gain()


@functools.cache
def _impact_design():
    from nscontrol.design.impact_observer import design_impact_observer
    from nscontrol.systems.impacting_bodies import ImpactingBodies

    plant = ImpactingBodies.from_springs([1.0, 1.0], [0.7], {(0, 0): 4.0, (0, 1): 6.0},
                                         {(0, 0): 2.8})
    return design_impact_observer(plant, [-0.5, -0.6, -0.7, -0.8], alpha=0.3,
                                  delta_min=0.6, delta_max=2.3)


def _ball():
    return _mod("nscontrol.systems.lagrangian").LagrangianSystem.bouncing_ball()


def _oscillator():
    return _mod("nscontrol.examples.ch11_convergent_pwa").one_sided_oscillator(0.1)


def _one_state(p):
    """A stand-in for a diagram's factory: only its state size is read before the check."""
    from types import SimpleNamespace

    return SimpleNamespace(n_states=1)


_OBSERVER = ([[0, 1], [-3, -4]], [[0], [1]], [[2, 1]], [[2, 1]])

#: One call per boolean option of the public API (or per entry point that checks it for
#: several: simulate's driver for every method, sweep.run for the diagrams, the progress bars
#: for every integrator), each given ``flag`` for that option. Covered through these and not
#: listed: the diagrams' and the report's progress (sweep.run, progress_iter),
#: simulate_friction_loop's compiled (closed_loop), run_observer's impacts (the design's
#: closed_loop), two_link_tracking's compiled, the bimodal/conewise constructors' continuous
#: and MechanicalPWL.frequencies' contact.
BOOLEAN_OPTIONS = {
    "simulate progress": (lambda f: nsc.simulate(_ball(), [1.0, 0.0], (0.0, 0.1),
                                                 progress=f), "progress"),
    "simulate sensitivity": (lambda f: nsc.simulate(_ball(), [1.0, 0.0], (0.0, 0.1),
                                                    sensitivity=f), "sensitivity"),
    "moreau_jean projection": (lambda f: nsc.simulate(_ball(), [1.0, 0.0], (0.0, 0.1), h=1e-2,
                                                      method="moreau_jean", projection=f),
                               "projection"),
    "moreau_jean integrate progress": (lambda f: _mod("nscontrol.simulate.moreau_jean")
                                       .integrate(_ball(), [1.0, 0.0], (0.0, 0.1), h=1e-2,
                                                  progress=f), "progress"),
    "event_driven integrate progress": (lambda f: _mod("nscontrol.simulate.event_driven")
                                        .integrate(_ball(), [1.0, 0.0], (0.0, 0.1),
                                                   progress=f), "progress"),
    "event_driven integrate sensitivity": (lambda f: _mod("nscontrol.simulate.event_driven")
                                           .integrate(_ball(), [1.0, 0.0], (0.0, 0.1),
                                                      sensitivity=f), "sensitivity"),
    "switching integrate sensitivity": (lambda f: _mod("nscontrol.simulate.switching")
                                        .integrate(_oscillator(), [0.0, 0.0], (0.0, 0.1),
                                                   sensitivity=f), "sensitivity"),
    "progress bar": (lambda f: _mod("nscontrol._progress").TimeProgress(0.0, 1.0, enable=f),
                     "progress"),
    "progress_iter": (lambda f: _mod("nscontrol._progress").progress_iter([1], enable=f),
                      "progress"),
    "sweep.run progress": (lambda f: _mod("nscontrol.sweep").run(abs, [1.0],
                                                                 executor="serial",
                                                                 progress=f), "progress"),
    "bifurcation_diagram warm_start": (lambda f: _mod("nscontrol.analysis.bifurcation")
                                       .bifurcation_diagram(_one_state, [1.0, 2.0],
                                                            warm_start=f), "warm_start"),
    "frequency_response progress": (lambda f: _mod("nscontrol.analysis.periodic")
                                    .frequency_response(_oscillator(), [1.0], progress=f),
                                    "progress"),
    "frequency_sweep progress": (lambda f: frequency_sweep(_oscillator(), [1.0], progress=f),
                                 "progress"),
    "periodic_steady_state fallback": (lambda f: _mod("nscontrol.analysis.periodic")
                                       .periodic_steady_state(_oscillator(), 1.0, fallback=f),
                                       "fallback"),
    "closed_loop compiled": (lambda f: nsc.closed_loop(_ball(), compiled=f), "compiled"),
    "PiecewiseStateFeedback discontinuous": (
        lambda f: _mod("nscontrol.systems.feedback").PiecewiseStateFeedback(
            [[[1.0, 0.0]]], discontinuous=f), "discontinuous"),
    "SuperTwistingController estimate_disturbance": (
        lambda f: _mod("nscontrol.design.sliding_mode").SuperTwistingController(
            _mod("nscontrol.systems.sliding_mode").SlidingModePlant.double_integrator(),
            1.0, 1.0, 1e-2, estimate_disturbance=f), "estimate_disturbance"),
    "PDLaw feedforward": (lambda f: _mod("nscontrol.design.friction_compensation").PDLaw(
        1.0, 1.0, 1.0, feedforward=f), "feedforward"),
    "design_zad compensate_offset": (
        lambda f: _mod("nscontrol.design.converter_regulation").design_zad(
            _mod("nscontrol.systems.buck").BuckConverter.normalized(0.35), T=0.18, x_ref=0.8,
            compensate_offset=f), "compensate_offset"),
    "static_contact_forces require_positive": (
        lambda f: _mod("nscontrol.design.contact_posture").static_contact_forces(
            _mod("nscontrol.systems.foot_body").foot_body_model(), [0.0, 0.05, 0.0, -0.1],
            [0, 1], require_positive=f), "require_positive"),
    "lure_observer_lmi precheck": (lambda f: _mod("nscontrol.design.lure_observer")
                                   .lure_observer_lmi(*_OBSERVER, variant="basic",
                                                      precheck=f), "precheck"),
    "max_observer_decay_rate precheck": (lambda f: _mod("nscontrol.design.lure_observer")
                                         .max_observer_decay_rate(*_OBSERVER, variant="basic",
                                                                  precheck=f), "precheck"),
    "pwl_feedback_linearize exact": (lambda f: _mod("nscontrol.design.pwl_linearization")
                                     .pwl_feedback_linearize(_pwl(), exact=f), "exact"),
    "pwl_feedback_linearize force": (lambda f: _mod("nscontrol.design.pwl_linearization")
                                     .pwl_feedback_linearize(_pwl(), force=f), "force"),
    "PWLLinearization.closed_loop check": (
        lambda f: _mod("nscontrol.design.pwl_linearization").pwl_feedback_linearize(
            _pwl()).transform.closed_loop(-0.5, check=f), "check"),
    "ImpactObserverDesign.closed_loop impacts": (
        lambda f: _impact_design().closed_loop(impacts=f), "impacts"),
    "lyapunov_certificate scale": (lambda f: _mod("nscontrol.numerics.lmi")
                                   .lyapunov_certificate(-np.eye(2), scale=f), "scale"),
    "quadratic_convergence normalise": (lambda f: _mod("nscontrol.analysis.convergence")
                                        .quadratic_convergence([-np.eye(2)], normalise=f),
                                        "normalise"),
    "peak_to_peak_bound refine": (lambda f: _mod("nscontrol.analysis.convergence")
                                  .peak_to_peak_bound([-np.eye(2)], np.eye(2), np.eye(2),
                                                      refine=f), "refine"),
    "ImpactOscillator drive_as_force": (lambda f: _mod("nscontrol.analysis.impact_oscillator")
                                        .ImpactOscillator().system(drive_as_force=f),
                                        "drive_as_force"),
    "MechanicalPWL contact": (lambda f: _mod("nscontrol.systems.beam").two_mode_beam()
                              .state_matrix(f), "contact"),
    "PiecewiseAffineSystem continuous": (
        lambda f: _mod("nscontrol.systems.pwa").PiecewiseAffineSystem.bimodal(
            -np.eye(2), -np.eye(2), [1.0, 0.0], continuous=f), "continuous"),
    "solve_lcp strict": (lambda f: _mod("nscontrol.numerics.lcp").solve_lcp(
        np.eye(2), [-1.0, 1.0], strict=f), "strict"),
    "stack_delassus sparse": (lambda f: _mod("nscontrol.testing.lcp_problems")
                              .stack_delassus(3, sparse=f), "sparse"),
    "ImpactingPendulum force_jacobian": (lambda f: _mod("nscontrol.testing.mechanics_problems")
                                         .ImpactingPendulum(force_jacobian=f).system(),
                                         "force_jacobian"),
    "ImpactingPendulum callable_mass": (lambda f: _mod("nscontrol.testing.mechanics_problems")
                                        .ImpactingPendulum(callable_mass=f).system(),
                                        "callable_mass"),
    "run_foot as_block": (lambda f: _mod("nscontrol.examples.ch04_posture_regulation")
                          .run_foot(-0.3, as_block=f), "as_block"),
}


@pytest.mark.parametrize(("option", "flag"), [
    (option, flag) for option in sorted(BOOLEAN_OPTIONS) for flag in ("yes", "no", "", 1, None)
    if not (flag is None and BOOLEAN_OPTIONS[option][1] == "progress")])  # None: decide
def test_boolean_options_take_only_bools(option, flag):
    call, name = BOOLEAN_OPTIONS[option]
    says = ["expected True", "pass a bool"] + (["string"] if isinstance(flag, str) else [])
    refused(lambda: call(flag), name, says=says)


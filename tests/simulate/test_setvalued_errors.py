"""Bad input to the set-valued models and integrators: each its specific error, with the way
out named."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import DimensionError, ModelError
from nscontrol.laws.friction import Stribeck
from nscontrol.laws.relay import Relay
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.systems.switched import FilippovSystem, PWMController, SwitchedAffineSystem

A = np.array([[0.0, 1.0], [0.0, 0.0]])
G = np.array([[0.0], [1.0]])
H = np.array([[1.0, 1.0]])


def _stribeck():
    return Stribeck(static=0.3, coulomb=0.1, stribeck_velocity=1.0, delta=2.0)


def test_non_monotone_law_is_refused_with_loop_transformation_named():
    with pytest.raises(ModelError, match="loop_transformation"):
        LureSystem(A, G, H, _stribeck())


def test_shapes_and_feedthrough_are_checked():
    with pytest.raises(DimensionError, match="H"):
        LureSystem(A, G, [[1.0, 1.0, 0.0]], Relay(1.0))
    with pytest.raises(DimensionError, match="law"):
        LureSystem(A, G, H, Relay(1.0, dim=2))
    with pytest.raises(ModelError, match="D \\+ D\\^T"):
        LureSystem(A, G, H, Relay(1.0), D=[[-1.0]])
    with pytest.raises(ModelError, match="B"):
        LureSystem(A, G, H, Relay(1.0), u=lambda t: 0.0)


def test_implicit_euler_options_and_ill_posed_steps():
    lure = LureSystem(A, G, H, Relay(1.0))
    with pytest.raises(ModelError, match="h: implicit_euler needs a step"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0))
    with pytest.raises(ModelError, match="unknown option"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-3, rtol=1e-3)
    with pytest.raises(ModelError, match="theta"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-3, theta=0.2)
    # H G < 0: the one-step matrix is not positive definite
    bad = LureSystem(A, G, -H, Relay(1.0))
    with pytest.raises(ModelError, match="not positive definite"):
        simulate(bad, [1.0, 0.0], (0.0, 1.0), h=1e-3)
    # I - h A singular
    sing = LureSystem(np.eye(2) * 100.0, G, H, Relay(1.0))
    with pytest.raises(ModelError, match="singular"):
        simulate(sing, [1.0, 0.0], (0.0, 1.0), h=1e-2)
    with pytest.raises(ModelError, match="implicit_euler"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), method="switching")


def test_partition_errors():
    A1 = [[0.0, 1.0], [-1.0, 0.0]]
    with pytest.raises(ModelError, match="overlap"):
        PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [1.0]), ([[-1.0, 0.0]], [1.0])))
    with pytest.raises(ModelError, match="do not cover"):
        PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]),
                                                 ([[-1.0, 0.0]], [-1.0])))
    # a bounded domain makes the same gap-free cover acceptable
    PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]), ([[-1.0, 0.0]], [0.0])),
                          domain=([[1.0, 0.0], [-1.0, 0.0]], [1.0, 1.0]))
    with pytest.raises(ModelError, match="continuous=False"):
        PiecewiseAffineSystem.bimodal(A1, [[0.0, 1.0], [-2.0, 0.0]], [0.0, 1.0])
    with pytest.raises(DimensionError, match="regions"):
        PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]),))


def test_switched_model_errors():
    A1 = np.array([[0.0, 1.0], [-1.0, 0.0]])
    with pytest.raises(DimensionError, match="field"):
        FilippovSystem(2, (lambda x: x[0],), lambda t, x, s: np.zeros(3))
    with pytest.raises(ModelError, match="at least two modes"):
        SwitchedAffineSystem(((A1, [0.0, 0.0]),))
    with pytest.raises(ModelError, match="pattern"):
        PWMController(0.1, lambda t, x: 0.05, pattern="random")
    with pytest.raises(ModelError, match="PWMController"):
        simulate(SwitchedAffineSystem(((A1, [0, 0]), (A1, [0, 1]))), [0.0, 0.0], (0.0, 1.0))
    # repelling sliding: both sides push away from x = 0
    rep = FilippovSystem.two_sided(lambda t, x: np.array([-1.0]), lambda t, x: np.array([1.0]),
                                   lambda x: float(x[0]), 1)
    with pytest.raises(ModelError, match="repelling"):
        simulate(rep, [0.0], (0.0, 1.0))


def test_non_monotone_law_message_gives_the_lure_recipe_and_the_recipe_runs():
    law = _stribeck()
    with pytest.raises(ModelError) as info:
        LureSystem(A, G, H, law)
    msg = str(info.value)
    assert "lt = law.loop_transformation(); LureSystem(lt.transform_A(A, G, H), G, H, " \
           "lt.monotone_part" in msg
    assert "pass loop_transformation=lt" not in msg      # LureSystem has no such keyword
    lt = law.loop_transformation()
    fixed = LureSystem(lt.transform_A(A, G, H), G, H, lt.monotone_part)
    assert fixed.law.monotone
    np.testing.assert_allclose(fixed.A, A + G @ (lt.slope[:, None] * H))
    tr = simulate(fixed, [0.2, 0.0], (0.0, 0.5), h=1e-2)
    assert tr.success and np.all(np.isfinite(tr.x))


def test_inadmissible_initial_state_is_refused_not_projected():
    from nscontrol.errors import InadmissibleStateError
    from nscontrol.testing.setvalued_problems import diode_circuit

    p = diode_circuit()
    with pytest.raises(InadmissibleStateError, match=r"x0: .*z\[0:1\] = \[-1\.\].*dom"):
        simulate(p.system, [-1.0, 0.0], (0.0, 1.0), h=1e-2)
    simulate(p.system, [0.0, 0.0], (0.0, 0.1), h=1e-2)   # on the boundary: admissible


def test_integrator_options_are_validated():
    from nscontrol.testing.setvalued_problems import bimodal_oscillator, relay_feedback

    lure = LureSystem(A, G, H, Relay(1.0))
    with pytest.raises(ModelError, match=r"signals: unknown name\(s\) \['foo'\]; this "
                                         r"integrator records \['w', 'y', 'z'\]"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-2, signals=["foo"])
    with pytest.raises(ModelError, match="signals: expected a sequence of signal names"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-2, signals="z")
    with pytest.raises(ModelError, match="record_every: expected an integer >= 1"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-2, record_every=0)
    with pytest.raises(ModelError, match="on_failure"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-2, on_failure="ignore")
    only_z = simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-2, signals=["z"])
    assert set(only_z.signals) == {"z"}
    p = bimodal_oscillator()
    for bad, match in (({"n_samples": 0}, "n_samples: expected an integer >= 2"),
                       ({"n_samples": 2.5}, "n_samples: expected an integer"),
                       ({"rtol": -1}, "rtol: expected a finite number > 0"),
                       ({"atol": 0.0}, "atol: expected a finite number > 0"),
                       ({"max_events": -1}, "max_events: expected an integer >= 0"),
                       ({"sensitivity": "yes"}, "sensitivity: expected True or False"),
                       ({"t_eval": [[0.0, 1.0]]}, "t_eval: expected an increasing 1-d"),
                       ({"t_eval": [1.0, 0.5]}, "t_eval: .*not sorted")):
        with pytest.raises(ModelError, match=match):
            simulate(p.system, p.x0, (0.0, 1.0), **bad)
    with pytest.raises(ModelError, match="rtol"):
        simulate(relay_feedback().switched, [1.0, 0.0], (0.0, 1.0), rtol=-1)


def test_switched_model_arguments_are_validated():
    A1 = np.array([[0.0, 1.0], [-1.0, 0.0]])
    with pytest.raises(DimensionError, match="n_states: expected an integer >= 1, got 2.5"):
        FilippovSystem(2.5, (lambda x: x[0],), lambda t, x, s: np.zeros(2))
    f = FilippovSystem(2.0, (lambda x: x[0],), lambda t, x, s: np.zeros(2))
    assert f.n_states == 2 and isinstance(f.n_states, int)
    with pytest.raises(DimensionError, match=r"gradients\[0\]: expected grad_0\(x\) of shape "
                                             r"\(2,\), got shape \(3,\)"):
        FilippovSystem(2, (lambda x: x[0],), lambda t, x, s: np.zeros(2),
                       gradients=(lambda x: np.ones(3),))
    with pytest.raises(ModelError, match="on_mode, off_mode: expected two different modes"):
        PWMController(0.1, lambda t, x: 0.05, on_mode=1, off_mode=1)
    with pytest.raises(ModelError, match="period"):
        PWMController(0.0, lambda t, x: 0.05)
    with pytest.raises(ModelError, match=r"controller=PWMController\(period, duty\)"):
        simulate(SwitchedAffineSystem(((A1, [0, 0]), (A1, [0, 1]))), [0.0, 0.0], (0.0, 1.0))
    with pytest.raises(ModelError, match="unknown option"):   # not a simulate option
        simulate(SwitchedAffineSystem(((A1, [0, 0]), (A1, [0, 1]))), [0.0, 0.0], (0.0, 1.0),
                 controller=PWMController(0.1, lambda t, x: 0.05))


def test_non_finite_duty_is_a_model_error_naming_the_sampling_instant():
    A1 = np.array([[0.0, 1.0], [-1.0, -0.5]])

    def duty(t, x):
        return np.nan if t >= 0.5 else 0.05

    buck = SwitchedAffineSystem(((A1, [0.0, 0.0]), (A1, [0.0, 1.0])), PWMController(0.1, duty))
    with pytest.raises(ModelError, match=r"duty: expected a finite duty time, got nan at "
                                         r"t_k = 0\.5") as info:
        simulate(buck, [0.0, 0.0], (0.0, 2.0))
    assert info.value.trajectory.t[-1] == pytest.approx(0.5, abs=1e-12)


def test_pwm_period_below_time_resolution_is_refused():
    A1 = np.array([[0.0, 1.0], [-1.0, -0.5]])
    buck = SwitchedAffineSystem(((A1, [0.0, 0.0]), (A1, [0.0, 1.0])),
                                PWMController(1e-9, lambda t, x: 5e-10))
    with pytest.raises(ModelError, match="period: T = 1e-09 is below the floating-point "
                                         "resolution"):
        simulate(buck, [0.0, 0.0], (1e8, 1e8 + 1e-6))


def test_pwa_domain_and_unbounded_overlap_are_checked():
    from nscontrol.errors import InadmissibleStateError

    A1 = [[0.0, 1.0], [-1.0, 0.0]]
    box = ([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]], [1.0, 1.0, 1.0, 1.0])
    pwa = PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]),
                                                   ([[-1.0, 0.0]], [0.0])), domain=box)
    with pytest.raises(InadmissibleStateError, match=r"x0: .* outside the domain .*row 0"):
        simulate(pwa, [1.5, 0.0], (0.0, 1.0))
    # regions 0 and 2 overlap only far from the origin: (-0.5, -2e6) lies in both
    Z = np.zeros((2, 2))
    with pytest.raises(ModelError, match="regions 0 and 2 overlap"):
        PiecewiseAffineSystem((Z, Z, Z), regions=(([[1.0, 0.0]], [0.0]),
                                                  ([[-1.0, 0.0], [1.0, -1e-6]], [0.0, 1.0]),
                                                  ([[-1.0, 1e-6]], [-1.0])))


def test_block_of_the_step_matrix_that_is_not_positive_is_named():
    from nscontrol.laws.monotone_function import MonotoneFunction
    from nscontrol.laws.normal_cone import Complementarity
    from nscontrol.laws.product import Product

    # triangular D_h whose second (observer) component has H G < 0
    A2, H2 = [[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [1.0, -1.0]]
    big = LureSystem(A2, np.eye(2), H2, Product(Complementarity(1), Relay(1.0)))
    with pytest.raises(ModelError, match=r"not positive definite on law component 1 .*"
                                         r"D_h\[1, 1\] = -0.01 .*triangular"):
        simulate(big, [1.0, 1.0], (0.0, 1.0), h=1e-2)
    # the same structure with a curved law: solved block by block, block 1 is named
    curved = MonotoneFunction(lambda z: z**3, lambda z: 3 * z**2)
    big = LureSystem(A2, np.eye(2), H2, Product(Complementarity(1), curved))
    with pytest.raises(ModelError, match=r"diagonal block 1 .*law components \[1\].*"
                                         r"block triangular"):
        simulate(big, [1.0, 1.0], (0.0, 1.0), h=1e-2)


def test_failed_one_step_solutions_raise_solver_error_with_the_partial_run(monkeypatch):
    from nscontrol.errors import SolverError
    from nscontrol.laws.monotone_function import MonotoneFunction
    from nscontrol.laws.product import Product
    from nscontrol.simulate.implicit_euler import _inclusion, _lure_lcp_kernels

    # Python path: a residual check that nothing can pass
    law = MonotoneFunction(lambda z: z**3, lambda z: 3 * z**2)
    curved = LureSystem([[0.0, 1.0], [-1.0, 0.0]], [[1.0, 0.2], [0.3, 1.0]], np.eye(2),
                        Product(law, law))
    assert simulate(curved, [1.0, 0.5], (0.0, 0.1), h=1e-2).stats["solver"] == "python"
    monkeypatch.setattr(_inclusion, "GRAPH_TOL", -1.0)
    with pytest.raises(SolverError, match="graph residual") as info:
        simulate(curved, [1.0, 0.5], (0.0, 0.1), h=1e-2)
    assert info.value.trajectory.status == -1 and info.value.trajectory.t.size == 1
    monkeypatch.undo()
    # LCP path: a kernel reporting a rejected residual at the fourth step
    real = _lure_lcp_kernels.lcp_steps

    def failing(*args):
        real(*args)
        return 3, 3, 1e-3

    monkeypatch.setattr(_lure_lcp_kernels, "lcp_steps", failing)
    coupled = LureSystem(np.zeros((2, 2)), [[1.0, 0.4], [0.3, 1.0]], np.eye(2),
                         Product(Relay(1.0), Relay(1.0)))
    with pytest.raises(SolverError, match="natural residual 0.001 is above 1e-10") as info:
        simulate(coupled, [1.0, 1.0], (0.0, 0.1), h=1e-2)
    assert info.value.status == "residual"
    part = info.value.trajectory
    assert part.status == -1 and part.t.size == 4          # x0 and the three verified steps
    ret = simulate(coupled, [1.0, 1.0], (0.0, 0.1), h=1e-2, on_failure="return")
    assert ret.status == -1 and ret.t.size == 4

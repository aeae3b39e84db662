"""The switching method's budgets (issue 29: no run can hang): ``max_steps`` (DOP853 steps on
the Filippov, nonlinear and PWA-with-a-function-input paths, periods on the PWM path) and
``min_rel_step`` (the smallest DOP853 step, as a fraction of the span). Spending one raises
``BudgetExceededError`` naming it, with every sample computed before it in
``err.trajectory``."""

import re

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import BudgetExceededError, ModelError, SolverError
from nscontrol.systems.nonlinear import NonlinearSystem
from nscontrol.systems.switched import FilippovSystem, PWMController, SwitchedAffineSystem
from nscontrol.testing import setvalued_problems as sp

EPS = np.finfo(float).eps


def _prefix_of_full_run(part, full):
    """Every sample of ``full`` up to the last time of ``part`` is in ``part``, unchanged: the
    budget stopped the same computation, it did not alter or drop what came before."""
    keep = full.t <= part.t[-1]
    np.testing.assert_array_equal(part.t, full.t[keep])
    np.testing.assert_array_equal(part.x, full.x[keep])


def _relay():
    # sp.relay_feedback's fields as Python callables: the DOP853 path, whose steps are counted
    # (the example itself, given as data, runs in the compiled loop)
    p = sp.relay_feedback(T=2.0)
    A, g, c = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0]), np.ones(2)
    f = FilippovSystem.two_sided(lambda t, x: A @ x + g, lambda t, x: A @ x - g,
                                 lambda x: float(c @ x), 2, gradient=lambda x: c)
    return f, p.x0, p.t_span


def _pwa_function_input():
    p = sp.bimodal_oscillator()
    omega = p.facts["omega"]
    return p.system, p.x0, (0.0, 15.0), {
        "u": lambda t: np.reshape(np.sin(omega * np.asarray(t, float)), (-1, 1))}


def _pwm():
    A = np.array([[0.0, 1.0], [-1.0, -0.5]])
    pwm = SwitchedAffineSystem(((A, [0.0, -1.0]), (A, [0.0, 1.0])),
                               PWMController(0.25, lambda t, x: 0.15))
    return pwm, [0.0, 0.0], (0.0, 25.0)


@pytest.mark.parametrize("case", ["filippov", "nonlinear", "pwa_function_input", "pwm"])
def test_max_steps_spent_raises_with_every_sample_before(case):
    if case == "filippov":
        system, x0, span = _relay()
        opts = {}
    elif case == "nonlinear":
        system = NonlinearSystem(2, lambda t, x: np.array([x[1], -x[0]]))
        x0, span, opts = [1.0, 0.0], (0.0, 20.0), {}
    elif case == "pwa_function_input":
        system, x0, span, opts = _pwa_function_input()
    else:
        system, x0, span = _pwm()
        opts = {}
    full = simulate(system, x0, span, **opts)
    used = full.stats["steps"]
    assert used > 10
    limit = used // 2
    with pytest.raises(BudgetExceededError, match=r"^max_steps: the run spent its") as info:
        simulate(system, x0, span, max_steps=limit, **opts)
    err = info.value
    assert isinstance(err, SolverError) and err.status == "budget"
    assert err.budget == "max_steps" and err.limit == limit and err.used == limit
    assert "raise max_steps" in str(err)
    part = err.trajectory
    assert part.status == -1 and span[0] < part.t[-1] < span[1]
    assert part.stats["steps"] == limit
    _prefix_of_full_run(part, full)


def test_pwm_budget_stops_at_the_period_it_cannot_pay():
    system, x0, span = _pwm()
    with pytest.raises(BudgetExceededError) as info:
        simulate(system, x0, span, max_steps=8, n_samples=101)
    part = info.value.trajectory
    # periods 0..7 were paid for: their two switch instants k T + d/2, k T + T - d/2 each
    # (centred pulse) are all there, and nothing after t_8 = 2.0 was computed
    assert part.t[-1] == 8 * 0.25 and len(part.events_of("switch")) == 2 * 8
    assert part.events[-1].time == 7 * 0.25 + 0.25 - 0.15 / 2


def test_min_rel_step_stops_a_blow_up_before_the_steps_reach_rounding():
    # x' = x^2 from 1 blows up at t = 1; DOP853's steps shrink like the distance to it, so
    # they fall below 1e-12 x the span 2 while 1 - t is still far above the rounding of t
    f = NonlinearSystem(1, lambda t, x: x**2)
    with pytest.raises(BudgetExceededError, match=r"^min_rel_step: DOP853 needed a step") as info:
        simulate(f, [1.0], (0.0, 2.0))
    err = info.value
    assert err.budget == "min_rel_step" and err.limit == 1e-12 and err.used > 0
    stop = _stop_time(err)
    assert 1.0 - 1e-6 < stop < 1.0
    part = err.trajectory
    # every requested sample before the stop is there (t_eval spacing 2e-3: the last is
    # 0.998) and is the closed form 1/(1 - t), to the integrator's tolerance
    assert part.status == -1 and part.t[-1] == pytest.approx(0.998, abs=1e-12)
    early = part.t < 0.9
    np.testing.assert_allclose(part.x[early, 0], 1.0 / (1.0 - part.t[early]), rtol=1e-9)
    # a coarser floor stops the same run earlier, by the same budget
    with pytest.raises(BudgetExceededError) as coarse:
        simulate(f, [1.0], (0.0, 2.0), min_rel_step=1e-6)
    assert coarse.value.budget == "min_rel_step" and _stop_time(coarse.value) < stop


@pytest.mark.parametrize("t0", [0.0, 0.5, 1000.0])
def test_a_piece_starting_at_a_crossing_far_from_t_0_is_no_budget_failure(t0):
    # x' = 2 below x = 0, 3.46 above, from x0 = -1e-3: the crossing at t_c = t0 + 5e-4, then
    # x = 3.46 (t - t_c). The state located at the crossing carries a rounding of about
    # eps |t| |F|; DOP853's own first step from it was 10 ulp(t), below min_rel_step of the
    # span for t0 = 0.5 (the run stopped at t = 0.5005, bug of issue 31)
    f = FilippovSystem.two_sided(lambda t, x: np.array([2.0]), lambda t, x: np.array([3.46]),
                                 lambda x: float(x[0]), 1, gradient=lambda x: np.ones(1))
    tr = simulate(f, [-1e-3], (t0, t0 + 0.15))
    assert [e.kind for e in tr.events] == ["crossing"]
    t_c = t0 + 1e-3 / 2.0
    # a constant field: DOP853 and its dense output are exact up to rounding, the event's root
    # is located to a few eps |t| by scipy's brentq; 100 eps (1 + |t|) covers both, and moves
    # x by |F| = 3.46 times that
    tol = 100.0 * EPS * (1.0 + abs(t0))
    assert abs(tr.events[0].time - t_c) <= tol
    after = tr.t > tr.events[0].time
    np.testing.assert_allclose(tr.x[after, 0], 3.46 * (tr.t[after] - t_c), rtol=0,
                               atol=3.46 * tol + 100.0 * EPS)
    assert tr.t[-1] == t0 + 0.15


def _stop_time(err):
    """The time a budget error's message says the run stopped at."""
    return float(re.search(r"at t = ([0-9.e+-]+)", str(err)).group(1))


@pytest.mark.parametrize("name, value, message", [
    ("max_steps", 0, "max_steps: expected an integer >= 1, got 0"),
    ("max_steps", 2.5, "max_steps: expected an integer >= 1, got 2.5"),
    ("max_steps", True, "max_steps: expected an integer >= 1, got True"),
    ("min_rel_step", 0.0, r"min_rel_step: expected a value in \(0.0, 1.0\), got 0.0"),
    ("min_rel_step", 1.0, r"min_rel_step: expected a value in \(0.0, 1.0\), got 1.0"),
    ("min_rel_step", float("nan"), r"min_rel_step: expected a value in \(0.0, 1.0\), got nan"),
    ("min_rel_step", "1e-9", r"^min_rel_step: "),
])
def test_budget_options_are_checked(name, value, message):
    system, x0, span = _relay()
    with pytest.raises(ModelError, match=message):
        simulate(system, x0, span, **{name: value})

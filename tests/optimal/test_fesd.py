"""Finite elements with switch detection (nscontrol.optimal.fesd) on a drift that speeds up
across a surface (nscontrol.optimal.problems.SpeedUp): the optimal switching time has a
closed form (1/2 here); FESD finds it to the solver's tolerance, a fixed grid misses it by
steps; the plan replayed by the library's event-locating switching integrator."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import DimensionError, ModelError  # noqa: E402
from nscontrol.optimal import SpeedUp, SwitchingProblem  # noqa: E402
from nscontrol.systems import FilippovSystem  # noqa: E402

CASE = SpeedUp()
N = 25


@pytest.fixture(scope="module")
def fesd_plan():
    return CASE.problem(N).solve()


def test_closed_form_switches_at_half_the_horizon():
    assert CASE.switch_time() == pytest.approx(0.5, abs=1e-15)
    assert CASE.cost() == pytest.approx(0.5 + 2 * (np.sqrt(3) - 1.5) ** 2, rel=1e-14)


def test_fesd_switching_time_and_cost_are_exact(fesd_plan):
    # constant fields: implicit Euler is exact on every element, the switch sits on an
    # element boundary; what is left is the polish's constraint tolerance (1e-10) over the
    # O(1) slopes of x, times 100
    (ts,) = fesd_plan.switch_times([1.0], 0.0)
    assert abs(ts - CASE.switch_time()) <= 1e-8
    assert abs(fesd_plan.cost - CASE.cost()) <= 1e-8
    assert fesd_plan.residual <= 1e-8 and fesd_plan.stats["polished"]
    # the inputs: 1 before the switch, 2√3 - 3 after it
    before = fesd_plan.t[:-1] < ts - 1e-9
    assert np.allclose(fesd_plan.u[before, 0], 1.0, atol=1e-7)
    assert np.allclose(fesd_plan.u[~before, 0], 2 * np.sqrt(3) - 3, atol=1e-7)


def test_a_fixed_grid_misses_the_switch_by_steps():
    plan = CASE.problem(N, switch_detection=False).solve()
    (ts,) = plan.switch_times([1.0], 0.0)
    h = CASE.T / N
    # the step that lands on the surface may take the faster field (the set-valued right-hand
    # side there): the grid's optimum moves the switch by whole steps (2.5 h measured)
    assert abs(ts - CASE.switch_time()) >= h / 2
    assert plan.residual <= 1e-8


def test_fesd_plan_replays_through_the_switching_integrator(fesd_plan):
    """Element by element (the input is held on each; a run across an input jump that sits
    within 1e-11 of the crossing makes DOP853 shrink its step below its floor), each run
    starting where the last one ended: the replayed boundary states and crossing instant
    against the plan's. Constant fields: DOP853 at rtol 1e-12 is exact to roundoff, so what
    is left is the plan's constraint tolerance (1e-10) accumulated over 25 elements."""
    plan = fesd_plan
    x, ends, crossings = np.array([-CASE.L]), [], []
    for n in range(len(plan.u)):
        un = float(plan.u[n, 0])
        f = FilippovSystem.two_sided(lambda t, x, un=un: np.array([un + CASE.a1]),
                                     lambda t, x, un=un: np.array([un + CASE.a2]),
                                     lambda x: float(x[0]), 1,
                                     gradient=lambda x: np.array([1.0]))
        # each element on (0, h_n) (autonomous fields): on a span starting at 0.5 the
        # switching integrator stops right after a crossing (BudgetExceededError
        # min_rel_step; reported, left to simulate/switching)
        traj = nsc.simulate(f, x, (0.0, plan.t[n + 1] - plan.t[n]), rtol=1e-12, atol=1e-12)
        crossings += [plan.t[n] + e.time for e in traj.events if e.kind == "crossing"]
        x = traj.x[-1]
        ends.append(x[0])
    assert np.max(np.abs(np.array(ends) - plan.x[1:, 0])) <= 1e-8
    assert len(crossings) <= 1   # located when the next element starts below 0 (by 5e-12 here)
    for tc in crossings:
        assert abs(tc - CASE.switch_time()) <= 1e-8
    replayed = replace(plan, x=np.concatenate([[[-CASE.L]], np.array(ends)[:, None]]))
    (ts,) = replayed.switch_times([1.0], 0.0)
    assert abs(ts - CASE.switch_time()) <= 1e-8


def test_bad_switching_problems_are_refused():
    z = np.zeros((1, 1))
    with pytest.raises(DimensionError, match="^A, b"):
        SwitchingProblem(A=(z,), b=([1.0],), B=[[1.0]], c=[1.0], d=0.0, x0=[-1.0],
                         x_final=[1.0], T=1.0, elements=5)
    with pytest.raises(ModelError, match="^elements"):
        SwitchingProblem(A=(z, z), b=([1.0], [3.0]), B=[[1.0]], c=[1.0], d=0.0, x0=[-1.0],
                         x_final=[1.0], T=1.0, elements=1)
    with pytest.raises(ModelError, match="^a2"):
        SpeedUp(a1=3.0, a2=1.0)


def test_from_rest_bounded_inputs_and_element_bounds():
    """The same closed-form switch from a start at rest (the problem has one optimum: J(s) is
    convex), input bounds that bind (u <= 0.9 < 1, the free optimum's first input) held to
    IPOPT's tolerance, element lengths inside the bounds asked."""
    N2 = 10
    plan = CASE.problem(N2).solve(guess=np.full((N2 + 1, 1), -CASE.L))
    (ts,) = plan.switch_times([1.0], 0.0)
    assert abs(ts - CASE.switch_time()) <= 1e-8
    base = CASE.problem(N2)
    bounded = replace(base, u_max=0.9, element_bounds=(0.5, 1.5)).solve()
    # a relaxed solve's IPOPT relaxes every bound by its bound_relax_factor (1e-8,
    # relative; the polish's 1e-10) and meets the constraints to tol (1e-10): 2e-8 allowed
    assert 0.9 - 1e-6 <= np.max(bounded.u) <= 0.9 + 2e-8
    h = np.diff(bounded.t)
    hbar = CASE.T / N2
    assert np.all(h >= 0.5 * hbar - 2e-8) and np.all(h <= 1.5 * hbar + 2e-8)
    assert bounded.cost > plan.cost          # a binding bound costs
    with pytest.raises(ModelError, match="^element_bounds"):
        replace(base, element_bounds=(1.0, 2.0))


def test_step_equilibration_is_the_engines_option():
    """SwitchingProblem passes its step equilibration to the engine. ``"mean"`` can only
    draw the lengths toward ``T/N`` (an optimum of ``J + ρP`` has ``P`` no larger than at
    the optimum of ``J``, SpeedUp's being unique); ``"delta"`` penalises differences within
    a stage, and each input here has one element: the plan is the unpenalised one, to the
    solver's tolerance (1e-8 on the lengths: IPOPT's tol 1e-10 on a problem whose lengths
    condition the switch time by O(N))."""
    N2 = 10
    base = CASE.problem(N2)
    mean = replace(base, equilibration=1.0)
    assert mean.engine().equilibration == 1.0
    assert mean.engine().equilibration_form == "mean"
    hbar = CASE.T / N2
    spread = [float(np.sum((np.diff(p.solve().t) - hbar) ** 2))
              for p in (base, mean)]
    assert spread[1] <= spread[0] + 1e-12
    assert spread[1] < spread[0]           # the penalty binds: lengths move
    plain, delta = (p.solve() for p in (base, replace(base, equilibration=1.0,
                                                       equilibration_form="delta")))
    assert np.max(np.abs(plain.t - delta.t)) <= 1e-8
    with pytest.raises(ModelError, match="^equilibration_form"):
        replace(base, equilibration_form="exact")
    with pytest.raises(ModelError, match="^equilibration"):
        replace(base, equilibration=-1.0)


def test_cold_homotopy_reaches_the_closed_form():
    """``warm_homotopy=False`` (each relaxed solve from the previous primal point only) is
    the same transcription solved along another path: SpeedUp's optimum is unique (J(s) is
    convex), so it ends on the closed-form switch, to the solver's tolerance as the warm
    path does (1e-8)."""
    base = CASE.problem(10)
    cold = replace(base, warm_homotopy=False)
    assert cold.engine().warm_homotopy is False
    plan = cold.solve()
    (ts,) = plan.switch_times([1.0], 0.0)
    assert abs(ts - CASE.switch_time()) <= 1e-8
    assert plan.cost == pytest.approx(base.solve().cost, rel=1e-8)
    with pytest.raises(ModelError, match="^warm_homotopy"):
        replace(base, warm_homotopy="no")

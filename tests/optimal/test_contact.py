"""Trajectory optimisation through friction (nscontrol.optimal): the pushed block against its
closed forms (nscontrol.optimal.problems), and every plan replayed by the library's own
Moreau–Jean integrator at the same step."""

from __future__ import annotations

import importlib
import sys

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import DimensionError, ModelError  # noqa: E402
from nscontrol.optimal import (  # noqa: E402
    ContactProblem,
    PushedBlock,
    Relaxation,
    ZeroOrderHold,
)

BLOCK = PushedBlock(mass=1.0, mu=0.5, distance=1.0)   # 6 d / T² = 6 > μ g: u*(T) < 0
T, N, U = 1.0, 50, 15.0
#: The polish solves its equalities to IPOPT's constraint tolerance (1e-10, the default
#: Relaxation.tol); a factor 100 covers the pairs' scaling (forces ~10, speeds ~1).
RESIDUAL_TOL = 1e-8


def replay(plan):
    """The plan's inputs through simulate at the plan's step."""
    return nsc.simulate(BLOCK.system(), BLOCK.x0, (0.0, plan.duration), method="moreau_jean",
                        h=plan.h, u=plan.input())


def replay_tol(plan) -> float:
    """Each planned step satisfies the Moreau–Jean step to the constraint tolerance and the
    contact law to the residual; the integrator solves it exactly, so the states part by at
    most N (tol + residual) max(1, h / m) (no growth: the sliding block's step is a
    contraction-free shift), times 10."""
    return 10 * N * (1e-10 + plan.residual) * max(1.0, plan.h / BLOCK.mass)


@pytest.fixture(scope="module")
def effort_plan():
    problem = ContactProblem(BLOCK.system(), BLOCK.x0, N, T / N, x_final=BLOCK.x_final,
                             u_min=-U, u_max=U)
    return problem.solve()


@pytest.fixture(scope="module")
def time_plan():
    problem = ContactProblem(BLOCK.system(), BLOCK.x0, N, 0.01, x_final=BLOCK.x_final,
                             u_min=-U, u_max=U, effort=0.0, minimum_time=True,
                             h_bounds=(1e-3, 0.1))
    return problem.solve()


# ---------------------------------------------------------------------------------------------
# Least effort in fixed time
# ---------------------------------------------------------------------------------------------
def test_least_effort_matches_the_discrete_closed_form(effort_plan):
    J_h = BLOCK.effort_cost_discrete(T, N)
    # a KKT point to IPOPT's 1e-10, multipliers ~|u| ~ 10, ~10 N constraints
    assert abs(effort_plan.cost - J_h) <= 1e-10 * 10 * 10 * N * (1 + J_h)
    h = T / N
    k = np.arange(N)
    w = 12 * BLOCK.mass * BLOCK.distance * ((N - 1) / 2 - k) / (h ** 2 * N * (N ** 2 - 1))
    assert np.max(np.abs(effort_plan.u[:, 0] - (BLOCK.friction_force + w))) <= 1e-6


def test_least_effort_is_second_order_close_to_the_continuous_optimum(effort_plan):
    J, h = BLOCK.effort_cost(T), T / N
    m, d = BLOCK.mass, BLOCK.distance
    # J_h - J = 12 m² d² / (T³ (N² - 1)) <= 24 m² d² h² / T⁵ for N >= 2 (problems.py)
    assert 0.0 < effort_plan.cost - J <= 24 * m ** 2 * d ** 2 * h ** 2 / T ** 5
    # u_k = u*(t_k + h/2) + w(t_k + h/2) / (N² - 1): the same O(h²) bound on the inputs
    t_mid = effort_plan.t[:-1] + h / 2
    gap = np.abs(effort_plan.u[:, 0] - BLOCK.effort_input(t_mid, T))
    assert gap.max() <= 6 * m * d / T ** 2 * 2 * h ** 2 / T ** 2 + 1e-6


def test_halving_the_step_divides_the_excess_cost_by_four(effort_plan):
    coarse = ContactProblem(BLOCK.system(), BLOCK.x0, N // 2, 2 * T / N,
                            x_final=BLOCK.x_final, u_min=-U, u_max=U).solve()
    J = BLOCK.effort_cost(T)
    ratio = (coarse.cost - J) / (effort_plan.cost - J)
    expected = (N ** 2 - 1) / ((N // 2) ** 2 - 1)    # 4.06 for N = 50
    assert abs(ratio - expected) <= 1e-4 * expected


def test_least_effort_plan_is_complementary_and_replays(effort_plan):
    assert effort_plan.residual <= RESIDUAL_TOL
    assert effort_plan.stats["polished"] and effort_plan.stats["active_set_consistent"]
    traj = replay(effort_plan)
    assert traj.t.shape == effort_plan.t.shape
    assert np.max(np.abs(traj.x - effort_plan.x)) <= min(1e-6, replay_tol(effort_plan))
    # the contact impulses too: the floor carries m g h per step, friction μ m g h
    view = effort_plan.trajectory()
    scale = BLOCK.mass * BLOCK.g * effort_plan.h
    assert np.max(np.abs(view.signals["impulse"] - traj.signals["impulse"])) <= 1e-6 * scale
    assert np.max(np.abs(view.signals["friction_impulse"]
                         - traj.signals["friction_impulse"])) <= 1e-6 * scale


# ---------------------------------------------------------------------------------------------
# Least time with a bounded force
# ---------------------------------------------------------------------------------------------
def test_least_time_is_bang_bang_within_the_grid_estimate(time_plan):
    Ts, h, vhat = BLOCK.minimum_time(U), time_plan.h, BLOCK.peak_speed(U)
    # T* <= T*_h <= T* + U h² / (4 m v̂) to first order in the lost distance (problems.py);
    # a factor 1.5 covers the neglected second-order term
    assert Ts - 1e-9 <= time_plan.duration <= Ts + 1.5 * U * h ** 2 / (4 * BLOCK.mass * vhat)
    u = time_plan.u[:, 0]
    inner = np.flatnonzero(np.abs(np.abs(u) - U) > 1e-6)
    assert inner.size <= 1                     # one step holds the mean of push and brake
    assert np.all(u[: inner[0]] >= U - 1e-6) and np.all(u[inner[0] + 1:] <= -U + 1e-6)
    tau = (u[inner[0]] + U) / (2 * U)          # the push's share of that step
    assert abs(time_plan.t[inner[0]] + tau * h - BLOCK.switch_time(U)) <= h


def test_least_time_plan_is_complementary_and_replays(time_plan):
    assert time_plan.residual <= RESIDUAL_TOL
    traj = replay(time_plan)
    assert np.max(np.abs(traj.x - time_plan.x)) <= min(1e-6, replay_tol(time_plan))


# ---------------------------------------------------------------------------------------------
# Pieces
# ---------------------------------------------------------------------------------------------
def test_zero_order_hold_reads_the_step_of_a_rounded_grid_time():
    hold = ZeroOrderHold(0.0, 0.1, np.arange(5.0)[:, None])
    assert [float(hold(0.1 * k)[0]) for k in range(5)] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert float(hold(3 * 0.1)[0]) == 3.0          # 0.30000000000000004
    assert float(hold(0.7)[0]) == 4.0 and float(hold(-1.0)[0]) == 0.0


def test_relaxation_schedule_ends_at_sigma_min():
    assert Relaxation(1e-2, 0.1, 1e-5).sigmas() == pytest.approx([1e-2, 1e-3, 1e-4, 1e-5])


def test_bad_problems_are_refused_naming_the_argument():
    s = BLOCK.system()
    with pytest.raises(ModelError, match="^steps"):
        ContactProblem(s, BLOCK.x0, 0, 0.1)
    with pytest.raises(DimensionError, match="^x_final"):
        ContactProblem(s, BLOCK.x0, 10, 0.1, x_final=[1.0, 0.0])
    with pytest.raises(ModelError, match="^system"):
        ContactProblem(nsc.systems.LagrangianSystem(lambda q: np.eye(1) * (2 + np.cos(q[0])),
                                                    gap_matrix=[[1.0]], gap_offset=[0.0]),
                       [0.0, 0.0], 10, 0.1)
    with pytest.raises(ModelError, match="^h_bounds"):
        ContactProblem(s, BLOCK.x0, 10, 0.1, minimum_time=True, h_bounds=(0.2, 0.3))
    with pytest.raises(ModelError, match="^u_max"):
        ContactProblem(s, BLOCK.x0, 10, 0.1, u_min=1.0, u_max=-1.0)
    with pytest.raises(ModelError, match="^x_final"):
        ContactProblem(s, BLOCK.x0, 10, 0.1, x_final=["1.0", 0.0, 0.0, 0.0])
    with pytest.raises(ModelError, match="^factor"):
        Relaxation(factor=1.5)
    with pytest.raises(ModelError, match="^settle_fraction"):
        Relaxation(settle_fraction=1.5)
    with pytest.raises(ModelError, match="^relaxation"):
        ContactProblem(s, BLOCK.x0, 10, 0.1).solve(relaxation=1e-3)


def test_without_casadi_the_import_names_the_extra(monkeypatch):
    for name in [m for m in sys.modules if m.startswith("nscontrol.optimal")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "casadi", None)   # `import casadi` raises ImportError
    with pytest.raises(ImportError, match=r"pip install 'nscontrol\[optimal\]'"):
        importlib.import_module("nscontrol.optimal")


# ---------------------------------------------------------------------------------------------
# A contact that closes along the plan (the active sets change)
# ---------------------------------------------------------------------------------------------
def test_a_landing_plan_from_a_simulated_guess_replays_through_the_impact():
    from nscontrol.errors import SolverError
    from nscontrol.systems import LagrangianSystem

    ball = LagrangianSystem([[1.0]], constant_force=[-9.81], gap_matrix=[[1.0]],
                            gap_offset=[0.0], actuation=[[1.0]])
    steps, h, x0 = 60, 0.01, [0.5, 0.0]
    problem = ContactProblem(ball, x0, steps, h, x_final=[0.0, 0.0], u_min=-5.0, u_max=5.0)
    # the straight line never closes the floor before the last step: no force can stop the
    # fall, and the failure says so instead of returning a penetrating plan
    with pytest.raises(SolverError, match="IPOPT failed"):
        problem.solve()
    free = nsc.simulate(ball, x0, (0.0, steps * h), method="moreau_jean", h=h)
    plan = problem.solve(guess=free)
    closed = plan.active[:, 0]
    assert plan.stats["active_set_consistent"] and not closed[0] and closed[-1]
    assert np.all(np.diff(closed.astype(int)) >= 0)        # lands once, stays
    assert plan.residual <= RESIDUAL_TOL
    traj = nsc.simulate(ball, x0, (0.0, plan.duration), method="moreau_jean", h=h,
                        u=plan.input())
    assert np.max(np.abs(traj.x - plan.x)) <= 1e-6

"""The simple car (nscontrol.optimal.problems.SimpleCar, nosnoc's ``simple_car_algebraic``):
its closed form against the library's switching integrator, and its FESD plan (nosnoc's
grid: 30 stages of 2 elements, from rest along σ from 1, as the peer bench) against the
physics: the replay through ``simulate``, the terminal condition, the crossings of
``v = 15`` against the closed form's, and the discrete Pontryagin structure of the input."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import ModelError  # noqa: E402
from nscontrol.optimal import Relaxation, SimpleCar  # noqa: E402
from nscontrol.systems import FilippovSystem  # noqa: E402

CAR = SimpleCar()
N, NFE = 30, 2
# DOP853 at rtol = atol = RTOL over a few hundred steps: global error <= steps x RTOL x |x|
# (|q| <= 500), 1e3 x 1e-10 x 500 = 5e-5.
RTOL = 1e-10
REPLAY = 1e3 * RTOL * CAR.distance
# The polish meets the constraints and stationarity to IPOPT's tol (1e-10) on O(1-500)
# entries: states and inputs within 1e-10 x 500 x 100.
EXACT = 5e-6


def car(u):
    """The car with the input ``u(t)`` (callable), as a Filippov system on ``v = v_s``."""
    def field(k):
        return lambda t, x: np.array([x[1], k * float(u(t))])

    return FilippovSystem.two_sided(field(CAR.k1), field(CAR.k2),
                                    lambda x: x[1] - CAR.v_switch, 2,
                                    gradient=lambda x: np.array([0.0, 1.0]))


@pytest.fixture(scope="module")
def plan():
    problem = CAR.problem(N, NFE)
    return problem.solve(Relaxation(sigma0=1.0), guess=np.tile(problem.x0, (N * NFE + 1, 1)))


def test_closed_form_reaches_the_target_at_its_cost():
    """``u*`` through the switching integrator ends at rest at ``d`` and crosses ``v_s`` at
    ``τ`` and ``T - τ``; its ``∫ u²`` (Simpson on 3001 points per piece: exact on the
    quadratic ``u*²`` of each piece, to roundoff) is ``J*``; ``|u|`` continuous at
    ``τ`` and the slopes in the ratio ``k₁ : k₂``."""
    tau, tau2 = CAR.switch_times()
    assert tau2 == pytest.approx(CAR.T - tau, abs=1e-12)
    assert 0.0 < tau < CAR.T / 2
    traj = nsc.simulate(car(CAR.input), [0.0, 0.0], (0.0, CAR.T), rtol=RTOL, atol=RTOL)
    assert np.max(np.abs(traj.x[-1] - [CAR.distance, 0.0])) <= REPLAY
    # located crossings: v's error (1e3 x RTOL x 25, v <= 25) over |v'| there (>= k₂ u(τ))
    crossings = [e.time for e in traj.events if e.kind == "crossing"]
    assert np.allclose(crossings, [tau, tau2], rtol=0.0,
                       atol=1e3 * RTOL * 25.0 / (CAR.k2 * CAR.input(tau)))
    from scipy.integrate import simpson

    pieces = (0.0, tau, CAR.T / 2, tau2, CAR.T)
    grids = [np.linspace(a, b, 3001) for a, b in zip(pieces[:-1], pieces[1:], strict=True)]
    J = sum(simpson(CAR.input(t) ** 2, x=t) for t in grids)
    assert J == pytest.approx(CAR.cost(), rel=1e-12)
    # continuous at τ (2ε times the slopes, <= 0.1), affine on each side: differences over
    # 1e-3 exact to roundoff (1e-16 / 1e-3 on slopes of 0.05-0.08)
    eps, d = 1e-9, 1e-3
    assert CAR.input(tau - eps) == pytest.approx(CAR.input(tau + eps), abs=1e-9)
    slope1 = (CAR.input(tau - d) - CAR.input(tau - 2 * d)) / d
    slope2 = (CAR.input(tau + 2 * d) - CAR.input(tau + d)) / d
    assert slope1 / slope2 == pytest.approx(CAR.k1 / CAR.k2, rel=1e-10)
    assert np.max(np.abs(CAR.input(np.linspace(0, CAR.T, 301)))) < CAR.u_max


def test_plan_meets_the_terminal_condition_and_the_homotopy_end(plan):
    assert np.max(np.abs(plan.x[-1] - [CAR.distance, 0.0])) <= EXACT
    assert np.max(np.abs(plan.x[0])) <= EXACT
    assert plan.residual <= 1e-8 and plan.stats["polished"]
    assert np.max(np.abs(plan.u)) <= CAR.u_max


def test_plan_replays_through_simulate_within_implicit_eulers_error(plan):
    """Stage by stage (the input held), from the replay's own state: ``v`` is exact (a
    constant acceleration on each element, the mode switching on an element boundary) and
    implicit Euler's ``q_{k+1} = q_k + h_k v_{k+1}`` overshoots the exact ``q`` by
    ``h_k Δv_k / 2`` per element: ``q_plan - q_replay`` is that sum, to the replay's
    tolerance."""
    x = np.zeros(2)
    H, dv = np.diff(plan.t), np.diff(plan.x[:, 1])
    for s in range(N):
        us = plan.u[s, 0]
        traj = nsc.simulate(car(lambda t, us=us: us), x, (0.0, plan.t_stages[s + 1]
                                                          - plan.t_stages[s]),
                            rtol=RTOL, atol=RTOL)
        x = traj.x[-1]
        k = (s + 1) * NFE
        assert abs(x[1] - plan.x[k, 1]) <= REPLAY + EXACT
        ie = 0.5 * float(np.sum(H[:k] * dv[:k]))
        assert abs(plan.x[k, 0] - x[0] - ie) <= REPLAY + EXACT
    # the end: the replay stops short of the target by the accumulated overshoot, at most
    # h_max / 2 times the total variation of v
    assert abs(x[0] - CAR.distance) <= 0.5 * H.max() * np.sum(np.abs(dv)) + REPLAY


def test_plan_crosses_within_a_control_stage_of_the_closed_form(plan):
    """The held input is the continuous one to first order in the stage length ``T / N``,
    and the crossing moves with it: each of the two crossings within one stage."""
    crossings = plan.crossings(lambda x: x[1] - CAR.v_switch)
    assert crossings.shape == (2,)
    assert np.max(np.abs(crossings - CAR.switch_times())) <= CAR.T / N
    # FESD puts each crossing on an element boundary
    assert np.min(np.abs(plan.t[:, None] - crossings[None, :]), axis=0).max() <= 1e-9


def test_plan_input_has_the_discrete_pontryagin_structure(plan):
    """Away from the crossings ``u`` steps by ``k p_q (T/N) / 2`` per stage (the module
    docstring): on runs of stages wholly in one mode with equal elements, second
    differences vanish and the steps of the two modes are in the ratio ``k₁ : k₂``, to the
    polish's tolerance (1e-10 on ``u`` of size 1, times 100)."""
    mode = np.argmax(plan.theta, axis=1).reshape(N, NFE)
    H = np.diff(plan.t).reshape(N, NFE)
    clean = (mode == mode[:, :1]).all(axis=1) & (np.abs(H - H[:, :1]) <= 1e-9).all(axis=1)
    u = plan.u[:, 0]
    steps = {0: [], 1: []}
    for s in range(1, N - 1):
        if clean[s - 1:s + 2].all() and len(set(mode[s - 1:s + 2, 0])) == 1:
            assert abs(u[s + 1] - 2 * u[s] + u[s - 1]) <= 1e-8
            steps[int(mode[s, 0])].append(u[s + 1] - u[s])
    assert len(steps[0]) >= 3 and len(steps[1]) >= 3
    assert np.mean(steps[0]) / np.mean(steps[1]) == pytest.approx(CAR.k1 / CAR.k2, rel=1e-6)


def test_centred_start_reaches_the_same_plan(plan):
    """nosnoc's centred start of the algebraic variables (``start="centred"``) leaves the
    first relaxation to choose the regions; on the car it ends on the same optimum (each
    plan's objective to the polish's stationarity, 1e-10 on an objective of 6, times 100)
    and the same crossings (on the same element boundaries)."""
    problem = CAR.problem(N, NFE, start="centred")
    centred = problem.solve(Relaxation(sigma0=1.0),
                            guess=np.tile(problem.x0, (N * NFE + 1, 1)))
    assert centred.objective == pytest.approx(plan.objective, abs=1e-8)
    assert np.allclose(centred.crossings(lambda x: x[1] - CAR.v_switch),
                       plan.crossings(lambda x: x[1] - CAR.v_switch), atol=1e-6)
    assert centred.residual <= 1e-8


def test_bad_cars_are_refused_with_specific_errors():
    with pytest.raises(ModelError, match="^distance"):
        SimpleCar(distance=400.0)
    with pytest.raises(ModelError, match="^u_max"):
        SimpleCar(u_max=0.5).switch_times()
    with pytest.raises(ModelError, match="^start"):
        CAR.problem(start="middle")

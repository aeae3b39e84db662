"""Budgets of the event-driven and exact PWA loops: spending one raises BudgetExceededError
naming the option, with the computed part; a budget that cannot be spent says why."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import BudgetExceededError
from nscontrol.systems import LagrangianSystem
from nscontrol.systems.hybrid import LinearHybridSystem

EPS = np.finfo(float).eps


def test_an_elastic_ball_spends_its_event_budget_with_the_part_computed():
    ball = LagrangianSystem.bouncing_ball(restitution=1.0)
    with pytest.raises(BudgetExceededError, match=r"^max_events: .* raise max_events") as info:
        nsc.simulate(ball, [1.0, 0.0], (0.0, 100.0), max_events=20, progress=False)
    err = info.value
    assert (err.budget, err.limit, err.used) == ("max_events", 20, 21)
    part = err.trajectory
    assert part.status == -1 and len(part.events_of("impact")) == 20
    t1 = np.sqrt(2.0 / 9.81)            # the 21st impact, where the budget ran out
    assert part.t[-1] == pytest.approx(41 * t1, rel=1e-12)


def test_every_event_spends_the_budget_a_touch_too():
    """A guard that only touches zero, once per turn of a rotation: before, touches were not
    counted and a run of touches had no budget at all."""
    A = np.array([[0.0, 1.0], [-1.0, 0.0]])              # x = (sin t, cos t)
    circle = LinearHybridSystem(A, [[-1.0, 0.0]], [1.0], lambda t, x, idx: x)  # x_1 <= 1
    traj = nsc.simulate(circle, [0.0, 1.0], (0.0, 100.0), progress=False)
    touches = traj.events
    assert len(touches) == 16                            # π/2 + 2πk <= 100
    np.testing.assert_allclose([e.time for e in touches], np.pi / 2 + 2 * np.pi * np.arange(16),
                               rtol=0, atol=1e-6)        # a touch: located to sqrt(tol)
    with pytest.raises(BudgetExceededError, match="^max_events") as info:
        nsc.simulate(circle, [0.0, 1.0], (0.0, 100.0), max_events=3, progress=False)
    assert info.value.budget == "max_events" and len(info.value.trajectory.events) == 3


def test_a_pwa_run_spends_its_event_budget_with_the_part_computed():
    from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    from nscontrol.numerics.lti import Exosystem

    system = one_sided_oscillator(0.1, u=Exosystem.sinusoid(1.0, 1.42))
    with pytest.raises(BudgetExceededError, match="^max_events") as info:
        nsc.simulate(system, [0.0, 0.0], (0.0, 100.0), method="switching", max_events=7,
                     progress=False)
    err = info.value
    assert (err.budget, err.limit, err.used) == ("max_events", 7, 8)
    assert err.trajectory.status == -1 and len(err.trajectory.events) == 8


def _poly(roots_mult):
    p = np.poly1d([1.0])
    for r, k in roots_mult:
        for _ in range(k):
            p = p * np.poly1d([-1.0, r])
    a = p.coeffs[::-1].astype(float).copy()
    return a if np.polyval(p, 0.0) > 0 else -a


@pytest.mark.parametrize("a", [
    _poly([(0.3, 1)]), _poly([(0.9, 1), (1.5, 2)]), _poly([(0.3, 5)]), _poly([(0.3, 9)]),
    _poly([(0.7, 7)]), _poly([(1e-3, 3)]), np.array([1e-30, 0.0, 0.0, -1.0]),
    np.array([1e-20, -1e-10, 0, 0, 0, 0, 0, 0, 0, -1.0]),
], ids=["simple", "near-double", "5-fold", "9-fold", "7-fold", "small-3-fold", "cube-1e-30",
        "flat-degree-9"])
def test_the_root_refinement_cannot_spend_its_budget(a):
    """The bracket halves at least every two iterations (an iterate that did not halve it is
    followed by the midpoint) and the refinement stops at a bracket of
    ``4 eps max(|hi|, 2^-20)``: at most 2·(70 + 1) iterations from the cell [0, 1], below
    the budget — so the loop ends by its own criterion, never by the budget."""
    from nscontrol.numerics._lti_kernels import ROOT_BUDGET, _horner, root_iterations

    m = a.size
    f0, f1 = _horner(a, m, 0.0), _horner(a, m, 1.0)
    assert f0 > 0.0 >= f1
    x, iterations = root_iterations(a, m, 0.0, 1.0, f0, f1)
    assert iterations <= 2 * (70 + 1) < ROOT_BUDGET
    assert 0.0 <= x <= 1.0
    if np.count_nonzero(np.isclose(np.roots(a[::-1]), x, rtol=1e-3)) <= 1:   # simple root
        assert abs(_horner(a, m, x)) <= 64 * EPS * np.sum(np.abs(a))

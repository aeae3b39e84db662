"""One conformance loop: every integrator over every known-answer problem of
:mod:`nscontrol.testing` that it declares it integrates (``Integrator.supports``).

Tolerances by what the method declares:

* ``exact_flow`` methods (matrix exponentials, events located on the exact solution, or
  DOP853 at rtol 1e-11 where a field is nonlinear): the problem's scale times a roundoff or
  solver-tolerance factor stated per problem;
* ``time_stepping`` methods (first order): the global error of a first-order scheme,
  ``h (T max|x''| / 2 + max|x'|)`` — the local error ``h² |x''| / 2`` summed over ``T / h``
  steps of a non-expanding flow, plus one step of the velocity at each kink — with the
  derivatives measured on the exact solution; and the error must halve (order >= 0.8) when
  ``h`` halves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.simulate import METHODS
from nscontrol.systems.closed_loop import ClosedLoop
from nscontrol.testing.mechanics_problems import BouncingBall, NewtonsCradle, RestingStack
from nscontrol.testing.setvalued_problems import (
    diode_circuit,
    relay_feedback,
    relay_scalar,
)

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(float).eps
H = {"moreau_jean": 1e-3, "implicit_euler": 2e-3}


@dataclass(frozen=True)
class Case:
    name: str
    system: Any
    x0: Any
    t_span: tuple[float, float]
    exact: Any = None               # t -> x (time-major)
    check: Any = None               # (traj, method, h) -> None, for mechanics


def _set_valued_cases() -> list[Case]:
    cases = []
    for p in (relay_scalar(), relay_feedback(), diode_circuit()):
        for variant, system in (("lure", p.system), ("filippov", p.switched)):
            if system is not None:
                cases.append(Case(f"{p.name}/{variant}", system, p.x0, p.t_span,
                                  exact=p.facts["exact"]))
    return cases


def _check_ball(traj, method, h):
    ball = BouncingBall()
    t_exact = ball.impact_times(5)
    t_run = traj.event_times("impact")[:5]
    assert t_run.size == 5
    if method == "event_driven":
        # roots of exact parabolas: a few ulps of t, times the number of flights
        np.testing.assert_allclose(t_run, t_exact, rtol=0, atol=100 * EPS * 5 * t_exact[-1])
    else:
        # event capturing: each impact is caught within the step that contains it, and the
        # O(h) velocity error of every earlier rebound shifts the next flight by O(h)
        k = np.arange(1, 6)
        assert np.all(np.abs(t_run - t_exact) <= 2 * k * h), (t_run - t_exact) / h


def _check_cradle(traj, method, h):
    cradle = NewtonsCradle(5)
    v = traj.x[:, cradle.n:]
    momentum = v.sum(axis=1) * cradle.mass
    # momentum is conserved exactly by Newton's law with equal masses: roundoff per impact
    np.testing.assert_allclose(momentum, cradle.velocity * cradle.mass, rtol=0,
                               atol=100 * EPS * cradle.n)
    np.testing.assert_allclose(v[-1, -1], cradle.velocity, rtol=0, atol=100 * EPS)
    t_run = traj.event_times("impact")
    exact = cradle.impact_times()
    tol = 100 * EPS * exact[-1] if method == "event_driven" else h   # within the step
    np.testing.assert_allclose(t_run[:exact.size], exact, rtol=0, atol=tol)


def _check_stack(traj, method, h):
    stack = RestingStack(4)
    # the stack is at rest: positions stay put to roundoff (in every method)
    drift = np.max(np.abs(traj.x - stack.x0))
    assert drift <= 1e3 * EPS * max(1.0, float(np.max(np.abs(stack.x0)))), drift
    if method == "moreau_jean":
        impulses = traj.signal("impulse")[-1]
        np.testing.assert_allclose(impulses, stack.impulses(h), rtol=100 * EPS * stack.n)


def _mechanics_cases() -> list[Case]:
    ball, cradle, stack = BouncingBall(), NewtonsCradle(5), RestingStack(4)
    return [Case("bouncing-ball", ball.system(), ball.x0, (0.0, 4.0), check=_check_ball),
            Case("newtons-cradle", cradle.system(), cradle.x0, (0.0, 1.2 * cradle.final_time),
                 check=_check_cradle),
            Case("resting-stack", stack.system(), stack.x0, (0.0, 0.5), check=_check_stack)]


def _check_smc(traj, method, h):
    # implicit first-order sliding mode on x'' = u, s = x + x' (alpha = 1): the known answer
    # s_k = s_0 - k alpha cG until |s_k| <= alpha cG, then s = 0 exactly (to rounding)
    cG = 1e-3 + 1e-3 ** 2 / 2          # c Γ of the double integrator at T = 1e-3
    s = traj.signal("s")
    k = np.arange(s.size)
    k_reach = math.ceil(1.0 / cG)
    assert traj.stats["steps"] == 2000
    # each tick rounds c x and Φ x (a few eps of |x| <= 1): the error grows at most linearly
    assert np.all(np.abs(s[:k_reach] - (1.0 - k[:k_reach] * cG)) <= 4 * EPS * (k[:k_reach] + 1))
    assert np.all(np.abs(s[k_reach:]) <= 4 * EPS)


def _sampled_cases() -> list[Case]:
    from nscontrol.design import FirstOrderSMC
    from nscontrol.systems import SlidingModePlant

    plant = SlidingModePlant.double_integrator()
    return [Case("sampled-first-order-smc",
                 nsc.closed_loop(plant, FirstOrderSMC(plant, 1.0, 1e-3)), [1.0, 0.0],
                 (0.0, 2.0), check=_check_smc)]


CASES = _set_valued_cases() + _mechanics_cases() + _sampled_cases()


def _runs(system: Any, name: str) -> bool:
    """Whether method ``name`` runs ``system``: a closed loop is lowered (never handed to a
    method as it is) for its own method, any other system as the method supports it."""
    if isinstance(system, ClosedLoop):
        return name == system.default_method
    return bool(METHODS[name].supports(system))


PAIRS = [(case, name) for case in CASES for name in METHODS if _runs(case.system, name)]


def test_every_problem_is_run_by_some_method_and_every_method_runs_some_problem():
    assert {c.name for c, _ in PAIRS} == {c.name for c in CASES}
    assert {m for _, m in PAIRS} == set(METHODS)


def _options(method: str, h: float | None) -> dict[str, Any]:
    return {} if h is None else {"h": h}


def _first_order_bound(exact, t_span, h):
    t = np.linspace(*t_span, 20001)
    x = np.asarray(exact(t), float).reshape(t.size, -1)
    dt = t[1] - t[0]
    xdot = np.diff(x, axis=0) / dt
    xddot = np.diff(xdot, axis=0) / dt
    # kinks (switchings) show as isolated spikes of x'': the smooth part's max is a high
    # quantile, the kinks' share is one step of |x'| each
    smooth = np.quantile(np.abs(xddot), 0.999)
    T = t_span[1] - t_span[0]
    return h * (T * smooth / 2 + np.max(np.abs(xdot))) + 1e3 * EPS


@pytest.mark.parametrize("case, method", PAIRS, ids=[f"{c.name}-{m}" for c, m in PAIRS])
def test_conformance(case, method):
    cls = METHODS[method]
    h = H.get(method) if "time_stepping" in cls.capabilities else None
    traj = nsc.simulate(case.system, case.x0, case.t_span, method=method,
                        **_options(method, h))
    assert traj.status == 0 and traj.t[-1] == pytest.approx(case.t_span[1], abs=1e-12)
    if case.check is not None:
        case.check(traj, method, h)
        return
    err = np.max(np.abs(traj.x - np.asarray(case.exact(traj.t)).reshape(traj.x.shape)))
    if h is None:
        # events located to ~1e-12 and DOP853 at rtol 1e-11: 1e-8 leaves two decades for the
        # error carried along the span (contracting or sliding flows)
        assert err <= 1e-8, err
        return
    assert err <= _first_order_bound(case.exact, case.t_span, h), err
    half = nsc.simulate(case.system, case.x0, case.t_span, method=method,
                        **_options(method, h / 2))
    err_half = np.max(np.abs(half.x - np.asarray(case.exact(half.t)).reshape(half.x.shape)))
    if err > 1e6 * EPS:      # above roundoff: the error must shrink at first order
        assert err / err_half >= 2 ** 0.8, (err, err_half)

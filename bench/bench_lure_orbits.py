"""Sensitivities of the discrete Lur'e map and of PWM runs, and what they buy for orbits.

Scenarios
---------
* ``lure_sensitivity_closed_form`` — one forcing period (2000 steps) of a forced oscillator
  with a relay (closed-form steps) with ``sensitivity=True``; reference: the same run
  without. The ratio (< 1) is the price of the exact discrete Jacobian.
* ``lure_sensitivity_lcp`` — the same with a saturation (one LCP a step).
* ``pwm_sensitivity`` — 200 periods of a PWM buck converter with a proportional duty law,
  with and without ``sensitivity=True``.
* ``lure_orbit_newton`` — the period-1 orbit of the saturated oscillator under implicit
  Euler (800 steps a period) by ``find_orbit`` (exact discrete Jacobian); reference: the same
  Newton iteration with a central-difference Jacobian of the map (2n more runs an iteration).
  Accuracy: the distance between the two fixed points and the iteration counts.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import time_per_call

from nscontrol import simulate
from nscontrol.analysis.orbits import Forced, find_orbit, stroboscopic_map
from nscontrol.laws.monotone_function import PiecewiseLinearFunction
from nscontrol.laws.relay import Relay
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.switched import PWMController, SwitchedAffineSystem

OMEGA = 1.5
PERIOD = 2 * np.pi / OMEGA
A = np.array([[0.0, 1.0], [-1.0, -0.2]])
E2 = np.array([0.0, 1.0])


def _oscillator(law: Any) -> LureSystem:
    return LureSystem(A, E2[:, None], np.array([[1.0, 0.0]]), law, B=E2[:, None],
                      u=Exosystem.sinusoid(3.0, OMEGA))


def _overhead(name: str, system: Any, x0: np.ndarray, t_span: tuple[float, float],
              steps: int, budget: float, **options: Any) -> dict[str, Any]:
    def plain() -> Any:
        return simulate(system, x0, t_span, **options)

    def with_jacobian() -> Any:
        return simulate(system, x0, t_span, sensitivity=True, **options)

    ours = time_per_call(with_jacobian, budget=budget)
    ref = time_per_call(plain, budget=budget)
    same = float(np.max(np.abs(plain().x[-1] - with_jacobian().x[-1])))
    return {"scenario": name, "size": steps, "ours_steps_per_s": steps / ours,
            "reference": "same run without sensitivity", "reference_steps_per_s": steps / ref,
            "ratio": ref / ours, "accuracy": {"final_state_difference": same}}


def _fd_newton(forced: Forced, x: np.ndarray, tol: float = 1e-11) -> tuple[np.ndarray, int]:
    """Newton on ``P(x) = x`` with a central-difference Jacobian (step 1e-6 (1 + |x_i|))."""
    for it in range(30):
        r = stroboscopic_map(forced, x).x - x
        if np.max(np.abs(r)) <= tol * max(1.0, float(np.max(np.abs(x)))):
            return x, it
        cols = []
        for i in range(x.shape[0]):
            d = 1e-6 * (1.0 + abs(x[i]))
            e = np.zeros_like(x)
            e[i] = d
            cols.append((_map(forced, x + e) - _map(forced, x - e)) / (2 * d))
        x = x + np.linalg.solve(np.column_stack(cols) - np.eye(x.shape[0]), -r)
    return x, 30


def _map(forced: Forced, x: np.ndarray) -> np.ndarray:
    return forced.simulate(x, (0.0, forced.period)).x[-1]


def _orbit_newton(quick: bool) -> dict[str, Any]:
    n = 200 if quick else 800
    forced = Forced(_oscillator(PiecewiseLinearFunction.saturation(1.0, 4.0)), None, PERIOD,
                    method="implicit_euler", options=(("h", PERIOD / n),))
    guess = np.array([-1.0, -4.5])
    find_orbit(forced, guess)   # warm-up (compilation)
    t0 = time.perf_counter()
    orbit = find_orbit(forced, guess, tol=1e-11)
    ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    x_fd, it_fd = _fd_newton(forced, guess)
    ref = time.perf_counter() - t0
    return {"scenario": "lure_orbit_newton", "size": n, "ours_s_per_solve": ours,
            "reference": "Newton with a central-difference Jacobian",
            "reference_s_per_solve": ref, "ratio": ref / ours,
            "accuracy": {"fixed_point_difference": float(np.max(np.abs(orbit.x0 - x_fd))),
                         "iterations": orbit.iterations, "reference_iterations": it_fd}}


def _buck() -> SwitchedAffineSystem:
    Ab = np.array([[0.0, -1.0], [1.0, -0.5]])
    return SwitchedAffineSystem(((Ab, [0.0, 0.0]), (Ab, [1.0, 0.0])),
                                PWMController(0.5, _proportional_duty, pattern="centered"))


def _proportional_duty(t: float, x: np.ndarray) -> float:
    return 0.5 * (0.5 - 0.3 * x[0] - 0.8 * (x[1] - 0.4))


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    budget = 0.3 if quick else 2.0
    n = 400 if quick else 2000
    h = PERIOD / n
    x0 = np.array([0.3, -0.2])
    yield _overhead("lure_sensitivity_closed_form", _oscillator(Relay(1.0)), x0,
                    (0.0, PERIOD), n, budget, method="implicit_euler", h=h)
    yield _overhead("lure_sensitivity_lcp", _oscillator(PiecewiseLinearFunction.saturation(
        1.0, 4.0)), x0, (0.0, PERIOD), n, budget, method="implicit_euler", h=h)
    periods = 40 if quick else 200
    yield _overhead("pwm_sensitivity", _buck(), np.array([0.3, 0.35]), (0.0, 0.5 * periods),
                    periods, budget, n_samples=2)
    yield _orbit_newton(quick)

"""Periodic orbits of nonlinear mechanics: the event-driven state transition (DOP853 with the
variational equation and Newton-impact saltation) against differences of the flow.

Scenarios
---------
* ``nlmech_map_transition`` — one period of the forced impacting pendulum
  (:class:`~nscontrol.testing.mechanics_problems.ImpactingPendulum`, one impact) with
  ``sensitivity=True``; reference: the Jacobian by fourth-order central differences of the
  flow (``8`` plain runs, the cheapest way to the same 1e-10 accuracy without a variational
  equation). Ratio > 1: the variational run is faster. Accuracy: the largest difference of
  the two Jacobians, and the cost of the transition relative to one plain run.
* ``nlmech_orbit_and_branch`` — ``find_orbit`` from the stored guess moved by ``1e-2`` and
  ``continue_orbit`` over 3 steps in the forcing: times, Newton and corrector iterations,
  the determinant of the monodromy against its closed form ``e² e^{-cT}``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from nscontrol import simulate
from nscontrol.analysis.continuation import continue_orbit
from nscontrol.analysis.orbits import find_orbit
from nscontrol.numerics.differences import central_difference_jacobian
from nscontrol.testing.mechanics_problems import ImpactingPendulum

OPTIONS = dict(rtol=1e-10, atol=1e-12, progress=False)


class _InForcing:
    """``a -> Forced`` of the pendulum at forcing ``a``."""

    def __init__(self, base: ImpactingPendulum) -> None:
        self.base = base

    def __call__(self, a: float):  # noqa: ANN204 - a bench helper
        return self.base.with_(forcing=float(a)).forced(**OPTIONS)


def _best_of(k: int, fn) -> tuple[float, object]:  # noqa: ANN001
    best, out = np.inf, None
    for _ in range(k):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run(quick: bool = False) -> Iterator[dict]:
    p = ImpactingPendulum()
    s, x0, T = p.system(), np.array(p.x_guess), p.period
    repeats = 2 if quick else 5

    def end(x: np.ndarray) -> np.ndarray:
        return simulate(s, x, (0.0, T), dt=T, **OPTIONS).x[-1]

    end(x0)                                                     # warm imports and caches
    t_plain, _ = _best_of(repeats, lambda: end(x0))
    t_sens, tr = _best_of(repeats, lambda: simulate(s, x0, (0.0, T), dt=T, sensitivity=True,
                                                    **OPTIONS))
    t_fd, fd = _best_of(repeats, lambda: central_difference_jacobian(end, x0, order=4))
    Phi = tr.stats["state_transition"]
    yield {"scenario": "nlmech_map_transition", "size": 2, "ours_s_per_solve": t_sens,
           "reference": "fourth-order differences of the flow (8 runs)",
           "reference_s_per_solve": t_fd, "ratio": t_fd / t_sens,
           "accuracy": {"max_jacobian_difference": float(np.max(np.abs(Phi - fd))),
                        "transition_cost_in_plain_runs": t_sens / t_plain}}

    t0 = time.perf_counter()
    orb = find_orbit(p.forced(**OPTIONS), x0 + 1e-2)
    t_orbit = time.perf_counter() - t0
    t0 = time.perf_counter()
    br = continue_orbit(_InForcing(p), p.forcing, orb.x0, p_range=(0.5, 0.7), step=0.02,
                        max_steps=3)
    t_branch = time.perf_counter() - t0
    det = np.prod(br.multipliers, axis=1).real
    yield {"scenario": "nlmech_orbit_and_branch", "size": br.n_steps,
           "ours_s_per_solve": t_orbit + t_branch, "reference": None,
           "reference_s_per_solve": None, "ratio": None,
           "accuracy": {"find_orbit_s": t_orbit, "newton_iterations": orb.iterations,
                        "continuation_s": t_branch, "corrector_iterations":
                        br.corrector_iterations, "forcing_reached": float(br.p[-1]),
                        "det_relative_error": float(np.max(np.abs(
                            det / p.monodromy_determinant() - 1.0)))}}

"""Trajectory optimisation speed (nscontrol.optimal): the problems with closed forms, each
solved three times; the median wall time of ``solve()`` (transcription built, every IPOPT
solve of the homotopy and the polish) and of IPOPT's solves alone, with the error against the
closed form. No reference yet: nosnoc, the peer of the issue, is not installed here (its
comparison is a later slice).

Run: ``nscontrol bench optimal --json`` (``--quick``: one solve each).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it in
# sys.modules.
import statistics
import time
from collections.abc import Callable, Iterator
from typing import Any

from nscontrol.optimal import ContactProblem, PushedBlock, SpeedUp

BLOCK, U, T, N = PushedBlock(), 15.0, 1.0, 50


def _effort() -> tuple[Any, dict]:
    plan = ContactProblem(BLOCK.system(), BLOCK.x0, N, T / N, x_final=BLOCK.x_final,
                          u_min=-U, u_max=U).solve()
    return plan, {"cost_error": abs(plan.cost - BLOCK.effort_cost_discrete(T, N))}


def _time() -> tuple[Any, dict]:
    plan = ContactProblem(BLOCK.system(), BLOCK.x0, N, 0.01, x_final=BLOCK.x_final,
                          u_min=-U, u_max=U, effort=0.0, minimum_time=True,
                          h_bounds=(1e-3, 0.1)).solve()
    return plan, {"time_excess": plan.duration - BLOCK.minimum_time(U)}


def _fesd(detect: bool) -> Callable[[], tuple[Any, dict]]:
    def solve() -> tuple[Any, dict]:
        case = SpeedUp()
        plan = case.problem(25, switch_detection=detect).solve()
        (ts,) = plan.switch_times([1.0], 0.0)
        return plan, {"switch_time_error": abs(ts - case.switch_time())}
    return solve


SCENARIOS = [("optimal/block_min_effort", 2 * N, _effort),
             ("optimal/block_min_time", 2 * N, _time),
             ("optimal/speedup_fesd", 25, _fesd(True)),
             ("optimal/speedup_fixed_grid", 25, _fesd(False))]


def run(quick: bool = False) -> Iterator[dict]:
    for name, size, solve in SCENARIOS:
        walls, ipopt = [], []
        for _ in range(1 if quick else 3):
            start = time.perf_counter()
            plan, accuracy = solve()
            walls.append(time.perf_counter() - start)
            ipopt.append(plan.stats["solve_time"])
        yield {"scenario": name, "size": size, "ours_s_per_solve": statistics.median(walls),
               "ipopt_s": statistics.median(ipopt), "solves": len(plan.stats["stages"]),
               "iterations": plan.stats["iterations"], "reference": None,
               "note": "nosnoc not installed; no peer measured yet",
               "accuracy": {**accuracy, "residual": plan.residual}}

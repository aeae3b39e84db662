"""Trajectory optimisation speed (nscontrol.optimal): the problems with closed forms, each
solved three times; the median wall time of ``solve()`` (transcription built, every IPOPT
solve of the homotopy and the polish) and of IPOPT's solves alone, with the error against the
closed form; the MPC block in closed loop (solve time per sample, wall and CPU: median, 90th
and 95th percentile, max) on the pushed block and on the cart-pole between walls (the
``optimal-cartpole`` example's contact-implicit MPC: 25 steps of 10 ms, 100 Hz sampling);
and the peer, nosnoc 0.2 (FESD, CasADi/IPOPT), run in its own virtual
environment when it exists (``.venv-nosnoc`` at the repository's root, or the interpreter
named by ``NSC_NOSNOC_PYTHON``; ``python3 -m venv .venv-nosnoc && .venv-nosnoc/bin/pip
install nosnoc``), skipped otherwise: the same switching problem (SpeedUp) solved by both,
optimum against the closed form and wall time side by side, and nosnoc's published
``sliding_mode_ocp`` example (nosnoc's time alone: two switching surfaces, beyond
SwitchingProblem's one hyperplane).

Run: ``nscontrol bench optimal --json`` (``--quick``: one solve each).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it in
# sys.modules.
import json
import os
import statistics
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

import nscontrol as nsc
from nscontrol.optimal import ContactMPC, ContactProblem, PushedBlock, SpeedUp
from nscontrol.systems import LagrangianSystem

ROOT = Path(__file__).resolve().parents[1]
NOSNOC_SCRIPT = ROOT / "bench" / "nosnoc" / "switching.py"

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


def nosnoc_python() -> tuple[str | None, str]:
    """The nosnoc venv's interpreter, or ``None`` and why."""
    py = os.environ.get("NSC_NOSNOC_PYTHON") or str(ROOT / ".venv-nosnoc" / "bin" / "python")
    if not Path(py).exists():
        return None, f"no nosnoc venv ({py} missing)"
    proc = subprocess.run([py, "-c", "import nosnoc"], capture_output=True, text=True)
    if proc.returncode:
        return None, f"nosnoc not importable by {py}: {proc.stderr.strip()[-300:]}"
    return py, ""


def run_nosnoc(py: str, cases: list[dict], repeats: int) -> list[dict]:
    """The JSON records of bench/nosnoc/switching.py run by the nosnoc venv."""
    proc = subprocess.run([py, str(NOSNOC_SCRIPT)], input=json.dumps(
        {"cases": cases, "repeats": repeats}), capture_output=True, text=True, timeout=1800)
    if proc.returncode:
        raise RuntimeError(f"nosnoc script failed:\n{proc.stderr[-2000:]}")
    return [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]


def _peer(quick: bool) -> Iterator[dict]:
    """SpeedUp by both (25 elements, one input each, free lengths: nosnoc's FESD with one
    element per stage and a free control grid), and nosnoc's sliding_mode_ocp."""
    py, why = nosnoc_python()
    repeats = 1 if quick else 3
    case = SpeedUp()
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        plan = case.problem(25).solve()
        walls.append(time.perf_counter() - start)
    (ts,) = plan.switch_times([1.0], 0.0)
    ours = {"cost_error": abs(plan.cost - case.cost()),
            "switch_time_error": abs(ts - case.switch_time())}
    rec = {"scenario": "optimal/speedup_vs_nosnoc", "size": 25,
           "ours_s_per_solve": statistics.median(walls), "reference": None,
           "reference_s_per_solve": None, "ratio": None, "accuracy": ours,
           "load_average_1min": os.getloadavg()[0]}
    if py is None:
        yield {**rec, "note": f"nosnoc skipped: {why}"}
        return
    cases = [{"name": "speedup", "a1": case.a1, "a2": case.a2, "L": case.L, "x_T": case.x_T,
              "T": case.T, "N": 25, "Nfe": 1, "equidistant": False},
             {"name": "sliding_mode_ocp"}]
    got = {r["name"]: r for r in run_nosnoc(py, cases, repeats)}
    ref = got["speedup"]
    ref_s = statistics.median(ref["walls"])
    yield {**rec, "reference": "nosnoc-0.2", "reference_s_per_solve": ref_s,
           "ratio": ref_s / rec["ours_s_per_solve"],
           "accuracy": {**ours, "reference_cost_error": abs(ref["effort"] - case.cost()),
                        "reference_switch_time_error": abs(ref["switch_time"]
                                                           - case.switch_time()),
                        "reference_status": ref["status"]}}
    slide = got["sliding_mode_ocp"]
    yield {"scenario": "optimal/nosnoc_sliding_mode_ocp", "size": 36, "ours_s_per_solve": None,
           "reference": "nosnoc-0.2", "reference_s_per_solve": statistics.median(slide["walls"]),
           "ratio": None, "accuracy": {"reference_status": slide["status"],
                                       "reference_cost": slide["cost"]},
           "note": "nosnoc's published example (two switching surfaces): not expressible by "
                   "SwitchingProblem (one hyperplane); nosnoc's time alone"}


def _mpc(quick: bool) -> dict:
    """The frictionless pushed block regulated to 1 m by ContactMPC in closed loop (the
    frictional Moreau–Jean takes no Python block yet): per-sample solve times."""
    m, g = BLOCK.mass, BLOCK.g
    plant = LagrangianSystem(np.eye(2) * m, constant_force=[0.0, -m * g],
                             gap_matrix=[[0.0, 1.0]], gap_offset=[0.0],
                             actuation=[[1.0], [0.0]], names=("x", "y"))
    h, steps = 0.04, 25
    mpc = ContactMPC(plant, BLOCK.x_final, steps, h, state_weight=[10.0, 0.0, 1.0, 0.0],
                     effort=1e-2, u_min=-U, u_max=U)
    start = time.perf_counter()
    traj = nsc.simulate(nsc.closed_loop(plant, mpc), BLOCK.x0, (0.0, 1.0 if quick else 3.0),
                        method="moreau_jean", h=h)
    wall = time.perf_counter() - start
    sig = mpc.signals(traj)
    warm = sig["solve_time"][1:]
    return {"scenario": "optimal/mpc_block_closed_loop", "size": steps,
            "ours_s_per_solve": float(np.median(warm)), "reference": None,
            "samples": int(sig["t"].size), "run_s": wall,
            "solve_time_first_s": float(sig["solve_time"][0]),
            **_distribution(sig, "solve_time"), **_distribution(sig, "cpu_time"),
            "iterations_median": float(np.median(sig["iterations"][1:])),
            "accuracy": {"final_error": float(abs(traj.x[-1, 0] - BLOCK.distance)),
                         "residual_max": float(sig["residual"].max())},
            "load_average_1min": os.getloadavg()[0]}


def _distribution(sig: dict, key: str) -> dict:
    """Median, 90th and 95th percentile and max of a per-sample record, first sample (the
    NLP built, the homotopy) left out."""
    warm = sig[key][1:]
    return {f"{key}_median_s": float(np.median(warm)),
            f"{key}_p90_s": float(np.percentile(warm, 90)),
            f"{key}_p95_s": float(np.percentile(warm, 95)), f"{key}_max_s": float(warm.max())}


def _mpc_cartpole(quick: bool) -> dict:
    """The optimal-cartpole example's contact-implicit MPC in closed loop: per-sample solve
    times against the 10 ms period (>= 100 Hz means a median below 10 ms)."""
    from nscontrol.examples.optimal_cartpole import PARAMETERS, run_controllers

    start = time.perf_counter()
    runs = run_controllers(T=1.0 if quick else PARAMETERS["T"])
    wall = time.perf_counter() - start
    mpc, traj = runs["contact"]
    sig = mpc.signals(traj)
    cpu = _distribution(sig, "cpu_time")
    return {"scenario": "optimal/mpc_cartpole_walls", "size": PARAMETERS["steps"],
            "ours_s_per_solve": cpu["cpu_time_median_s"], "reference": None,
            "samples": int(sig["t"].size), "run_s": wall, "period_s": PARAMETERS["h"],
            "rate_hz_at_median_cpu": 1.0 / cpu["cpu_time_median_s"],
            "solve_time_first_s": float(sig["solve_time"][0]),
            **_distribution(sig, "solve_time"), **cpu,
            "iterations_median": float(np.median(sig["iterations"][1:])),
            "iterations_max": float(sig["iterations"][1:].max()),
            "rounds_max": float(sig["rounds"].max()),
            "accuracy": {"final_state_max": float(np.abs(traj.x[-1]).max()),
                         "residual_max": float(sig["residual"].max())},
            "load_average_1min": os.getloadavg()[0],
            "note": "ours_s_per_solve is the median CPU time per warm sample; the wall "
                    "times count waits for a core on a loaded machine"}


def run(quick: bool = False) -> Iterator[dict]:
    yield _mpc_cartpole(quick)
    yield _mpc(quick)
    yield from _peer(quick)
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
               "note": "closed forms; the peer is in optimal/speedup_vs_nosnoc",
               "accuracy": {**accuracy, "residual": plan.residual}}

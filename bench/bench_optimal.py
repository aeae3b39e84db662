"""Trajectory optimisation speed (nscontrol.optimal): the problems with closed forms, each
solved three times; the median wall time of ``solve()`` (transcription built, every IPOPT
solve of the homotopy and the polish) and of IPOPT's solves alone, with the error against the
closed form; the MPC block in closed loop (solve time per sample, wall and CPU: median, 90th,
95th and 99th percentile, max; how many warm samples fell back from the mode iteration to
IPOPT) on the pushed block and on the cart-pole between walls (the ``optimal-cartpole``
example's contact-implicit MPC: 25 steps of 10 ms, 100 Hz sampling);
and the peer, nosnoc 0.2 (FESD, CasADi/IPOPT), run in its own virtual
environment when it exists (``.venv-nosnoc`` at the repository's root, or the interpreter
named by ``NSC_NOSNOC_PYTHON``; ``python3 -m venv .venv-nosnoc && .venv-nosnoc/bin/pip
install nosnoc``), skipped otherwise, each case timed in alternated rounds (one solve by
ours, then one by nosnoc kept running; medians and each side's fastest solve): the same
switching problem (SpeedUp) solved by both,
optimum against the closed form and wall time side by side, and nosnoc's published
``sliding_mode_ocp`` example with its own options (nosnoc's time alone), and two published
examples solved by both as the same discrete problem (FesdProblem: several and nonlinear
switching surfaces, nonlinear fields): ``sliding_mode_ocp`` and ``cart_pole_with_friction``,
and ``simple_car_algebraic`` (fields depending on the input per mode).

Run: ``nscontrol bench optimal --json`` (``--quick``: one solve each).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it in
# sys.modules.
import json
import os
import queue
import statistics
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from functools import partial
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


class NosnocProcess:
    """nosnoc's script kept running in its venv, answering one case at a time, so that each
    of its solves is timed next to one of ours: this host's speed drifts by tens of percent
    over minutes (nosnoc's motor took 0.34 s in one whole-bench run and 0.49 s in the next),
    and two sides timed minutes apart see different machines."""

    #: Seconds one case may take (five cart-pole solves take about 15 s).
    BUDGET_S = 1800.0

    def __init__(self, py: str) -> None:
        self._err = tempfile.TemporaryFile(mode="w+")
        self._proc = subprocess.Popen([py, str(NOSNOC_SCRIPT)], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=self._err, text=True)
        # the script's lines through a thread, so that a wait for one has a budget
        self._lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            self._lines.put(line)
        self._lines.put("")     # end of output: the process ended

    def __enter__(self) -> "NosnocProcess":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def solve(self, case: dict, repeats: int = 1) -> dict:
        """nosnoc's record of ``case`` (``repeats`` timed solves)."""
        stdin = self._proc.stdin
        assert stdin is not None
        stdin.write(json.dumps({"cases": [case], "repeats": repeats}) + "\n")
        stdin.flush()
        deadline = time.monotonic() + self.BUDGET_S
        records: list[dict] = []
        while True:
            try:
                line = self._lines.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                self._proc.kill()
                raise RuntimeError(f"nosnoc script: {case['name']} took more than "
                                   f"{self.BUDGET_S:g} s; stopped") from None
            if not line:
                break
            if line.startswith("{"):
                record = json.loads(line)
                if record.get("done") and records:
                    return records[-1]
                records.append(record)
        self._err.seek(0)
        raise RuntimeError(f"nosnoc script failed on {case['name']}:\n{self._err.read()[-2000:]}")

    def close(self) -> None:
        if self._proc.stdin is not None:
            self._proc.stdin.close()
        try:
            self._proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._err.close()


def _alternated(nosnoc: NosnocProcess, ours: Callable[[], tuple[dict, dict]],
                repeats: int) -> tuple[dict, dict]:
    """``repeats`` rounds of one solve by ours then one by nosnoc of the same case
    (``ours()`` returns nosnoc's case and our record of one timed solve): our last record
    with the medians of our timings, nosnoc's last record with all its timings."""
    mine, refs = [], []
    for _ in range(repeats):
        case, record = ours()
        mine.append(record)
        refs.append(nosnoc.solve(case))
    ours_out = dict(mine[-1])
    for key in ("wall", "cpu", "cached_wall", "cached_cpu"):
        if key in ours_out:
            ours_out[key] = statistics.median(r[key] for r in mine)
            ours_out[f"{key}_min"] = min(r[key] for r in mine)
    ref = dict(refs[-1])
    ref["walls"] = [w for r in refs for w in r["walls"]]
    ref["cpus"] = [c for r in refs for c in r["cpus"]]
    return ours_out, ref


def _timed(solve: Callable[[], Any], repeats: int) -> tuple[float, float, Any]:
    """Median wall and CPU (process) seconds of ``repeats`` calls, and the last result. The
    CPU time is the figure to read on a loaded machine: the wall time of two processes
    measured minutes apart sees different loads."""
    walls, cpus, out = [], [], None
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        out = solve()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus), out


#: Starts of the landing test: the rest start with every state after the first perturbed by
#: ``LANDING_SCALE`` (normal, far below every tolerance). These problems are non-convex and
#: their optimum depends on the path: how many of the perturbed solves reach nosnoc's optimum
#: tells a robust equal optimum from a lucky one (at the last stop, 3 of 12 such cart-pole
#: solves reached it).
LANDING_RUNS, LANDING_SCALE = 5, 1e-10


def _landings(build: Callable[[], Any], rest: np.ndarray, value: Callable[[Any], float],
              reference: float, tolerance: float, runs: int) -> dict:
    """How many of ``runs`` solves of ``build()`` (our side's homotopy) from ``rest``
    perturbed by :data:`LANDING_SCALE` end within ``tolerance`` of ``reference`` (``value``
    reads a plan's objective); their values."""
    from nscontrol.optimal import Relaxation

    rng = np.random.default_rng(20261204)
    values = []
    for _ in range(runs):
        guess = np.array(rest, float)
        guess[1:] += LANDING_SCALE * rng.standard_normal(guess[1:].shape)
        values.append(float(value(build().solve(Relaxation(**PEER_HOMOTOPY), guess=guess))))
    landed = sum(abs(v - reference) <= tolerance for v in values)
    return {"landed_from_perturbed_starts": f"{landed}/{runs}",
            "perturbed_start_values": values}


#: Our side's homotopy on nosnoc's examples: nosnoc's schedule (σ from 1, times 0.1, every
#: relaxed problem solved to the full tolerance, ``stage_tol=0``) with our early polish
#: (``settle_fraction``), which ends it sooner. Fair because the record checks the optimum
#: (``equal_optimum``), not the path; the schedule stays nosnoc's because the optimum of these
#: non-convex problems follows it: our default's ``sigma0=1e-3`` ends the cart-pole and the
#: simple car elsewhere, ``stage_tol=1e-2`` the sliding mode (5.5896 against 5.5687),
#: ``factor=0.01`` the cart-pole and the sliding mode (docs/optimal.md).
PEER_HOMOTOPY = {"sigma0": 1.0, "stage_tol": 0.0}


#: nosnoc's motor_with_friction example (examples/motor_with_friction/motor_with_friction_ocp.py):
#: slide mass, load mass, spring, back-EMF, resistance, inductance, force and speed constants,
#: guide friction.
MOTOR = {"m1": 1.03, "m2": 0.56, "k": 2.4e3, "umax": 5.0, "R": 2.0, "L": 2e-3, "KF": 12.0,
         "KS": 12.0, "FR": 2.1, "T": 0.08, "N": 30, "gamma_h": 0.9}


def _motor_problem() -> Any:
    """The motor as a SwitchingProblem: nosnoc's mode 1 (``v1 > 0``, friction ``-F_R``) is
    ours where ``ψ = -v1 < 0``; element lengths in nosnoc's ``[(1-γ_h) h̄, (1+γ_h) h̄]``.
    No step equilibration, as nosnoc's: its default ``HEURISTIC_DELTA`` penalises length
    differences within a control stage and each stage here has one element. Each relaxed
    solve cold from the previous primal point (``warm_homotopy=False``), as nosnoc's
    homotopy: warm (primal and dual at a small barrier) ours stays on the branch of the
    first relaxations and ends at 1.000529, nosnoc's optimum being 0.999900."""
    from nscontrol.optimal import SwitchingProblem

    p = MOTOR
    m1, m2, k = p["m1"], p["m2"], p["k"]
    A = np.array([[0, 1, 0, 0, 0], [-k / m1, 0, k / m1, 0, p["KF"] / m1], [0, 0, 0, 1, 0],
                  [k / m2, 0, -k / m2, 0, 0], [0, -p["KS"] / p["L"], 0, 0, -p["R"] / p["L"]]])
    B = np.zeros((5, 1))
    B[-1, 0] = 1.0 / p["L"]
    friction = np.array([0.0, -p["FR"] / m1, 0.0, 0.0, 0.0])
    g = p["gamma_h"]
    return SwitchingProblem(A=(A, A), b=(friction, -friction), B=B, c=[0, -1, 0, 0, 0], d=0.0,
                            x0=np.zeros(5), x_final=[0.01, 0, 0.01, 0, 0], T=p["T"],
                            elements=p["N"], u_min=-p["umax"], u_max=p["umax"],
                            element_bounds=(1.0 - g, 1.0 + g), warm_homotopy=False)


def _motor(repeats: int) -> tuple[dict, dict]:
    """Ours from nosnoc's start (every state at x0) and along nosnoc's homotopy (σ from 1,
    times 0.1)."""
    from nscontrol.optimal import Relaxation

    rest = np.zeros((MOTOR["N"] + 1, 5))
    # cold: a new problem each solve (its transcription built, as nosnoc's solver is);
    # cached: one problem solved again (its transcription kept from its first solve)
    wall, cpu, plan = _timed(lambda: _motor_problem().solve(Relaxation(**PEER_HOMOTOPY),
                                                            guess=rest), repeats)
    problem = _motor_problem()
    problem.solve(Relaxation(**PEER_HOMOTOPY), guess=rest)
    cached_wall, cached_cpu, _ = _timed(lambda: problem.solve(Relaxation(**PEER_HOMOTOPY),
                                                              guess=rest), repeats)
    case = {"name": "motor_with_friction", "N": MOTOR["N"], "gamma_h": MOTOR["gamma_h"]}
    return case, {"wall": wall, "cpu": cpu, "cost": plan.cost, "residual": plan.residual,
                  "iterations": plan.stats["iterations"], "cached_wall": cached_wall,
                  "cached_cpu": cached_cpu}


#: nosnoc's oscillator example (examples/oscillator/oscillator_example.py): spirals out
#: inside the unit circle, the other way round outside.
OMEGA_OSC, T_OSC = 2 * np.pi, np.pi / 2


def _oscillator(repeats: int) -> tuple[dict, dict]:
    """Our switching integrator (DOP853 between located crossings, rtol = atol = 1e-12),
    one untimed run first (the kernels load). Closed form: ``e^{T-1}(cos ω(T-1),
    -sin ω(T-1))``."""
    from nscontrol.systems import FilippovSystem

    w = OMEGA_OSC
    inside = np.array([[1.0, -w], [w, 1.0]])
    outside = np.array([[1.0, w], [-w, 1.0]])
    osc = FilippovSystem.two_sided(lambda t, x: inside @ x, lambda t, x: outside @ x,
                                   lambda x: x[0] ** 2 + x[1] ** 2 - 1.0, 2,
                                   gradient=lambda x: 2.0 * np.asarray(x))

    def run() -> Any:
        return nsc.simulate(osc, [np.exp(-1.0), 0.0], (0.0, T_OSC), rtol=1e-12, atol=1e-12)

    run()
    wall, cpu, traj = _timed(run, repeats)
    return {"name": "oscillator"}, {"wall": wall, "cpu": cpu, "x_end": traj.x[-1]}


def _oscillator_exact() -> np.ndarray:
    s = T_OSC - 1.0
    return np.exp(s) * np.array([np.cos(OMEGA_OSC * s), -np.sin(OMEGA_OSC * s)])


def _relay_fields() -> tuple[np.ndarray, np.ndarray]:
    omega, xi, sigma = 25.0, 0.05, 1.0
    A = np.array([[-(2 * xi * omega + 1), 1, 0], [-(2 * xi * omega + omega ** 2), 0, 1],
                  [-omega ** 2, 0, 0]])
    return A, np.array([1.0, -2 * sigma, 1.0])


def _relay(repeats: int) -> tuple[dict, dict]:
    """nosnoc's relay example (examples/relay/relay_feedback_system.py, Piiroinen and
    Kuznetsov's third-order relay feedback system) to T = 10: ours compiled (exact flows
    between located switches and sliding), one untimed run first; checked against the same
    system as Python fields on DOP853 at rtol = atol = 1e-12."""
    from nscontrol.systems import FilippovSystem

    A, b = _relay_fields()
    x0, span = [0.0, -0.001, -0.02], (0.0, 10.0)
    relay = FilippovSystem.two_sided((A, b), (A, -b), np.array([1.0, 0.0, 0.0]), 3)
    nsc.simulate(relay, x0, span)
    wall, cpu, traj = _timed(lambda: nsc.simulate(relay, x0, span), repeats)
    check = nsc.simulate(FilippovSystem.two_sided(
        lambda t, x: A @ x + b, lambda t, x: A @ x - b, lambda x: x[0], 3,
        gradient=lambda x: np.array([1.0, 0.0, 0.0])), x0, span, rtol=1e-12, atol=1e-12)
    return {"name": "relay"}, {"wall": wall, "cpu": cpu, "x_end": traj.x[-1],
                               "x_end_dop853": check.x[-1]}


def _versus(scenario: str, size: int, ours: dict, ref: dict, accuracy: dict,
            note: str) -> dict:
    """One side-by-side record: medians of wall and CPU seconds, their ratios."""
    ref_wall, ref_cpu = statistics.median(ref["walls"]), statistics.median(ref["cpus"])
    out = {"scenario": scenario, "size": size, "ours_s_per_solve": ours["wall"],
           "ours_cpu_s": ours["cpu"], "reference": "nosnoc-0.2",
           "reference_s_per_solve": ref_wall, "reference_cpu_s": ref_cpu,
           "ratio": ref_wall / ours["wall"], "ratio_cpu": ref_cpu / ours["cpu"],
           "accuracy": accuracy, "note": note, "load_average_1min": os.getloadavg()[0]}
    if "wall_min" in ours:   # alternated rounds: each side's fastest solve too (the
        # host's slow phases last seconds and lengthen one side's solves or the other's)
        out.update({"ours_s_per_solve_min": ours["wall_min"],
                    "reference_s_per_solve_min": min(ref["walls"]),
                    "ratio_min": min(ref["walls"]) / ours["wall_min"],
                    "ratio_cpu_min": min(ref["cpus"]) / ours["cpu_min"]})
    return out


def _published(got: dict, ours: dict, runs: int = LANDING_RUNS) -> Iterator[dict]:
    """nosnoc's published examples side by side (the motor's landing from ``runs``
    perturbed starts, :func:`_landings`)."""
    motor, ref = ours["motor_with_friction"], got["motor_with_friction"]
    rel = abs(motor["cost"] - ref["effort"]) / abs(ref["effort"])
    landing = _landings(_motor_problem, np.zeros((MOTOR["N"] + 1, 5)), lambda p: p.cost,
                        ref["effort"], 1e-6 * abs(ref["effort"]), runs)
    # the same problem? ours started from nosnoc's plan (untimed) must stay on its optimum
    from_ref = _motor_problem().solve(guess=np.asarray(ref["x_traj"]))
    rel_from_ref = abs(from_ref.cost - ref["effort"]) / abs(ref["effort"])
    yield {**_versus("optimal/nosnoc_motor_with_friction", MOTOR["N"], motor, ref, {
        "cost": motor["cost"], "reference_cost": ref["effort"], "cost_relative_difference": rel,
        "equal_optimum": rel <= 1e-6, "residual": motor["residual"],
        "iterations": motor["iterations"], "reference_status": ref["status"],
        "cost_from_reference_plan": from_ref.cost,
        "cost_from_reference_plan_relative_difference": rel_from_ref,
        "same_problem": rel_from_ref <= 1e-6, **landing},
        "nosnoc's example discretised as ours (implicit Euler, one element per input, free "
        "lengths within nosnoc's gamma_h bounds), both from nosnoc's start (at rest) and "
        "homotopy (sigma from 1, each relaxation cold from the previous primal point; ours "
        "ends at its early polish, the optimum checked, not the path); equal "
        "optimum: costs within 1e-6 relative (both solved to "
        "complementarity <= 1e-8); a non-convex problem: the two may stop in different local "
        "optima, and ours started from nosnoc's plan tells whether the problems are the same; "
        "ours_s_per_solve and the ratios: a new problem each solve (transcription built, as "
        "nosnoc's solver); ours_cached_*: one problem solved again (transcription kept)"),
        "ours_cached_s_per_solve": motor["cached_wall"], "ours_cached_cpu_s": motor["cached_cpu"],
        "ratio_cached": statistics.median(ref["walls"]) / motor["cached_wall"],
        "ratio_cpu_cached": statistics.median(ref["cpus"]) / motor["cached_cpu"]}
    osc, ref = ours["oscillator"], got["oscillator"]
    exact = _oscillator_exact()
    err, ref_err = (float(np.max(np.abs(np.asarray(x) - exact)))
                    for x in (osc["x_end"], ref["x_end"]))
    yield _versus("optimal/nosnoc_oscillator", 29, osc, ref, {
        "end_state_error": err, "reference_end_state_error": ref_err,
        "at_least_as_accurate": err <= ref_err},
        "simulation example: our switching integrator against nosnoc's FESD stepping "
        "(29 steps, Radau IIA 3 stages); errors against the closed form")
    relay, ref = ours["relay"], got["relay"]
    diff = float(np.max(np.abs(relay["x_end"] - relay["x_end_dop853"])))
    ref_diff = float(np.max(np.abs(np.asarray(ref["x_end"]) - relay["x_end"])))
    yield _versus("optimal/nosnoc_relay", 200, relay, ref, {
        "end_state_vs_dop853_1e-12": diff, "reference_end_state_vs_ours": ref_diff,
        "at_least_as_accurate": diff <= ref_diff},
        "simulation example to T = 10: our compiled Filippov loop against nosnoc's FESD "
        "stepping (200 steps, Radau IIA 2 stages); no closed form: ours checked against "
        "DOP853 at 1e-12, nosnoc against ours")


#: Alternated rounds per case against nosnoc (one solve by each side per round).
ROUNDS = 5


def _speedup_once(case: Any) -> dict:
    """One timed solve of SpeedUp (25 elements) by ours, with its errors."""
    wall, cpu, plan = _timed(lambda: case.problem(25).solve(), 1)
    (ts,) = plan.switch_times([1.0], 0.0)
    return {"wall": wall, "cpu": cpu, "cost_error": abs(plan.cost - case.cost()),
            "switch_time_error": abs(ts - case.switch_time())}


def _peer(quick: bool) -> Iterator[dict]:
    """SpeedUp by both (25 elements, one input each, free lengths: nosnoc's FESD with one
    element per stage and a free control grid), nosnoc's published examples
    motor_with_friction (an optimal control problem), oscillator and relay (simulations),
    sliding_mode_ocp, cart_pole_with_friction and simple_car_algebraic by both as the same
    discrete problem (FesdProblem), and nosnoc's sliding_mode_ocp with its own options
    alone. Each case is solved in rounds, one solve by ours then one by nosnoc
    (:func:`_alternated`)."""
    py, why = nosnoc_python()
    repeats = 1 if quick else ROUNDS
    case = SpeedUp()
    speedup = {"name": "speedup", "a1": case.a1, "a2": case.a2, "L": case.L, "x_T": case.x_T,
               "T": case.T, "N": 25, "Nfe": 1, "equidistant": False}
    if py is None:
        mine = _speedup_once(case)
        yield {"scenario": "optimal/speedup_vs_nosnoc", "size": 25,
               "ours_s_per_solve": mine["wall"], "ours_cpu_s": mine["cpu"],
               "reference": None, "reference_s_per_solve": None, "ratio": None,
               "accuracy": {k: mine[k] for k in ("cost_error", "switch_time_error")},
               "load_average_1min": os.getloadavg()[0], "note": f"nosnoc skipped: {why}"}
        return
    got, ours = {}, {}
    with NosnocProcess(py) as nosnoc:
        mine, ref = _alternated(nosnoc, lambda: (speedup, _speedup_once(case)), repeats)
        for solve in (_motor, _oscillator, _relay):
            o, r = _alternated(nosnoc, partial(solve, 1), repeats)
            ours[r["name"]], got[r["name"]] = o, r
        general = _general_pairs(nosnoc, repeats)
        car = _alternated(nosnoc, _simple_car_once, repeats)
        slide = nosnoc.solve({"name": "sliding_mode_ocp"}, repeats)
    yield _versus("optimal/speedup_vs_nosnoc", 25, mine, ref, {
        "cost_error": mine["cost_error"], "switch_time_error": mine["switch_time_error"],
        "reference_cost_error": abs(ref["effort"] - case.cost()),
        "reference_switch_time_error": abs(ref["switch_time"] - case.switch_time()),
        "reference_status": ref["status"]}, "nscontrol's SpeedUp (closed form), same "
        "transcription on both sides")
    yield from _published(got, ours, LANDING_RUNS if repeats > 1 else 1)
    yield from _published_general(*general, LANDING_RUNS if repeats > 1 else 1)
    yield _simple_car_record(*car)
    yield {"scenario": "optimal/nosnoc_sliding_mode_ocp", "size": 36, "ours_s_per_solve": None,
           "reference": "nosnoc-0.2", "reference_s_per_solve": statistics.median(slide["walls"]),
           "ratio": None, "accuracy": {"reference_status": slide["status"],
                                       "reference_cost": slide["cost"]},
           "note": "nosnoc's published example with its own options (two Radau stages): "
                   "nosnoc's time alone; the same problem discretised as ours on both sides "
                   "is optimal/nosnoc_sliding_mode_ocp_as_ours"}


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
            "iterations_median": float(np.median(sig["iterations"][1:])), **_modes(sig),
            "accuracy": {"final_error": float(abs(traj.x[-1, 0] - BLOCK.distance)),
                         "residual_max": float(sig["residual"].max())},
            "load_average_1min": os.getloadavg()[0]}


def _distribution(sig: dict, key: str) -> dict:
    """Median, 90th, 95th and 99th percentile and max of a per-sample record, first sample
    (the NLP built, the homotopy) left out."""
    warm = sig[key][1:]
    return {f"{key}_median_s": float(np.median(warm)),
            **{f"{key}_p{q}_s": float(np.percentile(warm, q)) for q in (90, 95, 99)},
            f"{key}_max_s": float(warm.max())}


def _modes(sig: dict) -> dict:
    """How the warm samples were solved: by the mode iteration (its KKT solves), or by
    IPOPT when it did not settle."""
    warm_ipopt = sig["ipopt"][1:]
    return {"ipopt_samples": int(warm_ipopt.sum()),
            "mode_iterations_median": float(np.median(sig["mode_iterations"][1:])),
            "mode_iterations_max": float(sig["mode_iterations"][1:].max())}


def _mpc_cartpole(quick: bool) -> dict:
    """The optimal-cartpole example's contact-implicit MPC in closed loop: per-sample solve
    times against the 10 ms period (>= 100 Hz means every sample below 10 ms: the max)."""
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
            "iterations_max": float(sig["iterations"][1:].max()), **_modes(sig),
            "rounds_max": float(sig["rounds"].max()),
            "accuracy": {"final_state_max": float(np.abs(traj.x[-1]).max()),
                         "settled_max_after_2_5_s": _settled(traj),
                         "impacts": int(np.count_nonzero(
                             np.abs(traj.signals["impulse"]).sum(axis=1))),
                         "residual_max": float(sig["residual"].max()),
                         "residual_max_warm": float(sig["residual"][1:].max())},
            "load_average_1min": os.getloadavg()[0],
            "note": "ours_s_per_solve is the median CPU time per warm sample; the wall "
                    "times count waits for a core on a loaded machine"}


def _settled(traj: Any) -> float | None:
    """Largest |state| from the example's settling time on; None when the run is shorter
    (``--quick`` runs 1 s)."""
    from nscontrol.examples.optimal_cartpole import PARAMETERS

    late = traj.x[traj.t >= PARAMETERS["settle_time"] - 1e-9]
    return float(np.abs(late).max()) if late.size else None


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


#: nosnoc's sliding_mode_ocp (examples/sliding_mode_ocp/sliding_mode_ocp.py): two nonlinear
#: switching surfaces, two layers of two fields each (their fields summed), T = 4, 6 stages
#: of 6 elements, step equilibration "mean" with ρ = 10, least ∫ (v1² + v2²) to a target.
SLIDING = {"N": 6, "Nfe": 6, "rho_h": 10.0, "equilibration": "HEURISTIC_MEAN", "T": 4.0,
           "u_max": 10.0, "x0": [2 * np.pi / 3, np.pi / 3, 0.0, 0.0],
           "target": [-np.pi / 6, -np.pi / 4]}

#: nosnoc's cart_pole_with_friction (examples/cart_pole_with_friction/): Coulomb friction
#: on the cart (surface v = 0), nonlinear fields, tracking cost, T = 5, 20 stages of 2
#: elements, step equilibration "delta" with ρ = 1 (nosnoc's defaults).
CART = {"N": 20, "Nfe": 2, "rho_h": 1.0, "equilibration": "HEURISTIC_DELTA", "friction": 2.0,
        "x0": [1.0, 0.0, 0.0, 0.0], "x_ref": [0.0, np.pi, 0.0, 0.0], "Q": [10, 100, 1, 1],
        "Q_terminal": [500, 100, 10, 10], "R": 1.0, "x_max": 5.0, "u_max": 30.0, "T": 5.0}


def _sliding_mode_problem() -> Any:
    """SLIDING as a FesdProblem: layer j moves x_j at ``v_j ∓ 1`` on either side of its
    surface ``c_j`` (field 1 where ``c_j > 0``, nosnoc's ``S = [[1], [-1]]``) and both layers
    push ``v`` by ``u`` (the layers' fields are summed, as nosnoc sums its subsystems).
    Each relaxed solve cold from the previous primal point, as nosnoc's homotopy (the warm
    one reaches the same optimum here, but not on the cart-pole)."""
    from nscontrol.optimal import FesdProblem, StewartSystem

    def field(j: int, side: float) -> Callable[[Any, Any], list]:
        def f(x: Any, u: Any) -> list:
            out = [0.0, 0.0, u[0], u[1]]
            out[j] = side + x[2 + j]
            return out
        return f

    layers = [StewartSystem([field(0, -1.0), field(0, 1.0)],
                            lambda x: x[0] + 0.15 * x[1] ** 2, signs=[[1.0], [-1.0]]),
              StewartSystem([field(1, -1.0), field(1, 1.0)],
                            lambda x: x[1] - 0.05 * x[0] ** 3, signs=[[1.0], [-1.0]])]
    p = SLIDING
    return FesdProblem(layers, p["x0"], p["T"], p["N"], elements=p["Nfe"], inputs=2,
                       stage_cost=lambda x, u: x[2] ** 2 + x[3] ** 2,
                       x_final=[*p["target"], np.nan, np.nan], u_min=-p["u_max"],
                       u_max=p["u_max"], element_bounds=(0.0, 2.0),
                       equilibration=p["rho_h"], equilibration_form="mean",
                       warm_homotopy=False)


def _cart_pole_problem() -> Any:
    """CART as a FesdProblem: the cart-pole's two fields (friction ``∓F`` on the cart, field
    1 where ``v > 0``), the inverse of its 2×2 mass matrix written out. Each relaxed solve
    cold from the previous primal point, as nosnoc's homotopy: warm (primal and dual at a
    small barrier) ours ends in another local optimum, 1200.0208 against 1199.9689."""
    import casadi as ca

    from nscontrol.optimal import FesdProblem, StewartSystem

    p = CART
    m1, m2, ell, g = 1.0, 0.1, 1.0, 9.81

    def field(friction: float) -> Callable[[Any, Any], Any]:
        def f(x: Any, u: Any) -> Any:
            th, v, om = x[1], x[2], x[3]
            a, b, d = m1 + m2, m2 * ell * ca.cos(th), m2 * ell ** 2
            r1 = u[0] + m2 * ell * om ** 2 * ca.sin(th) - friction
            r2 = -m2 * g * ell * ca.sin(th)
            det = a * d - b * b
            return ca.vertcat(v, om, (d * r1 - b * r2) / det, (a * r2 - b * r1) / det)
        return f

    ref, Q, Qt = np.array(p["x_ref"]), np.diag(p["Q"]), np.diag(p["Q_terminal"])
    layer = StewartSystem([field(p["friction"]), field(-p["friction"])], lambda x: x[2],
                          signs=[[1.0], [-1.0]])
    return FesdProblem(
        layer, p["x0"], p["T"], p["N"], elements=p["Nfe"], inputs=1,
        stage_cost=lambda x, u: ca.bilin(Q, x - ref, x - ref) + p["R"] * u[0] ** 2,
        terminal_cost=lambda x: ca.bilin(Qt, x - ref, x - ref), u_min=-p["u_max"],
        u_max=p["u_max"], x_min=[-p["x_max"], -np.inf, -np.inf, -np.inf],
        x_max=[p["x_max"], np.inf, np.inf, np.inf], element_bounds=(0.0, 2.0),
        equilibration=p["rho_h"], equilibration_form="delta", warm_homotopy=False)


def _general(name: str, build: Callable[[], Any], repeats: int) -> tuple[dict, dict]:
    """Ours on a published nosnoc example, from nosnoc's start (every state at x0) along
    nosnoc's homotopy (σ from 1, times 0.1, each solve cold from the previous primal
    point)."""
    from nscontrol.optimal import Relaxation

    problem = build()
    rest = np.tile(problem.x0, (problem.stages * problem.elements + 1, 1))
    wall, cpu, plan = _timed(lambda: build().solve(Relaxation(**PEER_HOMOTOPY), guess=rest),
                             repeats)
    return {"name": name}, {"wall": wall, "cpu": cpu, "cost": plan.cost,
                            "objective": plan.objective, "residual": plan.residual,
                            "iterations": plan.stats["iterations"], "t": plan.t,
                            "x": plan.x, "theta": plan.theta}


#: IPOPT's tolerances: nosnoc's (its comp_tol × 1e-2, comp_tol 1e-9) and IPOPT's acceptable
#: level (its default), where nosnoc's last solve may stop.
TOL_NOSNOC, TOL_ACCEPTABLE = 1e-11, 1e-6


def _our_accuracy() -> float:
    """How far our solve may miss: IPOPT's tolerance (Relaxation.tol), or its relaxation of
    constraint bounds (``bound_relax_factor``, IPOPT's default 1e-8 unless our options set
    it), which our plans keep (our bounds are constraint rows: an element may be -1e-8 long
    below its lower bound 0; nosnoc's are variable bounds with the factor 0)."""
    from nscontrol.optimal import Relaxation
    from nscontrol.optimal.homotopy import IPOPT_OPTIONS

    return max(Relaxation().tol, float(IPOPT_OPTIONS.get("bound_relax_factor", 1e-8)))


def _objective_tolerance(ref: dict, ref_obj: float) -> dict:
    """How far the two objectives may be apart at one optimum: nosnoc stops at its last
    relaxation ``σ_N`` (products ``θ λ <= σ_N``, no polish), whose optimum lies
    ``σ_N Σν`` above the limit's (``dJ/dσ = -Σν``, the multipliers of the products),
    estimated from its last two relaxed objectives as ``|J_N - J_{N-1}| σ_N / (σ_{N-1} -
    σ_N)``; ours is polished (the pairs exact). Each side's IPOPT solve is accurate to its
    ``ε`` times ``1 + |J|`` (a constraint missed by ``ε`` moves ``J`` by its multiplier
    times ``ε``; nosnoc's ``ε`` its tolerance, or the acceptable level, 1e-6, when its last
    solve stopped there; ours :func:`_our_accuracy`). The tolerance is 10 times their sum."""
    sig, obj = ref["sigmas"], ref["objectives"]
    bias = abs(obj[-1] - obj[-2]) * sig[-1] / (sig[-2] - sig[-1])
    eps_ref = TOL_ACCEPTABLE if ref["last_status"] == "Solved_To_Acceptable_Level" \
        else TOL_NOSNOC
    solve = (eps_ref + _our_accuracy()) * (1.0 + abs(ref_obj))
    return {"objective_tolerance": 10.0 * (bias + solve),
            "reference_relaxation_bias": bias, "solver_accuracy": solve,
            "reference_last_status": ref["last_status"]}


def _published_general(got: dict, ours: dict, runs: int = LANDING_RUNS) -> Iterator[dict]:
    """nosnoc's sliding_mode_ocp and cart_pole_with_friction side by side, the optimum of
    each side recomputed by one formula (FesdProblem.cost_of) on its own trajectory, and
    its complementarity residual by another (FesdProblem.residual_of, λ from the states)."""
    for name, build, size in (("sliding_mode_ocp_as_ours", _sliding_mode_problem, 36),
                              ("cart_pole_with_friction", _cart_pole_problem, 40)):
        mine, ref = ours[name], got[name]
        problem = build()
        ref_cost = problem.cost_of(ref["t_grid"], ref["x_traj"], ref["u_traj"])
        ref_obj = problem.cost_of(ref["t_grid"], ref["x_traj"], ref["u_traj"], penalty=True)
        diff = mine["objective"] - ref_obj
        tol = _objective_tolerance(ref, ref_obj)
        from_ref = problem.solve(guess=np.asarray(ref["x_traj"]))
        rel_from_ref = abs(from_ref.objective - ref_obj) / abs(ref_obj)
        rest = np.tile(problem.x0, (problem.stages * problem.elements + 1, 1))
        landing = _landings(build, rest, lambda p: p.objective, ref_obj,
                            tol["objective_tolerance"], runs)
        yield _versus(f"optimal/nosnoc_{name}", size, mine, ref, {
            **landing,
            "cost": mine["cost"], "reference_cost": ref_cost, "objective": mine["objective"],
            "reference_objective": ref_obj, "reference_objective_reported": ref["cost"],
            "same_objective_formula": abs(ref_obj - ref["cost"]) <= 1e-9 * abs(ref_obj),
            "objective_difference": diff, "objective_relative_difference": abs(diff) / abs(
                ref_obj), **tol, "equal_optimum": abs(diff) <= tol["objective_tolerance"],
            "ours_lower": mine["objective"] < ref_obj,
            "state_max_difference": float(np.max(np.abs(mine["x"] - np.asarray(
                ref["x_traj"])))),
            "grid_max_difference": float(np.max(np.abs(mine["t"] - np.asarray(
                ref["t_grid"])))),
            "residual": problem.residual_of(mine["x"], mine["theta"]),
            "reference_residual": problem.residual_of(ref["x_traj"], ref["theta"]),
            "reference_largest_product": ref["comp_res"],
            "iterations": mine["iterations"], "reference_status": ref["status"],
            "objective_from_reference_plan": from_ref.objective,
            "objective_from_reference_plan_relative_difference": rel_from_ref},
            "nosnoc's published problem discretised as ours on both sides (implicit Euler: "
            "Radau IIA with one stage; the same stages, elements per stage, element bounds, "
            "step equilibration, cross complementarity pairs and IPOPT iteration limit), "
            "both from nosnoc's start (at rest) and homotopy (sigma from 1 by 0.1, each "
            "solve cold from the previous primal point; ours ends at its early polish, the "
            "optimum checked, not the path); objective = sum h_k L(x_k+1, u) + "
            "terminal + step equilibration penalty, recomputed by one formula on each "
            "side's trajectory (nosnoc's own report alongside), residual max |min(theta, "
            "lambda)| with lambda from the states on each side; equal optimum: objectives "
            "within objective_tolerance (10 x nosnoc's last relaxation's bias estimated "
            "from its last two sigmas, plus each side's IPOPT tolerance x (1 + |J|)); "
            "state_max_difference and grid_max_difference compare the two plans element "
            "by element")


def _general_once(case: dict, name: str, build: Callable[[], Any]) -> tuple[dict, dict]:
    """nosnoc's ``case`` and one timed solve of ours."""
    return case, _general(name, build, 1)[1]


def _general_pairs(nosnoc: NosnocProcess, repeats: int) -> tuple[dict, dict]:
    """Several and nonlinear switching surfaces (FesdProblem) and nosnoc on its published
    sliding_mode_ocp and cart_pole_with_friction, both discretised as ours, in alternated
    rounds: nosnoc's records and ours, by name."""
    from nscontrol.optimal import Relaxation

    got, ours = {}, {}
    for name, build, spec in (("sliding_mode_ocp_as_ours", _sliding_mode_problem, SLIDING),
                              ("cart_pole_with_friction", _cart_pole_problem, CART)):
        case = {"name": name, "max_iter": Relaxation().max_iter,
                **{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                   for k, v in spec.items()}}
        ours[name], got[name] = _alternated(
            nosnoc, partial(_general_once, case, name, build), repeats)
    return got, ours


#: nosnoc's simple car (examples/simple_car_algebraics/simple_car_algebraic.py;
#: nscontrol.optimal.SimpleCar, its closed form): 30 stages of 2 elements. The example's step
#: equilibration (L2_RELAXED_SCALED) is not one of ours: both sides use nosnoc's default
#: HEURISTIC_DELTA with ρ = 1; the example's two Radau stages become one (implicit Euler).
CAR = {"N": 30, "Nfe": 2, "rho_h": 1.0, "equilibration": "HEURISTIC_DELTA"}


def _simple_car_problem() -> Any:
    """SimpleCar's FesdProblem on CAR's grid: field 1 (``v' = k1 u``) where
    ``c = v - v_switch < 0``, nosnoc's ``S = [[-1], [1]]``. nosnoc's switching function is
    an algebraic variable ``z`` with ``z = v - v_switch`` imposed at every stage point; ours
    is ``c = v - v_switch`` itself (the same values at the same points: the same discrete
    problem). nosnoc's start and homotopy: the algebraic variables centred (``θ = λ = 1/2``,
    ``μ = 1``), each relaxed solve cold from the previous primal point."""
    from nscontrol.optimal import SimpleCar

    return replace(SimpleCar().problem(CAR["N"], CAR["Nfe"], CAR["rho_h"], "delta",
                                       start="centred"), warm_homotopy=False)


def _simple_car_once() -> tuple[dict, dict]:
    """nosnoc's case of the simple car and one timed solve of ours."""
    from nscontrol.optimal import Relaxation, SimpleCar

    car = SimpleCar()
    case = {"name": "simple_car", **CAR, "max_iter": Relaxation().max_iter, "k1": car.k1,
            "k2": car.k2, "v_switch": car.v_switch, "x0": [0.0, 0.0],
            "x_final": [car.distance, 0.0], "T": car.T, "u_max": car.u_max}
    return case, _general("simple_car_algebraic", _simple_car_problem, 1)[1]


def _simple_car_record(mine: dict, ref: dict) -> dict:
    """nosnoc's simple car by both sides as the same discrete problem (FesdProblem: one
    switching surface, a field per mode that depends on the input), the optimum of each
    side recomputed by FesdProblem.cost_of on its own trajectory and its residual by
    FesdProblem.residual_of; equal optimum within the sliding-mode and cart-pole rows'
    derived tolerance (:func:`_objective_tolerance`)."""
    from nscontrol.optimal import SimpleCar

    name, car = "simple_car_algebraic", SimpleCar()
    problem = _simple_car_problem()
    ref_cost = problem.cost_of(ref["t_grid"], ref["x_traj"], ref["u_traj"])
    ref_obj = problem.cost_of(ref["t_grid"], ref["x_traj"], ref["u_traj"], penalty=True)
    diff = mine["objective"] - ref_obj
    tol = _objective_tolerance(ref, ref_obj)
    # from nosnoc's states, the algebraic variables consistent with them (not centred)
    from_ref = replace(problem, start="consistent").solve(guess=np.asarray(ref["x_traj"]))
    return _versus(f"optimal/nosnoc_{name}", CAR["N"] * CAR["Nfe"], mine, ref, {
        "cost": mine["cost"], "reference_cost": ref_cost, "objective": mine["objective"],
        "reference_objective": ref_obj, "reference_objective_reported": ref["cost"],
        "objective_difference": diff, "objective_relative_difference": abs(diff) / abs(
            ref_obj), **tol, "equal_optimum": abs(diff) <= tol["objective_tolerance"],
        "ours_lower": mine["objective"] < ref_obj,
        "state_max_difference": float(np.max(np.abs(mine["x"] - np.asarray(
            ref["x_traj"])))),
        "residual": problem.residual_of(mine["x"], mine["theta"]),
        "reference_residual": problem.residual_of(ref["x_traj"], ref["theta"]),
        "iterations": mine["iterations"],
        "reference_iterations": sum(ref.get("iterations", [])),
        "reference_status": ref["status"], "continuous_cost": car.cost(),
        "objective_from_reference_plan": from_ref.objective,
        "objective_from_reference_plan_relative_difference":
            abs(from_ref.objective - ref_obj) / abs(ref_obj)},
        "nosnoc's published simple car discretised as ours on both sides (implicit Euler: "
        "Radau IIA with one stage; 30 stages of 2 elements, lengths within (0, 2) h, step "
        "equilibration HEURISTIC_DELTA with rho 1 on both in place of the example's "
        "L2_RELAXED_SCALED, which ours has not; cross complementarity pairs and IPOPT "
        "iteration limit as ours), nosnoc's algebraic z = v - 15 being our switching "
        "function c = v - 15; both from nosnoc's start (at rest, the algebraic variables "
        "centred: start='centred') and homotopy (sigma from 1 by 0.1, each solve cold from "
        "the previous primal point; ours ends at its early polish, the optimum checked, "
        "not the path); objective = sum h_k u_k^2 + step equilibration "
        "penalty, recomputed by one formula on each side's trajectory; equal optimum: "
        "within objective_tolerance (as the sliding-mode and cart-pole rows); a non-convex "
        "problem: ours restarted from nosnoc's states (uniform lengths, default homotopy) "
        "may end in another local optimum")

"""Chapter 4: Moreau–Jean on the posture-regulation examples.

* Example A (foot + ankle-actuated body, M(q), heel and toe contacts), scenario A1 (push
  forward, the heel lifts and lands), 8 s at h = 1e-3 and 2.5e-4: steps per second of the
  model's compiled form (Moreau–Jean's compiled loop, the law folded into the forces, and the
  law as a compiled block), against the same model on the Python path (``compiled=None``) in
  the same run, and the deviation of (y, φ, θ) from the posture at the end. No Siconos run:
  it would need a LagrangianDS with Python callbacks for M(q) and a nonlinear relation for
  the gaps, not written here (``note`` says so).
* Example C (mass regulated against a wall, e = 0.5, 5 s, h = 1e-3 and 2.5e-4): ours (the law
  folded into the linear forces by closed_loop, compiled path) against Siconos'
  LagrangianLinearTIDS + LagrangianLinearTIR + NewtonImpactNSL + MoreauJeanOSI(½), timed in
  the same run; ``accuracy`` holds the largest difference of q over the run, the final
  q on both sides and the last impulses.

Run: ``nscontrol bench ch04 --json`` (``--quick``: h = 1e-3 only).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version, time_per_call

import nscontrol as nsc
from nscontrol.examples import ch04_posture_regulation as ex


def _foot(h: float) -> Iterator[dict[str, Any]]:
    from dataclasses import replace

    model, reg, plant = ex.foot_body_setup()
    system = reg.folded(plant)
    x0 = ex.initial_state(model, reg.design.q_star, -1.0)

    def run(sys_: Any) -> Any:
        return nsc.simulate(sys_, x0, (0.0, 8.0), method="moreau_jean", h=h, progress=False,
                            activation=model.contact_activation)

    run(system)                                   # warm-up (compiled kernels)
    start = time.perf_counter()
    traj = run(system)
    seconds = time.perf_counter() - start   # one run is seconds long: no repetition
    start = time.perf_counter()
    block = run(nsc.closed_loop(plant, reg))
    block_seconds = time.perf_counter() - start
    start = time.perf_counter()
    python = run(replace(system, compiled=None))
    python_seconds = time.perf_counter() - start
    steps = traj.stats["steps"]
    dev = float(np.abs(traj.x[-1, 1:4] - reg.design.q_star[1:4]).max())
    yield {"scenario": f"ch04 Example A (foot + body), A1, 8 s, h = {h:g}: compiled model "
                       f"vs the Python path", "size": steps,
           "ours_steps_per_s": steps / seconds, "ours_seconds": seconds,
           "reference": "the same model on Moreau-Jean's Python path",
           "reference_steps_per_s": steps / python_seconds, "ratio": python_seconds / seconds,
           "accuracy": {"path": traj.stats["path"], "final_deviation": dev,
                        "block_seconds": block_seconds, "block_path": block.stats["path"],
                        "python_seconds": python_seconds,
                        "max_x_difference_vs_python": float(np.abs(traj.x - python.x).max()),
                        "final_force_error_relative": float(
                            np.abs(traj.signals["impulse"][-1] / h - reg.design.lam_star).max()
                            / reg.design.lam_star.max())},
           "note": "no Siconos counterpart written (M(q) and nonlinear gaps need Python "
                   "callbacks in a LagrangianDS)"}


def _wall(h: float, have_siconos: bool, why: str) -> dict[str, Any]:
    e = 0.5
    _, reg, plant = ex.wall_mass_setup(e)
    loop = nsc.closed_loop(plant, reg.state_feedback())

    def ours() -> Any:
        return nsc.simulate(loop, [ex.WALL_Q0, 0.0], (0.0, 5.0), method="moreau_jean", h=h,
                            progress=False)

    traj = ours()
    steps = traj.stats["steps"]
    seconds = time_per_call(ours, budget=2.0)
    record: dict[str, Any] = {
        "scenario": f"ch04 Example C (wall), e = {e}, 5 s, h = {h:g}", "size": steps,
        "ours_steps_per_s": steps / seconds, "reference": None, "reference_steps_per_s": None,
        "ratio": None, "accuracy": {"q_final_ours": float(traj.x[-1, 0]),
                                    "path": traj.stats["path"]}}
    if not have_siconos:
        record["note"] = why
        return record
    sic = run_siconos("ch04_wall.py", {"m": 1.0, "kp": ex.WALL_KP, "kd": ex.WALL_KD,
                                       "force": ex.WALL_FORCE, "q0": ex.WALL_Q0, "e": e,
                                       "h": h, "T": 5.0, "repeats": 3})[-1]
    q_sic = np.array(sic["q_history"])
    q_ours = traj.x[1:, 0]
    k = min(q_sic.size, q_ours.size)
    record.update(reference=siconos_version() + " LagrangianLinearTIDS + MoreauJeanOSI",
                  reference_steps_per_s=sic["steps"] / sic["seconds"],
                  ratio=(steps / seconds) / (sic["steps"] / sic["seconds"]))
    record["accuracy"].update(
        q_final_siconos=sic["q"], max_q_difference=float(np.abs(q_ours[:k] - q_sic[:k]).max()),
        last_impulse_ours=float(traj.signals["impulse"][-1, 0]), last_impulse_siconos=sic["P"])
    return record


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    have_siconos, why = siconos_available()
    steps = (1e-3,) if quick else (1e-3, 2.5e-4)
    for h in steps:
        yield _wall(h, have_siconos, why)
    for h in steps:
        yield from _foot(h)

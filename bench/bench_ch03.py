"""Chapter 3: the closed-loop tracking runs, ours against Siconos on the 1-DOF task.

1. ``one-dof``: a unit mass above the ground under the chapter's switching controller
   (half-sine task, e = 0.7, h = 1e-3, one 8 s cycle, 8 000 steps), ``one_dof_tracking`` on
   its default path (the compiled closed loop; ``path`` in ``accuracy``). Siconos runs the same
   scenario (``LagrangianLinearTIDS``, Newton impact, Moreau–Jean θ = ½, LCP) with the same
   controller written in its Python (``bench/siconos/ch03_one_dof.py``). ``ratio`` = our
   steps/s over Siconos'; ``accuracy``: largest position difference over the free motion
   before the first impact (both schemes are the same θ-method: they should agree to
   rounding), the impact times of both and how many coincide to within one step.
2. ``two-link`` (no reference): the 30 s, three-cycle run of the arm at h = 1e-3 (1e-4 unless
   ``quick``: 300 000 steps), our steps/s; the Siconos Python bindings would need a
   Python-side ``LagrangianDS`` with plugins for M(q), forces and Jacobians, not done.
   This is the example's default run (compiled: ``path`` in ``accuracy``); record 4
   compares the compiled and Python paths of the same loop.
3. ``two-link M(q), compiled``: the arm's compiled model (``TwoLinkArm().system()`` carries a
   ``CompiledModel``) under a sampled joint PD written as a compiled block, 30 s at
   h = 1e-4 (300 000 steps, impacts on the ground), against the same loop on the Python path
   (``closed_loop(..., compiled=False)``, a 3 s run) in the same process: what the compiled
   Moreau–Jean loop does for M(q) once a controller has a compiled form.

4. ``two-link, compiled tracking controller``: the run of 2. (30 s, h = 1e-4) with the
   switching controller's compiled form in ``closed_loop`` (the compiled Moreau–Jean loop
   with the arm's compiled model), against the same loop on the Python path
   (``compiled=False``, a 3 s run) in the same process; ``accuracy``: the largest state
   difference over those 3 s and the cycles completed.
5. ``1-DOF, Python path``: scenario 1 on the fallback path (``one_dof_tracking(...,
   compiled=False)``: the same controller kernels called from Moreau–Jean's Python loop);
   ``ratio``: its steps/s over Siconos' (measured in 1.), when Siconos is there.

Run: ``nscontrol bench ch03 --json``.
"""

import math
import os
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version

from nscontrol.examples.ch03_two_link_tracking import one_dof_tracking, two_link_tracking

H = 1e-3
OMEGA = 2 * math.pi / 8


def _timed(fn: Any) -> tuple[float, Any]:
    fn()                                   # warm-up: compiled kernels, caches
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    seconds, ours = _timed(lambda: one_dof_tracking(cycles=1, h=H, restitution=0.7))
    steps = ours.traj.t.size - 1
    rate = steps / seconds
    impacts = [float(t) for t in ours.traj.t[:-1][
        (ours.traj.signals["impulse"][1:, 0] > 0) & (ours.traj.signals["impulse"][:-1, 0] == 0)
        & (ours.traj.x[:-1, 1] < 0)]]
    record: dict[str, Any] = {
        "scenario": f"ch03 1-DOF tracking, one 8 s cycle, e = 0.7, h = {H:g}",
        "size": steps, "ours_steps_per_s": rate, "reference": None,
        "reference_steps_per_s": None, "ratio": None,
        "accuracy": {"impacts_ours": len(impacts), "first_impact_ours": impacts[0],
                     "path": ours.traj.stats["path"]},
        # the ratio moves with the machine's load (both sides share its cores)
        "load_average_1min": os.getloadavg()[0]}
    sic_rate = None
    have, why = siconos_available()
    if not have:
        record["note"] = why
    else:
        payload = {"h": H, "T": 8.0, "e": 0.7, "q0": 0.05, "A": 0.1, "omega": OMEGA,
                   "g1": 5.0, "g2": 5.0, "Kf": 0.5, "g": 9.81, "sample_every": 1}
        sic = run_siconos("ch03_one_dof.py", payload)[-1]
        sic_rate = float(sic["steps"] / sic["seconds"])
        q_sic = np.array(sic["q"])
        first = int(round(impacts[0] / H))
        n = min(first, q_sic.size, ours.traj.t.size)
        sic_imp = sic["impacts"]
        same = sum(any(abs(a - b) <= 1.5 * H for b in sic_imp) for a in impacts)
        record.update(reference=siconos_version() + " MoreauJeanOSI + LCP, Python controller",
                      reference_steps_per_s=sic_rate, ratio=rate / sic_rate)
        record["accuracy"].update(
            max_q_difference_before_first_impact=float(np.max(np.abs(
                ours.traj.x[:n, 0] - q_sic[:n]))),
            impacts_siconos=len(sic_imp), first_impact_siconos=sic_imp[0] if sic_imp else None,
            impacts_within_one_step=same)
    yield record

    h = 1e-3 if quick else 1e-4
    start = time.perf_counter()
    arm = two_link_tracking("siconos-current", cycles=3, h=h)
    seconds = time.perf_counter() - start
    steps = arm.traj.t.size - 1
    yield {"scenario": f"ch03 two-link arm, 3 cycles (30 s), h = {h:g}", "size": steps,
           "ours_steps_per_s": steps / seconds, "ours_seconds": seconds, "reference": None,
           "reference_steps_per_s": None, "ratio": None,
           "note": "no Siconos counterpart (needs a Python-side LagrangianDS with plugins)",
           "accuracy": {"cycles": len([c for c in arm.controller.cycles
                                       if math.isfinite(c.t_constrained)]),
                        "path": arm.traj.stats["path"]}}
    yield _compiled_arm(quick)
    yield _compiled_tracking(quick)
    yield _python_one_dof(sic_rate)


def _tracking_loop(arm: bool, compiled: bool) -> tuple[Any, Any, Any]:
    """The chapter's switching controller on the arm (the ``siconos-current`` set-up) or
    on the 1-DOF mass, as a ``closed_loop`` block; returns ``(loop, x0, controller)``."""
    import nscontrol as nsc
    from nscontrol.design.complementarity_tracking import (
        CircleTask,
        ContactPhaseDesign,
        HalfSineTask,
        PBCGains,
        SwitchingTrackingController,
        TransitionDesign,
    )
    from nscontrol.systems.two_link import OneDofMass, TwoLinkArm

    if arm:
        model: Any = TwoLinkArm()
        ctrl = SwitchingTrackingController(model, CircleTask(period=10.0),
                                           PBCGains(8.0, 7.0, 0.5), TransitionDesign(),
                                           ContactPhaseDesign(lam_rate=1.5))
        x0 = np.array([0.9, -1.6, 0.0, 0.0])
    else:
        model = OneDofMass()
        ctrl = SwitchingTrackingController(model, HalfSineTask(omega=OMEGA),
                                           PBCGains(5.0, 5.0, 0.5), TransitionDesign(),
                                           ContactPhaseDesign(lam_rate=1.5))
        x0 = np.array([0.05, 0.0])
    return nsc.closed_loop(model.system(0.7), ctrl, compiled=compiled), x0, ctrl


def _compiled_tracking(quick: bool) -> dict[str, Any]:
    import nscontrol as nsc

    h, T, T_py = (1e-3, 30.0, 3.0) if quick else (1e-4, 30.0, 3.0)

    def run_loop(compiled: bool, T_run: float) -> tuple[Any, Any]:
        loop, x0, ctrl = _tracking_loop(True, compiled)
        return nsc.simulate(loop, x0, (0.0, T_run), method="moreau_jean", h=h, theta=0.5,
                            progress=False), ctrl
    run_loop(True, 0.01)                                     # warm-up
    start = time.perf_counter()
    fast, ctrl = run_loop(True, T)
    seconds = time.perf_counter() - start
    start = time.perf_counter()
    slow, _ = run_loop(False, T_py)
    py_seconds = time.perf_counter() - start
    steps, py_steps = fast.stats["steps"], slow.stats["steps"]
    k = py_steps + 1
    log = ctrl.signals(fast)
    return {"scenario": f"ch03 two-link arm, compiled tracking controller, {T:g} s, "
                        f"h = {h:g}, against the Python path", "size": steps,
            "ours_steps_per_s": steps / seconds, "ours_seconds": seconds,
            "reference": "the same loop on Moreau-Jean's Python path",
            "reference_steps_per_s": py_steps / py_seconds,
            "ratio": (steps / seconds) / (py_steps / py_seconds),
            "accuracy": {"path": fast.stats["path"],
                         "cycles": len([c for c in ctrl.cycles_of(fast)
                                        if math.isfinite(c.t_constrained)]),
                         "take_offs": int(log["cycle"].max()),
                         "max_x_difference_first_3s": float(np.abs(fast.x[:k]
                                                                   - slow.x[:k]).max())}}


def _python_one_dof(sic_rate: float | None) -> dict[str, Any]:
    seconds, ours = _timed(lambda: one_dof_tracking(cycles=1, h=H, restitution=0.7,
                                                    compiled=False))
    steps = ours.traj.t.size - 1
    rate = steps / seconds
    return {"scenario": f"ch03 1-DOF tracking, Python path (compiled=False), one 8 s cycle, "
                        f"e = 0.7, h = {H:g}", "size": steps, "ours_steps_per_s": rate,
            "reference": None if sic_rate is None else "Siconos (record 1)",
            "reference_steps_per_s": sic_rate,
            "ratio": None if sic_rate is None else rate / sic_rate,
            "accuracy": {"path": ours.traj.stats["path"],
                         "path_reason": ours.traj.stats["path_reason"]}}


def _compiled_arm(quick: bool) -> dict[str, Any]:
    import nscontrol as nsc
    from nscontrol.systems import StateFeedback, TwoLinkArm

    h, T = (1e-3, 30.0) if quick else (1e-4, 30.0)
    plant = TwoLinkArm().system(0.7)
    # joint PD towards a posture below the ground line: the end effector hits and rests
    pd = StateFeedback([[-30.0, 0.0, -8.0, 0.0], [0.0, -30.0, 0.0, -8.0]],
                       k=[30.0 * -0.3, 30.0 * 0.4], period=1e-3)
    x0 = [0.8, -0.6, 0.0, 0.0]

    def run_loop(compiled: bool, T_run: float) -> Any:
        return nsc.simulate(nsc.closed_loop(plant, pd, compiled=compiled), x0, (0.0, T_run),
                            method="moreau_jean", h=h, progress=False)
    run_loop(True, 0.01)                                     # warm-up
    start = time.perf_counter()
    fast = run_loop(True, T)
    seconds = time.perf_counter() - start
    T_py = 3.0
    start = time.perf_counter()
    slow = run_loop(False, T_py)
    py_seconds = time.perf_counter() - start
    steps, py_steps = fast.stats["steps"], slow.stats["steps"]
    k = py_steps + 1
    return {"scenario": f"ch03 two-link arm, compiled model + compiled PD block, {T:g} s, "
                        f"h = {h:g}, against the Python path", "size": steps,
            "ours_steps_per_s": steps / seconds, "ours_seconds": seconds,
            "reference": "the same loop on Moreau-Jean's Python path",
            "reference_steps_per_s": py_steps / py_seconds,
            "ratio": (steps / seconds) / (py_steps / py_seconds),
            "accuracy": {"path": fast.stats["path"], "impacts": len(fast.events),
                         "max_x_difference_first_3s": float(np.abs(fast.x[:k]
                                                                   - slow.x[:k]).max())}}


if __name__ == "__main__":
    import json

    for rec in run(quick=True):
        print(json.dumps(rec, default=float))

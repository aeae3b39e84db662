"""Sliding-mode control: the sampled first-order SMC against Siconos's control toolbox, and the
super-twisting problem against a generic implicit solver.

Scenarios:

* first-order SMC on the double integrator ``x'' = u``, ``sigma = x1 + x2``, ``x0 = (1, 0)``,
  ``alpha = 1``, ``h = 1e-3``, ``T = 10`` (``T = 2`` with ``--quick``): our implicit
  ``FirstOrderSMC`` run by ``simulate(closed_loop(plant, ctrl), method="sampled_zoh")`` (one
  ``simulate`` call per run, fixed costs included) against Siconos's ``LinearSMC``, and our
  explicit one
  against ``ExplicitLinearSMC`` (``ControlZOHSimulation``, run by /usr/bin/python3); steps/s of
  both, ratio, and the accuracy figures: reaching time, ``max |sigma|`` after it,
  ``max |x_ours - x_siconos|`` over the run;
* the super-twisting problem ``x'' = u + 0.3 sin 5t`` (``L = 1.5``, ``T = 6``): our
  continuous-time run (switching integrator through second-order sliding) and our implicit
  sampled controller at ``h = 1e-3``, with the reaching-time error against the event-driven
  reference 2.1363530; against ``solve_nivp`` (semismooth Newton, backward Euler) when it is
  importable from a separate environment (``$SOLVE_NIVP_PYTHON``, default
  ``/tmp/nivp-venv/bin/python``), skipped with a note otherwise.

Run: ``nscontrol bench smc --json``.
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import json
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version

import nscontrol as nsc
from nscontrol.analysis import reaching_time
from nscontrol.design import FirstOrderSMC, SuperTwistingController, super_twisting_gains
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems import SlidingModePlant

T_REF = 2.1363530       # event-driven reference (tests/systems/test_sliding_mode_plant.py)
NIVP_PYTHON = os.environ.get("SOLVE_NIVP_PYTHON", "/tmp/nivp-venv/bin/python")
NIVP_SCRIPT = Path(__file__).resolve().parent / "solve_nivp" / "super_twisting.py"


def run_sampled(plant: Any, ctrl: Any, x0: Any, t_span: tuple[float, float]) -> Any:
    """The sampled loop, as a user runs it."""
    return nsc.simulate(nsc.closed_loop(plant, ctrl), x0, t_span, method="sampled_zoh",
                        progress=False)


def _best_of(fn: Any, repeats: int) -> tuple[Any, float]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def _first_order(discretization: str, quick: bool) -> dict[str, Any]:
    h, T, alpha = 1e-3, 2.0 if quick else 10.0, 1.0
    plant = SlidingModePlant.double_integrator()
    ctrl = FirstOrderSMC(plant, alpha, h, discretization)
    run_sampled(plant, ctrl, [1.0, 0.0], (0.0, 0.01))            # warm-up (compilation)
    tr, seconds = _best_of(lambda: run_sampled(plant, ctrl, [1.0, 0.0], (0.0, T)), 5)
    steps = tr.t.size - 1
    s = tr.signal("s")
    name = "LinearSMC" if discretization == "implicit" else "ExplicitLinearSMC"
    t_r = reaching_time(tr.t, s, 1e-12)
    acc: dict[str, Any] = {"ours_reaching_time": t_r,
                           "ours_max_abs_sigma_after_1.01": float(np.max(np.abs(s[tr.t > 1.01])))}
    record: dict[str, Any] = {
        "scenario": f"first-order SMC ({discretization}) on a double integrator, h = {h:g}, "
                    f"T = {T:g}", "size": steps, "ours_steps_per_s": steps / seconds,
        "reference": None, "reference_steps_per_s": None, "ratio": None, "accuracy": acc}
    ok, why = siconos_available()
    if not ok:
        record["note"] = why
        return record
    sic = run_siconos("smc_double_integrator.py", {
        "controller": name, "x0": [1.0, 0.0], "alpha": alpha, "h": h, "T": T,
        "repeats": 1 if quick else 3})[-1]
    sig = np.array(sic["sigma"])
    ts = np.array(sic["t"])
    n = min(sig.size, s.size)
    acc.update({"siconos_reaching_time": reaching_time(ts, sig, 1e-12),
                "siconos_max_abs_sigma_after_1.01": float(np.max(np.abs(sig[ts > 1.01]))),
                "max_abs_sigma_difference": float(np.max(np.abs(sig[:n] - s[:n])))})
    ref_rate = sic["steps"] / sic["seconds"]
    record.update(reference=f"{siconos_version()} ControlZOHSimulation + {name}",
                  reference_steps_per_s=ref_rate, ratio=(steps / seconds) / ref_rate)
    return record


def _super_twisting(quick: bool) -> Iterator[dict[str, Any]]:
    k1, k2 = super_twisting_gains(1.5)
    plant = SlidingModePlant.double_integrator(disturbance=Exosystem.sinusoid(0.3, omega=5.0))
    loop = plant.super_twisting_loop(k1, k2)
    tr, seconds = _best_of(lambda: nsc.simulate(loop, [0.5, 0.0, 0.0], (0.0, 6.0),
                                                progress=False), 1)
    t_r = float(tr.event_times("two_sliding_start")[0])
    nivp = _solve_nivp(1e-2 if quick else 1e-3)
    record: dict[str, Any] = {
        "scenario": "super-twisting x'' = u + 0.3 sin 5t, continuous time through "
                    "second-order sliding (switching integrator), T = 6",
        "size": int(tr.stats.get("pieces", 0)), "ours_steps_per_s": None,
        "ours_seconds": seconds, "reference": None, "reference_steps_per_s": None,
        "ratio": None, "accuracy": {"ours_reaching_time_error": abs(t_r - T_REF)}}
    if nivp is None or "error" in nivp:
        record["note"] = ("solve_nivp not importable from " + NIVP_PYTHON
                          if nivp is None else f"solve_nivp failed: {nivp['error']}")
    else:
        record.update(reference=f"solve_nivp {nivp['version']} ({nivp['setup']})",
                      reference_seconds=nivp["seconds"],
                      ratio=nivp["seconds"] / seconds)
        record["accuracy"].update(reference_reaching_time_error=abs(nivp["t_reach"] - T_REF),
                                  reference_steps=nivp["steps"])
    yield record
    h = 1e-3
    ctrl = SuperTwistingController(plant, k1, k2, h)
    run_sampled(plant, ctrl, [0.5, 0.0], (0.0, 0.01))
    trs, seconds = _best_of(lambda: run_sampled(plant, ctrl, [0.5, 0.0], (0.0, 6.0)), 5)
    s = trs.signal("s")
    yield {"scenario": f"super-twisting, implicit sampled controller, h = {h:g}, T = 6",
           "size": trs.t.size - 1, "ours_steps_per_s": (trs.t.size - 1) / seconds,
           "reference": None, "reference_steps_per_s": None, "ratio": None,
           "note": "no sampled super-twisting in Siconos's control toolbox",
           "accuracy": {"max_abs_s_after_4": float(np.max(np.abs(s[trs.t >= 4.0])))}}


def _solve_nivp(h: float) -> dict[str, Any] | None:
    if not Path(NIVP_PYTHON).exists():
        return None
    proc = subprocess.run([NIVP_PYTHON, str(NIVP_SCRIPT), repr(h)], capture_output=True,
                          text=True,
                          timeout=900)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = proc.stderr.strip().splitlines()[-1:] or ["no output"]
        if "No module named" in tail[0]:
            return None
        return {"error": tail[0]}
    return json.loads(lines[-1])


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    """The records of the scenarios in the module's docstring."""
    yield _first_order("implicit", quick)
    yield _first_order("explicit", quick)
    yield from _super_twisting(quick)

"""Chapter 7: the one-link robot with friction compensation and a reduced-order observer.

Scenarios:

* the reference example's 10 s set-point run (Stribeck friction, h = 1e-4, exact
  compensation): our steps/s (no Siconos counterpart of the set-valued Stribeck law);
* the same loop on Coulomb friction (T_s = T_c = 0.2, no viscous term), T = 2 s, against
  Siconos (relay Lur'e system by EulerMoreauOSI + Relay, the same controller and observer
  written again in its script, the torque held in the system's ``b``): steps/s of both and
  ``max |theta_ours - theta_siconos|``;
* the kappa diagram (kappa in [0, 1.5], set-point runs at h = 1e-3, T = 10): wall time
  serial and on 2 local worker processes (``nscontrol.sweep``).

Run: ``nscontrol bench ch07 --json`` (``--quick``: 21 kappa points, 2 s runs).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version

from nscontrol import sweep
from nscontrol.design.friction_compensation import PDLaw, SetPoint, simulate_friction_loop
from nscontrol.examples import ch07_friction_compensation as ex
from nscontrol.laws import Stribeck
from nscontrol.systems import OneLinkRobot

P = ex.REFERENCE


def _timed(fn: Any) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _reference_run(quick: bool) -> dict[str, Any]:
    T = 2.0 if quick else P["T"]
    robot = OneLinkRobot(P["J"], ex.reference_friction())
    pd = PDLaw(P["kp"], P["kd"], P["J"], SetPoint(P["theta_r"]))
    simulate_friction_loop(robot, pd, l=P["l"], kappa=1.0, h=P["h"], T=0.01)   # warm-up
    run, seconds = _timed(lambda: simulate_friction_loop(robot, pd, l=P["l"], kappa=1.0,
                                                         h=P["h"], T=T))
    steps = run.t.size - 1
    return {"scenario": f"ch07 set-point run, Stribeck, h = {P['h']:g}, T = {T:g}",
            "size": steps, "ours_steps_per_s": steps / seconds, "reference": None,
            "reference_steps_per_s": None, "ratio": None,
            "note": "no Siconos counterpart of the set-valued Stribeck law",
            "accuracy": {"final_error": float(abs(run.error[-1]))}}


def _coulomb_run(quick: bool) -> dict[str, Any]:
    T, h, Tc, kappa = 2.0, P["h"], 0.2, 1.0
    robot = OneLinkRobot(P["J"], Stribeck(Tc, Tc, 1.0, 2.0, 0.0))
    pd = PDLaw(P["kp"], P["kd"], P["J"], SetPoint(P["theta_r"]))
    simulate_friction_loop(robot, pd, l=P["l"], kappa=kappa, h=h, T=0.01)
    run, seconds = _timed(lambda: simulate_friction_loop(robot, pd, l=P["l"], kappa=kappa,
                                                         h=h, T=T))
    steps = run.t.size - 1
    record: dict[str, Any] = {
        "scenario": f"ch07 one-link, Coulomb friction, PD + compensation + observer, "
                    f"h = {h:g}, T = {T:g}",
        "size": steps, "ours_steps_per_s": steps / seconds, "reference": None,
        "reference_steps_per_s": None, "ratio": None, "accuracy": {}}
    ok, why = siconos_available()
    if not ok:
        record["note"] = why
        return record
    sic = run_siconos("ch07_one_link.py", {
        "J": P["J"], "Tc": Tc, "kp": P["kp"], "kd": P["kd"], "l": P["l"], "kappa": kappa,
        "theta_r": P["theta_r"], "theta0": 0.0, "h": h, "T": T,
        "repeats": 1 if quick else 3})[-1]
    theirs = np.array(sic["theta"])
    n = min(theirs.size, run.theta.size)
    record.update(reference=siconos_version() + " EulerMoreauOSI + Relay (Python loop)",
                  reference_steps_per_s=sic["steps"] / sic["seconds"],
                  ratio=(steps / seconds) / (sic["steps"] / sic["seconds"]))
    record["accuracy"] = {"max_theta_difference": float(np.max(np.abs(run.theta[:n]
                                                                        - theirs[:n])))}
    return record


def _diagram(quick: bool) -> dict[str, Any]:
    kappas = list(np.linspace(0.0, 1.5, 21 if quick else ex.KAPPA_POINTS))
    _, serial = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor="serial",
                                         progress=False))
    with ProcessPoolExecutor(2) as pool:
        _, parallel = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor=pool,
                                               progress=False))
    return {"scenario": f"ch07 kappa diagram, {len(kappas)} runs of {ex.KAPPA_T:g} s at "
                        f"h = {ex.KAPPA_H:g}: serial vs 2 worker processes",
            "size": len(kappas), "ours_steps_per_s": None, "reference": "serial",
            "reference_steps_per_s": None, "ratio": serial / parallel,
            "accuracy": {"serial_seconds": serial, "two_workers_seconds": parallel}}


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    yield _reference_run(quick)
    yield _coulomb_run(quick)
    yield _diagram(quick)

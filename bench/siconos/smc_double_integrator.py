"""Siconos side of bench_smc.py: first-order sliding-mode control of a double integrator
with the control toolbox (ControlZOHSimulation + LinearSMC or ExplicitLinearSMC).

Run by /usr/bin/python3. Reads JSON on stdin: ``controller`` ("LinearSMC" or
"ExplicitLinearSMC"), ``x0``, ``alpha``, ``h``, ``T``, ``repeats``. The plant
``x1' = x2``, ``x2' = u``, sliding variable ``sigma = x1 + x2``, sensor reading the whole
state. Prints one JSON line with ``steps``, ``seconds`` (``run()`` only, best of
``repeats``), the times and ``sigma`` at every step and ``u`` at every step.
"""

import json
import sys
import time

import numpy as np
import siconos.kernel as sk
from siconos.control.controller import ExplicitLinearSMC, LinearSMC
from siconos.control.sensor import LinearSensor
from siconos.control.simulation import ControlZOHSimulation


def once(sc):
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    ds = sk.FirstOrderLinearTIDS(np.array(sc["x0"], dtype=float), A.copy())
    sim = ControlZOHSimulation(0.0, sc["T"], sc["h"])
    sim.setSaveOnlyMainSimulation(True)
    sim.addDynamicalSystem(ds)
    sens = LinearSensor(ds, np.eye(2), np.zeros((2, 2)))
    sim.addSensor(sens, sc["h"])
    kind = LinearSMC if sc["controller"] == "LinearSMC" else ExplicitLinearSMC
    ctrl = kind(sens)
    ctrl.setCsurface(np.array([[1.0, 1.0]]))
    ctrl.setB(np.array([[0.0], [1.0]]))
    ctrl.setAlpha(sc["alpha"])
    sim.addActuator(ctrl, sc["h"])
    sim.initialize()
    start = time.perf_counter()
    sim.run()
    seconds = time.perf_counter() - start
    data = np.array(sim.data())
    return seconds, data


def main():
    sc = json.loads(sys.stdin.read())
    best, data = None, None
    for _ in range(int(sc.get("repeats", 1))):
        seconds, data = once(sc)
        best = seconds if best is None else min(best, seconds)
    t, x, u = data[:, 0], data[:, 1:3], data[:, 3]
    print(json.dumps({"steps": int(t.size - 1), "seconds": best, "t": t.tolist(),
                      "sigma": (x[:, 0] + x[:, 1]).tolist(), "u": u.tolist()}))


if __name__ == "__main__":
    main()

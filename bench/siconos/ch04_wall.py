"""Siconos side of bench_ch04.py: Example C (a mass regulated against a wall).

Run by /usr/bin/python3 (Debian's python3-siconos). Reads JSON on stdin
``{"m", "kp", "kd", "force", "q0", "e", "h", "T", "repeats"}`` and prints one JSON line with
``steps``, ``seconds`` (the time loop, median of ``repeats`` runs), the final ``q``, ``v``,
the last impulse ``P`` and the largest penetration. The closed loop
``m q'' = -kp q - kd v + force + P`` is a LagrangianLinearTIDS (stiffness kp, damping kd,
constant external force); the wall ``g = -q >= 0`` a LagrangianLinearTIR with Newton's law.
"""

import json
import sys
import time

import numpy as np
import siconos.kernel as sk


def once(p):
    ds = sk.LagrangianLinearTIDS([p["q0"]], [0.0], np.array([[p["m"]]]),
                                 np.array([[p["kp"]]]), np.array([[p["kd"]]]))
    ds.setFExtPtr(np.array([p["force"]]))
    inter = sk.Interaction(sk.NewtonImpactNSL(p["e"]),
                           sk.LagrangianLinearTIR(np.array([[-1.0]])))
    nsds = sk.NonSmoothDynamicalSystem(0.0, p["T"])
    nsds.insertDynamicalSystem(ds)
    nsds.link(inter, ds)
    osi = sk.MoreauJeanOSI(0.5)
    osi.setConstraintActivationThreshold(1e-12)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, p["h"]), osi, sk.LCP())
    k, pen, q_hist = 0, 0.0, []
    start = time.perf_counter()
    while sim.hasNextEvent():
        sim.computeOneStep()
        k += 1
        q = float(ds.q()[0])
        pen = max(pen, q)
        q_hist.append(q)
        sim.nextStep()
    seconds = time.perf_counter() - start
    return {"steps": k, "seconds": seconds, "q": float(ds.q()[0]),
            "v": float(ds.velocity()[0]), "P": float(inter.lambda_(1)[0]),
            "penetration": pen, "q_history": q_hist}


def main():
    p = json.load(sys.stdin)
    runs = [once(p) for _ in range(max(1, int(p.get("repeats", 3))))]
    out = runs[-1]
    out["seconds"] = sorted(r["seconds"] for r in runs)[len(runs) // 2]
    print(json.dumps(out))


if __name__ == "__main__":
    main()

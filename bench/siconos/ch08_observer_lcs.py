"""Siconos side of bench_ch08.py: plant + Lur'e observer of spec ch08 §5.1 (ObserverLCS).

Run by /usr/bin/python3 (Debian's python3-siconos, numpy 1.x). Reads JSON on stdin::

    {"A_cl", "G", "H_cl" (rows of the two relations), "D", "B_cl", "x0", "h", "T", "theta",
     "amplitude", "omega"}

The closed loop is one first-order linear DS with the stacked state ``[x; xhat]`` (its ``A``
already holds the injection ``L C``) and two complementarity interactions,
``0 <= lambda_i ⟂ H_i X + D lambda_i + u(t) >= 0``, one for the plant and one for the
observer (``FirstOrderLinearTIR``, ``ComplementarityConditionNSL``, ``EulerMoreauOSI(theta)``,
``LCP``). The input ``u(t) = a sin(omega t)`` enters through ``b`` and the relations' ``e``,
set before every step to ``B_cl ((1-θ)u(t_k) + θu(t_{k+1}))`` and ``u(t_{k+1})`` (the same
sampling as nscontrol's θ-method). Prints one JSON line: ``{"t", "x", "steps_per_s",
"steps", "lcp_failures"}``.
"""

import json
import sys
import time

import numpy as np
import siconos.kernel as sk


def build(p):
    A = np.array(p["A_cl"], dtype=float)
    X0 = np.array(p["x0"], dtype=float)
    ds = sk.FirstOrderLinearTIDS(X0.copy(), A.copy())
    ds.setbPtr(np.zeros(A.shape[0]))
    nsds = sk.NonSmoothDynamicalSystem(0.0, p["T"])
    nsds.insertDynamicalSystem(ds)
    relations = []
    for i, H in enumerate(p["H_cl"]):
        C = np.array([H], dtype=float)
        Bi = np.zeros((A.shape[0], 1))
        Bi[:, 0] = np.array(p["G"][i], dtype=float)
        rel = sk.FirstOrderLinearTIR(C.copy(), Bi.copy())  # copies: see siconos-reference.md
        rel.setDPtr(np.array([[p["D"]]], dtype=float))
        rel.setePtr(np.zeros(1))
        inter = sk.Interaction(sk.ComplementarityConditionNSL(1), rel)
        nsds.link(inter, ds)
        relations.append(rel)
    osi = sk.EulerMoreauOSI(p["theta"])
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, p["h"]), osi, sk.LCP())
    return ds, relations, sim


def main():
    p = json.load(sys.stdin)
    ds, relations, sim = build(p)
    h, T, theta = p["h"], p["T"], p["theta"]
    B = np.array(p["B_cl"], dtype=float)
    n_steps = int(round(T / h))

    def u(t):
        return p["amplitude"] * np.sin(p["omega"] * t)

    ts = [0.0]
    xs = [np.array(ds.x()).copy().tolist()]
    start = time.perf_counter()
    for k in range(n_steps):
        t0, t1 = k * h, (k + 1) * h
        ds.setbPtr(B * ((1.0 - theta) * u(t0) + theta * u(t1)))
        for rel in relations:
            rel.setePtr(np.array([u(t1)]))
        sim.computeOneStep()
        xs.append(np.array(ds.x()).copy().tolist())
        ts.append(t1)
        sim.nextStep()
    elapsed = time.perf_counter() - start
    print(json.dumps({"t": ts, "x": xs, "steps": n_steps,
                      "steps_per_s": n_steps / elapsed}), flush=True)


if __name__ == "__main__":
    main()

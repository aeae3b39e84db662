"""Siconos side of bench_ch07.py: the one-link robot with Coulomb friction as a relay Lur'e
system (EulerMoreauOSI + Relay), closed by the same digital controller and observer.

Run by /usr/bin/python3. Reads JSON on stdin: ``J``, ``Tc`` (Coulomb level), ``kp``, ``kd``,
``l``, ``kappa``, ``theta_r``, ``theta0``, ``h``, ``T``, ``repeats``. The plant
``theta' = omega``, ``J omega' = u - Tc Sign(omega)`` is a FirstOrderLinearDS whose ``b``
carries the held torque ``u/J`` over each step; the relation ``y = omega``,
``r = (Tc/J) lambda`` with the relay law ``lambda in -Sign(y)``. The controller (PD +
compensation ``kappa Tc sign(omega_hat)``, 0 at 0) and the reduced-order observer (backward
Euler on the new sample) are written here again, in plain Python. Prints one JSON line with
``steps``, ``seconds`` (time loop only, best of ``repeats``) and the angle at every step.
"""

import json
import math
import sys
import time

import numpy as np
import siconos.kernel as sk


def one_link(sc):
    J, Tc, kp, kd, l = sc["J"], sc["Tc"], sc["kp"], sc["kd"], sc["l"]
    kappa, r, h, T = sc["kappa"], sc["theta_r"], sc["h"], sc["T"]
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    ds = sk.FirstOrderLinearDS(np.array([sc["theta0"], 0.0]), A.copy())
    ds.setb(np.zeros(2))
    rel = sk.FirstOrderLinearTIR(np.array([[0.0, 1.0]]), np.array([[0.0], [Tc / J]]))
    inter = sk.Interaction(sk.RelayNSL(1, -1.0, 1.0), rel)
    nsds = sk.NonSmoothDynamicalSystem(0.0, T)
    nsds.insertDynamicalSystem(ds)
    nsds.link(inter, ds)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, h), sk.EulerMoreauOSI(1.0),
                          sk.Relay())
    theta = sc["theta0"]
    xi = 0.0 - l * theta                  # omega_hat(0) = 0
    thetas = [theta]
    b = np.zeros(2)
    k = 0
    start = time.perf_counter()
    while sim.hasNextEvent():
        w_hat = xi + l * theta
        upd = -kp * (theta - r) - kd * w_hat
        comp = 0.0 if w_hat == 0.0 else math.copysign(kappa * Tc, w_hat)
        b[1] = (upd + comp) / J
        ds.setb(b)
        sim.computeOneStep()
        sim.nextStep()
        theta = float(ds.x()[0])
        xi = (xi + h * (-l * l * theta + upd / J)) / (1.0 + h * l)
        thetas.append(theta)
        k += 1
    return {"steps": k, "seconds": time.perf_counter() - start, "theta": thetas}


def main():
    sc = json.load(sys.stdin)
    best = None
    for _ in range(int(sc.get("repeats", 3))):
        out = one_link(sc)
        if best is None or out["seconds"] < best["seconds"]:
            best = out
    print(json.dumps(dict(name="one_link", **best)))


if __name__ == "__main__":
    main()

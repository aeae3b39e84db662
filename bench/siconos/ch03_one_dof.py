"""Siconos side of bench_ch03.py: the 1-DOF tracking task of chapter 3 in Siconos.

A unit mass above the ground (``LagrangianLinearTIDS``, gravity, Newton impact law,
Moreau–Jean θ = ½, LCP), driven by the chapter's switching passivity-based controller written
here again in plain Python (Siconos' Python cannot import nscontrol): free motion on the
positive half-wave of ``q_d = A sin ωt``, the time warp and the cubic dive to ``-d``, the
pressing law after the first impact, the constrained law with the force ramp after 5 contact
steps, the quintic lift-off. The external force is set before every step (zero-order hold).

Reads JSON on stdin ``{"h", "T", "e", "q0", "A", "omega", "g1", "g2", "Kf", "g"}`` and prints
one JSON line: ``steps``, ``seconds`` (time loop, controller included), ``q`` and ``v`` every
``sample_every`` steps, the impact times (rising edges of the impulse while approaching).
"""

import json
import math
import sys
import time

import numpy as np
import siconos.kernel as sk


def blend(th):
    if th >= 1.0:
        return 1.0, 0.0, 0.0
    th = max(th, 0.0)
    return (10 * th**3 - 15 * th**4 + 6 * th**5, 30 * th**2 - 60 * th**3 + 30 * th**4,
            60 * th - 180 * th**2 + 120 * th**3)


class Controller:
    """Phases 0 free, 1 approach, 2 impacts, 3 constrained (one coordinate)."""

    def __init__(self, p):
        self.p = p
        self.A, self.w = p["A"], p["omega"]
        self.P = 2 * math.pi / self.w
        self.phase, self.k, self.count, self.lift = 0, 0, 0, -math.inf
        self.tau0 = self.d = self.q10 = math.nan

    def nominal(self, t):
        A, w = self.A, self.w
        return A * math.sin(w * t), A * w * math.cos(w * t), -A * w * w * math.sin(w * t)

    def tau0_of(self, k):
        return k * self.P + (math.pi - math.asin(0.01 / self.A)) / self.w

    def reference(self, t):
        if self.phase == 0:
            a, b, c = self.nominal(t)
            s, ds, dds = blend((t - self.lift) / 0.5)
            if s < 1.0:
                a, b, c = s * a, ds / 0.5 * a + s * b, dds / 0.25 * a + 2 * ds / 0.5 * b + s * c
            return a, b, c, None, 0.0
        if self.phase == 1:
            delta, Delta = 0.4, 1.0
            if t < self.tau0 + delta:
                s, d = t - self.tau0, delta
                psi = self.tau0 + (s - d) ** 2 * s / d**2
                dpsi = (s - d) * (3 * s - d) / d**2
                ddpsi = (6 * s - 4 * d) / d**2
                a, b, c = self.nominal(psi)
                return a, b * dpsi, c * dpsi**2 + b * ddpsi, None, 0.0
            th = min((t - self.tau0 - delta) / Delta, 1.0)
            amp = self.q10 + self.d
            if th >= 1.0:
                return -self.d, 0.0, 0.0, None, 0.0
            return (self.q10 - 3 * amp * th * th + 2 * amp * th**3,
                    (-6 * amp * th + 6 * amp * th * th) / Delta,
                    (-6 * amp + 12 * amp * th) / Delta**2, None, 0.0)
        if self.phase == 2:
            return 0.0, 0.0, 0.0, -self.d, 0.0
        return 0.0, 0.0, 0.0, None, 1.5 * max((self.k + 1) * self.P - t, 0.0)

    def __call__(self, t, q, v, lam):
        p = self.p
        g1, g2 = p["g1"], p["g2"]
        if self.phase == 0 and t >= self.tau0_of(self.k) - 1e-12:
            qd, dqd, _, _, _ = self.reference(t)
            s = v - dqd + g2 * (q - qd)
            v1 = 0.5 * s * s
            self.d = min(max(100.0 * math.sqrt(v1), 0.005), 0.05)
            self.tau0, self.q10 = t, self.nominal(t)[0]
            self.phase = 1
        elif self.phase == 1 and lam > 0.0:
            self.phase, self.count = 2, 1
        elif self.phase == 2:
            self.count = self.count + 1 if lam > 0.0 else 0
            if self.count >= 5:
                self.phase = 3
        if self.phase in (2, 3) and t >= (self.k + 1) * self.P - 1e-12:
            self.phase, self.lift, self.k = 0, t, self.k + 1
        qd, dqd, ddqd, qstar, lam_d = self.reference(t)
        dqr = dqd - g2 * (q - qd)
        ddqr = ddqd - g2 * (v - dqd)
        sbar = v - dqr if qstar is None else v - dqd + g2 * (q - qstar)
        u = ddqr + p["g"] - g1 * sbar
        if self.phase == 3:
            u += -lam_d + p["Kf"] * (min(lam, 20.0) - lam_d)
        return u


def main():
    p = json.load(sys.stdin)
    h, T, g = p["h"], p["T"], p["g"]
    mass = sk.LagrangianLinearTIDS([p["q0"]], [0.0], np.eye(1))
    force = np.array([-g])
    mass.setFExtPtr(force)
    inter = sk.Interaction(sk.NewtonImpactNSL(p["e"]), sk.LagrangianLinearTIR(np.eye(1)))
    nsds = sk.NonSmoothDynamicalSystem(0.0, T)
    nsds.insertDynamicalSystem(mass)
    nsds.link(inter, mass)
    osi = sk.MoreauJeanOSI(0.5)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, h), osi, sk.LCP())
    ctrl = Controller(p)
    every = p.get("sample_every", 100)
    qs, vs, impacts = [], [], []
    lam_prev, k = 0.0, 0
    start = time.perf_counter()
    while sim.hasNextEvent():
        q, v = float(mass.q()[0]), float(mass.velocity()[0])
        if k % every == 0:
            qs.append(q)
            vs.append(v)
        force[0] = -g + ctrl(k * h, q, v, lam_prev / h)
        mass.setFExtPtr(force)
        sim.computeOneStep()
        lam = float(inter.lambda_(1)[0])
        if lam > 0.0 and lam_prev == 0.0 and v < 0.0:
            impacts.append(k * h)
        lam_prev = lam
        k += 1
        sim.nextStep()
    seconds = time.perf_counter() - start
    print(json.dumps({"steps": k, "seconds": seconds, "q": qs, "v": vs, "impacts": impacts}))


if __name__ == "__main__":
    main()

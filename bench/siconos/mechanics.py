"""Siconos side of bench_mechanics.py: the same mechanical scenarios, the time loop timed.

Run by /usr/bin/python3 (Debian's python3-siconos, numpy 1.x). Reads JSON on stdin:
``{"scenarios": [{"kind": "ball_mj"|"ball_ed"|"stack"|"cradle", ...}], "budget": seconds}``
and prints one JSON line per scenario with ``steps``, ``seconds`` (time loop only) and the
figures needed for accuracy (impact times, impulses, momentum, energy, penetration).
"""

import json
import sys
import time

import numpy as np
import siconos.kernel as sk
import siconos.numerics as sn


def _ball(e, g, q0):
    ball = sk.LagrangianLinearTIDS([q0], [0.0], np.eye(1))
    ball.setFExtPtr(np.array([-g]))
    inter = sk.Interaction(sk.NewtonImpactNSL(e), sk.LagrangianLinearTIR(np.eye(1)))
    nsds = sk.NonSmoothDynamicalSystem(0.0, 1.0)
    nsds.insertDynamicalSystem(ball)
    nsds.link(inter, ball)
    return nsds, ball, inter


def ball_mj(sc):
    h, T = sc["h"], sc["T"]
    nsds, ball, inter = _ball(sc["e"], sc["g"], sc["q0"])
    nsds.setT(T)
    osi = sk.MoreauJeanOSI(0.5)
    osi.setConstraintActivationThreshold(1e-12)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, h), osi, sk.LCP())
    impacts, pen, prev, k = [], 0.0, 0.0, 0
    start = time.perf_counter()
    while sim.hasNextEvent():
        sim.computeOneStep()
        lam = inter.lambda_(1)[0]
        q = ball.q()[0]
        k += 1
        if lam > 0.0 and prev == 0.0:
            impacts.append(k * h)
        prev = lam
        pen = max(pen, -q)
        sim.nextStep()
    seconds = time.perf_counter() - start
    return {"steps": k, "seconds": seconds, "impacts": impacts, "penetration": pen,
            "final": [float(ball.q()[0]), float(ball.velocity()[0])]}


def _ball_ed_once(sc):
    T = sc["T"]
    nsds, ball, inter = _ball(sc["e"], sc["g"], sc["q0"])
    nsds.setT(T)
    sim = sk.EventDriven(nsds, sk.TimeDiscretisation(0.0, T))
    sim.insertIntegrator(sk.LsodarOSI())
    sim.insertNonSmoothProblem(sk.LCP(), sk.SICONOS_OSNSP_ED_IMPACT)
    sim.insertNonSmoothProblem(sk.LCP(), sk.SICONOS_OSNSP_ED_SMOOTH_ACC)
    manager = sim.eventsManager()
    impacts, events = [], 0
    start = time.perf_counter()
    while sim.hasNextEvent() and events < sc["max_events"]:
        sim.advanceToEvent()
        if manager.nextEvent().getType() == 2:  # non-smooth event: an impact
            impacts.append(float(manager.nextTime()))
        sim.processEvents()
        events += 1
    seconds = time.perf_counter() - start
    return events, seconds, impacts, [float(ball.q()[0]), float(ball.velocity()[0])]


def ball_ed(sc):
    """The whole run, repeated within the budget (a run takes milliseconds): the median time
    of the time loop, as the other side's median of batches."""
    runs, start = [], time.perf_counter()
    while len(runs) < 3 or (time.perf_counter() - start < min(sc["budget"], 2.0)
                            and len(runs) < 200):
        runs.append(_ball_ed_once(sc))
    events, _, impacts, final = runs[-1]
    seconds = sorted(r[1] for r in runs)[len(runs) // 2]
    return {"steps": events, "seconds": seconds, "impacts": impacts, "final": final,
            "repeats": len(runs)}


def _chain(n, positions, velocities, ground, e):
    """n unit masses on a line, contacts between neighbours (+ the ground under mass 0)."""
    nsds = sk.NonSmoothDynamicalSystem(0.0, 1.0)
    bodies, inters = [], []
    for k in range(n):
        ds = sk.LagrangianLinearTIDS([positions[k]], [velocities[k]], np.eye(1))
        if ground is not None:
            ds.setFExtPtr(np.array([-ground]))
        nsds.insertDynamicalSystem(ds)
        bodies.append(ds)
    law = sk.NewtonImpactNSL(e)
    if ground is not None:
        inter = sk.Interaction(law, sk.LagrangianLinearTIR(np.eye(1)))
        nsds.link(inter, bodies[0])
        inters.append(inter)
    for k in range(n - 1):
        inter = sk.Interaction(law, sk.LagrangianLinearTIR(np.array([[-1.0, 1.0]])))
        nsds.link(inter, bodies[k], bodies[k + 1])
        inters.append(inter)
    return nsds, bodies, inters


def _run_chain(nsds, h, max_steps, budget, solver):
    nsds.setT(h * (max_steps + 1))
    osi = sk.MoreauJeanOSI(0.5)
    osi.setConstraintActivationThreshold(1e-12)
    lcp = sk.LCP(solver)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, h), osi, lcp)
    k = 0
    start = time.perf_counter()
    while sim.hasNextEvent() and k < max_steps:
        sim.computeOneStep()
        sim.nextStep()
        k += 1
        if time.perf_counter() - start > budget:
            break
    return k, time.perf_counter() - start


def stack(sc):
    n, h = sc["n"], sc["h"]
    nsds, bodies, inters = _chain(n, [0.0] * n, [0.0] * n, sc["g"], 0.0)
    steps, seconds = _run_chain(nsds, h, sc["max_steps"], sc["budget"], sn.SICONOS_LCP_LEMKE)
    impulses = [float(i.lambda_(1)[0]) for i in inters]
    return {"steps": steps, "seconds": seconds, "impulses": impulses}


def cradle(sc):
    n, h = sc["n"], sc["h"]
    pos = [sc["spacing"] * k for k in range(n)]
    vel = [sc["velocity"]] + [0.0] * (n - 1)
    nsds, bodies, _ = _chain(n, pos, vel, None, 1.0)
    steps, seconds = _run_chain(nsds, h, sc["max_steps"], sc["budget"], sn.SICONOS_LCP_LEMKE)
    v = np.array([float(b.velocity()[0]) for b in bodies])
    return {"steps": steps, "seconds": seconds, "momentum": float(v.sum()),
            "energy": float(0.5 * (v ** 2).sum())}


def main():
    payload = json.load(sys.stdin)
    runners = {"ball_mj": ball_mj, "ball_ed": ball_ed, "stack": stack, "cradle": cradle}
    for sc in payload["scenarios"]:
        sc.setdefault("budget", payload.get("budget", 5.0))
        try:
            out = runners[sc["kind"]](sc)
        except Exception as exc:  # report and go on with the other scenarios
            out = {"error": f"{type(exc).__name__}: {exc}"}
        out["name"] = sc["name"]
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()

"""Mechanics integrators against Siconos, same scenarios and steps, in one run.

1. bouncing ball (e = 0.9, q0 = 1, g = 9.81, T = 10): Moreau–Jean at h = 1e-3 and 1e-4
   (Siconos MoreauJeanOSI(½) + LCP), and event-driven (Siconos EventDriven + LsodarOSI);
2. a stack of N unit masses at rest on the ground, all contacts active, e = 0, h = 1e-3
   (N = 10, 100, 1000; Siconos MoreauJeanOSI + LCP Lemke);
3. Newton's cradle: N beads 1 cm apart, striker at 1 m/s, e = 1, h = 1e-3 (N = 10, 100, 1000).

Both sides time their time loop only; Siconos gets a time budget per scenario (about a second
per step at N = 1000) and its per-step figure is reported. The event-driven ball, a whole run
of a few milliseconds, is timed on both sides as the median of single runs. ``ratio`` = our
steps/s over Siconos's; ``accuracy`` holds both sides' errors against the closed forms (impact
times, impulses ``(N - k) m g h``, momentum and energy).

Run: ``nscontrol bench mechanics --json`` (``--quick``: smaller sizes).
"""

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version, time_per_call

from nscontrol.simulate import simulate
from nscontrol.testing.mechanics_problems import BouncingBall, NewtonsCradle, RestingStack

H = 1e-3
SICONOS_BUDGET = 8.0  # seconds per scenario on the Siconos side


def _ours_mj(system: Any, x0: np.ndarray, t_end: float, h: float, **kw: Any) -> Any:
    return simulate(system, x0, (0.0, t_end), method="moreau_jean", h=h, progress=False,
                    **kw)


def _timed(fn: Any, budget: float) -> tuple[float, Any]:
    """Seconds per call of ``fn`` (after a warm-up) and the last result."""
    out = {}

    def call() -> None:
        out["r"] = fn()

    return time_per_call(call, budget=budget, min_calls=2), out["r"]


def _record(scenario: str, size: Any, ours: float, ref: float | None, accuracy: dict,
            unit: str = "steps", note: str = "") -> dict:
    rec = {"scenario": scenario, "size": size, "ours_steps_per_s": ours,
           "reference": siconos_version() if ref is not None else None,
           "reference_steps_per_s": ref, "ratio": ours / ref if ref else None,
           "unit": unit, "accuracy": accuracy}
    if note:
        rec["note"] = note
    return rec


def scenarios(quick: bool) -> dict[str, dict]:
    ball = {"e": 0.9, "g": 9.81, "q0": 1.0, "T": 10.0}
    out = {f"ball-mj-h{h:g}": {"kind": "ball_mj", "h": h, **ball} for h in (1e-3, 1e-4)}
    out["ball-ed"] = {"kind": "ball_ed", "max_events": 100_000, **ball}
    for n in (10, 100) if quick else (10, 100, 1000):
        out[f"stack-{n}"] = {"kind": "stack", "n": n, "h": H, "g": 9.81,
                             "max_steps": {10: 2000, 100: 300, 1000: 50}[n]}
        out[f"cradle-{n}"] = {"kind": "cradle", "n": n, "h": H, "spacing": 0.01,
                              "velocity": 1.0, "max_steps": {10: 2000, 100: 2000, 1000: 10000}[n]}
    return out


def run(quick: bool = False) -> Iterator[dict]:
    specs = scenarios(quick)
    ok, why = siconos_available()
    ref: dict[str, dict] = {}
    if ok:
        payload = {"scenarios": [dict(name=k, **v) for k, v in specs.items()],
                   "budget": 2.0 if quick else SICONOS_BUDGET}
        ref = {r["name"]: r for r in run_siconos("mechanics.py", payload, timeout=280)}
    note = "" if ok else f"Siconos skipped: {why}"
    budget = 0.3 if quick else 1.0
    yield from _ball_mj(specs, ref, budget, note)
    yield _ball_ed(specs["ball-ed"], ref.get("ball-ed"), budget, note)
    for name, sc in specs.items():
        if sc["kind"] == "stack":
            yield _stack(sc, ref.get(name), budget, note)
        elif sc["kind"] == "cradle":
            yield _cradle(sc, ref.get(name), budget, note)


def _rate(r: dict | None) -> float | None:
    if not r or "error" in r or not r.get("steps"):
        return None
    return r["steps"] / r["seconds"]


def _ball_mj(specs: dict, ref: dict, budget: float, note: str) -> Iterator[dict]:
    ball = BouncingBall()
    exact = ball.impact_times(10)
    for name, sc in specs.items():
        if sc["kind"] != "ball_mj":
            continue
        h = sc["h"]
        system = ball.system()
        s, traj = _timed(lambda system=system, h=h: _ours_mj(
            system, ball.x0, 10.0, h, record_every=10**9, signals=()), budget)
        steps = traj.stats["steps"]
        full = _ours_mj(system, ball.x0, 10.0, h, signals=["gap"])
        ours_t = full.event_times("impact")[:10]
        r = ref.get(name)
        acc = {"ours_impact_time_err_first10": float(np.max(np.abs(ours_t - exact))),
               "ours_penetration": full.stats["max_penetration"]}
        if r and "impacts" in r:
            acc["siconos_impact_time_err_first10"] = float(np.max(np.abs(
                np.array(r["impacts"][:10]) - exact)))
            acc["siconos_penetration"] = r["penetration"]
        yield _record(name, h, steps / s, _rate(r), acc, note=note or r.get("error", "")
                      if r else note)


def _median_run(fn: Any, budget: float) -> tuple[float, Any]:
    """Median seconds of single calls of ``fn`` within ``budget`` (after a warm-up) and the
    last result: the statistic of the Siconos side of this scenario (median of whole runs).
    A batch mean would also count the time the process waits for a core on a loaded machine,
    which the other side's median leaves out."""
    out = fn()
    times: list[float] = []
    end = time.perf_counter() + budget
    while len(times) < 3 or (time.perf_counter() < end and len(times) < 5000):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return sorted(times)[len(times) // 2], out


def _ball_ed(sc: dict, r: dict | None, budget: float, note: str) -> dict:
    ball = BouncingBall()
    system = ball.system()

    def run() -> Any:
        return simulate(system, ball.x0, (0.0, 10.0), dt=10.0, progress=False)

    s, traj = _median_run(run, budget)
    s_batches, _ = _timed(run, budget)
    events = len(traj.events)
    t = traj.event_times("impact")
    acc = {"ours_impact_time_err_first20": float(np.max(np.abs(t[:20] - ball.impact_times(20)))),
           "ours_accumulation_err": float(abs(traj.event_times("accumulation")[0]
                                              - ball.accumulation_time))}
    if r and "impacts" in r:
        ti = np.array(r["impacts"][:20])
        acc["siconos_impact_time_err_first20"] = float(np.max(np.abs(
            ti - ball.impact_times(ti.size))))
        acc["siconos_events"] = r["steps"]
    rec = _record("ball-ed", "events", events / s, _rate(r), acc, unit="events", note=note)
    # the two sides process different events (we resolve the accumulation after 65 impacts,
    # Siconos bounces on): the time of the whole scenario is compared too
    rec["ours_events"] = events
    rec["ours_s_per_run"] = s
    rec["ours_s_per_run_batches"] = s_batches  # mean of batches, waits for a core included
    if r and "seconds" in r:
        rec["reference_s_per_run"] = r["seconds"]
        rec["ratio_per_run"] = r["seconds"] / s
    return rec


def _stack(sc: dict, r: dict | None, budget: float, note: str) -> dict:
    n = sc["n"]
    prob = RestingStack(n)
    system = prob.system()
    steps = 1000
    s, traj = _timed(lambda: _ours_mj(system, prob.x0, steps * H, H, record_every=10**9,
                                      signals=["impulse"]), budget)
    exact = prob.impulses(H)
    acc = {"ours_impulse_rel_err": float(np.max(np.abs(traj.signals["impulse"][-1] - exact)
                                              / exact)),
           "ours_s_per_step": s / steps}
    if r and "impulses" in r:
        acc["siconos_impulse_rel_err"] = float(np.max(np.abs(np.array(r["impulses"]) - exact)
                                                     / exact))
        acc["siconos_steps_timed"] = r["steps"]
    return _record(f"stack-{n}", n, steps / s, _rate(r), acc, note=note)


def _cradle(sc: dict, r: dict | None, budget: float, note: str) -> dict:
    n = sc["n"]
    prob = NewtonsCradle(n)
    system = prob.system()
    steps = sc["max_steps"]
    s, traj = _timed(lambda: _ours_mj(system, prob.x0, steps * H, H, record_every=10**9,
                                      signals=()), budget)
    v = traj.x[-1, n:]
    acc = {"ours_momentum_err": float(abs(v.sum() - 1.0)),
           "ours_energy_err": float(abs(0.5 * (v**2).sum() - 0.5)),
           "ours_impacts": len(traj.events), "ours_s_per_step": s / steps}
    if r and "momentum" in r:
        acc["siconos_momentum_err"] = abs(r["momentum"] - 1.0)
        acc["siconos_energy_err"] = abs(r["energy"] - 0.5)
        acc["siconos_steps_timed"] = r["steps"]
    return _record(f"cradle-{n}", n, steps / s, _rate(r), acc, note=note)


if __name__ == "__main__":
    import json

    for record in run(quick=False):
        print(json.dumps(record), flush=True)

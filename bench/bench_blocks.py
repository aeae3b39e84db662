"""The closed loop's block stepper (``simulate/_block_kernels.py``): its Python path (blocks
written in Python, stepped by :class:`~nscontrol.simulate._block_runner.BlockRunner`) and
its compiled path, on chapter 7's loop (one-link robot, Stribeck friction, the compensating
PD and the reduced-order observer, both sampled at every step, h = 1e-4).

Scenarios:

* ``python-vs-compiled``: the Python blocks' steps/s (``closed_loop(..., compiled=False)``)
  against the same loop with the blocks' compiled forms (reference), 1 s runs (10⁴ ticks);
* ``python-now-vs-before`` (only with ``BLOCKS_BEFORE=/path/to/older/src`` set, the ``src``
  folder of another checkout): the Python blocks of this tree against those of the older
  tree, each in its own interpreter, alternately, the CPU time of the best of 5 runs each
  (the machine's other load moves both alike); ``ratio`` > 1: this tree is faster.

Run: ``nscontrol bench blocks --json`` (``--quick``: 0.3 s runs).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

_RUN = r"""
import json, sys, time
from nscontrol.design.friction_compensation import PDLaw, SetPoint, simulate_friction_loop
from nscontrol.examples import ch07_friction_compensation as ex
from nscontrol.systems import OneLinkRobot

P = ex.REFERENCE
robot = OneLinkRobot(P["J"], ex.reference_friction())
pd = PDLaw(P["kp"], P["kd"], P["J"], SetPoint(P["theta_r"]))
T, compiled, repeat = float(sys.argv[1]), sys.argv[2] == "1", int(sys.argv[3])

def once(T):
    return simulate_friction_loop(robot, pd, l=P["l"], kappa=1.0, h=P["h"], T=T,
                                  compiled=compiled)

once(0.01)
best = float("inf")
for _ in range(repeat):
    t0 = time.process_time()
    run = once(T)
    best = min(best, time.process_time() - t0)
print(json.dumps({"steps": run.t.size - 1, "seconds": best, "theta": float(run.theta[-1])}))
"""


def _timed(src: str | None, T: float, compiled: bool, repeat: int = 5) -> dict[str, Any]:
    """Steps and best CPU seconds of the loop in a fresh interpreter on ``src``."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = src
        env["NUMBA_CACHE_DIR"] = os.path.join(src, ".numba-bench-cache")
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    out = subprocess.run([sys.executable, "-c", _RUN, str(T), "1" if compiled else "0",
                          str(repeat)], env=env, capture_output=True, text=True, check=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def _python_vs_compiled(T: float) -> dict[str, Any]:
    py, fast = _timed(None, T, False), _timed(None, T, True)
    ours, ref = py["steps"] / py["seconds"], fast["steps"] / fast["seconds"]
    return {"scenario": f"ch07 loop, h = 1e-4, T = {T:g}: Python blocks vs compiled blocks",
            "size": py["steps"], "ours_steps_per_s": ours,
            "reference": "the same blocks compiled", "reference_steps_per_s": ref,
            "ratio": ours / ref,
            "accuracy": {"theta_difference": abs(py["theta"] - fast["theta"])}}


def _now_vs_before(T: float, before: str, rounds: int = 3) -> dict[str, Any]:
    now_s, before_s = float("inf"), float("inf")
    for _ in range(rounds):                   # alternately: both see the same load
        now = _timed(None, T, False)
        old = _timed(before, T, False)
        now_s, before_s = min(now_s, now["seconds"]), min(before_s, old["seconds"])
    return {"scenario": f"ch07 loop, h = 1e-4, T = {T:g}: Python blocks, this tree vs "
                        f"{before}",
            "size": now["steps"], "ours_steps_per_s": now["steps"] / now_s,
            "reference": f"Python blocks of {before}",
            "reference_steps_per_s": old["steps"] / before_s, "ratio": before_s / now_s,
            "accuracy": {"theta_difference": abs(now["theta"] - old["theta"])}}


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    T = 0.3 if quick else 1.0
    yield _python_vs_compiled(T)
    before = os.environ.get("BLOCKS_BEFORE")
    if before:
        yield _now_vs_before(T, before)

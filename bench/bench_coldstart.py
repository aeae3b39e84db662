"""The first ``simulate`` of a new user, nothing compiled (issue 32: at most 5 s on 2 cores).

Runs ``tests/trial/new_user.py`` (the README's bouncing ball) three times, each in a fresh
process with a fresh ``NUMBA_CACHE_DIR``, and once more on the cache the last run filled (the
second process of a user: kernels loaded, not compiled). ``ours_s_per_solve`` is the median
wall time of the cold first runs; the CPU seconds are given beside it, since the machine may
be shared (a cold compile is one thread: on an idle machine its wall time is its CPU time).
The reference is the warm first run of a new process. The load average is recorded.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "tests" / "trial" / "new_user.py"
GOAL_S = 5.0


def _trial(cache: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    env["NUMBA_CACHE_DIR"] = cache
    out = subprocess.run([sys.executable, str(SCRIPT)], env=env, capture_output=True,
                         text=True, timeout=1800, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> Iterator[dict]:
    repeats = 1 if quick else 3
    cold = []
    with tempfile.TemporaryDirectory(prefix="nscontrol-coldstart-") as tmp:
        load = os.getloadavg()
        for k in range(repeats):
            cold.append(_trial(str(Path(tmp) / f"cache{k}")))
        warm = _trial(str(Path(tmp) / f"cache{repeats - 1}"))
        load_after = os.getloadavg()
    ours = statistics.median(r["first_run_s"] for r in cold)
    yield {"scenario": "bouncing-ball-first-simulate-cold", "size": 2,
           "ours_s_per_solve": ours, "goal_s": GOAL_S, "meets_goal": ours <= GOAL_S,
           "first_run_s": [r["first_run_s"] for r in cold],
           "first_run_cpu_s": [r["first_run_cpu_s"] for r in cold],
           "import_s": [r["import_s"] for r in cold],
           "reference": "the same first run with the kernels in the cache",
           "reference_s_per_solve": warm["first_run_s"],
           "ratio": warm["first_run_s"] / ours, "unit": "runs",
           "load_average": [load[0], load_after[0]],
           "accuracy": {"first_impact_error": max(r["first_impact_error"] for r in cold)}}

"""Progress written to a log (stderr a file or a pipe): plain lines, no carriage returns or
cursor moves, a bounded number of them."""

from __future__ import annotations

import os
import subprocess
import sys

SCRIPT = """
import nscontrol._progress as P
P.ITER_DELAY = 0.0
for i in P.progress_iter(range(4), desc="examples", label=lambda i: f"ex{i}"):
    bar = P.TimeProgress(0.0, 1.0, delay=0.0, desc="simulate")
    for k in range(1, 1001):
        bar.update(k / 1000)
    bar.close()
for i in P.progress_iter(range(1000), desc="sweep"):
    pass
"""


def test_piped_progress_is_plain_lines() -> None:
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}     # no first-compile notice here
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         check=True, timeout=120, env=env)
    err = out.stderr
    assert "\r" not in err and "\x1b" not in err
    lines = err.splitlines()
    # one line per labelled item, and per tenth of each run (10 x 4 runs) and of the sweep
    # (a line per tenth of the count, the first at 0): nothing per update
    assert sum(line.startswith("examples (running ex") for line in lines) == 4
    assert sum(line.startswith("simulate") for line in lines) <= 4 * 11
    assert 1 <= sum(line.startswith("sweep") for line in lines) <= 11
    assert any(line.startswith("simulate t=1: 100%") for line in lines)


NOTICE = """
import nscontrol._progress as P
bars = [P.TimeProgress(0.0, 1.0, desc="simulate") for _ in range(2)]
print(repr(bars[0]._desc), repr(bars[1]._desc))
"""


def test_a_run_that_compiles_nothing_says_nothing_of_compiling(tmp_path):
    # a fresh NUMBA_CACHE_DIR holds no kernel, but these bars run none: no notice (the
    # notice comes with a kernel actually compiled, tests/test_compile_background.py and
    # tests/trial/; before, any bar of a process with an uncached module announced one)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", NOTICE], capture_output=True, text=True,
                         check=True, timeout=120, env=env)
    assert "nscontrol:" not in out.stderr
    assert out.stdout.split() == ["'simulate'", "'simulate'"]

"""The new-user trial (issue 32): a fresh process with a fresh ``NUMBA_CACHE_DIR`` runs the
README's bouncing ball. Nothing is compiled yet, so (the default, ``NSCONTROL_COMPILE=
background``) the library says that the kernels compile in the background and that this run is
interpreted; the run finishes with the right answer; the background compiler caches every
kernel the run needs, so a second process compiles nothing, and its compiled run agrees with
the interpreted one to rounding. How long the first run takes is measured by ``nscontrol bench
coldstart`` (never a timed test)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nscontrol._compile_background import wait_for_exit

SCRIPT = Path(__file__).with_name("new_user.py")


def run_trial(cache: Path, *args: str, mode: str = "background") -> tuple[dict, str]:
    """Run the trial script on the kernel cache ``cache``; its JSON and its stderr."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    env["NUMBA_CACHE_DIR"] = str(cache)
    env["NSCONTROL_COMPILE"] = mode
    out = subprocess.run([sys.executable, str(SCRIPT), *args], env=env, capture_output=True,
                         text=True, timeout=1500, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


@pytest.mark.slow   # the background compile takes 10-30 s of CPU
def test_a_new_user_is_told_the_run_is_interpreted_and_the_next_process_runs_compiled(
        tmp_path):
    cache = tmp_path / "numba"
    cold, stderr = run_trial(cache, str(tmp_path / "interpreted.npz"))
    assert stderr.count("compiling it (and any other this run needs) in the background") == 1
    assert "this run uses the interpreted path" in stderr
    assert cold["background"] and cold["helper_pid"] is not None
    assert cold["t_end"] == 10.0
    # the first impact from rest at 1 m is at sqrt(2/g); the search locates an event to
    # rounding (its tolerance 1e-12 relative, lti.first_event), a factor 100 of margin
    assert cold["first_impact_error"] <= 1e-10

    assert wait_for_exit(cold["helper_pid"], timeout=1500.0, poll=0.5), \
        f"the background compiler (pid {cold['helper_pid']}) still runs after 1500 s"
    log = (cache / "nscontrol-compile.log").read_text()
    assert "nscontrol._warm:" not in log               # no kernel failed to compile or cache
    warm, stderr = run_trial(cache, str(tmp_path / "compiled.npz"), mode="wait")
    assert "nscontrol: compiling" not in stderr        # everything the run needs was cached
    assert not warm["background"]

    a, b = np.load(tmp_path / "interpreted.npz"), np.load(tmp_path / "compiled.npz")
    # The same kernels' source, run by Python (numpy scalars) and compiled: IEEE double
    # arithmetic either way, but LLVM may reorder or fuse a few operations and its math
    # functions may differ from numpy's by an ulp. The ball's impact map contracts
    # (v -> 0.9 v), so an ulp lost at one impact does not grow: after n impacts the gap is at
    # most n ulps of the largest time/state, with a factor 8 for the roundings of one impact.
    n = len(a["impacts"])
    eps = np.finfo(float).eps
    assert len(b["impacts"]) == n and a["t"].shape == b["t"].shape
    assert np.max(np.abs(a["impacts"] - b["impacts"])) <= 8 * n * eps * 10.0
    assert np.max(np.abs(a["t"] - b["t"])) <= 8 * n * eps * 10.0
    scale = np.max(np.abs(b["x"]))
    assert np.max(np.abs(a["x"] - b["x"])) <= 8 * n * eps * scale
    print(f"interpreted vs compiled: impacts {np.max(np.abs(a['impacts'] - b['impacts'])):.2e},"
          f" states {np.max(np.abs(a['x'] - b['x'])):.2e}, n = {n}")

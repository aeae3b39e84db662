"""The new-user trial (issue 32): a fresh process with a fresh ``NUMBA_CACHE_DIR`` runs the
README's bouncing ball; the library says that it compiles, and the run finishes with the
right answer. How long the first run takes is measured by ``nscontrol bench coldstart``
(never a timed test)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).with_name("new_user.py")


def run_trial(cache: Path) -> tuple[dict, str]:
    """Run the trial script with nothing compiled in ``cache``; its JSON and its stderr."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    env["NUMBA_CACHE_DIR"] = str(cache)
    out = subprocess.run([sys.executable, str(SCRIPT)], env=env, capture_output=True,
                         text=True, timeout=1500, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


@pytest.mark.slow   # the cold compile takes 10-30 s of CPU
def test_a_new_user_is_told_of_the_compile_and_the_first_run_finishes(tmp_path):
    record, stderr = run_trial(tmp_path / "numba")
    assert "nscontrol: compiling numerical kernels" in stderr
    assert stderr.count("nscontrol: compiling") == 1          # once per process
    assert record["t_end"] == 10.0
    # the first impact from rest at 1 m is at sqrt(2/g); the search locates an event to
    # rounding (its tolerance 1e-12 relative, lti.first_event), a factor 100 of margin
    assert record["first_impact_error"] <= 1e-10
    assert any((tmp_path / "numba").rglob("*.nbi"))            # it compiled into the cache
    again, stderr = run_trial(tmp_path / "numba")               # the second process loads
    assert again["first_impact_error"] == record["first_impact_error"]

"""The background compile of a first run's kernels (``nscontrol._compile_background``): its
mode switch, its notices (once per process, counting what the run compiles), and its promise
that a run is never left interpreted for good. The full first run is ``tests/trial/``."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import nscontrol._compile_background as background
import nscontrol._progress as progress
from nscontrol.errors import ModelError


def test_the_mode_is_background_by_default_and_a_bad_one_is_refused(monkeypatch):
    monkeypatch.delenv("NSCONTROL_COMPILE", raising=False)
    assert background.mode() == "background"
    monkeypatch.setenv("NSCONTROL_COMPILE", " Wait ")
    assert background.mode() == "wait"
    monkeypatch.setenv("NSCONTROL_COMPILE", "later")
    with pytest.raises(ModelError, match=r"^NSCONTROL_COMPILE: expected one of background, "
                                         r"wait, got 'later'"):
        background.mode()


def test_only_types_another_process_can_rebuild_go_to_the_background():
    from numba import typeof
    from numba.core import types

    assert background._portable((typeof(np.zeros((2, 2))), types.float64, types.int64,
                                 types.UniTuple(types.float64, 2), types.none,
                                 typeof(np.zeros(3, dtype=bool))))
    assert not background._portable((types.float64, typeof(np.zeros(2, dtype=object))))
    assert not background._portable((types.pyobject,))


def test_the_notices_come_once_per_process_and_count_what_this_run_compiles(monkeypatch,
                                                                             capsys):
    monkeypatch.setattr(progress, "_announced", False)
    monkeypatch.setattr(progress, "_compiled_here", [])
    monkeypatch.setattr(progress, "_reported_background", False)
    monkeypatch.setattr(background, "_requested", [])
    bar = progress.TimeProgress(0.0, 1.0, desc="simulate", delay=100.0)
    background._requested.append("m.f")
    progress.compiling_in_background("m.f", 1)
    assert bar._bar is not None                       # shown at once, saying why
    assert bar._note == "interpreted while 1 kernel compiles in the background"
    background._requested.append("m.g")
    progress.compiling_in_background("m.g", 2)
    assert bar._note == "interpreted while 2 kernels compile in the background"
    bar.close()
    err = capsys.readouterr().err
    assert err.count("kernel m.f is not compiled yet") == 1 and "m.g is not" not in err
    assert "this run uses the interpreted path" in err
    assert "this run needed 2 kernels not yet compiled" in err
    # a later run that compiles (in the foreground) counts its own, and says nothing again
    other = progress.TimeProgress(0.0, 1.0, desc="simulate", delay=100.0)
    progress.compiling_now("m.h")
    assert other._note == "compiling kernels, first run only: 1 so far, now m.h"
    other.close()
    assert "nscontrol:" not in capsys.readouterr().err   # the bar's line only


FALLBACK = """
import subprocess, sys, time
import numpy as np
import nscontrol._compile_background as background
# a background compiler that dies at once: the kernel must not stay interpreted
background._start_helper = lambda: subprocess.Popen(
    [sys.executable, "-c", "import sys; sys.stdin.readline(); sys.exit(3)"],
    stdin=subprocess.PIPE)
from nscontrol.numerics import _lti_kernels as k
M, x, out = np.array([[1.0, 2.0], [3.0, 4.0]]), np.array([1.0, -1.0]), np.zeros(2)
k._matvec(M, x, out)
first = (len(k._matvec.signatures), out.tolist())
background._helper.wait()
time.sleep(background.RECHECK_S)
k._matvec(M, x, out)
print(first, len(k._matvec.signatures), out.tolist(), background.requested())
"""


def test_a_failed_background_compile_compiles_in_the_foreground(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "NSCONTROL_COMPILE": "background"}
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", FALLBACK], capture_output=True, text=True,
                         check=True, timeout=600, env=env)
    # the first call ran interpreted (nothing compiled), the one after the helper's death
    # compiled; both computed [1 - 2, 3 - 4]
    assert out.stdout.split("\n")[0] == ("(0, [-1.0, -1.0]) 1 [-1.0, -1.0] "
                                         "['numerics._lti_kernels._matvec']")
    assert "kernel numerics._lti_kernels._matvec is not compiled yet" in out.stderr


def test_kernels_whose_source_cannot_run_as_python_compile_in_the_foreground():
    """An intrinsic (compiled-only), a record read through ``view`` (fields as attributes:
    numba's, not numpy's) or a structured argument make the source unusable as Python."""
    from nscontrol.numerics import _lti_kernels
    from nscontrol.simulate.sampled_zoh import _zoh_kernels
    from nscontrol.systems import _foot_body_kernels

    x = np.zeros(2)
    assert background._interpretable(_lti_kernels._matvec, (np.eye(2), x, x))
    assert not background._interpretable(_zoh_kernels.run_chunk, ())        # an intrinsic
    assert not background._interpretable(_foot_body_kernels.support_abscissae, (x, x))
    record = np.zeros(1, [("a", float)])
    assert not background._interpretable(_lti_kernels._matvec, (record, x, x))
    assert not background._interpretable(_lti_kernels._matvec, (record[0], x, x))

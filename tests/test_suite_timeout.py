"""The suite's per-test limit (issue 29): a test that hangs fails with a traceback inside its
xdist worker, and the run goes on and ends, also under ``--dist loadfile`` (where a killed
worker once left the tail of the suite deadlocked)."""

import subprocess
import sys
import textwrap
import time

import pytest

#: The tiny suite's per-test limit and its sleeping test's sleep: far apart, so the verdict
#: does not depend on the machine's speed.
LIMIT, SLEEP = 2, 120


def test_the_suite_has_a_per_test_limit_that_fails_inside_the_worker(request):
    assert float(request.config.getini("timeout")) > 0
    assert request.config.getini("timeout_method") == "signal"


def test_a_hanging_test_fails_with_timeout_and_the_run_goes_on(request, tmp_path):
    method = request.config.getini("timeout_method")
    (tmp_path / "pytest.ini").write_text(textwrap.dedent(f"""\
        [pytest]
        timeout = {LIMIT}
        timeout_method = {method}
        """))
    (tmp_path / "test_hangs.py").write_text(textwrap.dedent(f"""\
        import time

        def test_sleeps_past_the_limit():
            time.sleep({SLEEP})

        def test_after_it_in_the_same_file():
            assert True
        """))
    (tmp_path / "test_other.py").write_text(textwrap.dedent("""\
        def test_one():
            assert 1 + 1 == 2

        def test_two():
            assert "a" * 2 == "aa"
        """))
    start = time.monotonic()
    try:
        done = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "--dist", "loadfile",
                               "-p", "no:cacheprovider", "-q", str(tmp_path)],
                              cwd=tmp_path, capture_output=True, text=True, timeout=SLEEP - 20)
    except subprocess.TimeoutExpired as exc:   # the run hung: the limit did not work
        pytest.fail(f"the tiny suite did not end within {exc.timeout} s")
    elapsed = time.monotonic() - start
    out = done.stdout + done.stderr
    assert done.returncode == 1, out
    assert "Timeout" in out and "test_sleeps_past_the_limit" in out, out
    assert "1 failed, 3 passed" in out, out     # the same file's next test ran too
    assert elapsed < SLEEP, out

"""``nscontrol report`` and ``warmup`` on every core: the examples (kernel groups) run side by
side, each in its own process, with the same rows as one after another; a failing or dying
one is reported and the others kept; ``--jobs`` is checked; Ctrl-C stops every process."""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import subprocess
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

import nscontrol.report as report_mod
from nscontrol import _processes
from nscontrol.cli import main
from nscontrol.errors import ModelError
from nscontrol.examples import Example, ExampleResult, check
from nscontrol.examples import warmup as warmup_mod
from nscontrol.examples._figures import new_figure, save_figure

SMALL = ["bouncing-ball", "newtons-cradle"]


def _without_times(html: str) -> str:
    """The page with its runtimes (``12.3 s``, ``took 40 s``) blanked."""
    return re.sub(r"\b\d+(?:\.\d+)? s\b", "# s", html)


def test_parallel_report_has_the_serial_rows_and_page(tmp_path):
    serial = report_mod.write_report(tmp_path / "serial", SMALL, progress=False, jobs=1)
    parallel = report_mod.write_report(tmp_path / "parallel", SMALL, progress=False, jobs=2)
    for summary in (serial, parallel):
        for row in summary["examples"]:
            row.pop("seconds")
    # the same examples, in the same order, with the same metrics, checks and verdicts (the
    # same compiled kernels on the same inputs: equal to the last bit)
    assert [r["example"] for r in parallel["examples"]] == SMALL
    assert parallel == serial
    pages = [(tmp_path / d / "index.html").read_text() for d in ("serial", "parallel")]
    assert _without_times(pages[0]) == _without_times(pages[1])
    for name in SMALL:
        figures = [sorted(p.name for p in (tmp_path / d / name).glob("*.png"))
                   for d in ("serial", "parallel")]
        assert figures[0] == figures[1] and figures[0]


def _good(out_dir):
    figures = []
    fig, ax = new_figure()
    ax.plot([0, 1], [0, 1])
    save_figure(fig, out_dir, "line", figures)
    print("a line the example printed")
    return ExampleResult("good", {"err": 1e-13}, [check("err", 1e-13, 1e-10)], figures)


def _also_good(out_dir):
    return ExampleResult("also-good", {"n": 3}, [check("n", 3, 3, "==")], [])


def _broken(out_dir):
    raise RuntimeError("deliberately broken example")


def _dies(out_dir):
    os._exit(3)        # the process ends without a word (as a crash in compiled code would)


def _unsendable(out_dir):
    return ExampleResult("unsendable", {"f": lambda: 0}, [], [])


def test_failing_and_dying_examples_in_the_pool_are_reported_and_the_others_kept(
        tmp_path, monkeypatch):
    fake = [Example("good", "a good one", "test", _good),
            Example("broken", "a broken one", "test", _broken),
            Example("dies", "one whose process dies", "test", _dies),
            Example("unsendable", "one whose result cannot be pickled", "test", _unsendable),
            Example("also-good", "another good one", "test", _also_good)]
    monkeypatch.setattr(report_mod, "all_examples", lambda: fake)
    result = CliRunner().invoke(main, ["report", "--out", str(tmp_path), "--jobs", "2"])
    assert result.exit_code == 1, result.output
    summary = json.loads((tmp_path / "report.json").read_text())
    by_name = {e["example"]: e for e in summary["examples"]}
    assert [e["example"] for e in summary["examples"]] == [e.name for e in fake]
    assert by_name["good"]["passed"] and by_name["also-good"]["passed"]
    assert "deliberately broken" in by_name["broken"]["error"]
    assert "died" in by_name["dies"]["error"] and "exit code 3" in by_name["dies"]["error"]
    assert "cannot be sent back" in by_name["unsendable"]["error"]
    assert not any(by_name[n]["passed"] for n in ("broken", "dies", "unsendable"))
    assert (tmp_path / "good" / "line.png").stat().st_size > 1000
    assert "a line the example printed" in (tmp_path / "good" / "output.txt").read_text()
    assert "[pass] also-good" in result.output and "[FAIL] dies" in result.output


@pytest.mark.parametrize("command", [["report", "--only", "bouncing-ball"], ["warmup"]])
@pytest.mark.parametrize("jobs", ["0", "-2", "two", "1.5"])
def test_jobs_must_be_a_positive_integer(command, jobs, tmp_path):
    result = CliRunner().invoke(main, [*command, "--jobs", jobs],
                                env={"NUMBA_CACHE_DIR": str(tmp_path)})
    assert result.exit_code == 2
    assert "Invalid value for '--jobs'" in result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize("jobs", [0, 2.5, True, "2"])
def test_write_report_refuses_bad_jobs_before_running(jobs, tmp_path, monkeypatch):
    monkeypatch.setattr(report_mod, "all_examples",
                        lambda: [Example("broken", "", "test", _broken)])
    with pytest.raises(ModelError, match=r"^jobs: expected an integer >= 1"):
        report_mod.write_report(tmp_path, jobs=jobs)
    assert not (tmp_path / "report.json").exists()


def _quick():
    return "quick"


def _sleeps_with_a_child(pid_file):
    child = subprocess.Popen(["sleep", "60"])
    Path(pid_file).write_text(f"{os.getpid()} {child.pid}")
    time.sleep(60)


def _gone(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_ctrl_c_stops_every_running_process_and_their_children(tmp_path):
    pid_file = tmp_path / "pids"

    def interrupt(index, outcome):      # Ctrl-C arrives as the first task finishes
        deadline = time.monotonic() + 30
        while not pid_file.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        raise KeyboardInterrupt

    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        _processes.run_each([(_quick, ()), (_sleeps_with_a_child, (str(pid_file),))], 2,
                            on_done=interrupt)
    assert time.monotonic() - start < 30        # not the sleeper's 60 s
    pids = [int(p) for p in pid_file.read_text().split()]
    deadline = time.monotonic() + 10
    while not all(_gone(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(_gone(p) for p in pids)


def test_run_each_keeps_the_order_of_the_tasks_and_runs_no_more_than_jobs_at_once(tmp_path):
    outcomes = _processes.run_each([(_quick, ())] * 5, 2)
    assert [o.value for o in outcomes] == ["quick"] * 5 and not any(o.error for o in outcomes)


def _imported_before_running(name):
    import sys

    return name in sys.modules


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                    reason="children inherit the parent's modules only when forked")
def test_shared_modules_are_imported_once_here_and_inherited_by_every_child(
        tmp_path, monkeypatch):
    name = f"nsc_shared_probe_{os.getpid()}"
    (tmp_path / f"{name}.py").write_text("VALUE = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    tasks = [(_imported_before_running, (name,))] * 3
    # without shared the children start without it (and the parent never imports it)
    assert [o.value for o in _processes.run_each(tasks, 2)] == [False] * 3
    outcomes = _processes.run_each(tasks, 2, shared=[name, "nsc_no_such_module"])
    assert [o.value for o in outcomes] == [True] * 3 and not any(o.error for o in outcomes)
    # a module that is not installed is skipped, not an error: the task that needs it says so
    assert _processes.preload(["nsc_no_such_module", name]) == [name]


def _blas_setting():
    import numpy  # noqa: F401 - loads numpy's BLAS
    import scipy.linalg  # noqa: F401 - and scipy's

    return os.environ.get("OPENBLAS_NUM_THREADS"), _processes.blas_threads()


def test_side_by_side_tasks_do_their_linear_algebra_on_one_thread(monkeypatch):
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    # the parent has loaded numpy's and scipy's BLAS (as the report's parent does) before
    # the children fork: they are set to one thread through OpenBLAS's own setter, and the
    # processes they start through the environment
    _blas_setting()
    outcomes = _processes.run_each([(_blas_setting, ())] * 2, 2)
    for o in outcomes:
        variable, threads = o.value
        assert variable == "1" and all(t == 1 for t in threads)
    # one at a time (the only task on the machine) keeps the library's default
    (variable, _), = (o.value for o in _processes.run_each([(_blas_setting, ())], 1))
    assert variable is None
    assert os.environ.get("OPENBLAS_NUM_THREADS") is None      # this process is left alone


def test_the_reports_shared_modules_exist():
    import importlib.util

    assert all(importlib.util.find_spec(m) is not None for m in report_mod.SHARED_IMPORTS)


def _step_ok():
    pass


def _step_fails():
    raise ValueError("no such kernel")


def _saves_an_index_entry():
    """Calls numba's cache-index save on a stub that checks the cache's lock is held."""
    import fcntl

    import numba.core.caching as caching

    from nscontrol._compile_background import lock_path

    class Stub:
        held = None

        def _load_index(self):
            return {}

        def _data_name(self, i):
            return f"x.{i}.nbc"

        def _save_index(self, overloads):
            with open(lock_path(), "a") as handle:   # another open file: the lock conflicts
                try:
                    fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    Stub.held = False
                    fcntl.flock(handle, fcntl.LOCK_UN)
                except BlockingIOError:
                    Stub.held = True

        def _save_data(self, name, data):
            pass

    caching.IndexDataCacheFile.save(Stub(), "key", b"data")
    if not Stub.held:
        raise AssertionError("the cache index was written without the cache's lock")


@pytest.mark.parametrize("jobs", [1, 2])
def test_warm_up_steps_run_side_by_side_write_the_index_under_the_lock_and_report_failures(
        jobs, tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    steps = [("fine", _step_ok), ("broken", _step_fails), ("index", _saves_an_index_entry)]
    monkeypatch.setattr(warmup_mod, "STEPS", steps)
    lines: list[str] = []
    failed = warmup_mod.warm_up(lines.append, jobs=jobs)
    assert failed == ["broken: ValueError: no such kernel"]
    assert len(lines) == 3 and all(any(what in line for line in lines) for what, _ in steps)
    if jobs > 1:
        assert any(re.fullmatch(r"broken: FAILED in \d+ s \(CPU \d+ s\)", line)
                   for line in lines)


def test_the_longest_examples_of_the_previous_report_start_first(tmp_path):
    names = ["a", "b", "c", "d"]
    examples = [Example(n, n, "test", _also_good) for n in names]
    assert report_mod._longest_first(examples, tmp_path) == [0, 1, 2, 3]   # no report yet
    previous = {"examples": [{"example": "a", "seconds": 1.0}, {"example": "b", "seconds": 9.0},
                             {"example": "d", "seconds": 3.0}]}
    (tmp_path / "report.json").write_text(json.dumps(previous))
    # c has no previous time: it goes first (it may be long), then b, d, a
    assert report_mod._longest_first(examples, tmp_path) == [2, 1, 3, 0]
    (tmp_path / "report.json").write_text("{not json")
    assert report_mod._longest_first(examples, tmp_path) == [0, 1, 2, 3]


def test_rows_keep_the_catalogue_order_when_started_longest_first(tmp_path, monkeypatch):
    fake = [Example("good", "", "test", _good), Example("also-good", "", "test", _also_good),
            Example("broken", "", "test", _broken)]
    monkeypatch.setattr(report_mod, "all_examples", lambda: fake)
    previous = {"examples": [{"example": "good", "seconds": 1.0},
                             {"example": "also-good", "seconds": 2.0},
                             {"example": "broken", "seconds": 5.0}]}
    (tmp_path / "report.json").write_text(json.dumps(previous))
    summary = report_mod.write_report(tmp_path, progress=False, jobs=2)
    assert [r["example"] for r in summary["examples"]] == ["good", "also-good", "broken"]
    assert [r["passed"] for r in summary["examples"]] == [True, True, False]
    assert "deliberately broken" in summary["examples"][2]["error"]

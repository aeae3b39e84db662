"""Run independent tasks side by side, each in its own child process (``nscontrol report``
and ``nscontrol warmup`` on every core).

A task is a module-level function and its arguments. At most ``jobs`` children run at once;
each runs one task and sends back its value (pickled), or the traceback of the exception it
raised, with the seconds it took and whatever it printed. One child per task, rather than a
pool of long-lived workers, keeps the tasks apart: a task that raises, or whose process
dies, costs only its own result, and memory is returned after each task. (A child loads the
compiled kernels it uses from numba's on-disk cache: milliseconds per kernel.)

Children are forked where the platform allows it (they start in a few milliseconds and see
the parent's modules as imported); elsewhere the platform's default start method is used, so
the task must then be importable by name. With fork, the modules the tasks share
(``shared``) are imported once here before the first child starts (:func:`preload`): every
child inherits them instead of importing them again (numpy, scipy, matplotlib, numba and
cvxpy take about 1.5 s of CPU to import, per process). Each child leads its own process group and
ignores Ctrl-C: on Ctrl-C (or any exception) in the parent, every running child is
terminated with the processes it started (a sweep's pool inside an example), and the
exception goes on.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import multiprocessing
import os
import signal
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

__all__ = ["Outcome", "default_jobs", "check_jobs", "run_each", "preload",
           "one_blas_thread", "blas_threads"]


@dataclass
class Outcome:
    """What one task gave: its ``value`` (None when it failed), the ``error`` text (empty on
    success), its wall ``seconds``, the ``output`` it printed (stdout and stderr) and the
    ``cpu`` seconds used by its process and the processes it started and saw end (NaN when it
    died)."""

    value: Any
    error: str
    seconds: float
    output: str = ""
    cpu: float = float("nan")


def default_jobs() -> int:
    """The cores this process may run on (its CPU affinity where the platform says it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:              # no sched_getaffinity (macOS, Windows)
        return max(1, os.cpu_count() or 1)


def check_jobs(jobs: Any, name: str = "jobs") -> int:
    """``jobs`` as a positive number of processes; ``None`` gives :func:`default_jobs`.

    Raises
    ------
    ModelError
        Not an integer, or below 1.
    """
    from ._validation import check_integer

    if jobs is None:
        return default_jobs()
    return int(check_integer(name, jobs, minimum=1))


def _context() -> Any:
    if "fork" in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("fork")
    return multiprocessing.get_context()


#: The variables that set the threads of the BLAS libraries a process loads.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: OpenBLAS's thread setter and getter under the names its builds export: plain, and those of
#: the copies numpy (64-bit integers) and scipy ship.
_OPENBLAS_SYMBOLS = {"set": ("openblas_set_num_threads", "scipy_openblas_set_num_threads",
                             "scipy_openblas_set_num_threads64_", "openblas_set_num_threads64_"),
                     "get": ("openblas_get_num_threads", "scipy_openblas_get_num_threads",
                             "scipy_openblas_get_num_threads64_", "openblas_get_num_threads64_")}


def _openblas(kind: str) -> list[Any]:
    """OpenBLAS's ``kind`` (``"set"`` or ``"get"``) function of every OpenBLAS library
    loaded in this process, found in its memory map (Linux; elsewhere none)."""
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split(None, 5)[5].strip() for line in maps
                     if "openblas" in line.lower() and len(line.split(None, 5)) == 6}
    except OSError:
        return []
    found = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        fn = next((getattr(lib, name) for name in _OPENBLAS_SYMBOLS[kind]
                   if hasattr(lib, name)), None)
        if fn is not None:
            found.append(fn)
    return found


def blas_threads() -> list[int]:
    """The threads of each OpenBLAS library loaded in this process (Linux; else ``[]``)."""
    counts = []
    for get in _openblas("get"):
        get.restype = ctypes.c_int
        counts.append(int(get()))
    return counts


def one_blas_thread() -> None:
    """Do this process's linear algebra on one thread, and that of the processes it starts.

    Tasks side by side already fill the cores: OpenBLAS's own threads then only compete with
    them, and on the small matrices of the examples they cost far more than they save (a 3 x 3
    triangular solve by scipy: 2 ms of CPU instead of 13 us on a loaded two-core machine). The
    environment reaches the processes started later (a sweep's pool), which load their BLAS
    afresh; the libraries already loaded here (numpy's and scipy's OpenBLAS) are told through
    their own setter (Linux; elsewhere only the environment).
    """
    for name in BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"
    for set_threads in _openblas("set"):
        set_threads(ctypes.c_int(1))


def _child(fn: Callable[..., Any], args: tuple[Any, ...], conn: Connection,
           one_thread: bool = False) -> None:
    """Run ``fn(*args)`` and send ``(value, error, seconds, output)`` to the parent (on one
    BLAS thread when ``one_thread``: :func:`one_blas_thread`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)    # the parent decides what Ctrl-C stops
    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    if one_thread:
        one_blas_thread()
    output = io.StringIO()
    start, cpu = time.perf_counter(), _cpu_seconds()
    value, error = None, ""
    with contextlib.redirect_stdout(output), contextlib.redirect_stderr(output):
        try:
            value = fn(*args)
        except Exception:  # noqa: BLE001 - sent back as text, the other tasks go on
            error = traceback.format_exc()
    seconds, cpu = time.perf_counter() - start, _cpu_seconds() - cpu
    try:
        conn.send((value, error, seconds, output.getvalue(), cpu))
    except Exception:  # noqa: BLE001 - a value that cannot be pickled: say so instead
        conn.send((None, f"the task's result cannot be sent back from its process:\n"
                         f"{traceback.format_exc()}", seconds, output.getvalue(), cpu))
    conn.close()


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its children that have ended (a task's pool)."""
    try:
        import resource
    except ImportError:                 # not on Windows
        return time.process_time()
    own, ended = (resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                       resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime


def preload(modules: Sequence[str]) -> list[str]:
    """Import ``modules`` in this process when children are forked (they then inherit them);
    returns those imported. A module that cannot be imported (an optional extra that is not
    installed) is skipped: the task that needs it says so in its own process."""
    import importlib

    if _context().get_start_method() != "fork":
        return []                       # spawned children import everything again anyway
    done = []
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError:
            continue
        done.append(name)
    return done


def run_each(tasks: Sequence[tuple[Callable[..., Any], tuple[Any, ...]]], jobs: int, *,
             on_done: Callable[[int, Outcome], None] | None = None,
             shared: Sequence[str] = ()) -> list[Outcome]:
    """Run ``fn(*args)`` for every ``(fn, args)`` of ``tasks``, at most ``jobs`` at a time,
    in the order given; returns one :class:`Outcome` per task, in the order of ``tasks``.

    ``on_done(index, outcome)`` is called in this process as each task finishes. A task that
    raises, returns a value that cannot be pickled, or whose process dies gives an outcome
    with ``value=None`` and the reason in ``error``; the other tasks run on. ``shared``: the
    modules the tasks import, imported here first (:func:`preload`). With ``jobs > 1`` each
    task does its linear algebra on one thread (:func:`one_blas_thread`): the tasks fill the
    cores.
    """
    ctx = _context()
    if tasks:
        preload(shared)
    queue = list(enumerate(tasks))
    queue.reverse()                     # pop() from the end: the first task starts first
    outcomes: list[Outcome | None] = [None] * len(tasks)
    running: dict[Connection, tuple[int, Any, float]] = {}
    try:
        while queue or running:
            while queue and len(running) < jobs:
                index, (fn, args) = queue.pop()
                recv, send = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_child, args=(fn, args, send, jobs > 1))
                proc.start()
                with contextlib.suppress(OSError):      # the child does it too (no race)
                    os.setpgid(proc.pid, proc.pid)
                send.close()                            # EOF here when the child ends
                running[recv] = (index, proc, time.perf_counter())
            for conn in wait(list(running)):
                assert isinstance(conn, Connection)
                index, proc, start = running.pop(conn)
                outcome = _receive(conn, proc, start)
                outcomes[index] = outcome
                if on_done is not None:
                    on_done(index, outcome)
    finally:
        for conn, (_, proc, _) in running.items():     # Ctrl-C or an error: stop them all
            _stop(proc)
            conn.close()
    assert all(o is not None for o in outcomes)
    return [o for o in outcomes if o is not None]


def _receive(conn: Connection, proc: Any, start: float) -> Outcome:
    try:
        value, error, seconds, output, cpu = conn.recv()
    except (EOFError, OSError):
        value, error, seconds, output, cpu = (None, None, time.perf_counter() - start, "",
                                              float("nan"))
    finally:
        conn.close()
    proc.join()
    if error is None:
        error = (f"the task's process died before it finished (exit code {proc.exitcode}"
                 f"{': killed by signal ' + str(-proc.exitcode) if proc.exitcode < 0 else ''})")
    return Outcome(value, error, seconds, output, cpu)


def _stop(proc: Any) -> None:
    """Terminate a child and every process of its group, then reap it."""
    for sig, grace in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, sig)
        with contextlib.suppress(OSError):
            os.kill(proc.pid, sig)
        proc.join(grace)
        if not proc.is_alive():
            return

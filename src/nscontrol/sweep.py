"""Parameter sweeps over any :class:`concurrent.futures.Executor`.

``run(fn, grid)`` evaluates ``fn(point)`` for every point of ``grid`` — in local processes by
default, in a Dask cluster when given ``dask.distributed.Client(...).get_executor()``, a
``Client`` or a scheduler address such as ``"tcp://10.0.0.5:8786"`` (extra ``cluster``) — and
returns a frozen :class:`SweepResult` holding the values **in grid order** and, per point, the
error that point raised. One failing point never loses the others, and with ``point_timeout``
(local process pools) one that never returns is stopped and recorded as failed.

Picklability
------------
With process-based executors (the default, and every remote Dask worker) ``fn`` and the grid
points travel by pickle: ``fn`` must be a module-level function (or a
:func:`functools.partial` of one, or an instance of a module-level class with ``__call__``),
not a lambda, a closure or a function defined in ``__main__`` of an interactive session. Use
``executor="serial"`` or a :class:`~concurrent.futures.ThreadPoolExecutor` for anything else.
A task that cannot be shipped is recorded as each point's :class:`PointError` with the rule in
its message (Dask serialises at ``submit``, local pools in transit); it never aborts the sweep.

Tasks
-----
Points travel to workers in *chunks*: one task runs several points one after the other, so
that a task lasts about :data:`MIN_TASK_SECONDS` and a scheduler's fixed cost per task (about
a millisecond on a local pool, several on Dask: see :data:`MIN_TASK_SECONDS`) stays small
beside it. The first task on each worker is
one point, timed in the worker; later chunks are sized from the measured time per point,
and never so large that fewer than two chunks per worker remain (the last chunks shrink, so
the workers finish together). A point that alone lasts a task is handed out only to a free
worker, so none waits queued behind a long one. Results do not depend on the chunking: each
point is still ``fn(point)``, recorded in grid order with its own error. ``chunk=1`` sends
one point per task, ``chunk=n`` exactly ``n``.

``executor="auto"`` times the first point in this process and sends the rest to a local
process pool only when that pays (see :data:`AUTO_PARALLEL_SECONDS`); it is the default of the
frequency-response helpers of :mod:`nscontrol.analysis.periodic`.
"""

from __future__ import annotations

import difflib
import math
import os
import pickle
import re
import shutil
import signal
import tempfile
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

from ._validation import check_bool, check_integer, check_positive
from .errors import ModelError, NscontrolError

__all__ = ["run", "SweepResult", "PointError", "SweepError", "AUTO_PARALLEL_SECONDS",
           "MAX_POOL_RESTARTS", "MIN_TASK_SECONDS"]


class SweepError(NscontrolError, RuntimeError):
    """Raised by :meth:`SweepResult.raise_on_error` when some points of a sweep failed."""


@dataclass(frozen=True)
class PointError:
    """Why one grid point failed.

    Attributes
    ----------
    index
        Position of the point in the grid.
    type
        Name of the exception class (``"ValueError"``, ``"BrokenProcessPool"``...).
    message
        ``str(exception)``.
    traceback
        The formatted traceback from the worker (empty when the worker itself was lost).
    """

    index: int
    type: str
    message: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"point {self.index}: {self.type}: {self.message}"


@dataclass(frozen=True)
class SweepResult:
    """Outcome of :func:`run`, in grid order.

    Attributes
    ----------
    grid : tuple
        The points, as given.
    values : tuple
        ``fn(point)`` for each point; ``None`` where the point failed.
    errors : tuple of PointError or None
        ``None`` where the point succeeded.
    """

    grid: tuple[Any, ...]
    values: tuple[Any, ...]
    errors: tuple[PointError | None, ...]

    @property
    def ok(self) -> bool:
        """True when every point succeeded."""
        return all(e is None for e in self.errors)

    @property
    def failed(self) -> tuple[PointError, ...]:
        """The errors of the failed points, in grid order."""
        return tuple(e for e in self.errors if e is not None)

    @property
    def succeeded(self) -> tuple[int, ...]:
        """Indices of the points that succeeded."""
        return tuple(i for i, e in enumerate(self.errors) if e is None)

    def __len__(self) -> int:
        return len(self.grid)

    def __iter__(self) -> Iterator[Any]:
        return iter(self.values)

    def raise_on_error(self) -> SweepResult:
        """Return ``self`` when every point succeeded, else raise :class:`SweepError`."""
        if not self.ok:
            lines = "\n".join(str(e) for e in self.failed[:10])
            raise SweepError(f"{len(self.failed)} of {len(self)} sweep points failed:\n{lines}")
        return self


@dataclass(frozen=True)
class _Guarded:
    """Picklable wrapper running ``fn(point)`` in the worker and catching its exception there
    (exception objects themselves need not be picklable).

    Every exception but ``KeyboardInterrupt`` is the point's error, ``SystemExit`` included.
    In local worker processes (``marks`` set) the wrapper leaves a file named after the point
    in ``marks`` while it runs, holding the worker's pid and the start time, so that after a
    worker dies the points it was running are known, and a point running longer than
    ``point_timeout`` is found with the process to end; and it pickles the value itself
    (``ship``), so that a value that cannot travel back is reported as such for its point.
    """

    fn: Callable[[Any], Any]
    marks: str | None = None
    ship: bool = False

    def __call__(self, indexed: tuple[int, Any]) -> tuple[bool, Any]:
        index, point = indexed
        mark = None if self.marks is None else os.path.join(self.marks, str(index))
        if mark is not None:
            with open(mark, "w") as fh:
                fh.write(f"{os.getpid()} {time.time()!r}")
        try:
            value = self.fn(point)
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # recorded per point: see SweepResult.errors
            result = False, PointError(index, type(exc).__name__, _describe(exc),
                                       traceback.format_exc())
        else:
            result = True, value
            if self.ship:
                result = _shipped(index, value)
        if mark is not None:
            os.unlink(mark)
        return result


def _describe(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        return (f"fn called sys.exit({exc.code!r}) (SystemExit) instead of returning or "
                "raising an Exception; the other points ran")
    return str(exc)


def _shipped(index: int, value: Any) -> tuple[bool, Any]:
    """``(True, pickled value)``, or the point's error saying its value cannot be sent back."""
    try:
        return True, _Pickled(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))
    except Exception as exc:
        return False, PointError(
            index, type(exc).__name__,
            f"the value fn returned for point {index} (a {type(value).__name__}) cannot be "
            f"sent back from the worker process ({exc}); return picklable data (numbers, "
            f"arrays, tuples or dataclasses of them), or run with executor='serial' or a "
            f"ThreadPoolExecutor", traceback.format_exc())


@dataclass(frozen=True)
class _Pickled:
    """A value pickled in the worker (transport then copies bytes only)."""

    data: bytes


@dataclass(frozen=True)
class _Batch:
    """Picklable task running a chunk of ``(index, point)`` pairs through ``call`` in turn:
    ``(((index, (ok, payload)), ...), seconds, interrupted)``.

    ``seconds`` is the time the chunk took in the worker (what sizes the next chunks, free of
    the scheduler's own delays). A ``KeyboardInterrupt`` in a point ends the chunk: the points
    finished before it are returned with ``interrupted`` set, so the caller keeps them and
    re-raises.
    """

    call: _Guarded

    def __call__(self, chunk: tuple[tuple[int, Any], ...]
                 ) -> tuple[tuple[tuple[int, Any], ...], float, bool]:
        out: list[tuple[int, Any]] = []
        start = time.perf_counter()
        try:
            for indexed in chunk:
                out.append((indexed[0], self.call(indexed)))
        except KeyboardInterrupt:
            return tuple(out), time.perf_counter() - start, True
        return tuple(out), time.perf_counter() - start, False


#: Wall time (seconds) a task of automatically chunked points aims at (``run``'s default
#: ``min_task_seconds``). Measured on the project's 2-core machine under load (load average
#: 10-11), ``math.sqrt`` over 400 points one per task: ~1 ms per task on a 2-process local
#: pool, 7-24 ms on a 2-worker Dask ``LocalCluster``; at 0.5 s per task such a cost is 0.2-5 %
#: of the task, while a grid of a few seconds of work still makes several chunks per worker.
MIN_TASK_SECONDS = 0.5

#: Automatic chunks are never larger than ``remaining points / (this × workers)``: at least
#: this many chunks per worker remain to be handed out, so the tail shrinks and the workers
#: finish within about one small chunk of each other.
_CHUNKS_PER_WORKER = 2


#: ``executor="auto"`` goes parallel when the pilot point predicts more serial work than this
#: (seconds) for the rest of the grid. Measured on the project's 2-core machine (fork start
#: method, best of 3): a local pool starts, runs a task and shuts down in ~0.035 s; a
#: chapter-11 shooting point (400 samples) costs ~8 ms; serial vs two processes: 10 points
#: 0.091/0.085 s, 15 points 0.136/0.112 s, 60 points 0.462/0.320 s — break-even near 10
#: points (~0.09 s of work). 0.15 s leaves a margin for a busy second core.
AUTO_PARALLEL_SECONDS = 0.15


def run(fn: Callable[[Any], Any], grid: Iterable[Any], *,
        executor: Executor | str | Any | None = None,
        progress: bool | None = None, desc: str = "sweep",
        point_timeout: float | None = None, chunk: int | None = None,
        min_task_seconds: float = MIN_TASK_SECONDS) -> SweepResult:
    """Evaluate ``fn(point)`` for every point of ``grid``, in parallel.

    Parameters
    ----------
    fn
        One-argument function. Must be picklable for process and cluster executors (see the
        module docstring).
    grid
        The points (any iterable; materialised once).
    executor
        ``None``: a local :class:`~concurrent.futures.ProcessPoolExecutor` with
        ``min(os.cpu_count(), len(grid))`` workers, created and shut down here.
        An :class:`~concurrent.futures.Executor` (e.g. ``Client.get_executor()``): used as is,
        not shut down. A ``dask.distributed.Client``: its executor. A string: ``"serial"`` runs
        in this process (debugging, unpicklable ``fn``); ``"auto"`` runs the first point here,
        timed, and the rest in a local process pool when that predicts more than
        :data:`AUTO_PARALLEL_SECONDS` of serial work (and ``fn`` pickles and there are two or
        more CPUs), else here too; anything else is a Dask scheduler address, connected to
        (and disconnected from) here.
    progress
        Progress bar on stderr: ``None`` shows it when the sweep lasts more than 2 s,
        ``True`` always, ``False`` never.
    desc
        Label of the progress bar.
    point_timeout
        Wall-time budget of one point, in seconds (``None``: none). A point still running
        after it is recorded as a :class:`PointError` of type ``BudgetExceededError`` naming
        ``point_timeout``, and the worker process running it is ended; the other points run
        on (those that were running beside it are re-run in a fresh pool). Enforced on local
        process pools only (``None``, ``"auto"``, which then runs every point in the pool,
        and a :class:`~concurrent.futures.ProcessPoolExecutor`, which the ended worker
        leaves broken for later use): a point running in this process, a thread or a Dask
        worker cannot be stopped, so those executors refuse the option.
    chunk
        Points per task on a parallel executor. ``None`` (default): automatic, the first
        task of each worker one point, timed in the worker, then chunks lasting about
        ``min_task_seconds`` each, shrinking at the end so the workers finish together (see
        the module docstring). An integer ``n >= 1``: ``n`` points per task (``1``: one task
        per point). Ignored by ``"serial"``. Values and errors are the same for any chunking.
    min_task_seconds
        Wall time an automatic chunk aims at, in seconds (default
        :data:`MIN_TASK_SECONDS`); raise it when a scheduler's cost per task is high.

    Returns
    -------
    SweepResult
        Values and per-point errors in grid order. A point that cannot be submitted (an
        unpicklable ``fn`` or point on a cluster), fails in transit or loses its worker is
        recorded as that point's :class:`PointError`; the message says which picklability
        rule was broken.

    A worker process that dies (``os._exit``, a segfault, the OOM killer) breaks a local pool
    and fails every point still queued on it; those points are re-run in a fresh pool. The
    points the dead workers were running are re-run alone, each in its own process: one that
    kills its process again is recorded as its own :class:`PointError` (``WorkerDied``), the
    others keep their values. At most :data:`MAX_POOL_RESTARTS` fresh pools are started
    after such deaths (the workers ended for ``point_timeout`` do not count: each of those
    settles its point).

    Raises
    ------
    ModelError
        ``fn`` is not callable, ``grid`` is not an iterable of points, or ``executor`` is of
        an unsupported type or a string that is neither ``"serial"``, ``"auto"`` nor a
        scheduler address (``tcp://host:port`` or ``host:port``); ``point_timeout`` is not a
        positive number, or is given with an executor that cannot stop a running point;
        ``chunk`` is not ``None`` or an integer >= 1; ``min_task_seconds`` is not a positive
        number.
    KeyboardInterrupt
        Re-raised after the points that finished are kept: ``err.sweep_result`` holds the
        :class:`SweepResult` so far (unfinished points carry a ``KeyboardInterrupt`` error).
    ImportError
        A scheduler address was given but ``dask[distributed]`` is not installed.

    Examples
    --------
    >>> import math
    >>> from nscontrol import sweep
    >>> res = sweep.run(math.sqrt, [4.0, -1.0, 9.0], executor="serial", progress=False)
    >>> res.values, res.errors[1].type
    ((2.0, None, 3.0), 'ValueError')
    """
    if not callable(fn):
        raise ModelError(f"fn: expected a callable taking one grid point, got "
                         f"{type(fn).__name__}")
    points = _points(grid)
    _check_executor(executor)
    budget = _check_point_timeout(point_timeout, executor)
    sizing = _Sizing(None if chunk is None else check_integer("chunk", chunk, minimum=1),
                     check_positive("min_task_seconds", min_task_seconds,
                                    hint="the seconds one task of chunked points aims at"))
    if not points:
        return SweepResult((), (), ())
    call = _Guarded(fn)
    values: list[Any] = [None] * len(points)
    errors: list[PointError | None] = [None] * len(points)
    done = [False] * len(points)
    todo = list(enumerate(points))
    bar = _bar(len(points), check_bool("progress", progress, allow_none=True), desc)
    try:
        if isinstance(executor, str) and executor == "auto" and budget is None:
            _run_auto(call, todo, values, errors, bar, done, sizing)
        else:                          # "auto" with a budget: every point in a local pool
            auto = isinstance(executor, str) and executor == "auto"
            with _executor_for(None if auto else executor, len(points)) as ex:
                _dispatch(ex, call, todo, values, errors, bar, done, budget, sizing)
    except KeyboardInterrupt as exc:
        for i, finished in enumerate(done):
            if not finished:
                errors[i] = PointError(i, "KeyboardInterrupt", "not run: the sweep was "
                                       "interrupted")
        # a new attribute on the interrupt: the points finished so far travel with it
        exc.sweep_result = SweepResult(  # type: ignore[attr-defined]
            points, tuple(values), tuple(errors))
        exc.add_note(f"nscontrol.sweep: {sum(done)} of {len(points)} points finished; "
                     "err.sweep_result holds them")
        raise
    finally:
        if bar is not None:
            bar.close()
    return SweepResult(points, tuple(values), tuple(errors))


#: Fresh local pools :func:`run` starts after worker processes died, before it records the
#: points not yet run as errors.
MAX_POOL_RESTARTS = 10

#: Longest wait (seconds) between two looks for points over ``point_timeout``; the wait is
#: also at most a quarter of the budget, so a point is ended within 1.25 budgets (plus the
#: time to end its process).
_POLL_SECONDS = 0.25

_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ucx|ws|wss)://)?"
                      r"(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9_.-]*[A-Za-z0-9])?)"
                      r":(\d{1,5})$")
_INPROC = re.compile(r"^inproc://\S+$")        # an in-process LocalCluster's scheduler
_NAMES = ("serial", "auto")


def _points(grid: Any) -> tuple[Any, ...]:
    """The grid as a tuple; a string or a non-iterable is a mistake, not a grid."""
    if isinstance(grid, str | bytes):
        raise ModelError(f"grid: expected an iterable of points, got the string {grid!r}; "
                         "pass a list of points (e.g. [0.1, 0.2])")
    try:
        return tuple(grid)
    except TypeError:
        raise ModelError(f"grid: expected an iterable of points (a list, a range, an array), "
                         f"got {type(grid).__name__} {grid!r}; write [point] for a single "
                         "point or range(n) for n points") from None


def _check_executor(executor: Any) -> None:
    """Refuse a string that is no executor name and no scheduler address (a typo such as
    ``'seriall'`` would otherwise be dialled as a Dask address)."""
    if not isinstance(executor, str) or executor in _NAMES:
        return
    match = _ADDRESS.match(executor)
    if (match and 0 < int(match.group(1)) < 65536) or _INPROC.match(executor):
        return
    close = difflib.get_close_matches(executor, _NAMES, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise ModelError(f"executor: {executor!r} is neither 'serial', 'auto' nor a Dask scheduler "
                     f"address (tcp://host:port or host:port){hint}")


def _check_point_timeout(point_timeout: Any, executor: Any) -> float | None:
    """The per-point budget in seconds (None: unlimited); refused where no running point can
    be stopped (only ending its process stops a point: a thread or Dask task cannot be)."""
    if point_timeout is None:
        return None
    budget = check_positive("point_timeout", point_timeout)
    local = (executor is None or isinstance(executor, ProcessPoolExecutor)
             or (isinstance(executor, str) and executor == "auto"))
    if not local:
        what = (repr(executor) if isinstance(executor, str)
                else f"a {type(executor).__name__}")
        raise ModelError(
            f"point_timeout: a running point can be stopped only by ending its worker process, "
            f"which nscontrol does on local process pools only (executor=None, 'auto' or a "
            f"ProcessPoolExecutor), got executor={what}; run on a local pool, or bound the "
            f"work inside fn (its own step or iteration budgets); on Dask, Future.cancel leaves "
            f"a running task in its worker thread, only restarting the workers stops it")
    return budget


def _run_auto(call: _Guarded, todo: list[tuple[int, Any]], values: list[Any],
              errors: list[PointError | None], bar: Any, done: list[bool],
              sizing: _Sizing) -> None:
    """``executor="auto"``: a timed pilot point here, then processes only if they pay (its
    time sizes their first chunks)."""
    t = time.perf_counter()
    _gather(None, call, todo[:1], values, errors, bar, done)
    pilot = time.perf_counter() - t
    rest = todo[1:]
    workers = min(os.cpu_count() or 1, len(rest))
    if (workers > 1 and pilot * len(rest) > AUTO_PARALLEL_SECONDS
            and not _pickling_problem(call, dask=False)):
        sizing.observe(1, pilot)
        with _owned_pool(workers) as pool:
            _dispatch(pool, call, rest, values, errors, bar, done, None, sizing)
    else:
        _gather(None, call, rest, values, errors, bar, done)


def _dispatch(ex: Executor | None, call: _Guarded, todo: list[tuple[int, Any]],
              values: list[Any], errors: list[PointError | None], bar: Any,
              done: list[bool], budget: float | None = None,
              sizing: _Sizing | None = None) -> None:
    """Local process pools get crash recovery and the per-point budget; other executors run
    as they are."""
    if isinstance(ex, ProcessPoolExecutor):
        _gather_recovering(ex, call, todo, values, errors, bar, done, budget, sizing)
    else:
        _gather(ex, call, todo, values, errors, bar, done, budget, sizing)


def _gather_recovering(pool: ProcessPoolExecutor, call: _Guarded, todo: list[tuple[int, Any]],
                       values: list[Any], errors: list[PointError | None], bar: Any,
                       done: list[bool], budget: float | None = None,
                       sizing: _Sizing | None = None) -> None:
    """:func:`_gather` on a local pool, re-running the points a dead worker took with it.

    After a crash the points whose marks remain (they were running) are re-run alone, each
    in a fresh one-worker pool, so the culprit is identified; the other points of the lost
    tasks (those a chunk had finished or not reached) go to a fresh pool of the same size.
    When the pool broke because workers were ended for the ``budget`` (their points
    settled), the culprits are known: every lost point goes to the fresh pool. Each round
    settles at least one point; at most :data:`MAX_POOL_RESTARTS` rounds follow a crash.
    """
    marks = tempfile.mkdtemp(prefix="nscontrol-sweep-")
    call = replace(call, marks=marks, ship=True)
    workers = getattr(pool, "_max_workers", None) or (os.cpu_count() or 1)
    context = getattr(pool, "_mp_context", None)
    try:
        lost, ended = _gather(pool, call, todo, values, errors, bar, done, budget, sizing)
        restarts = 0
        while lost:
            running = {int(n) for n in os.listdir(marks)}
            for n in os.listdir(marks):
                os.unlink(os.path.join(marks, n))
            if not ended:
                restarts += 1
                # the points the dead workers held (the first few lost ones when no mark says)
                suspects = [ip for ip in lost if ip[0] in running] or lost[:workers]
                for i, p in suspects:
                    _run_alone(call, i, p, context, values, errors, bar, done, budget)
                lost = [ip for ip in lost if not done[ip[0]]]
            if lost and not ended and restarts >= MAX_POOL_RESTARTS:
                for i, _ in lost:
                    _settle(i, PointError(i, "BrokenProcessPool", (
                        f"not run: worker processes died {restarts} times in this sweep "
                        f"(MAX_POOL_RESTARTS = {MAX_POOL_RESTARTS} fresh pools spent); run "
                        "these points with executor='serial' to see why")),
                        values, errors, bar, done)
                return
            if lost:
                with _owned_pool(workers, context) as fresh:
                    lost, ended = _gather(fresh, call, lost, values, errors, bar, done, budget,
                                          sizing)
    finally:
        shutil.rmtree(marks, ignore_errors=True)


def _run_alone(call: _Guarded, i: int, p: Any, context: Any, values: list[Any],
               errors: list[PointError | None], bar: Any, done: list[bool],
               budget: float | None) -> None:
    """One point in a fresh one-worker pool: its value, its error, or its own crash."""
    with _owned_pool(1, context) as solo:
        lost, _ = _gather(solo, call, [(i, p)], values, errors, bar, done, budget)
    if lost:
        _settle(i, PointError(i, "WorkerDied", (
            f"the worker process died while running point {i} (os._exit, a segfault, the "
            "OOM killer...); re-run alone in a fresh process it died again; the other "
            "points were re-run in a fresh pool")), values, errors, bar, done)


def _settle(i: int, error: PointError, values: list[Any], errors: list[PointError | None],
            bar: Any, done: list[bool]) -> None:
    errors[i] = error
    _tick(i, bar, done)


def _tick(i: int, bar: Any, done: list[bool]) -> None:
    done[i] = True
    if bar is not None:
        bar.update(1)


@contextmanager
def _owned_pool(workers: int, context: Any = None) -> Iterator[ProcessPoolExecutor]:
    """A local pool created (and shut down) here; on an interrupt or a crash it does not wait
    for the queued points."""
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context)
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


class _Sizing:
    """How points are cut into tasks: ``chunk`` points each (``None``: automatic, aiming at
    ``min_seconds`` per task), and the time per point measured so far in the workers (shared
    by the rounds of one sweep, so a fresh pool after a crash starts from it)."""

    def __init__(self, chunk: int | None = 1, min_seconds: float = MIN_TASK_SECONDS) -> None:
        self.chunk = chunk
        self.min_seconds = min_seconds
        self.seconds = 0.0
        self.points = 0

    def observe(self, points: int, seconds: float) -> None:
        """``points`` more points took ``seconds`` of a worker's wall time."""
        self.points += points
        self.seconds += seconds

    def size(self, remaining: int, workers: int) -> int:
        """Points in the next task, ``remaining`` points not yet handed out."""
        if self.chunk is not None:
            return min(self.chunk, remaining)
        if not self.points:
            return 1                           # the pilots: one point per worker, timed
        per_point = self.seconds / self.points
        target = (math.ceil(self.min_seconds / per_point) if per_point > 0.0 else remaining)
        balance = math.ceil(remaining / (_CHUNKS_PER_WORKER * workers))
        return max(1, min(target, balance, remaining))

    def in_flight(self, workers: int) -> float:
        """Tasks submitted and not finished that the sweep keeps at most: all of them with a
        fixed chunk; one pilot per worker until a time is known; one per worker when a
        single point lasts a whole task (``min_seconds`` or more); else two per worker (one
        running, one queued, so no worker waits for the next chunk's round trip).

        A queued task waits in the queue of the worker the executor chose for it: behind a
        point of several seconds it would wait while another worker falls idle (Dask places
        a task by its estimate of the workers' queues, not knowing how long a point runs), so
        long points are handed out one per free worker, in grid order — the round trip that a
        queue hides (milliseconds) is small beside them."""
        if self.chunk is not None:
            return math.inf
        if not self.points or self.seconds >= self.min_seconds * self.points:
            return workers
        return 2 * workers


class _Chunker:
    """The points of one round not yet handed out, cut into tasks in grid order; a task that
    failed as a whole (a point that cannot travel, a lost Dask worker) comes back as single
    points, so that only the culprit fails."""

    def __init__(self, todo: list[tuple[int, Any]], workers: int, sizing: _Sizing) -> None:
        self.queue = deque(todo)
        self.singles: deque[tuple[int, Any]] = deque()
        self.workers = max(1, workers)
        self.sizing = sizing

    def __bool__(self) -> bool:
        return bool(self.queue or self.singles)

    def may_submit(self, running: int) -> bool:
        return bool(self) and running < self.sizing.in_flight(self.workers)

    def take(self) -> tuple[tuple[int, Any], ...]:
        if self.singles:
            return (self.singles.popleft(),)
        n = self.sizing.size(len(self.queue), self.workers)
        return tuple(self.queue.popleft() for _ in range(n))

    def split(self, chunk: Iterable[tuple[int, Any]]) -> None:
        self.singles.extendleft(reversed(list(chunk)))

    def rest(self) -> list[tuple[int, Any]]:
        rest = [*self.singles, *self.queue]
        self.singles.clear()
        self.queue.clear()
        return rest


def _workers(ex: Executor) -> int:
    """How many tasks ``ex`` runs at once: a pool's ``max_workers``, a Dask cluster's
    threads, else the CPUs here.

    For Dask, the client's own copy of the scheduler's identity (``total_threads``, which
    the client refreshes every few seconds) is read first: asking the scheduler
    (``Client.nthreads()``) is a round trip, and measured on a 2-worker ``LocalCluster`` the
    first task submitted right after it took ~11 ms to come back instead of ~3 ms, a cost
    every sweep paid (1-2 % of a one-second sweep). The count only sizes chunks, so a count
    a few seconds old is harmless."""
    n = getattr(ex, "_max_workers", None)
    client = getattr(ex, "_client", None)     # dask.distributed's ClientExecutor
    if client is not None:
        identity = getattr(client, "_scheduler_identity", None)
        n = identity.get("total_threads") if isinstance(identity, dict) else None
        if not n and hasattr(client, "nthreads"):
            try:
                n = sum(client.nthreads().values())
            except Exception:                   # a cluster that cannot say: guess below
                n = None
    return max(1, int(n or os.cpu_count() or 1))


def _gather(ex: Executor | None, call: _Guarded, todo: list[tuple[int, Any]], values: list[Any],
            errors: list[PointError | None], bar: Any, done: list[bool],
            budget: float | None = None, sizing: _Sizing | None = None
            ) -> tuple[list[tuple[int, Any]], int]:
    """Run the ``(index, point)`` pairs of ``todo`` on ``ex`` (in this process when None), in
    tasks cut by ``sizing`` (default: one point each), and store values and errors by index.
    Returns the pairs lost to a broken local pool (not stored: the caller re-runs them) and
    how many workers were ended because their point ran over ``budget`` seconds (local pools
    with marks only)."""
    if ex is None:
        for i, p in todo:
            _store(i, call((i, p)), values, errors)
            _tick(i, bar, done)
        return [], 0
    return _Round(ex, call, todo, values, errors, bar, done,
                  sizing or _Sizing()).run(budget)


class _Round:
    """The tasks of one :func:`_gather` on an executor: submitted as the chunker cuts them,
    their points stored as they finish."""

    def __init__(self, ex: Executor, call: _Guarded, todo: list[tuple[int, Any]],
                 values: list[Any], errors: list[PointError | None], bar: Any,
                 done: list[bool], sizing: _Sizing) -> None:
        self.ex, self.call, self.batch = ex, call, _Batch(call)
        self.values, self.errors, self.bar, self.done = values, errors, bar, done
        self.plan = _Chunker(todo, _workers(ex), sizing)
        self.sizing = sizing
        self.dask = type(ex).__module__.startswith("distributed")
        self.points = dict(todo)
        self.futures: dict[Future, tuple[tuple[int, Any], ...]] = {}
        self.lost: list[tuple[int, Any]] = []
        self.broken = False
        self.fn_problem = ""       # set once fn itself is known not to serialise: no submits
        self.diagnosis: str | None = None

    def run(self, budget: float | None) -> tuple[list[tuple[int, Any]], int]:
        timed = budget is not None and self.call.marks is not None
        poll = min(_POLL_SECONDS, budget / 4) if timed and budget is not None else None
        ended = 0
        self.submit()
        while self.futures:
            finished, _ = wait(set(self.futures), timeout=poll, return_when=FIRST_COMPLETED)
            interrupted = False
            for f in finished:
                interrupted |= self.receive(f)
            if interrupted:
                raise KeyboardInterrupt
            if timed and self.futures and budget is not None:
                running = {i for chunk in self.futures.values() for i, _ in chunk}
                ended += _end_overdue(self.ex, self.call, budget, running, self.values,
                                      self.errors, self.bar, self.done)
            self.submit()
        self.lost += self.plan.rest()      # not handed out: the pool broke first
        return sorted(self.lost, key=lambda ip: ip[0]), ended

    def submit(self) -> None:
        """Hand out tasks while the sizing allows (none once the pool is broken)."""
        while not self.broken and self.plan.may_submit(len(self.futures)):
            chunk = self.plan.take()
            if self.fn_problem:
                for i, _ in chunk:
                    _settle(i, PointError(i, "PicklingError", self.fn_problem), self.values,
                            self.errors, self.bar, self.done)
                continue
            try:
                self.futures[self.ex.submit(self.batch, chunk)] = chunk
            except BrokenProcessPool:
                self.broken = True
                self.lost += chunk
            except Exception as exc:  # Dask serialises at submit: record, go on
                self.refused(chunk, exc)

    def refused(self, chunk: tuple[tuple[int, Any], ...], exc: Exception) -> None:
        """A task ``submit`` refused: fn cannot travel (every point says so), or one of its
        points cannot (the chunk's points are sent again one by one to find which)."""
        self.fn_problem = _pickling_problem(self.call, dask=self.dask)
        if not self.fn_problem and len(chunk) > 1:
            self.plan.split(chunk)
            return
        for i, _ in chunk:
            _settle(i, PointError(
                i, type(exc).__name__, self.fn_problem or
                f"could not submit point {i} ({exc}); with process or cluster executors "
                f"every grid point must be picklable", traceback.format_exc()),
                self.values, self.errors, self.bar, self.done)

    def receive(self, f: Future) -> bool:
        """Store the points of a finished task; True when one of them was interrupted."""
        chunk = self.futures.pop(f)
        left = [ip for ip in chunk if not self.done[ip[0]]]  # not settled by the budget
        failure = f.exception()
        if isinstance(failure, BrokenProcessPool):
            self.broken = True
            self.lost += left
            return False
        if isinstance(failure, KeyboardInterrupt):
            raise failure
        if failure is not None and len(left) > 1:   # which point? each alone, once more
            self.plan.split(left)
            return False
        if failure is not None:
            for i, p in left:
                if self.diagnosis is None:
                    self.diagnosis = (_pickling_problem(self.call, dask=self.dask)
                                      or _transit_problem(i, p))
                _settle(i, PointError(i, type(failure).__name__, f"{failure}; "
                                      f"{self.diagnosis}" if self.diagnosis else str(failure)),
                        self.values, self.errors, self.bar, self.done)
            return False
        results, seconds, interrupted = f.result()
        self.sizing.observe(len(results), seconds)
        for i, outcome in results:
            if not self.done[i]:
                _store(i, outcome, self.values, self.errors)
                _tick(i, self.bar, self.done)
        return bool(interrupted)


def _end_overdue(pool: Any, call: _Guarded, budget: float, pending: set[int],
                 values: list[Any], errors: list[PointError | None], bar: Any,
                 done: list[bool]) -> int:
    """Settle every point of ``pending`` running longer than ``budget`` as a
    ``BudgetExceededError`` and end its worker process (the only way to stop it). Returns
    how many were ended."""
    assert call.marks is not None
    processes = getattr(pool, "_processes", None) or {}
    now, ended = time.time(), 0
    for name in os.listdir(call.marks):
        mark = os.path.join(call.marks, name)
        try:
            with open(mark) as fh:
                pid_text, start_text = fh.read().split()
            i, pid, elapsed = int(name), int(pid_text), now - float(start_text)
        except (OSError, ValueError):  # being written or removed right now: next look
            continue
        if i not in pending or done[i] or elapsed <= budget:
            continue
        process = processes.get(pid)
        if processes and process is None:  # not a worker of this pool: a stale mark
            continue
        _settle(i, PointError(i, "BudgetExceededError", (
            f"point {i} ran longer than point_timeout={budget:g} s (stopped after "
            f"{elapsed:.3g} s by ending its worker process); raise point_timeout, or run the "
            f"point alone (executor='serial') to see why it is slow")), values, errors, bar,
            done)
        os.unlink(mark)
        if process is not None:
            process.kill()
        else:
            os.kill(pid, getattr(signal, "SIGKILL", signal.SIGTERM))
        ended += 1
    return ended


def _transit_problem(index: int, point: Any) -> str:
    """Why a task whose ``fn`` pickles failed in transit: its point, or else its value."""
    try:
        pickle.dumps(point)
    except Exception as exc:
        return (f"point {index} cannot be pickled ({type(exc).__name__}: {exc}); with process "
                "or cluster executors every grid point travels by pickle")
    return (f"the point or the value fn returned for point {index} could not be sent between "
            "processes; return picklable data, or run with executor='serial'")


def _pickling_problem(call: _Guarded, *, dask: bool) -> str:
    """Why the task cannot travel to process or cluster workers (empty when it can): the rule
    of the module docstring, with the serialiser's own error."""
    try:
        if dask:
            from distributed.protocol.pickle import dumps  # pickle, then cloudpickle
        else:
            from pickle import dumps
        dumps(call)
    except Exception as exc:
        return (f"fn cannot be pickled ({type(exc).__name__}: {exc}); process and cluster "
                f"executors ship fn to their workers by pickle: use a module-level function, "
                f"a functools.partial of one or an instance of a module-level class holding "
                f"picklable data, or run with executor='serial' or a ThreadPoolExecutor")
    return ""


def _store(index: int, outcome: tuple[bool, Any], values: list[Any],
           errors: list[PointError | None]) -> None:
    """Unpack one point's ``(ok, payload)``: its value (unpickled when the worker shipped it
    pickled) or its :class:`PointError`."""
    ok, payload = outcome
    if ok and isinstance(payload, _Pickled):
        try:
            values[index] = pickle.loads(payload.data)
        except Exception as exc:
            errors[index] = PointError(index, type(exc).__name__, (
                f"the value fn returned for point {index} could not be unpickled in this "
                f"process ({exc}); its class must be importable here"), traceback.format_exc())
    elif ok:
        values[index] = payload
    else:
        errors[index] = payload


def _bar(total: int, progress: bool | None, desc: str) -> Any:
    if progress is False:
        return None
    from ._progress import count_bar

    return count_bar(total, desc=desc, delay=0.0 if progress else 2.0)


@contextmanager
def _executor_for(executor: Any, n_points: int) -> Iterator[Executor | None]:
    """Resolve the ``executor`` argument; shut down only what was created here."""
    if executor is None:
        workers = max(1, min(os.cpu_count() or 1, n_points))
        with _owned_pool(workers) as pool:
            yield pool
    elif isinstance(executor, str) and executor == "serial":
        yield None
    elif isinstance(executor, str):
        with _dask_client(executor) as client:
            yield client.get_executor()
    elif isinstance(executor, Executor):
        yield executor
    elif hasattr(executor, "get_executor"):  # a dask.distributed.Client
        yield executor.get_executor()
    else:
        raise ModelError(f"executor: expected None, 'serial', 'auto', a "
                         f"concurrent.futures.Executor, a dask.distributed.Client or a "
                         f"scheduler address, got {type(executor).__name__}")


@contextmanager
def _dask_client(address: str) -> Iterator[Any]:
    try:
        from dask.distributed import Client
    except ImportError as exc:  # pragma: no cover - depends on the installed extras
        raise ImportError(f"executor={address!r} needs dask.distributed: install the "
                          f"'cluster' extra (pip install nscontrol[cluster])") from exc
    client = Client(address)
    try:
        yield client
    finally:
        client.close()

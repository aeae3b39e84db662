"""Parameter sweeps over any :class:`concurrent.futures.Executor`.

``run(fn, grid)`` evaluates ``fn(point)`` for every point of ``grid`` — in local processes by
default, in a Dask cluster when given ``dask.distributed.Client(...).get_executor()``, a
``Client`` or a scheduler address such as ``"tcp://10.0.0.5:8786"`` (extra ``cluster``) — and
returns a frozen :class:`SweepResult` holding the values **in grid order** and, per point, the
error that point raised. One failing point never loses the others.

Picklability
------------
With process-based executors (the default, and every remote Dask worker) ``fn`` and the grid
points travel by pickle: ``fn`` must be a module-level function (or a
:func:`functools.partial` of one, or an instance of a module-level class with ``__call__``),
not a lambda, a closure or a function defined in ``__main__`` of an interactive session. Use
``executor="serial"`` or a :class:`~concurrent.futures.ThreadPoolExecutor` for anything else.
A task that cannot be shipped is recorded as each point's :class:`PointError` with the rule in
its message (Dask serialises at ``submit``, local pools in transit); it never aborts the sweep.

``executor="auto"`` times the first point in this process and sends the rest to a local
process pool only when that pays (see :data:`AUTO_PARALLEL_SECONDS`); it is the default of the
frequency-response helpers of :mod:`nscontrol.analysis.periodic`.
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from .errors import ModelError, NscontrolError

__all__ = ["run", "SweepResult", "PointError", "SweepError", "AUTO_PARALLEL_SECONDS"]


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
    (exception objects themselves need not be picklable)."""

    fn: Callable[[Any], Any]

    def __call__(self, indexed: tuple[int, Any]) -> tuple[bool, Any]:
        index, point = indexed
        try:
            return True, self.fn(point)
        except Exception as exc:  # recorded per point, never swallowed: see SweepResult.errors
            return False, PointError(index, type(exc).__name__, str(exc),
                                     traceback.format_exc())


#: ``executor="auto"`` goes parallel when the pilot point predicts more serial work than this
#: (seconds) for the rest of the grid. Measured on the project's 2-core machine (fork start
#: method, best of 3): a local pool starts, runs a task and shuts down in ~0.035 s; a
#: chapter-11 shooting point (400 samples) costs ~8 ms; serial vs two processes: 10 points
#: 0.091/0.085 s, 15 points 0.136/0.112 s, 60 points 0.462/0.320 s — break-even near 10
#: points (~0.09 s of work). 0.15 s leaves a margin for a busy second core.
AUTO_PARALLEL_SECONDS = 0.15


def run(fn: Callable[[Any], Any], grid: Iterable[Any], *,
        executor: Executor | str | Any | None = None,
        progress: bool | None = None, desc: str = "sweep") -> SweepResult:
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

    Returns
    -------
    SweepResult
        Values and per-point errors in grid order. A point that cannot be submitted (an
        unpicklable ``fn`` or point on a cluster), fails in transit or loses its worker is
        recorded as that point's :class:`PointError`; the message says which picklability
        rule was broken.

    Raises
    ------
    ModelError
        ``fn`` is not callable, or ``executor`` is of an unsupported type.
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
    points = tuple(grid)
    if not points:
        return SweepResult((), (), ())
    call = _Guarded(fn)
    values: list[Any] = [None] * len(points)
    errors: list[PointError | None] = [None] * len(points)
    todo = list(enumerate(points))
    bar = _bar(len(points), progress, desc)
    try:
        if isinstance(executor, str) and executor == "auto":
            _run_auto(call, todo, values, errors, bar)
        else:
            with _executor_for(executor, len(points)) as ex:
                _gather(ex, call, todo, values, errors, bar)
    finally:
        if bar is not None:
            bar.close()
    return SweepResult(points, tuple(values), tuple(errors))


def _run_auto(call: _Guarded, todo: list[tuple[int, Any]], values: list[Any],
              errors: list[PointError | None], bar: Any) -> None:
    """``executor="auto"``: a timed pilot point here, then processes only if they pay."""
    t = time.perf_counter()
    _gather(None, call, todo[:1], values, errors, bar)
    pilot = time.perf_counter() - t
    rest = todo[1:]
    workers = min(os.cpu_count() or 1, len(rest))
    if (workers > 1 and pilot * len(rest) > AUTO_PARALLEL_SECONDS
            and not _pickling_problem(call, dask=False)):
        with ProcessPoolExecutor(max_workers=workers) as pool:
            _gather(pool, call, rest, values, errors, bar)
    else:
        _gather(None, call, rest, values, errors, bar)


def _gather(ex: Executor | None, call: _Guarded, todo: list[tuple[int, Any]], values: list[Any],
            errors: list[PointError | None], bar: Any) -> None:
    """Run the ``(index, point)`` pairs of ``todo`` on ``ex`` (in this process when None) and
    store values and errors by index."""
    if ex is None:
        for i, p in todo:
            _store(i, _resolved(call, (i, p)), values, errors, "")
            if bar is not None:
                bar.update(1)
        return
    dask = type(ex).__module__.startswith("distributed")
    futures: dict[Future, int] = {}
    fn_problem = ""  # set once fn itself is known not to serialise: no more submits
    for i, p in todo:
        if not fn_problem:
            try:
                futures[ex.submit(call, (i, p))] = i
                continue
            except Exception as exc:  # Dask serialises at submit: record, go on
                fn_problem = _pickling_problem(call, dask=dask)
                errors[i] = PointError(
                    i, type(exc).__name__, fn_problem or
                    f"could not submit point {i} ({exc}); with process or cluster executors "
                    f"every grid point must be picklable", traceback.format_exc())
        else:
            errors[i] = PointError(i, "PicklingError", fn_problem)
        if bar is not None:
            bar.update(1)
    diagnosis: str | None = None
    for f in as_completed(futures):
        i = futures[f]
        if diagnosis is None and f.exception() is not None:
            diagnosis = _pickling_problem(call, dask=dask)
        _store(i, f, values, errors, diagnosis or "")
        if bar is not None:
            bar.update(1)


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


def _store(index: int, future: Future, values: list[Any], errors: list[PointError | None],
           diagnosis: str) -> None:
    """Unpack one finished future; a lost worker or an unpicklable fn is that point's error
    (``diagnosis`` says which picklability rule was broken, if any)."""
    try:
        ok, payload = future.result()
    except Exception as exc:
        errors[index] = PointError(index, type(exc).__name__,
                                   f"{exc}; {diagnosis}" if diagnosis else str(exc))
        return
    if ok:
        values[index] = payload
    else:
        errors[index] = payload


def _resolved(call: _Guarded, arg: tuple[int, Any]) -> Future:
    """A finished future for the serial path (same unpacking as the parallel one)."""
    fut: Future = Future()
    fut.set_result(call(arg))
    return fut


def _bar(total: int, progress: bool | None, desc: str) -> Any:
    if progress is False:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, file=sys.stderr, leave=False,
                delay=0.0 if progress else 2.0)


@contextmanager
def _executor_for(executor: Any, n_points: int) -> Iterator[Executor | None]:
    """Resolve the ``executor`` argument; shut down only what was created here."""
    if executor is None:
        workers = max(1, min(os.cpu_count() or 1, n_points))
        with ProcessPoolExecutor(max_workers=workers) as pool:
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

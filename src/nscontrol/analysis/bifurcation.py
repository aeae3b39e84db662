"""Brute-force bifurcation diagrams, serial or on a cluster through :mod:`nscontrol.sweep`.

For every parameter value ``p`` of a grid, :func:`bifurcation_diagram` simulates
``factory(p)`` (a :class:`~nscontrol.analysis.orbits.Forced`) for ``n_transient`` periods,
then records the stroboscopic (Poincaré) points ``x(kT)`` of ``n_sample`` more periods and
their period multiplicity. Each point starts from where the previous one ended (a **warm
start**), walking the grid up and, separately, down: coexisting attractors show as the two
sweeps disagreeing over a hysteresis interval.

Chunks and determinism
----------------------
The grid is cut into chunks of ``chunk_size`` consecutive values; a chunk is one task of
:func:`nscontrol.sweep.run`, so a warm-start chain never leaves its worker, and the first
point of every chunk starts cold from ``x0``. The result therefore depends on
``chunk_size`` but not on the executor: serial, local processes and a Dask cluster give
identical arrays. A point that raises is recorded (its samples are NaN, its message kept)
and the chain restarts cold from ``x0`` at the next value; a lost chunk (a dead worker) marks
its points as failed — never the others.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._files import Reader, load_hdf5, put, save_hdf5
from .._validation import FloatArray, as_vector, check_bool, check_integer
from ..errors import ModelError
from .orbits import at_times, sample_on_grid
from .periodic import _multiplicity_rtol, period_multiplicity

__all__ = ["BifurcationDiagram", "bifurcation_diagram", "parse_grid"]


@dataclass(frozen=True, eq=False)
class BifurcationDiagram:
    """Poincaré points against a parameter, for each sweep direction.

    Attributes
    ----------
    parameter_name
        Axis label.
    values
        ``(N,)`` increasing parameter values.
    directions
        ``("up", "down")`` or one of them.
    points
        ``(len(directions), N, n_sample, n)`` stroboscopic points (NaN where a point failed).
    multiplicity
        ``(len(directions), N)`` period multiplicity (``0``: none found up to 6; ``-1``: failed).
    errors
        ``((direction, index, message), ...)`` of the failed points.
    chunk_size
        Warm-start chain length used.
    state_names
        Names of the state components.
    """

    parameter_name: str
    values: FloatArray
    directions: tuple[str, ...]
    points: FloatArray
    multiplicity: np.ndarray
    errors: tuple[tuple[str, int, str], ...]
    chunk_size: int
    state_names: tuple[str, ...] = ()

    def sweep(self, direction: str) -> tuple[FloatArray, np.ndarray]:
        """``(points, multiplicity)`` of one direction."""
        if direction not in self.directions:
            raise ModelError(f"direction: expected one of {self.directions}, got {direction!r}")
        i = self.directions.index(direction)
        return self.points[i], self.multiplicity[i]

    def plot(self, ax: Any = None, *, component: int = 0, size: float = 1.0) -> Any:
        """Scatter the Poincaré points' ``component`` against the parameter, one colour per
        sweep direction. Returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        for i, d in enumerate(self.directions):
            P = self.points[i][:, :, component]
            ax.plot(np.repeat(self.values, P.shape[1]), P.ravel(), ".", ms=size,
                    color=("C2", "C1")[i % 2], alpha=0.5, label=f"brute force ({d})")
        names = self.state_names
        ax.set_xlabel(self.parameter_name)
        ax.set_ylabel(f"{names[component] if names else f'x{component}'} at t = 0 mod T")
        return ax

    def to_pandas(self) -> Any:
        """Long format: one row per (direction, value, sample) with the state components."""
        import pandas as pd

        d, N, S, n = self.points.shape
        names = self.state_names or tuple(f"x{i}" for i in range(n))
        data: dict[str, Any] = {
            "direction": np.repeat(np.array(self.directions), N * S),
            self.parameter_name: np.tile(np.repeat(self.values, S), d),
            "sample": np.tile(np.arange(S), d * N),
            "multiplicity": np.repeat(self.multiplicity.ravel(), S)}
        flat = self.points.reshape(-1, n)
        for i, nm in enumerate(names):
            data[nm] = flat[:, i]
        return pd.DataFrame(data)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write to HDF5 (format ``nscontrol.BifurcationDiagram/1``), with a Fletcher-32
        checksum on every non-empty dataset, atomically (the mechanism of every result type,
        :mod:`nscontrol._files`).

        Parameters
        ----------
        path : str or path-like
            The file to write; its folder must exist.

        Returns
        -------
        Path
            ``path``.

        Raises
        ------
        FileNotFoundError, IsADirectoryError
            The folder of ``path`` does not exist, or ``path`` is a folder.
        OSError
            The disk is full (or a quota, a file size limit): the previous file is unchanged
            and no temporary file remains.
        """
        return save_hdf5(path, self._write)

    def _write(self, f: Any) -> None:
        """The body of :meth:`save`, into the open (empty) ``f``."""
        f.attrs.update(format=_FORMAT, parameter_name=self.parameter_name,
                       chunk_size=self.chunk_size)
        f.attrs["directions"] = np.array(self.directions, dtype="S")
        f.attrs["state_names"] = np.array(self.state_names, dtype="S")
        put(f, "values", self.values)
        put(f, "points", self.points, compression="gzip")
        put(f, "multiplicity", self.multiplicity)
        put(f, "error_direction", np.array([e[0] for e in self.errors], dtype="S"))
        put(f, "error_index", np.array([e[1] for e in self.errors], int))
        put(f, "error_message", np.array([e[2].encode() for e in self.errors], dtype="S"))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> BifurcationDiagram:
        """Read a file written by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
            The file.

        Returns
        -------
        BifurcationDiagram
            The diagram saved there.

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ModelError
            ``path`` is not a bifurcation diagram file: not HDF5 (a text file), empty,
            truncated, of another format, missing a dataset or attribute, or a dataset fails
            its checksum (flipped bytes). The message says which, and names the member.
        """
        return load_hdf5(path, cls._read, formats=(_FORMAT,), what="bifurcation diagram",
                         writer="BifurcationDiagram.save")

    @classmethod
    def _read(cls, r: Reader, fmt: str) -> BifurcationDiagram:
        """The body of :meth:`load`; every member goes through ``r`` (errors named)."""
        direction, index = r.data("error_direction"), r.data("error_index")
        message = r.data("error_message")
        r.where = "the error table (error_direction, error_index, error_message)"
        errors = tuple((d.decode(), int(i), m.decode())
                       for d, i, m in zip(direction, index, message, strict=True))
        values, points, multiplicity = r.data("values"), r.data("points"), r.data("multiplicity")
        directions = tuple(s.decode() for s in r.attr("directions"))
        names = tuple(s.decode() for s in r.attr("state_names"))
        return cls(str(r.attr("parameter_name")), values, directions, points, multiplicity,
                   errors, int(r.attr("chunk_size")), names)


_FORMAT = "nscontrol.BifurcationDiagram/1"


@dataclass(frozen=True)
class _ChunkTask:
    """One warm-start chain: picklable (module-level class holding a picklable factory)."""

    factory: Callable[[float], Any]
    x0: FloatArray | None
    n_transient: int
    n_sample: int
    rtol: float
    warm_start: bool = True

    def __call__(self, chunk: tuple[str, tuple[int, ...], tuple[float, ...]]
                 ) -> list[tuple[int, FloatArray | None, int, str]]:
        direction, indices, values = chunk
        out: list[tuple[int, FloatArray | None, int, str]] = []
        x = None
        for i, p in zip(indices, values, strict=True):
            try:
                forced = self.factory(p)
                x = self._start(forced) if x is None else x
                samples, x = self._point(forced, x)
                out.append((i, samples, period_multiplicity(samples, rtol=self.rtol), ""))
                x = x if self.warm_start else None
            except Exception as exc:   # recorded per point; the chain restarts cold
                out.append((i, None, -1, f"{type(exc).__name__}: {exc}"))
                x = None
        return out

    def _start(self, forced: Any) -> FloatArray:
        n = forced.n_states
        if self.x0 is None and hasattr(forced, "initial_state"):   # a map's own cold start
            return as_vector("initial_state()", forced.initial_state(), n)
        return np.zeros(n) if self.x0 is None else as_vector("x0", self.x0, n)

    def _point(self, forced: Any, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        T, nt, ns = forced.period, self.n_transient, self.n_sample
        if hasattr(forced, "stroboscopic_samples"):   # a map in closed form: iterate it
            samples, last = forced.stroboscopic_samples(x, nt, ns)
            return np.asarray(samples, float), np.asarray(last, float)
        tr = sample_on_grid(forced, x, T, nt + ns)
        X = at_times(tr, T * np.arange(nt, nt + ns + 1, dtype=float))
        return X[:-1], X[-1]


def _chunks(n: int, size: int, directions: tuple[str, ...], values: FloatArray
            ) -> list[tuple[str, tuple[int, ...], tuple[float, ...]]]:
    out = []
    for d in directions:
        order = list(range(n)) if d == "up" else list(range(n - 1, -1, -1))
        for s in range(0, n, size):
            idx = tuple(order[s:s + size])
            out.append((d, idx, tuple(float(values[i]) for i in idx)))
    return out


def bifurcation_diagram(factory: Callable[[float], Any], values: Any, *,
                        n_transient: int = 200, n_sample: int = 100, x0: Any = None,
                        directions: tuple[str, ...] = ("up", "down"), chunk_size: int = 100,
                        executor: Any = "serial", progress: bool | None = None,
                        rtol: float = 1e-6, parameter_name: str = "p",
                        state_names: tuple[str, ...] = (),
                        warm_start: bool = True) -> BifurcationDiagram:
    """Brute-force bifurcation diagram of ``factory(p)`` over ``values``.

    Parameters
    ----------
    factory
        ``p -> Forced`` (a module-level callable for process or Dask executors, e.g.
        :class:`~nscontrol.analysis.impact_oscillator.OscillatorFamily`), or ``p -> map``: an
        object with ``n_states``, ``period`` and ``stroboscopic_samples(x, n_transient,
        n_sample) -> (samples, last)`` (a stroboscopic map in closed form, iterated instead
        of simulated; with ``initial_state()`` it also gives its own cold start, used when
        ``x0`` is None).
    values : array_like
        Parameter values (sorted increasingly here).
    n_transient, n_sample
        Periods discarded, then periods sampled, per value.
    x0
        Cold-start state (default zeros) of every chunk and after a failed point.
    directions
        ``("up", "down")``, ``("up",)`` or ``("down",)``.
    chunk_size
        Values per warm-start chain (one task each).
    executor
        As :func:`nscontrol.sweep.run`: ``"serial"`` (default), ``None`` (local processes),
        an ``Executor``, a ``distributed.Client`` or a scheduler address.
    progress
        Progress bar (per chunk), as :func:`nscontrol.sweep.run`.
    rtol
        Tolerance of the period-multiplicity test (relative to the largest sample), in
        ``(0, 1)``.
    parameter_name : str
        Name of the parameter (axis labels, saved files).
    state_names : tuple of str
        Names of the state components (default ``x0, x1, ...``).
    warm_start : bool
        ``True``: each point starts where the previous one of its chunk ended; ``False``:
        every point starts cold (from ``x0`` or the map's ``initial_state()``).

    Returns
    -------
    BifurcationDiagram

    Examples
    --------
    >>> from nscontrol.analysis.impact_oscillator import ImpactOscillator, OscillatorFamily
    >>> fam = OscillatorFamily(ImpactOscillator(omega=2.5, stop=0.1), "forcing")
    >>> bd = bifurcation_diagram(fam, [0.3, 2.0], n_transient=200, n_sample=8,
    ...                          progress=False, directions=("up",))
    >>> bd.multiplicity.tolist()    # non-impacting, then the stable impacting period-1 orbit
    [[1, 1]]
    """
    from .. import sweep

    vals = np.sort(as_vector("values", values))
    nt = check_integer("n_transient", n_transient, minimum=0)
    ns = check_integer("n_sample", n_sample, minimum=1)
    cs = check_integer("chunk_size", chunk_size, minimum=1)
    dirs = tuple(directions)
    if not dirs or any(d not in ("up", "down") for d in dirs) or len(set(dirs)) != len(dirs):
        raise ModelError(f"directions: expected a non-empty subset of ('up', 'down'), got "
                         f"{directions!r}")
    if not callable(factory):
        raise ModelError(f"factory: expected a callable p -> Forced (or p -> map), got "
                         f"{type(factory).__name__}")
    first = factory(float(vals[0]))     # its size checks x0 before anything runs
    n = int(first.n_states)
    task = _ChunkTask(factory, None if x0 is None else as_vector("x0", x0, n), nt, ns,
                      _multiplicity_rtol(rtol), check_bool("warm_start", warm_start))
    chunks = _chunks(len(vals), cs, dirs, vals)
    res = sweep.run(task, chunks, executor=executor, progress=progress, desc="bifurcation")
    pts = np.full((len(dirs), len(vals), ns, n), np.nan)
    mult = np.full((len(dirs), len(vals)), -1, dtype=int)
    errors: list[tuple[str, int, str]] = []
    for chunk, value, err in zip(chunks, res.values, res.errors, strict=True):
        di = dirs.index(chunk[0])
        if err is not None:
            errors.extend((chunk[0], i, f"chunk lost: {err.type}: {err.message}")
                          for i in chunk[1])
            continue
        for i, samples, m, msg in value:
            if samples is None:
                errors.append((chunk[0], i, msg))
            else:
                pts[di, i], mult[di, i] = samples, m
    names = tuple(state_names) or tuple(getattr(getattr(first, "system", None), "state_names",
                                                 ()) or ())
    errors.sort(key=lambda e: (dirs.index(e[0]), e[1]))
    return BifurcationDiagram(parameter_name, vals, dirs, pts, mult, tuple(errors), cs, names)


def parse_grid(spec: str) -> tuple[str, FloatArray]:
    """``"NAME=START:STOP:N"`` -> ``(NAME, linspace(START, STOP, N))``.

    Parameters
    ----------
    spec : str
        The grid, as on the command line.

    Examples
    --------
    >>> parse_grid("forcing=0.2:2.2:3")
    ('forcing', array([0.2, 1.2, 2.2]))
    """
    try:
        name, rng = spec.split("=", 1)
        start, stop, num = rng.split(":")
        n = int(num)
        values = np.linspace(float(start), float(stop), n)
    except ValueError:
        raise ValueError(f"param: expected NAME=START:STOP:N (e.g. forcing=0.2:2.2:200), got "
                         f"{spec!r}") from None
    if not name.strip() or n < 1 or not np.all(np.isfinite(values)):
        raise ValueError(f"param: expected a name, finite bounds and N >= 1, got {spec!r}")
    return name.strip(), values

"""The one result type of every integrator: :class:`Trajectory`.

Arrays are **time-major**: ``x[k]`` is the state at ``t[k]``, so ``x`` has shape
``(n_times, n_states)`` and every signal has ``n_times`` rows. Events (impacts, mode switches,
sliding starts and exits) live apart from the samples, in :attr:`Trajectory.events`, each with
its exact time and the state just before and just after.

Integrators fill a :class:`Recorder` (which grows its buffers geometrically, keeps every k-th
step or selected signals only) and call :meth:`Recorder.finish` to obtain the frozen result.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._files import Reader, load_hdf5, put, save_hdf5
from .._validation import as_float_array, as_real_scalar, check_integer
from ..errors import DimensionError, ModelError
from ._run_context import register_recorder

__all__ = ["Event", "Trajectory", "Recorder", "STATUS_MESSAGES"]

FloatArray = NDArray[np.float64]

#: Meaning of :attr:`Trajectory.status`, as in scipy's ``solve_ivp``.
STATUS_MESSAGES = {
    0: "the end of the time span was reached",
    1: "a terminal event stopped the run",
    -1: "the run failed; the trajectory holds what was computed before the failure",
}


@dataclass(frozen=True, eq=False)
class Event:
    """One discrete event of a run.

    Attributes
    ----------
    time
        Exact event time.
    kind
        ``"impact"``, ``"crossing"``, ``"sliding_start"``, ``"sliding_exit"``, ``"grazing"``,
        ``"contact_start"``, ``"contact_end"``, ``"accumulation"``, ``"switch"``... The
        integrator documents the kinds it emits.
    index
        The contact (mechanics) or switching surface (switched systems) concerned, ``-1`` when
        not applicable.
    pre, post
        The state just before and just after the event.
    mode_from, mode_to
        Discrete modes before and after (switched systems), ``-1`` when not applicable.
    """

    time: float
    kind: str
    index: int
    pre: FloatArray
    post: FloatArray
    mode_from: int = -1
    mode_to: int = -1


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Result of :func:`nscontrol.simulate`.

    Attributes
    ----------
    t : ndarray, shape (n_times,)
        Sample times (increasing; an event time may appear twice, for the pre- and post-event
        samples).
    x : ndarray, shape (n_times, n_states)
        States, time-major.
    signals : dict of str to ndarray
        Named signals with ``n_times`` rows (``"y"``, ``"u"``, ``"lambda"``, ``"gap"``,
        ``"impulse"``, ``"energy"``, ``"xhat"``, ``"error"``...).
    events : tuple of Event
        Discrete events in time order.
    stats : dict
        Solver statistics (steps, LCP solves, iterations, function evaluations...).
    status : int
        0: end of the time span reached; 1: a terminal event stopped the run; -1: failure.
    message : str
        Human-readable reason the run stopped.
    method : str
        The integrator that produced it.
    state_names : tuple of str
        One name per state component (``"q1"``, ``"v1"``...); may be empty.
    """

    t: FloatArray
    x: FloatArray
    signals: dict[str, np.ndarray] = field(default_factory=dict)
    events: tuple[Event, ...] = ()
    stats: dict[str, Any] = field(default_factory=dict)
    status: int = 0
    message: str = STATUS_MESSAGES[0]
    method: str = ""
    state_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=np.float64)
        x = np.asarray(self.x, dtype=np.float64)
        if x.ndim == 1:
            x = x.reshape(-1, 1)
        if t.ndim != 1 or x.shape[0] != t.shape[0]:
            raise DimensionError(f"Trajectory: t has shape {t.shape} but x has shape "
                                 f"{x.shape}; x must be time-major (n_times, n_states)")
        _check_times(t)
        for name, sig in self.signals.items():
            if np.shape(sig)[0] != t.shape[0]:
                raise DimensionError(f"Trajectory: signal {name!r} has {np.shape(sig)[0]} rows, "
                                     f"expected {t.shape[0]} (one per sample)")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "x", x)

    @classmethod
    def _from_record(cls, **values: Any) -> Trajectory:
        """A trajectory from a :class:`Recorder`'s buffers, which satisfy the checks of
        ``__post_init__`` by construction (float64 arrays, time-major, one row per sample,
        finite times in order): every field given, nothing converted or checked."""
        traj = object.__new__(cls)
        for name in cls.__dataclass_fields__:
            object.__setattr__(traj, name, values[name])
        return traj

    # -- views --------------------------------------------------------------------------
    @property
    def success(self) -> bool:
        """True unless the run failed (``status >= 0``)."""
        return self.status >= 0

    @property
    def n_states(self) -> int:
        """Number of state components (``x.shape[1]``)."""
        return int(self.x.shape[1])

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def event_times(self, kind: str | None = None) -> FloatArray:
        """Times of the events, optionally only those of one ``kind``."""
        return np.array([e.time for e in self.events if kind is None or e.kind == kind],
                        dtype=np.float64)

    def events_of(self, kind: str) -> tuple[Event, ...]:
        """The events of one ``kind``."""
        return tuple(e for e in self.events if e.kind == kind)

    def signal(self, name: str) -> np.ndarray:
        """A named signal, with a clear error listing the available ones."""
        try:
            return self.signals[name]
        except KeyError:
            raise KeyError(f"no signal {name!r} in this trajectory; available: "
                           f"{sorted(self.signals)}") from None

    def state(self, name_or_index: str | int) -> FloatArray:
        """One state component over time, by name or index."""
        if isinstance(name_or_index, str):
            if name_or_index not in self.state_names:
                raise KeyError(f"no state {name_or_index!r}; states are {self.state_names}")
            return self.x[:, self.state_names.index(name_or_index)]
        return self.x[:, name_or_index]

    def slice(self, t0: float | None = None, t1: float | None = None) -> Trajectory:
        """The part of the trajectory with ``t0 <= t <= t1`` (events included likewise)."""
        lo = -np.inf if t0 is None else as_real_scalar("t0", t0)
        hi = np.inf if t1 is None else as_real_scalar("t1", t1)
        if np.isnan(lo) or np.isnan(hi):
            raise ModelError(f"t0, t1: expected times (or None), got ({t0!r}, {t1!r})")
        keep = (self.t >= lo) & (self.t <= hi)
        return replace(
            self,
            t=self.t[keep],
            x=self.x[keep],
            signals={k: np.asarray(v)[keep] for k, v in self.signals.items()},
            events=tuple(e for e in self.events if lo <= e.time <= hi),
        )

    def at(self, t: float | FloatArray) -> FloatArray:
        """States linearly interpolated at time(s) ``t`` (right-continuous at events).

        Raises
        ------
        ModelError
            A time outside the recorded span ``[t[0], t[-1]]`` (beyond round-off): the run
            says nothing about it, and the end state would be a wrong answer.
        """
        tq = np.atleast_1d(as_float_array("t", t))
        self._check_in_span("t", tq)
        out = self._interpolate(self.x, *self._weights(tq))
        return out[0] if np.ndim(t) == 0 else out

    def resample(self, t_eval: Any) -> Trajectory:
        """The trajectory sampled at ``t_eval`` (states and signals linearly interpolated,
        right-continuous at events; the event table and stats kept).

        This is how ``simulate(..., t_eval=...)`` samples a method that cannot stop at
        requested times (time-stepping schemes): the interpolation error, ``O(h²)`` times the
        second derivative between steps, is below the scheme's own ``O(h)`` error. Times
        outside ``[t[0], t[-1]]`` are refused.

        Raises
        ------
        ModelError
            ``t_eval`` outside the recorded span, or this trajectory has fewer than 2 samples.
        """
        tq = np.atleast_1d(as_float_array("t_eval", t_eval))
        if len(self.t) < 2:
            raise ModelError("t_eval: the run recorded fewer than 2 samples; nothing to "
                             "interpolate")
        self._check_in_span("t_eval", tq)
        weights = self._weights(tq)
        signals = {k: self._interpolate(np.asarray(v, dtype=np.float64), *weights)
                   for k, v in self.signals.items()}
        stats = {**self.stats, "t_eval": "interpolated"}
        return replace(self, t=tq.copy(), x=self._interpolate(self.x, *weights),
                       signals=signals, stats=stats)

    def _check_in_span(self, name: str, tq: FloatArray) -> None:
        """Refuse query times outside ``[t[0], t[-1]]`` beyond the round-off of the end
        times (a few ulps of the largest ``|t|``: 1e-12 relative leaves a factor ~4500)."""
        if not tq.size or not self.t.size:
            return
        scale = 1e-12 * max(1.0, float(np.max(np.abs(self.t))))
        if tq.min() < self.t[0] - scale or tq.max() > self.t[-1] + scale:
            raise ModelError(f"{name}: times must lie in the simulated span [{self.t[0]:.6g}, "
                             f"{self.t[-1]:.6g}], got [{tq.min():.6g}, {tq.max():.6g}]; "
                             f"simulate over a longer span, or query inside it")

    def _weights(self, tq: FloatArray) -> tuple[np.ndarray, FloatArray]:
        idx = np.clip(np.searchsorted(self.t, tq, side="right") - 1, 0, len(self.t) - 2)
        t_a, t_b = self.t[idx], self.t[idx + 1]
        span = np.where(t_b > t_a, t_b - t_a, 1.0)
        return idx, np.clip((tq - t_a) / span, 0.0, 1.0)

    @staticmethod
    def _interpolate(values: np.ndarray, idx: np.ndarray, w: FloatArray) -> np.ndarray:
        w = w.reshape((-1,) + (1,) * (values.ndim - 1))
        return (1.0 - w) * values[idx] + w * values[idx + 1]

    # -- persistence ----------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        """Write the trajectory to an HDF5 file (lossless: :meth:`load` returns an equal one).

        Layout (format ``nscontrol.Trajectory/3``): datasets ``t``, ``x``, group ``signals``
        (one dataset each), group ``events`` (columns), group ``stats``: a numeric array stat
        is a dataset of its own (any size: HDF5 attributes stop at 64 KB), every other stat
        (``None``, bool, int, float, str, list, tuple, dict, complex, numpy scalars, arrays
        nested in containers) a JSON string dataset tagged so that :meth:`load` restores
        its type (tuples stay tuples, dicts with non-string keys keep their keys).

        Every non-empty dataset carries a Fletcher-32 checksum, so :meth:`load` detects flipped
        bytes instead of returning wrong numbers. The file is written atomically: into a
        temporary file in the same folder, renamed over ``path`` (``os.replace``) only once
        complete, so a failed save leaves an existing file untouched (see
        :mod:`nscontrol._files`, shared by every result type).

        Parameters
        ----------
        path : str or Path
            The file to write; its folder must exist.

        Raises
        ------
        ModelError
            A stat of a type that has no lossless encoding (the message names its key), or a
            signal name HDF5 would read as a path (containing ``/``, empty or ``"."``).
        FileNotFoundError, IsADirectoryError
            The folder of ``path`` does not exist, or ``path`` is a folder.
        OSError
            The disk is full (or a quota, a file size limit): the previous file is unchanged,
            no temporary file remains, and the process goes on unharmed.
        """
        for name in self.signals:
            _check_signal_name(name)
        save_hdf5(path, self._write)

    def _write(self, f: Any) -> None:
        """The body of :meth:`save`: the whole file, written into the open (empty) ``f``."""
        f.attrs["format"] = _FORMAT
        f.attrs["status"] = self.status
        f.attrs["message"] = self.message
        f.attrs["method"] = self.method
        f.attrs["state_names"] = list(self.state_names)
        put(f, "t", self.t)
        put(f, "x", self.x)
        sig = f.create_group("signals")
        for name, value in self.signals.items():
            put(sig, name, np.asarray(value))
        ev = f.create_group("events")
        n = self.n_states
        put(ev, "time", np.array([e.time for e in self.events], float))
        put(ev, "kind", np.array([e.kind.encode() for e in self.events], dtype="S"))
        for key in ("index", "mode_from", "mode_to"):
            put(ev, key, np.array([getattr(e, key) for e in self.events], dtype=np.int64))
        for key in ("pre", "post"):
            data = [np.asarray(getattr(e, key), float) for e in self.events]
            width = max((d.size for d in data), default=n)
            arr = np.full((len(data), width), np.nan)
            sizes = np.array([d.size for d in data], dtype=np.int64)
            for i, d in enumerate(data):
                arr[i, : d.size] = d
            put(ev, key, arr)
            put(ev, key + "_size", sizes)
        st = f.create_group("stats")
        for key, value in self.stats.items():
            if not isinstance(key, str):
                raise ModelError(f"stats: expected string keys, got {key!r}")
            _save_stat(st, key, value)

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """Read a trajectory written by :meth:`save` (formats 1 to 3).

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ModelError
            ``path`` is not an nscontrol trajectory file: not HDF5 (a text file), empty,
            truncated, missing a group or dataset, or a dataset fails its checksum (flipped
            bytes). The message says which, and names the dataset.
        """
        return load_hdf5(path, cls._read, formats=(_FORMAT, _FORMAT_V2, _FORMAT_V1),
                         what="trajectory", writer="Trajectory.save")

    @classmethod
    def _read(cls, r: Reader, fmt: str) -> Trajectory:
        """The body of :meth:`load`; every dataset goes through ``r`` (errors named)."""
        pre, post = r.data("events/pre"), r.data("events/post")
        pre_n, post_n = r.data("events/pre_size"), r.data("events/post_size")
        time, kind = r.data("events/time"), r.data("events/kind")
        index, m_from, m_to = (r.data(f"events/{k}") for k in ("index", "mode_from", "mode_to"))
        events = tuple(
            Event(time=float(time[i]), kind=kind[i].decode(), index=int(index[i]),
                  pre=pre[i, : pre_n[i]].copy(), post=post[i, : post_n[i]].copy(),
                  mode_from=int(m_from[i]), mode_to=int(m_to[i]))
            for i in range(time.shape[0]))
        if fmt == _FORMAT_V1:
            stats = {k: (v.item() if isinstance(v, np.generic) else v)
                     for k, v in r.group("stats").attrs.items()}
        else:
            stats = _load_stats(r)
        signals = {k: r.data(f"signals/{k}") for k in r.group("signals")}
        t, x = r.data("t"), r.data("x")
        status, message = int(r.attr("status")), str(r.attr("message"))
        method, names = str(r.attr("method")), tuple(str(s) for s in r.attr("state_names"))
        r.where = "the file"
        return cls(t=t, x=x, signals=signals, events=events, stats=stats, status=status,
                   message=message, method=method, state_names=names)

    def to_pandas(self) -> Any:
        """Samples as a pandas DataFrame indexed by ``t`` (states, then flattened signals).

        python-control's name for it; :meth:`to_dataframe` is the same method. Needs pandas
        (``pip install 'nscontrol[dataframe]'``; the error says so when it is missing).
        """
        pd = _import_pandas()
        names = self.state_names or tuple(f"x{i}" for i in range(self.n_states))
        cols: dict[str, np.ndarray] = {n: self.x[:, i] for i, n in enumerate(names)}
        for key, value in self.signals.items():
            arr = np.asarray(value).reshape(len(self.t), -1)
            if arr.shape[1] == 1:
                cols[key] = arr[:, 0]
            else:
                cols.update({f"{key}[{j}]": arr[:, j] for j in range(arr.shape[1])})
        return pd.DataFrame(cols, index=pd.Index(self.t, name="t"))

    to_dataframe = to_pandas

    def events_dataframe(self) -> Any:
        """The event table as a pandas DataFrame (one row per event)."""
        pd = _import_pandas()

        return pd.DataFrame({
            "time": [e.time for e in self.events], "kind": [e.kind for e in self.events],
            "index": [e.index for e in self.events],
            "mode_from": [e.mode_from for e in self.events],
            "mode_to": [e.mode_to for e in self.events],
        })

    # -- plotting --------------------------------------------------------------------------
    def plot(self, states: Sequence[str | int] | None = None,
             signals: Iterable[str] = (), *, mark_events: bool | str = True,
             ax: Any = None, units: Mapping[str, str] | None = None,
             subplots: str = "shared") -> Any:
        """Plot states (and signals, one panel each) against time; returns the figure.

        Parameters
        ----------
        states
            Names or indices of the states to draw (default: all, up to 8).
        signals
            Names of signals to draw in extra panels below the states.
        mark_events
            Draw a vertical line at every event (or only at events of this kind).
        ax
            An existing matplotlib axes for the states panel; signals then go nowhere.
        units
            Unit of each state or signal by name (e.g. ``{"q": "m", "v": "m/s"}``): the
            axes read ``"q, v [m, m/s]"``; without units an axis is labelled by the names.
        subplots
            How the states share panels: ``"shared"`` (one panel, the default), ``"groups"``
            (one panel per name stem: ``q1, q2`` together, ``v1, v2`` together, ``xhat...``
            apart) or ``"each"`` (one panel per state). Ignored when ``ax`` is given.

        Raises
        ------
        ModelError
            ``subplots`` not one of the three.

        Examples
        --------
        >>> import matplotlib; matplotlib.use("Agg")
        >>> traj = Trajectory(t=np.linspace(0, 1, 5), x=np.zeros((5, 2)), state_names=("q", "v"))
        >>> fig = traj.plot(units={"q": "m", "v": "m/s"})
        >>> fig.axes[0].get_ylabel(), fig.axes[0].get_xlabel()
        ('q, v [m, m/s]', 't [s]')
        """
        import matplotlib.pyplot as plt

        signals = list(signals)
        picks = list(range(min(self.n_states, 8))) if states is None else list(states)
        names = [str(p if isinstance(p, str) else
                     (self.state_names[p] if self.state_names else f"x{p}")) for p in picks]
        panels = _state_panels(names, "shared" if ax is not None else subplots)
        axes: Any   # matplotlib axes: an array of them, or a list of the one given
        if ax is None:
            rows = len(panels) + len(signals)
            # constrained layout keeps the time label and long tick labels inside a saved PNG
            fig, axes = plt.subplots(rows, 1, sharex=True, squeeze=False, layout="constrained",
                                     figsize=(7, 2.0 + 2.0 * rows))
            axes = axes[:, 0]
        else:
            fig, axes = ax.figure, [ax]
        units = dict(units or {})
        for a, panel in zip(axes, panels, strict=False):
            for i in panel:
                a.plot(self.t, self.state(picks[i]), label=names[i])
            a.set_ylabel(_axis_label([names[i] for i in panel], units))
            if len(panel) > 1:
                a.legend(loc="best", fontsize="small")
        for a, name in zip(axes[len(panels):], signals, strict=False):
            a.plot(self.t, self.signal(name))
            a.set_ylabel(_axis_label([name], units))
        if mark_events:
            kind = mark_events if isinstance(mark_events, str) else None
            for te in self.event_times(kind)[:500]:
                for a in axes:
                    a.axvline(te, color="0.7", lw=0.5, zorder=0)
        axes[-1].set_xlabel("t [s]")
        return fig


def _state_panels(names: Sequence[str], subplots: Any) -> list[list[int]]:
    """The indices of ``names`` drawn in each panel (see :meth:`Trajectory.plot`)."""
    if subplots == "shared":
        return [list(range(len(names)))]
    if subplots == "each":
        return [[i] for i in range(len(names))]
    if subplots != "groups":
        raise ModelError(f"subplots: expected 'shared', 'groups' or 'each', got {subplots!r}")
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(names):   # the stem: the name without its index or suffix
        stem = re.match(r"[^\d_\[(]*", name)
        groups.setdefault(stem.group(0) if stem and stem.group(0) else name, []).append(i)
    return list(groups.values())


def _axis_label(names: Sequence[str], units: Mapping[str, str]) -> str:
    """``"q, v [m, m/s]"``: the names (the first four, then "..."), with their units in
    brackets when known (one unit when they share it)."""
    shown = list(names[:4]) + (["..."] if len(names) > 4 else [])
    found = [units[n] for n in names[:4] if n in units]
    if not found:
        return ", ".join(shown)
    unit = found[0] if len(set(found)) == 1 else ", ".join(units.get(n, "?") for n in names[:4])
    return f"{', '.join(shown)} [{unit}]"


_FORMAT = "nscontrol.Trajectory/3"
_FORMAT_V2 = "nscontrol.Trajectory/2"      # stats as variable-length JSON strings
_FORMAT_V1 = "nscontrol.Trajectory/1"      # stats as attributes

def _check_times(t: FloatArray) -> None:
    """Refuse sample times that are not finite or that decrease (equal ones are allowed: an
    event time appears twice, for the pre- and the post-event sample)."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ModelError(f"t: expected finite sample times, got {t[bad[0]]} at index "
                         f"{bad[0]} ({bad.size} non-finite); drop or fix those samples")
    back = np.flatnonzero(np.diff(t) < 0.0)
    if back.size:
        k = int(back[0])
        raise ModelError(f"t: expected non-decreasing sample times, got t[{k}] = {t[k]!r} > "
                         f"t[{k + 1}] = {t[k + 1]!r} ({back.size} decrease(s)); sort the "
                         "samples (np.argsort(t, kind='stable')) with their states")


def _check_signal_name(name: Any) -> None:
    """A signal name HDF5 stores as one dataset name (``/`` would make it a path)."""
    if not isinstance(name, str) or name in ("", ".") or "/" in name:
        raise ModelError(f"signals: cannot save signal name {name!r}: a name must be a "
                         "non-empty string without '/' (HDF5 reads '/' as a group path); "
                         "rename the signal, e.g. with '_' instead of '/'")


def _save_stat(group: Any, key: str, value: Any) -> None:
    """One stat into the ``stats`` group: numeric arrays as datasets, the rest as tagged JSON.

    Datasets are named by position (``"0"``, ``"1"``...: a key may hold ``/``, which HDF5
    would read as a path) and carry the key in their ``key`` attribute.
    """
    name = str(len(group))
    if isinstance(value, np.ndarray) and value.dtype.kind in "biufc":
        ds = put(group, name, value)
        ds.attrs["encoding"] = "array"
    else:
        try:
            text = json.dumps(_to_json(value, f"stats[{key!r}]"), allow_nan=True)
        except RecursionError:
            raise ModelError(f"stats[{key!r}]: cannot be saved: the value is nested too "
                             f"deeply (or refers to itself)") from None
        # UTF-8 bytes in a fixed-size array: a checksum covers them (a variable-length
        # string's checksum would cover only its heap reference)
        ds = put(group, name, np.frombuffer(text.encode(), dtype=np.uint8))
        ds.attrs["encoding"] = "json-utf8"
    ds.attrs["key"] = key


def _load_stats(r: Reader) -> dict[str, Any]:
    group = r.group("stats")
    out: dict[str, Any] = {}
    for name in sorted(group, key=int):
        raw: Any = r.data(f"stats/{name}")
        encoding = r.attr("encoding", of=f"stats/{name}")
        if encoding == "array":
            value = raw
        elif encoding == "json-utf8":
            value = _from_json(json.loads(raw.tobytes().decode()))
        else:                    # format 2: a variable-length string
            value = _from_json(json.loads(raw.decode() if isinstance(raw, bytes) else raw))
        out[str(r.attr("key", of=f"stats/{name}"))] = value
    return out


_TAGS = ("__tuple__", "__ndarray__", "__complex__", "__items__")


def _to_json(value: Any, where: str) -> Any:
    """A JSON-encodable image of ``value`` from which :func:`_from_json` restores it."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int | float) and not isinstance(value, bool):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, complex | np.complexfloating):
        return {"__complex__": [float(value.real), float(value.imag)]}
    if isinstance(value, list):
        return [_to_json(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, tuple):
        return {"__tuple__": [_to_json(v, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufcU":
            raise ModelError(f"{where}: cannot be saved: arrays of dtype {value.dtype} have no "
                             "lossless encoding; convert to a numeric or string array")
        flat = [_to_json(v, where) for v in value.ravel().tolist()]
        return {"__ndarray__": flat, "dtype": value.dtype.str, "shape": list(value.shape)}
    if isinstance(value, Mapping):
        if all(isinstance(k, str) for k in value) and not any(k in _TAGS for k in value):
            return {k: _to_json(v, f"{where}[{k!r}]") for k, v in value.items()}
        return {"__items__": [[_to_json(k, where), _to_json(v, f"{where}[{k!r}]")]
                              for k, v in value.items()]}
    raise ModelError(f"{where}: cannot be saved: values of type {type(value).__name__} have no "
                     "lossless encoding; store numbers, strings, None, lists, tuples, dicts or "
                     "numpy arrays")


def _from_json(data: Any) -> Any:
    if isinstance(data, list):
        return [_from_json(v) for v in data]
    if not isinstance(data, dict):
        return data
    if "__tuple__" in data:
        return tuple(_from_json(v) for v in data["__tuple__"])
    if "__complex__" in data:
        re, im = data["__complex__"]
        return complex(re, im)
    if "__ndarray__" in data:
        dtype = np.dtype(data["dtype"])
        flat = [_from_json(v) for v in data["__ndarray__"]]
        return np.array(flat, dtype=dtype).reshape(data["shape"])
    if "__items__" in data:
        return {_hashable(_from_json(k)): _from_json(v) for k, v in data["__items__"]}
    return {k: _from_json(v) for k, v in data.items()}


def _hashable(key: Any) -> Any:
    return tuple(_hashable(k) for k in key) if isinstance(key, list) else key



@dataclass
class ChunkProgress:
    """The rows of a chunk in progress (see :meth:`Recorder.chunk`): the stepping loop's
    buffers and how many of their leading rows hold finished steps."""

    done: int = 0
    rows: tuple[np.ndarray, ...] = ()

    def written(self) -> tuple[np.ndarray, ...]:
        """The finished rows of each buffer."""
        return tuple(r[:self.done] for r in self.rows)


def evaluable_prefix(evaluate: Callable[[int], object], n: int) -> int:
    """The longest ``k < n`` for which ``evaluate(k)`` returns, found by bisection, given that
    ``evaluate(n)`` raised: how many leading times of a chunk a vectorised input ``u(t)``
    can be sampled at (a pure function of time), so that the steps before the first failing
    time are still run and recorded (see :meth:`Recorder.chunk`)."""
    ok, bad = 0, n          # evaluate(ok) returns (or ok == 0), evaluate(bad) raises
    while bad - ok > 1:
        mid = (ok + bad) // 2
        try:
            evaluate(mid)
        except Exception:  # noqa: BLE001 - the caller re-raises the original error
            bad = mid
        else:
            ok = mid
    return ok


class Recorder:
    """Growing buffers an integrator writes samples and events into.

    Parameters
    ----------
    n_states
        State dimension.
    every
        Keep every ``every``-th call to :meth:`sample` (events are always kept, and
        :meth:`sample` with ``force=True`` always records, e.g. for the final state). The
        user-facing option is ``record_every``: an integer ``>= 1``.
    signals
        Names of the signals to keep; ``None`` keeps all that the integrator offers.
    capacity
        Initial buffer length (buffers double when full).
    offered
        The names of the signals the integrator can record. When given, a requested name
        outside it (a typo) is refused at once; when not, :meth:`finish` refuses a requested
        signal that was never recorded, so a typo never yields a silently empty result.

    Raises
    ------
    ModelError
        ``every`` not an integer ``>= 1``; ``signals`` a bare string or holding names the
        integrator does not offer (the message lists the offered ones).

    Examples
    --------
    >>> rec = Recorder(1, signals=["gap"], offered=("gap", "energy", "impulse"))
    >>> Recorder(1, signals=["gpa"], offered=("gap", "energy"))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: signals: unknown name(s) ['gpa']; this integrator ...
    """

    def __init__(self, n_states: int, *, every: int = 1, signals: Iterable[str] | None = None,
                 capacity: int = 1024, offered: Iterable[str] | None = None) -> None:
        self.n_states = check_integer("n_states", n_states, minimum=0, error=DimensionError)
        self.every = check_integer("record_every", every, minimum=1)
        self.offered = None if offered is None else tuple(offered)
        self.keep = None if signals is None else _signal_names(signals, self.offered)
        self._t = np.empty(max(int(capacity), 1))
        self._x = np.empty((self._t.shape[0], self.n_states))
        self._sig: dict[str, np.ndarray] = {}
        self._n = 0
        self._calls = 0
        self.events: list[Event] = []
        register_recorder(self)   # the driver keeps the samples of a run that fails

    def __len__(self) -> int:
        """Number of samples recorded so far."""
        return self._n

    def snapshot(self, *, status: int = -1, message: str | None = None,
                 method: str = "", state_names: Sequence[str] = (),
                 stats: Mapping[str, Any] | None = None, last: bool = False) -> Trajectory:
        """The samples and events recorded so far as a :class:`Trajectory` (used for the
        partial trajectory of a run that fails).

        ``last=True`` says the recorder records nothing more: the trajectory then views its
        buffers instead of copying them (a Ctrl-C after a million samples is answered without
        copying tens of megabytes into fresh pages, whose faults alone once took 0.4 s).
        Otherwise the recorder may go on and the trajectory holds copies."""
        return self._freeze(status, message, method, dict(stats or {}), state_names,
                            copy=not last)

    @contextmanager
    def chunk(self, record: Callable[[ChunkProgress], None]) -> Iterator[ChunkProgress]:
        """A chunk of steps computed into the stepping loop's own buffers and recorded at its
        end: the one place where a failed run keeps the chunk's samples.

        The block receives a :class:`ChunkProgress`; the stepping loop puts its buffers in
        ``rows`` and counts the rows written in ``done``. Any exception escaping the block
        (a user callback's own error, ``KeyboardInterrupt``, a library error) without a
        trajectory of its own first has ``record(progress)`` record the ``done`` rows, so
        that the driver's partial trajectory holds every sample computed before the failure.
        """
        progress = ChunkProgress()
        try:
            yield progress
        except BaseException as err:
            if progress.done and getattr(err, "trajectory", None) is None:
                record(progress)
            raise

    @staticmethod
    def capacity_for(n_samples: int, every: Any = 1) -> int:
        """An initial ``capacity`` for about ``n_samples`` offered samples kept one in
        ``every`` (so a run of known length never regrows its buffers), bounded by 2**16 rows
        (past that the buffers double as needed: a few copies in a long run). The bound keeps
        the first allocation small: a signal's buffer is filled with NaN, which touches every
        page, and a fresh page costs a fault (a million-row buffer took 0.25 s on a loaded
        machine, most of the time from a Ctrl-C to the partial trajectory of a long run)."""
        k = every if isinstance(every, int) and every >= 1 else 1
        return int(min(max(n_samples, 0) // k + 4, 2**16))

    def wants(self, name: str) -> bool:
        """Whether signal ``name`` is to be recorded (integrators may skip computing it)."""
        return self.keep is None or name in self.keep

    def _grow(self) -> None:
        # the new buffers are built aside and swapped in by plain attribute stores (no call
        # between them, so no KeyboardInterrupt either): an interrupt while copying leaves
        # the old buffers whole, and the partial trajectory recorded after it consistent
        cap = 2 * self._t.shape[0]
        t = np.resize(self._t, cap)
        x = np.resize(self._x, (cap, self.n_states))
        sig = {k: np.resize(v, (cap,) + v.shape[1:]) for k, v in self._sig.items()}
        self._t, self._x, self._sig = t, x, sig

    def sample(self, t: float, x: np.ndarray, force: bool = False,
               **signals: Any) -> None:
        """Record the state (and signals) at ``t``, subject to ``every``."""
        self._calls += 1
        if not force and (self._calls - 1) % self.every:
            return
        if self._n == self._t.shape[0]:
            self._grow()
        i = self._n
        self._t[i] = t
        self._x[i] = x
        for name, value in signals.items():
            if not self.wants(name):
                continue
            val = np.asarray(value, dtype=np.float64)
            buf = self._sig.get(name)
            if buf is None:
                buf = np.full((self._t.shape[0],) + val.shape, np.nan)
                self._sig[name] = buf
            buf[i] = val
        self._n += 1

    def extend(self, t: np.ndarray, x: np.ndarray | tuple[np.ndarray, ...],
               **signals: np.ndarray) -> None:
        """Record a block of samples at once (as produced by a compiled kernel).

        ``every`` is applied to the block as if each row had been passed to :meth:`sample`.
        ``x`` may be given as column blocks ``(q, v)``: only the kept rows are then joined
        (a long chunk recorded sparsely is never copied whole).
        """
        t = np.asarray(t, float)
        k = t.shape[0]
        offset = (-self._calls) % self.every
        sel = slice(offset, k, self.every)     # a basic slice: views, no index array
        size = len(range(offset, k, self.every))
        self._calls += k
        while self._n + size > self._t.shape[0]:
            self._grow()
        i0, i1 = self._n, self._n + size
        self._t[i0:i1] = t[sel]
        if isinstance(x, tuple):
            col = 0
            for block in x:
                width = block.shape[1]
                self._x[i0:i1, col:col + width] = block[sel]
                col += width
        else:
            self._x[i0:i1] = np.asarray(x, float)[sel]
        for name, value in signals.items():
            if not self.wants(name):
                continue
            val = np.asarray(value, float)
            buf = self._sig.get(name)
            if buf is None:
                buf = np.full((self._t.shape[0],) + val.shape[1:], np.nan)
                self._sig[name] = buf
            buf[i0:i1] = val[sel]
        self._n = i1

    def event(self, time: float, kind: str, index: int = -1, pre: Any = (), post: Any = (),
              mode_from: int = -1, mode_to: int = -1) -> None:
        """Record one event."""
        self.events.append(Event(float(time), kind, int(index), np.array(pre, float),
                                 np.array(post, float), int(mode_from), int(mode_to)))

    def events_block(self, times: Any, kind: str, indices: Any, pre: Any, post: Any) -> None:
        """Record a block of events of one ``kind`` at once (as produced by a compiled
        kernel): ``times`` and ``indices`` of length ``k``, ``pre``/``post`` of shape
        ``(k, n)`` (copied once for the whole block)."""
        pre = np.array(pre, dtype=np.float64)
        post = np.array(post, dtype=np.float64)
        self.events.extend(Event(t, kind, i, a, b) for t, i, a, b in zip(
            np.asarray(times, dtype=np.float64).tolist(),
            np.asarray(indices, dtype=np.int64).tolist(), pre, post, strict=True))

    def signal_min(self, name: str) -> float | None:
        """The smallest value of signal ``name`` recorded so far (``None``: none recorded, or
        the signal has no component — e.g. the gaps of a system without contacts)."""
        values = self._sig.get(name)
        if values is None or not self._n or values[:self._n].size == 0:
            return None
        return float(values[:self._n].min())

    @property
    def last_time(self) -> float:
        """Time of the last recorded sample (``-inf`` before the first one)."""
        return float(self._t[self._n - 1]) if self._n else -np.inf

    def finish(self, *, status: int = 0, message: str | None = None, method: str = "",
               stats: Mapping[str, Any] | None = None,
               state_names: Sequence[str] = ()) -> Trajectory:
        """Freeze the buffers into a :class:`Trajectory`.

        Raises
        ------
        ModelError
            Without ``offered``: a requested signal was never recorded (an unknown name);
            ``err.trajectory`` holds the finished trajectory.
        """
        traj = self._freeze(status, message, method, stats, state_names)
        if self.keep is not None and self.offered is None and self._n:
            missing = sorted(self.keep - set(self._sig))
            if missing:
                raise ModelError(f"signals: requested signal(s) {missing} were never recorded "
                                 f"by {method or 'the integrator'}; it recorded "
                                 f"{sorted(self._sig)} (check the names; err.trajectory "
                                 "holds the run)", trajectory=traj)
        return traj

    def _freeze(self, status: int, message: str | None, method: str,
                stats: Mapping[str, Any] | None, state_names: Sequence[str],
                copy: bool = True) -> Trajectory:
        n = self._n
        t, x = self._t[:n], self._x[:n]
        signals = {k: v[:n] for k, v in self._sig.items()}
        if copy:
            t, x = t.copy(), x.copy()
            signals = {k: v.copy() for k, v in signals.items()}
        if n > 1 and (t[1:] < t[:-1]).any():
            # a forced sample at a root found after its piece was sampled (the switching
            # method's grazings): put it in time order; stable, so pre/post pairs keep theirs
            order = np.argsort(t, kind="stable")
            t, x = t[order], x[order]
            signals = {k: v[order] for k, v in signals.items()}
        if not math.isfinite(float(t.sum())):   # a NaN or infinite time (the sum of finite
            _check_times(t)                     # times overflowing passes the full check)
        # the buffers are float64, time-major, one row per sample and now in time order:
        # what Trajectory.__post_init__ checks holds by construction, so it is skipped
        return Trajectory._from_record(
            t=t, x=x, signals=signals,
            events=tuple(sorted(self.events, key=_event_time)) if self.events else (),
            stats=dict(stats or {}), status=status,
            message=STATUS_MESSAGES[status] if message is None else message,
            method=method, state_names=tuple(state_names),
        )


def _event_time(event: Event) -> float:
    return event.time


def _signal_names(signals: Iterable[str], offered: tuple[str, ...] | None) -> set[str]:
    """The requested signal names, checked against the offered ones when known."""
    if isinstance(signals, str | bytes):
        raise ModelError(f"signals: expected a sequence of signal names, got the string "
                         f"{signals!r} (write signals=[{signals!r}])")
    names = list(signals)
    bad = [n for n in names if not isinstance(n, str)]
    if bad:
        raise ModelError(f"signals: expected signal names (str), got {bad!r}")
    if offered is not None:
        unknown = sorted(set(names) - set(offered))
        if unknown:
            raise ModelError(f"signals: unknown name(s) {unknown}; this integrator "
                             f"records {sorted(offered)}")
    return set(names)


def _import_pandas() -> Any:
    """pandas, or an ImportError that says which extra installs it."""
    try:
        import pandas
    except ImportError as exc:
        raise ImportError("pandas is needed for DataFrames of trajectories and is not "
                          "installed: pip install 'nscontrol[dataframe]'") from exc
    return pandas

"""What a Moreau–Jean run records: the states, the signals ``impulse``, ``gap`` and
``energy``, and the ``"impact"`` events (a contact whose impulse becomes positive while
approaching), with the jump listeners called for each step that has one."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ..trajectory import ChunkProgress, Recorder
from ._runners import RunState

__all__ = ["signals_of", "sample_initial", "record_chunk", "record_finished", "impact",
           "record_impacts"]


def signals_of(system: Any, q: FloatArray, v: FloatArray, p: FloatArray,
               rec: Recorder) -> dict[str, FloatArray]:
    """The signals ``rec`` wants of the rows ``q``, ``v``, ``p``."""
    out: dict[str, FloatArray] = {}
    if rec.wants("impulse"):
        out["impulse"] = p
    if rec.wants("gap"):
        out["gap"] = np.array([system.gaps(qi) for qi in q]) if system.gap is not None \
            else np.asarray((system.gap_matrix @ q.T).T) + system.gap_offset
    if rec.wants("energy"):
        out["energy"] = system.energy(np.concatenate((q, v), axis=1))
    return out


def sample_initial(rec: Recorder, system: Any, t0: float, x0: FloatArray) -> None:
    """The first sample alone (always kept): a run that ends before its first chunk is
    recorded (:func:`record_chunk` records it with that chunk otherwise)."""
    n = system.n_dof
    sig = signals_of(system, x0[None, :n], x0[None, n:], np.zeros((1, system.n_contacts)),
                     rec)
    rec.sample(t0, x0, **{key: val[0] for key, val in sig.items()})


def impact(system: Any, q: FloatArray, v: FloatArray, rising: np.ndarray
           ) -> tuple[np.ndarray, FloatArray]:
    """Of the contacts whose impulse rose over a step from ``(q, v)`` (the mask
    ``rising``), those approaching at the step's start, ``G v < 0``, and their ``G v``."""
    contacts = np.flatnonzero(rising)
    un = np.asarray(system.gap_jacobian(q)[contacts] @ v).ravel()
    keep = un < 0.0
    return contacts[keep], un[keep]


def jump_listener(system: Any, listeners: Sequence[Callable[..., None]]
                  ) -> Callable[..., None]:
    """``after_step(t, x_minus, x_plus, p, p_before)``: the listeners called at once for a
    step with an impact (the blocks' reset, before their next step)."""
    n = system.n_dof

    def after_step(t: float, x_minus: FloatArray, x_plus: FloatArray, p: FloatArray,
                   p_before: FloatArray) -> None:
        rising = (p > 0.0) & (p_before == 0.0)
        if not rising.any():
            return
        contacts, _ = impact(system, x_minus[:n], x_minus[n:], rising)
        if contacts.size:
            for listener in listeners:
                listener(t, x_minus, x_plus, contacts, p.copy())

    return after_step


def record_finished(progress: ChunkProgress, *, rec: Recorder, system: Any,
                    times: FloatArray, state: RunState, q_pre: FloatArray,
                    v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                    h: float) -> None:
    """Record the steps a failed chunk finished (see :meth:`Recorder.chunk`)."""
    q, v, p = progress.written()
    record_chunk(rec, system, times[:progress.done] + h, q, v, p, state, q_pre, v_pre,
                 listeners, h)


#: ``(q, v, p, rec) -> signals or None``: a runner's own evaluation of rows' signals
RowSignals = Callable[[FloatArray, FloatArray, FloatArray, Recorder],
                      dict[str, FloatArray] | None]


def record_chunk(rec: Recorder, system: Any, times: FloatArray, q: FloatArray,
                 v: FloatArray, p: FloatArray, state: RunState, q_pre: FloatArray,
                 v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                 h: float, signals: RowSignals | None = None) -> None:
    """Write a chunk of steps and its impact events; call the jump listeners. ``signals``:
    the runner's evaluation of the rows' signals (the compiled path; when it gives ``None``,
    or without it, :func:`signals_of`). While the run's first sample is held back
    (``state.first``, the run's first time: the chunk starts from ``q_pre, v_pre`` without
    impulse), it is written with the chunk: one evaluation of the signals and one write
    for both (a run's fixed cost)."""
    rows = (q, v, p)
    if state.first is not None:
        times = np.concatenate(((state.first,), times))
        rows = (np.concatenate((q_pre[None], q)), np.concatenate((v_pre[None], v)),
                np.concatenate((state.p_prev[None], p)))
        state.first = None
    sig = None if signals is None else signals(*rows, rec)
    rec.extend(times, rows[:2], **(signals_of(system, *rows, rec) if sig is None else sig))
    record_impacts(rec, system, times[-q.shape[0]:], q, v, p, state.p_prev, q_pre, v_pre,
                   listeners, h)
    state.p_prev = p[-1].copy()


def record_impacts(rec: Recorder, system: Any, times: FloatArray, q: FloatArray,
                   v: FloatArray, p: FloatArray, p_before: FloatArray, q_pre: FloatArray,
                   v_pre: FloatArray, listeners: Sequence[Callable[..., None]],
                   h: float) -> None:
    """The ``"impact"`` events of a chunk of steps ending at ``times`` (states ``q``, ``v``
    and normal impulses ``p`` per step, from ``q_pre``, ``v_pre`` and ``p_before`` before
    it): a contact whose impulse becomes positive while it approaches; the jump listeners
    called for each step that has one (plain and frictional Moreau–Jean alike)."""
    if not p.any():   # no impulse, no impact (most chunks of a flight)
        return
    positive = p > 0.0
    prev = np.vstack([p_before[None, :], p[:-1]])
    rising = positive & (prev == 0.0)
    for k in np.flatnonzero(rising.any(axis=1)):
        qb = q_pre if k == 0 else q[k - 1]
        vb = v_pre if k == 0 else v[k - 1]
        contacts, un = impact(system, qb, vb, rising[k])
        if contacts.size == 0:
            continue
        # the impact time inside the step, where the gap extrapolated from the step's start
        # reaches zero (the step's end would bias every impact time by up to h)
        gap = np.asarray(system.gaps(qb))[contacts]
        tau = np.clip(gap / -un, 0.0, h)
        x_minus, x_plus = np.concatenate([qb, vb]), np.concatenate([q[k], v[k]])
        for j, tj in zip(contacts, tau, strict=True):
            rec.event(times[k] - h + tj, "impact", int(j), x_minus, x_plus)
        for listener in listeners:
            listener(float(times[k]), x_minus, x_plus, contacts, p[k].copy())

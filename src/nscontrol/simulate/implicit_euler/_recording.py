"""What a run of implicit Euler records: the steps of a chunk (state, ``z``, ``w``,
``y = C x``, the final one always kept), and the warning about steps at a corner of the
law's graph when the discrete map's Jacobian was asked for."""

from __future__ import annotations

import warnings
from typing import Any

from ..._validation import FloatArray
from ...errors import NscontrolWarning
from ..trajectory import ChunkProgress, Recorder

__all__ = ["record_block", "record_finished", "warn_degenerate"]


def record_block(rec: Recorder, system: Any, t: FloatArray, X: FloatArray, Z: FloatArray,
                 W: FloatArray, *, last: bool) -> None:
    """Record the steps ending at ``t`` (``last``: the final one is kept whatever
    ``record_every`` says)."""
    if X.shape[0] == 0:
        return
    sig = {}
    if rec.wants("z"):
        sig["z"] = Z
    if rec.wants("w"):
        sig["w"] = W
    if rec.wants("y"):
        sig["y"] = X @ system.C.T
    if last and X.shape[0] > 1:
        rec.extend(t[:-1], X[:-1], **{k: v[:-1] for k, v in sig.items()})
        rec.sample(t[-1], X[-1], force=True, **{k: v[-1] for k, v in sig.items()})
    elif last:
        rec.sample(t[-1], X[-1], force=True, **{k: v[-1] for k, v in sig.items()})
    else:
        rec.extend(t, X, **sig)


def record_finished(progress: ChunkProgress, *, rec: Recorder, system: Any,
                    times: FloatArray) -> None:
    """Record the steps a failed chunk finished (see :meth:`Recorder.chunk`)."""
    X, Z, W = progress.written()
    record_block(rec, system, times[1:1 + progress.done], X, Z, W, last=True)


def warn_degenerate(jac: Any) -> None:
    """Warn that ``jac.degenerate_steps`` steps ended at a corner of the law's graph."""
    warnings.warn(f"implicit_euler: {jac.degenerate_steps} step(s) ended at a corner of the "
                  f"law's graph (first at t = {jac.first_degenerate_time:.6g}), where the "
                  f"discrete map is not differentiable; stats['state_transition'] uses the "
                  f"constraint-active one-sided derivative there", NscontrolWarning,
                  stacklevel=5)   # integrate (under end, _recorded_run, drive)

"""Per-contact (or per-guard) event history and the accumulation (Zeno) tests."""

from __future__ import annotations

import numpy as np

from .._event_kernels import ZENO_CLOSE, ZENO_DUE, zeno_push, zeno_status
from ._options import _Options


class _Zeno:
    """Per-slot (contact or guard) event times and the accumulation tests, on arrays shared
    with the compiled event loop (:func:`nscontrol.simulate._event_kernels.zeno_status` is
    the one test)."""

    def __init__(self, opts: _Options, n_slots: int,
                 arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        self.opts = opts
        if arrays is None:  # (times, count, first time) per slot; count zero: empty history
            arrays = (np.zeros((max(n_slots, 1), 6)), np.zeros(max(n_slots, 1), dtype=np.int64),
                      np.zeros(max(n_slots, 1)))
        self.hist: np.ndarray = arrays[0]
        self.count: np.ndarray = arrays[1]
        self.first: np.ndarray = arrays[2]
        self.n_events = 0

    def reset(self, j: int) -> None:
        self.count[j] = 0

    def _status(self, j: int, t: float, geometric: bool) -> tuple[int, float]:
        o = self.opts
        return zeno_status(self.hist, self.count, self.first, j, t, geometric, o.ratio_tol,
                           o.horizon, o.rel, o.min_interval)

    def too_close(self, j: int, t: float) -> bool:
        """Whether an event of slot ``j`` at ``t`` follows the previous one too closely."""
        return self._status(j, t, False)[0] == ZENO_CLOSE

    def push(self, j: int, t: float) -> None:
        zeno_push(self.hist, self.count, self.first, j, t)

    def add(self, j: int, t: float) -> float | None:
        """Record an impact; return the accumulation time when it is due."""
        code, t_acc = self._status(j, t, True)
        self.push(j, t)
        return t_acc if code == ZENO_DUE else None

    def check(self, j: int, t: float) -> tuple[bool, float | None]:
        """Both tests at once, history unchanged: ``(too close, accumulation time or
        None)`` (the closeness test comes first in :func:`zeno_status`)."""
        code, t_acc = self._status(j, t, True)
        return code == ZENO_CLOSE, (t_acc if code == ZENO_DUE else None)

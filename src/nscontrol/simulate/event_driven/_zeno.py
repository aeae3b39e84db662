"""Per-contact (or per-guard) event history and the accumulation (Zeno) tests."""

from __future__ import annotations

import numpy as np

from ._options import _Options


class _Zeno:
    """Per-slot (contact or guard) event times and the accumulation tests, on arrays shared
    with the compiled event loop (:func:`nscontrol.simulate._event_kernels.zeno_status` is
    the one test)."""

    def __init__(self, opts: _Options, n_slots: int) -> None:
        self.opts = opts
        self.hist = np.zeros((max(n_slots, 1), 6))
        self.count = np.zeros(max(n_slots, 1), dtype=np.int64)
        self.first = np.zeros(max(n_slots, 1))
        self.n_events = 0

    def reset(self, j: int) -> None:
        self.count[j] = 0

    def _status(self, j: int, t: float, geometric: bool) -> tuple[int, float]:
        from .._event_kernels import zeno_status

        o = self.opts
        return zeno_status(self.hist, self.count, self.first, j, t, geometric, o.ratio_tol,
                           o.horizon, o.rel, o.min_interval)

    def too_close(self, j: int, t: float) -> bool:
        from .._event_kernels import ZENO_CLOSE

        return self._status(j, t, False)[0] == ZENO_CLOSE

    def push(self, j: int, t: float) -> None:
        from .._event_kernels import zeno_push

        zeno_push(self.hist, self.count, self.first, j, t)

    def add(self, j: int, t: float) -> float | None:
        """Record an impact; return the accumulation time when it is due."""
        from .._event_kernels import ZENO_DUE

        code, t_acc = self._status(j, t, True)
        self.push(j, t)
        return t_acc if code == ZENO_DUE else None

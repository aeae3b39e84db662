"""The loop every method's run goes through (``simulate/loop.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nscontrol.errors import SolverError
from nscontrol.simulate.loop import END, Stop, drive, tick_count, tick_time
from nscontrol.simulate.trajectory import Recorder


class _Decay:
    """Explicit Euler on x' = -x, one chunk of ten steps per advance; fails at ``t_fail``."""

    def __init__(self, h: float, n: int, t_fail: float = math.inf) -> None:
        self.h, self.n, self.k, self.x, self.t_fail = h, n, 0, 1.0, t_fail
        self.rec = Recorder(1)
        self.rec.sample(0.0, np.array([1.0]), force=True)

    def advance(self) -> float | Stop:
        if self.k == self.n:
            return END
        for _ in range(min(10, self.n - self.k)):
            if (self.k + 1) * self.h > self.t_fail:
                return Stop(-1, "failed on purpose", "test")
            self.x *= 1.0 - self.h
            self.k += 1
            self.rec.sample(self.k * self.h, np.array([self.x]))
        return self.k * self.h

    def finish(self, stop: Stop) -> object:
        return self.rec.finish(status=stop.status, message=stop.message, method="decay")


def test_drive_runs_every_piece_and_returns_the_record() -> None:
    traj = drive(_Decay(0.01, 95), (0.0, 0.95), desc="decay", progress=False)
    assert traj.t.shape == (96,) and traj.status == 0
    # explicit Euler: x_k = (1 - h)^k exactly up to k roundings (k * eps relative)
    assert abs(traj.x[-1, 0] - 0.99 ** 95) <= 95 * np.finfo(float).eps


def test_a_failing_stop_raises_with_the_run_so_far() -> None:
    with pytest.raises(SolverError, match="failed on purpose") as info:
        drive(_Decay(0.01, 95, t_fail=0.305), (0.0, 0.95), desc="decay", progress=False)
    traj = info.value.trajectory
    assert info.value.status == "test" and traj.status == -1
    assert traj.t[-1] == pytest.approx(0.30, abs=1e-12)   # 30 steps recorded, none lost


@pytest.mark.parametrize("period", [1e-4, 1e-3, 0.1, 1.0 / 3.0])
def test_ticks_are_counted_not_accumulated(period: float) -> None:
    n = 10**6
    tf = tick_time(0.0, n, period)
    assert tick_count(0.0, tf, period) == n
    # the instants are t0 + k T to one rounding (|t| eps), whatever k
    k = np.arange(0, n + 1, 997)
    t = np.array([tick_time(0.5, int(i), period) for i in k])
    assert np.max(np.abs(t - (0.5 + k * period))) <= np.finfo(float).eps * (0.5 + tf)

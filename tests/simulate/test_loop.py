"""The loop every method's run goes through (``simulate/loop.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nscontrol.errors import SolverError, ZenoError
from nscontrol.simulate.loop import END, Recording, Stop, drive, tick_count, tick_time
from nscontrol.simulate.trajectory import Recorder


class _Decay:
    """Explicit Euler on x' = -x, one chunk of ten steps per advance; fails at ``t_fail``."""

    recording = Recording(1)

    def __init__(self, h: float, n: int, t_fail: float = math.inf) -> None:
        self.h, self.n, self.k, self.x, self.t_fail = h, n, 0, 1.0, t_fail

    def start(self, rec: Recorder) -> None:
        self.rec = rec
        rec.sample(0.0, np.array([1.0]), force=True)

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

    def settle(self) -> None:
        """Every step is recorded as it is taken."""

    def end(self, stop: Stop) -> dict[str, int]:
        return {"steps": self.k}


def test_drive_runs_every_piece_and_returns_the_record() -> None:
    traj = drive(_Decay(0.01, 95), (0.0, 0.95), desc="decay", progress=False)
    assert traj.t.shape == (96,) and traj.status == 0 and traj.stats["steps"] == 95
    # explicit Euler: x_k = (1 - h)^k exactly up to k roundings (k * eps relative)
    assert abs(traj.x[-1, 0] - 0.99 ** 95) <= 95 * np.finfo(float).eps


def test_a_failing_stop_raises_with_the_run_so_far() -> None:
    with pytest.raises(SolverError, match="failed on purpose") as info:
        drive(_Decay(0.01, 95, t_fail=0.305), (0.0, 0.95), desc="decay", progress=False)
    traj = info.value.trajectory
    assert info.value.status == "test" and traj.status == -1
    assert traj.t[-1] == pytest.approx(0.30, abs=1e-12)   # 30 steps recorded, none lost
    assert traj.stats["steps"] == 30                      # the part run's statistics


class _Held:
    """A stepper of the loop's own record: explicit Euler on x' = -x, ten steps per advance,
    held in a buffer of its own and handed to the record every third piece (and at
    ``settle``), as event_driven's sample buffer does; raises ``error`` at step
    ``fail_at``."""

    recording = Recording(1, state_names=("x",))

    def __init__(self, n: int, fail_at: int = -1, error: BaseException | None = None) -> None:
        self.h, self.n, self.k, self.x = 0.01, n, 0, 1.0
        self.fail_at, self.error = fail_at, error
        self.held: list[tuple[float, float]] = []
        self.pieces = 0

    def start(self, rec: Recorder) -> None:
        self.rec = rec
        rec.sample(0.0, np.array([1.0]), force=True)

    def advance(self) -> float | Stop:
        if self.k == self.n:
            return END
        for _ in range(min(10, self.n - self.k)):
            if self.k == self.fail_at:
                assert self.error is not None
                raise self.error
            self.x *= 1.0 - self.h
            self.k += 1
            self.held.append((self.k * self.h, self.x))
        self.pieces += 1
        if self.pieces % 3 == 0:
            self.settle()
        return self.k * self.h

    def settle(self) -> None:
        for t, x in self.held:
            self.rec.sample(t, np.array([x]))
        self.held.clear()

    def end(self, stop: Stop) -> dict[str, object]:
        return {"steps": self.k}


def test_drive_builds_the_record_and_freezes_it_with_the_steppers_stats() -> None:
    traj = drive(_Held(95), (0.0, 0.95), desc="held", progress=False)
    assert traj.t.shape == (96,) and traj.status == 0 and traj.method == "held"
    assert traj.stats == {"steps": 95} and traj.state_names == ("x",)
    np.testing.assert_allclose(traj.t, 0.01 * np.arange(96), rtol=0, atol=1e-15)
    assert abs(traj.x[-1, 0] - 0.99 ** 95) <= 95 * np.finfo(float).eps


@pytest.mark.parametrize("error", [ValueError("a callback failed"), KeyboardInterrupt(),
                                   ZenoError("accumulation", time=0.4)])
def test_any_exception_leaves_with_every_sample_before_it(error: BaseException) -> None:
    # step 47 raises: 47 steps were computed, 17 of them still held in the stepper's buffer
    # (the last hand-over was after the third piece, step 30): the loop has them handed over
    with pytest.raises(type(error)) as info:
        drive(_Held(95, fail_at=47, error=error), (0.0, 0.95), desc="held", progress=False)
    traj = info.value.trajectory  # type: ignore[attr-defined]
    assert traj.status == -1 and traj.method == "held" and traj.state_names == ("x",)
    assert traj.t.shape == (48,) and traj.t[-1] == pytest.approx(0.47, abs=1e-15)
    assert abs(traj.x[-1, 0] - 0.99 ** 47) <= 47 * np.finfo(float).eps
    library = isinstance(error, ZenoError)
    assert (traj.message == str(error)) if library else traj.message.startswith(
        f"interrupted by {type(error).__name__}")
    notes = getattr(info.value, "__notes__", [])
    assert (notes == []) if library else "48 samples" in notes[0]


def test_an_error_carrying_its_own_trajectory_keeps_it() -> None:
    own = drive(_Held(5), (0.0, 0.05), desc="held", progress=False)
    error = ZenoError("accumulation", time=0.1, trajectory=own)
    with pytest.raises(ZenoError) as info:
        drive(_Held(95, fail_at=20, error=error), (0.0, 0.95), desc="held", progress=False)
    assert info.value.trajectory is own


@pytest.mark.parametrize("period", [1e-4, 1e-3, 0.1, 1.0 / 3.0])
def test_ticks_are_counted_not_accumulated(period: float) -> None:
    n = 10**6
    tf = tick_time(0.0, n, period)
    assert tick_count(0.0, tf, period) == n
    # the instants are t0 + k T to one rounding (|t| eps), whatever k
    k = np.arange(0, n + 1, 997)
    t = np.array([tick_time(0.5, int(i), period) for i in k])
    assert np.max(np.abs(t - (0.5 + k * period))) <= np.finfo(float).eps * (0.5 + tf)

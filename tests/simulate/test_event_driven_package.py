"""The event-driven package's shortcuts change nothing: fast event objects, pooled arrays,
block-wise recording, reused options and the open-gap shortcut of the ``x0`` check.

The comparisons are between two runs doing the same floating-point operations in the same
order, so they agree bit for bit (``array_equal``), not to a tolerance — except a flight
longer than the whole sample buffer, which resumes from a propagated grid state (its bound
is stated where it is asserted).
"""

import importlib
from dataclasses import fields

import numpy as np
import pytest

from nscontrol.errors import DimensionError, InadmissibleStateError, ModelError
from nscontrol.simulate import simulate
from nscontrol.simulate.trajectory import Event, Recorder, Trajectory
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.testing.mechanics_problems import BouncingBall

ed = importlib.import_module("nscontrol.simulate.event_driven")
recording = importlib.import_module("nscontrol.simulate.event_driven._recording")
flight = importlib.import_module("nscontrol.simulate.event_driven._flight")


def _same(a: Trajectory, b: Trajectory) -> None:
    assert np.array_equal(a.t, b.t)
    assert np.array_equal(a.x, b.x)
    assert a.signals.keys() == b.signals.keys()
    for k in a.signals:
        assert np.array_equal(a.signals[k], b.signals[k])
    assert [(e.time, e.kind, e.index) for e in a.events] == \
        [(e.time, e.kind, e.index) for e in b.events]
    for ea, eb in zip(a.events, b.events, strict=True):
        assert np.array_equal(ea.pre, eb.pre) and np.array_equal(ea.post, eb.post)
    assert np.array_equal(a.stats["impulses"], b.stats["impulses"])


def test_helpers_stay_importable_from_the_package() -> None:
    from nscontrol.simulate.event_driven import integrate, reorder_listeners, reorder_states

    assert callable(integrate) and callable(reorder_listeners) and callable(reorder_states)


def test_block_events_equal_events_built_by_the_constructor() -> None:
    rec = Recorder(2)
    times = np.array([0.5, 1.5])
    pre, post = np.arange(4.0).reshape(2, 2), -np.arange(4.0).reshape(2, 2)
    recording.append_events(rec, times, "impact", np.array([0, 3]), pre, post)
    built = [Event(0.5, "impact", 0, pre[0], post[0]), Event(1.5, "impact", 3, pre[1], post[1])]
    for fast, ref in zip(rec.events, built, strict=True):
        assert type(fast) is Event
        for f in fields(Event):  # every field, also one added to Event later
            a, b = getattr(fast, f.name), getattr(ref, f.name)
            assert np.array_equal(a, b) and type(a) is type(b), f.name
    pre[:] = 99.0  # the events own their states
    assert rec.events[0].pre.tolist() == [0.0, 1.0]


def test_recording_in_small_blocks_changes_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    ball = BouncingBall()
    ref = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=0.1, progress=False)
    # a buffer of 16 rows (a flight has at most 8 grid points here): the compiled loop hands
    # the buffer back before every flight that does not fit, dozens of times, and redoes the
    # flight from the same state
    monkeypatch.setattr(recording._Samples, "CAPACITY", 16)
    monkeypatch.setattr(flight._Workspace, "SAMPLES", 16)
    small = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=0.1, progress=False)
    assert len(ref) > 200
    _same(small, ref)


def test_a_flight_longer_than_the_buffer_resumes_on_the_grid(
        monkeypatch: pytest.MonkeyPatch) -> None:
    ball = BouncingBall()
    ref = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=0.01, progress=False)
    monkeypatch.setattr(recording._Samples, "CAPACITY", 16)
    monkeypatch.setattr(flight._Workspace, "SAMPLES", 16)
    small = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=0.01, progress=False)
    # flights of up to 45 grid points: resumed from a propagated grid state, each event is
    # searched again from there; the event times agree to the accumulated rounding of ~65
    # bounces, measured 1.7e-13 s: bound 1e-12 s (the closed-form accuracy the ball's test
    # asserts)
    assert len(small) == len(ref)
    assert np.max(np.abs(small.event_times() - ref.event_times())) < 1e-12
    assert np.max(np.abs(small.x - ref.x)) < 1e-12


def test_record_every_thins_the_same_rows() -> None:
    ball = BouncingBall()
    system = ball.system()
    full = simulate(system, ball.x0, (0.0, 10.0), dt=0.01, progress=False)
    thin = simulate(system, ball.x0, (0.0, 10.0), dt=0.01, progress=False, record_every=7)
    keep = np.unique(np.append(np.arange(0, len(full), 7), len(full) - 1))  # + final state
    assert np.array_equal(thin.t, full.t[keep])
    assert np.array_equal(thin.x, full.x[keep])
    assert np.array_equal(thin.signals["energy"], full.signals["energy"][keep])


def test_runs_of_one_system_share_arrays_but_not_results() -> None:
    ball = BouncingBall()
    system = ball.system()
    ref = simulate(system, ball.x0, (0.0, 10.0), progress=False)
    nested = []

    def listener(t: float, *_: object) -> None:  # a run started while another one is going
        if not nested:
            nested.append(simulate(system, ball.x0, (0.0, 10.0), progress=False))

    outer = simulate(system, ball.x0, (0.0, 10.0), progress=False, listeners=[listener])
    _same(outer, ref)
    _same(nested[0], ref)
    _same(simulate(system, ball.x0, (0.0, 10.0), progress=False), ref)


def test_reused_options_are_still_checked() -> None:
    ball = BouncingBall()
    system = ball.system()
    first = simulate(system, ball.x0, (0.0, 1.0), dt=0.1, progress=False)
    again = simulate(system, ball.x0, (0.0, 1.0), dt=0.1, progress=False)
    _same(again, first)
    with pytest.raises(ModelError, match="dt"):
        simulate(system, ball.x0, (0.0, 1.0), dt=-0.1, progress=False)
    with pytest.raises(ModelError, match="max_events"):
        simulate(system, ball.x0, (0.0, 1.0), dt=0.1, max_events=True, progress=False)
    with pytest.raises(ModelError, match="on_failure"):
        simulate(system, ball.x0, (0.0, 1.0), dt=0.1, on_failure="ignore", progress=False)


@pytest.mark.parametrize("x0, error", [
    (np.array([-1e-3, 0.0]), InadmissibleStateError),  # penetrating
    (np.array([0.0, -1.0]), InadmissibleStateError),  # closed and approaching
    (np.array([np.nan, 0.0]), ModelError),
    (np.array([1.0, 0.0, 0.0]), DimensionError),
])
def test_the_open_gap_shortcut_refuses_what_the_full_check_refuses(
        x0: np.ndarray, error: type) -> None:
    system = LagrangianSystem.bouncing_ball(0.9)
    with pytest.raises(error):
        simulate(system, x0, (0.0, 1.0), progress=False)


def test_a_closed_gap_takes_the_full_check_and_rests() -> None:
    system = LagrangianSystem.bouncing_ball(0.9)
    traj = simulate(system, np.array([0.0, 0.0]), (0.0, 1.0), progress=False)
    assert [e.kind for e in traj.events] == ["contact_start"]
    assert np.all(traj.x == 0.0)


def test_a_listener_error_leaves_every_sample_in_the_recorder(
        monkeypatch: pytest.MonkeyPatch) -> None:
    recorders: list[Recorder] = []
    init = Recorder.__init__

    def keep(self: Recorder, *args: object, **kwargs: object) -> None:
        init(self, *args, **kwargs)  # type: ignore[arg-type]
        recorders.append(self)

    monkeypatch.setattr(Recorder, "__init__", keep)
    seen: list[float] = []

    def listener(t: float, *_: object) -> None:
        seen.append(t)
        if len(seen) == 10:
            raise RuntimeError("listener failed")

    ball = BouncingBall()
    with pytest.raises(RuntimeError, match="listener failed"):
        simulate(ball.system(), ball.x0, (0.0, 10.0), progress=False, listeners=[listener])
    # the samples of the compiled block (up to the accumulation, after the 10th impact) were
    # handed to the recorder, not left in the run's buffer
    assert recorders[-1].last_time >= seen[-1]

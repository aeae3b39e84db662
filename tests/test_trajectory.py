"""The one result type: construction checks, slicing, interpolation, HDF5 round trip."""

import numpy as np
import pytest

from nscontrol.errors import DimensionError
from nscontrol.simulate import Recorder, Trajectory


def _sample_trajectory(every: int = 1) -> Trajectory:
    rec = Recorder(2, every=every)
    for k in range(10):
        t = 0.1 * k
        rec.sample(t, [np.cos(t), np.sin(t)], y=np.cos(t), lam=[t, 2 * t])
    rec.event(0.45, "impact", 0, pre=[1.0, -1.0], post=[1.0, 0.9])
    rec.event(0.75, "crossing", 1, pre=[0.0, 1.0], post=[0.0, 1.0], mode_from=0, mode_to=1)
    return rec.finish(method="test", stats={"steps": 10, "note": "x"},
                      state_names=("q", "v"))


def test_recorder_builds_time_major_arrays():
    traj = _sample_trajectory()
    assert traj.x.shape == (10, 2)
    assert traj.signals["lam"].shape == (10, 2)
    assert traj.success and traj.status == 0
    np.testing.assert_allclose(traj.state("v"), np.sin(traj.t))
    assert list(traj.event_times("impact")) == [0.45]


def test_record_every_keeps_every_kth_sample_and_forced_ones():
    rec = Recorder(1, every=3)
    for k in range(10):
        rec.sample(float(k), [k], force=(k == 9))
    rec.extend(np.arange(10.0, 16.0), np.arange(10.0, 16.0)[:, None])
    traj = rec.finish()
    assert list(traj.t) == [0, 3, 6, 9, 12, 15]


def test_slice_and_interpolation():
    traj = _sample_trajectory()
    part = traj.slice(0.3, 0.61)
    np.testing.assert_allclose(part.t, [0.3, 0.4, 0.5, 0.6])  # 0.1*6 > 0.6 in floats
    assert [e.kind for e in part.events] == ["impact"]
    mid = traj.at(0.25)
    np.testing.assert_allclose(mid, 0.5 * (traj.x[2] + traj.x[3]))


def test_hdf5_round_trip_is_lossless(tmp_path):
    traj = _sample_trajectory()
    path = tmp_path / "traj.h5"
    traj.save(path)
    back = Trajectory.load(path)
    np.testing.assert_array_equal(back.t, traj.t)
    np.testing.assert_array_equal(back.x, traj.x)
    for k in traj.signals:
        np.testing.assert_array_equal(back.signals[k], traj.signals[k])
    assert [(e.time, e.kind, e.index, e.mode_from, e.mode_to) for e in back.events] == \
        [(e.time, e.kind, e.index, e.mode_from, e.mode_to) for e in traj.events]
    for a, b in zip(back.events, traj.events, strict=True):
        np.testing.assert_array_equal(a.pre, b.pre)
        np.testing.assert_array_equal(a.post, b.post)
    assert back.stats == traj.stats and back.state_names == traj.state_names
    assert back.method == "test" and back.message == traj.message


def test_dataframe_and_plot():
    traj = _sample_trajectory()
    df = traj.to_dataframe()
    assert list(df.columns) == ["q", "v", "y", "lam[0]", "lam[1]"]
    fig = traj.plot(signals=["y"])
    assert len(fig.axes) == 2


def test_shape_mismatch_is_reported():
    with pytest.raises(DimensionError, match="time-major"):
        Trajectory(t=np.zeros(3), x=np.zeros((4, 2)))
    with pytest.raises(DimensionError, match="signal 'y'"):
        Trajectory(t=np.zeros(3), x=np.zeros((3, 2)), signals={"y": np.zeros(2)})

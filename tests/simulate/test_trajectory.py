"""The one result type: construction checks, slicing, interpolation, HDF5 round trip."""

import numpy as np
import pytest

from nscontrol.errors import DimensionError, ModelError
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


def test_hdf5_round_trip_of_every_kind_of_stat(tmp_path):
    rng = np.random.default_rng(7)
    stats = {
        "saltation_matrices": rng.standard_normal((2308, 2, 2)),   # 74 KB: beyond attributes
        "state_transition": rng.standard_normal((3, 3)),
        "none": None, "flag": True, "steps": 12345, "h": 0.1, "nan": float("nan"),
        "solver": "lemke", "counts": [1, 2, 3], "mixed": [1, "a", None, 2.5],
        "pair": (1, "two"), "nested": {"a": 1, "b": [0.5, None], "c": {"d": "e"}},
        "int_keys": {0: "zero", (1, 2): "pair"}, "complex": 1.0 - 2.0j,
        "numpy_scalar": np.float64(1.0 / 3.0), "numpy_int": np.int64(2**40),
        "arrays_in_list": [np.eye(2), np.arange(3)], "slash/key": np.arange(4),
        "long_list": list(range(50_000)),
    }
    traj = Trajectory(t=np.arange(3.0), x=np.zeros((3, 1)), stats=stats)
    path = tmp_path / "stats.h5"
    traj.save(path)
    back = Trajectory.load(path).stats
    assert list(back) == list(stats)                       # insertion order kept
    for key in ("saltation_matrices", "state_transition", "slash/key"):
        assert isinstance(back[key], np.ndarray) and back[key].dtype == stats[key].dtype
        np.testing.assert_array_equal(back[key], stats[key])
    for key in ("none", "flag", "steps", "h", "solver", "counts", "mixed", "pair", "nested",
                "int_keys", "complex", "long_list"):
        assert back[key] == stats[key] and type(back[key]) is type(stats[key]), key
    assert np.isnan(back["nan"])
    assert back["numpy_scalar"] == stats["numpy_scalar"]    # same value, as a Python float
    assert back["numpy_int"] == 2**40
    for a, b in zip(back["arrays_in_list"], stats["arrays_in_list"], strict=True):
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a, b)


def test_unsaveable_stat_names_its_key(tmp_path):
    traj = Trajectory(t=np.arange(2.0), x=np.zeros((2, 1)), stats={"fn": print})
    with pytest.raises(ModelError, match=r"^stats\['fn'\]: cannot be saved: values of type"):
        traj.save(tmp_path / "bad.h5")


def test_load_refuses_other_files(tmp_path):
    import h5py

    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something else"
    with pytest.raises(ModelError, match=r"^path: expected an nscontrol trajectory file"):
        Trajectory.load(tmp_path / "other.h5")


def test_recorder_refuses_unknown_signals_and_bad_record_every():
    offered = ("gap", "energy", "impulse")
    Recorder(2, signals=["gap"], offered=offered)          # known names pass
    with pytest.raises(ModelError, match=r"^signals: unknown name\(s\) \['gpa'\]; this "
                                         r"integrator records \['energy', 'gap', 'impulse'\]"):
        Recorder(2, signals=["gap", "gpa"], offered=offered)
    with pytest.raises(ModelError, match=r"^signals: expected a sequence of signal names, got "
                                         r"the string 'gap'"):
        Recorder(2, signals="gap", offered=offered)
    for every in (0, -1, 2.5, "3", True, None):
        with pytest.raises(ModelError, match=r"^record_every: expected an integer >= 1"):
            Recorder(2, every=every)
    assert Recorder(2, every=3.0).every == 3                # an integral float is an integer
    # backward compatible positional/keyword use by the integrators
    rec = Recorder(1, every=2, signals=None)
    rec.sample(0.0, [1.0], y=1.0)
    assert rec.finish().signals["y"].shape == (1,)


def test_recorder_without_offered_refuses_a_signal_never_recorded():
    rec = Recorder(1, signals=["y", "yy"])
    for k in range(3):
        rec.sample(float(k), [k], y=2.0 * k, z=1.0)
    with pytest.raises(ModelError, match=r"^signals: requested signal\(s\) \['yy'\] were never "
                                         r"recorded by test; it recorded \['y'\]") as err:
        rec.finish(method="test")
    assert isinstance(err.value.trajectory, Trajectory)   # the run is not lost
    np.testing.assert_array_equal(err.value.trajectory.signals["y"], [0.0, 2.0, 4.0])


def test_docstrings_of_views():
    assert Trajectory.n_states.__doc__ and Recorder.last_time.__doc__
    rec = Recorder(2)
    assert rec.last_time == -np.inf
    rec.sample(0.5, [0.0, 1.0])
    assert rec.last_time == 0.5 and rec.finish().n_states == 2


def test_an_interrupt_while_the_buffers_grow_leaves_the_recorder_whole(monkeypatch):
    """A KeyboardInterrupt that lands while the recorder copies its buffers (between the
    time and the state buffers) must leave them as they were: the partial trajectory is
    then recorded from consistent buffers (it used to fail with a broadcast error)."""
    from nscontrol.simulate import trajectory as tr

    rec = tr.Recorder(2, signals=["u"], offered=("u",), capacity=4)
    rec.extend(np.arange(4.0), np.ones((4, 2)), u=np.zeros((4, 1)))
    calls, resize = [], np.resize

    def interrupted(a, shape):
        calls.append(shape)
        if len(calls) == 2:        # the time buffer is copied, the state buffer is not
            raise KeyboardInterrupt
        return resize(a, shape)

    monkeypatch.setattr(tr.np, "resize", interrupted)
    with pytest.raises(KeyboardInterrupt):
        rec.extend(np.arange(4.0, 8.0), np.ones((4, 2)), u=np.zeros((4, 1)))
    monkeypatch.setattr(tr.np, "resize", resize)
    rec.extend(np.arange(4.0, 8.0), 2 * np.ones((4, 2)), u=np.ones((4, 1)))
    traj = rec.finish()
    np.testing.assert_array_equal(traj.t, np.arange(8.0))
    np.testing.assert_array_equal(traj.x[4:], 2 * np.ones((4, 2)))
    np.testing.assert_array_equal(traj.signal("u")[:, 0], [0, 0, 0, 0, 1, 1, 1, 1])


def _plot_traj():
    t = np.linspace(0.0, 1.0, 11)
    x = np.column_stack([t, 2 * t, -t, 1 - t, t**2])
    return Trajectory(t=t, x=x, state_names=("q1", "q2", "v1", "v2", "xhat_0"))


@pytest.mark.parametrize("subplots, panels", [("shared", [5]), ("groups", [2, 2, 1]),
                                              ("each", [1, 1, 1, 1, 1])])
def test_plot_panels(subplots, panels):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = _plot_traj().plot(subplots=subplots, signals=())
    assert [len(a.get_lines()) for a in fig.axes] == panels
    plt.close(fig)


def test_plot_keeps_the_time_label_inside_a_saved_figure(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = _plot_traj().plot()    # one panel: the case that lost its label before
    fig.savefig(tmp_path / "p.png")   # draws: the layout is computed
    box = fig.axes[-1].xaxis.label.get_window_extent()
    width, height = fig.canvas.get_width_height()
    assert box.y0 >= 0 and box.y1 <= height and box.x0 >= 0 and box.x1 <= width
    plt.close(fig)


def test_plot_refuses_an_unknown_layout():
    with pytest.raises(ModelError, match="subplots"):
        _plot_traj().plot(subplots="grid")

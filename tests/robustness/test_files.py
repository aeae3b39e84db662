"""Class 2: trajectories and their files — nothing accepted silently, nothing lost.

Sample times must be finite and non-decreasing; a save is atomic (a failed save leaves the
previous file byte for byte); every dataset carries a Fletcher-32 checksum, so flipped bytes
raise ``ModelError`` instead of loading wrong numbers; an unreadable file (text, empty,
truncated, missing a group or dataset) raises ``ModelError`` naming what is wrong. Every
comparison here is exact: a lossless round trip returns the same bits.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.simulate.trajectory import Event, Trajectory


def sample_trajectory(n: int = 200) -> Trajectory:
    t = np.linspace(0.0, 1.0, n)
    t = np.insert(t, n // 2, t[n // 2])          # an event time appears twice (pre/post)
    x = np.column_stack([np.sin(7 * t), np.cos(3 * t)])
    ev = Event(time=float(t[n // 2]), kind="impact", index=0, pre=x[n // 2], post=-x[n // 2])
    return Trajectory(t=t, x=x, signals={"gap": x[:, :1] + 1.0}, events=(ev,),
                      stats={"steps": n, "note": "ok"}, method="test")


def assert_model_error(call, *words: str) -> str:
    with pytest.raises(ModelError) as info:
        call()
    msg = str(info.value)
    for w in words:
        assert w in msg, msg
    return msg


# ----------------------------------------------------------------------------- construction


@pytest.mark.parametrize("t", [[1.0, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, -1e-300],
                               [0.0, 2.0, 1.0, 3.0]])
def test_decreasing_times_refused(t):
    msg = assert_model_error(lambda: Trajectory(t=t, x=np.zeros((len(t), 1))), "t:",
                             "non-decreasing")
    assert "sort" in msg


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_times_refused(bad):
    assert_model_error(lambda: Trajectory(t=[0.0, bad], x=np.zeros((2, 1))), "t:", "finite")


def test_repeated_event_time_allowed():
    traj = Trajectory(t=[0.0, 1.0, 1.0, 2.0], x=np.zeros((4, 1)))
    assert len(traj) == 4


# ----------------------------------------------------------------------------- atomic save


def test_round_trip_is_lossless(tmp_path):
    traj = sample_trajectory()
    traj.save(tmp_path / "a.h5")
    back = Trajectory.load(tmp_path / "a.h5")
    assert np.array_equal(back.t, traj.t) and np.array_equal(back.x, traj.x)
    assert np.array_equal(back.signal("gap"), traj.signal("gap"))
    assert back.stats == traj.stats and back.events[0].kind == "impact"
    with h5py.File(tmp_path / "a.h5") as f:
        assert f["x"].fletcher32 and f["t"].fletcher32 and f["signals/gap"].fletcher32
        assert all(f[f"stats/{k}"].fletcher32 for k in f["stats"])


@pytest.mark.parametrize("bad_stat", [object(), {"lock": object()}, [1, print]])
def test_failed_save_leaves_previous_file(tmp_path, bad_stat):
    path = tmp_path / "run.h5"
    sample_trajectory().save(path)
    before = path.read_bytes()
    bad = Trajectory(t=[0.0, 1.0], x=np.zeros((2, 1)), stats={"bad": bad_stat})
    assert_model_error(lambda: bad.save(path), "stats['bad']")
    assert path.read_bytes() == before                      # not truncated, not replaced
    assert sorted(os.listdir(tmp_path)) == ["run.h5"]       # no temporary file left behind
    assert np.array_equal(Trajectory.load(path).x, sample_trajectory().x)


@pytest.mark.parametrize("name", ["a/b", "/x", "", ".", "u/"])
def test_signal_name_with_slash_refused_at_save(tmp_path, name):
    path = tmp_path / "run.h5"
    sample_trajectory().save(path)
    before = path.read_bytes()
    traj = Trajectory(t=[0.0, 1.0], x=np.zeros((2, 1)), signals={name: np.ones(2)})
    assert_model_error(lambda: traj.save(path), "signals:", repr(name), "rename")
    assert path.read_bytes() == before


def test_interrupted_save_leaves_previous_file(tmp_path, monkeypatch):
    """A KeyboardInterrupt in the middle of writing: the old file and only it remains."""
    path = tmp_path / "run.h5"
    sample_trajectory().save(path)
    before = path.read_bytes()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    import importlib

    module = importlib.import_module("nscontrol.simulate.trajectory")
    monkeypatch.setattr(module, "_save_stat", interrupted)
    with pytest.raises(KeyboardInterrupt):
        sample_trajectory().save(path)
    assert path.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["run.h5"]


# ----------------------------------------------------------------------------- checksums


def flip_bytes_in(path: Path, dataset: str, count: int = 1) -> None:
    """Flip ``count`` bytes in the middle of ``dataset``'s stored data (its first chunk)."""
    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info(0)
        offset, size = info.byte_offset, info.size
    with open(path, "r+b") as fh:
        for k in range(count):
            fh.seek(offset + size // 2 + k)
            byte = fh.read(1)[0]
            fh.seek(offset + size // 2 + k)
            fh.write(bytes([byte ^ 0xFF]))


@pytest.mark.parametrize(("dataset", "count"), [("x", 1), ("x", 8), ("t", 1),
                                                ("signals/gap", 3), ("events/pre", 1),
                                                ("stats/1", 1)])
def test_flipped_bytes_fail_to_load(tmp_path, dataset, count):
    path = tmp_path / "run.h5"
    sample_trajectory().save(path)
    flip_bytes_in(path, dataset, count)
    assert_model_error(lambda: Trajectory.load(path), f"'{dataset}'", "checksum", "corrupt")


# ----------------------------------------------------------------------------- bad files


def test_text_file(tmp_path):
    path = tmp_path / "run.h5"
    path.write_text("t,x\n0,1\n")
    assert_model_error(lambda: Trajectory.load(path), "path:", "not an HDF5 file",
                       "Trajectory.save")


def test_empty_file(tmp_path):
    path = tmp_path / "run.h5"
    path.touch()
    assert_model_error(lambda: Trajectory.load(path), "path:", "empty")


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.9])
def test_truncated_file(tmp_path, fraction):
    path = tmp_path / "run.h5"
    sample_trajectory().save(path)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    assert_model_error(lambda: Trajectory.load(path), "path:")


@pytest.mark.parametrize("member", ["events", "signals", "stats", "x", "t", "events/pre"])
def test_file_missing_a_group_or_dataset(tmp_path, member):
    path = tmp_path / "run.h5"
    sample_trajectory().save(path)
    with h5py.File(path, "a") as f:
        del f[member]
    assert_model_error(lambda: Trajectory.load(path), "path:", "missing", "Trajectory.save")


def test_hdf5_file_of_another_kind(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.arange(3)
    assert_model_error(lambda: Trajectory.load(path), "path:", "format")


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="path: no trajectory file"):
        Trajectory.load(tmp_path / "nope.h5")


def test_recorder_puts_a_late_forced_sample_in_time_order():
    """An integrator that finds a root after sampling its piece (the switching method's
    grazings) records it late; the finished trajectory is in time order, signals with it."""
    from nscontrol.simulate.trajectory import Recorder

    rec = Recorder(1)
    for tk in (0.0, 1.0, 1.0, 2.0):
        rec.sample(tk, [tk], gap=[10 * tk])
    rec.sample(0.5, [0.5], force=True, gap=[5.0])
    traj = rec.finish()
    assert traj.t.tolist() == [0.0, 0.5, 1.0, 1.0, 2.0]
    assert traj.x[:, 0].tolist() == traj.t.tolist()
    assert traj.signal("gap")[:, 0].tolist() == [0.0, 5.0, 10.0, 10.0, 20.0]


def test_save_into_missing_folder_or_onto_a_folder(tmp_path):
    traj = sample_trajectory()
    with pytest.raises(FileNotFoundError, match="path: folder .* does not exist"):
        traj.save(tmp_path / "missing" / "run.h5")
    with pytest.raises(IsADirectoryError, match="is a folder"):
        traj.save(tmp_path)
    assert os.listdir(tmp_path) == []

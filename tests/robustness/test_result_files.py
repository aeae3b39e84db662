"""Class 2, every result type: ``Trajectory``, ``Branch`` and ``BifurcationDiagram`` files
share one mechanism (``nscontrol._files``) and so the same guarantees.

- Every non-empty dataset carries a Fletcher-32 checksum: one byte flipped anywhere in a
  dataset's stored bytes (its chunks, the stored sums included) makes ``load`` raise
  ``ModelError`` naming that dataset. Fletcher-32 sums 16-bit words modulo 65535; flipping
  one byte changes one word by (255 - 2b)·256^j, odd times a unit modulo 65535, never 0, so
  every single-byte flip is detected: the tests require all of them.
- ``load`` raises ``FileNotFoundError`` for a missing path and ``ModelError`` for a text,
  empty, truncated or incomplete file and for another format.
- A save that fails on a full disk (simulated by ``RLIMIT_FSIZE``, which makes writes fail
  with ``EFBIG`` like ``ENOSPC``) raises ``OSError``, leaves the previous file byte for byte
  and no temporary file, and the process goes on and exits normally (HDF5 used to die at
  exit or at the next close with SIGSEGV/SIGBUS).
- A save killed between writing its temporary file and renaming it leaves an orphan; the
  next save to the same target removes it (and only orphans of dead processes of this host).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

import nscontrol
from nscontrol.analysis.bifurcation import BifurcationDiagram
from nscontrol.analysis.continuation import Branch, SpecialPoint
from nscontrol.errors import ModelError
from nscontrol.simulate.trajectory import Event, Trajectory

#: Where this process imports nscontrol from: the children import the same code.
SRC = Path(nscontrol.__file__).resolve().parents[1]


def sample_trajectory(n: int = 200) -> Trajectory:
    t = np.linspace(0.0, 1.0, n)
    x = np.column_stack([np.sin(7 * t), np.cos(3 * t)])
    ev = Event(time=0.5, kind="impact", index=0, pre=x[n // 2], post=-x[n // 2])
    return Trajectory(t=t, x=x, signals={"gap": x[:, :1] + 1.0}, events=(ev,),
                      stats={"steps": n, "note": "ok"}, method="test")


def sample_branch(n: int = 60) -> Branch:
    p = np.linspace(1.0, 2.0, n)
    nodes = np.stack([np.column_stack([np.sin(p), np.cos(p), p]),
                      np.column_stack([np.cos(p), p, np.sin(p)])], axis=1)   # (n, 2, 3)
    mult = np.column_stack([np.exp(1j * p), 0.5 * np.exp(-1j * p), 0.1 * p + 0j])
    flip = SpecialPoint("flip", 1.5, n // 2, nodes[n // 2], mult[n // 2], 1e-7)
    return Branch("F", p, nodes, 2 * np.pi / p, mult, p > 1.5, np.full(n, 1), (flip,),
                  "p_range end", n_steps=n, corrector_iterations=3 * n,
                  state_names=("q", "v", "s"))


def sample_diagram(n: int = 40) -> BifurcationDiagram:
    values = np.linspace(0.3, 2.0, n)
    points = np.stack([np.sin(np.outer(values, np.arange(1, 25))).reshape(n, 12, 2),
                       np.cos(np.outer(values, np.arange(1, 25))).reshape(n, 12, 2)])
    points[1, 3] = np.nan
    mult = np.vstack([np.full(n, 1), np.arange(n) % 3])
    mult[1, 3] = -1
    return BifurcationDiagram("forcing", values, ("up", "down"), points, mult,
                              (("down", 3, "no orbit here: ModelError"),), 4, ("q", "v"))


KINDS: dict[str, tuple[Callable[[], object], Callable[[Path], object]]] = {
    "trajectory": (sample_trajectory, Trajectory.load),
    "branch": (sample_branch, Branch.load),
    "diagram": (sample_diagram, BifurcationDiagram.load),
}


def saved(kind: str, path: Path) -> Path:
    KINDS[kind][0]().save(path)  # type: ignore[attr-defined]
    return path


def load(kind: str, path: Path) -> object:
    return KINDS[kind][1](path)


def assert_model_error(call, *words: str) -> str:
    with pytest.raises(ModelError) as info:
        call()
    msg = str(info.value)
    for w in words:
        assert w in msg, msg
    return msg


def datasets(path: Path) -> list[str]:
    """Every dataset of the file that holds data."""
    names: list[str] = []
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: names.append(name)
                     if isinstance(obj, h5py.Dataset) and obj.size else None)
    return names


def stored_bytes(path: Path, name: str) -> list[tuple[int, int]]:
    """``(offset, size)`` in the file of each stored piece of dataset ``name``: its chunks
    (checksum included) or, for contiguous storage, the one block."""
    with h5py.File(path, "r") as f:
        ds = f[name]
        if ds.chunks is None:
            return [(ds.id.get_offset(), ds.id.get_storage_size())]
        infos = [ds.id.get_chunk_info(i) for i in range(ds.id.get_num_chunks())]
        return [(info.byte_offset, info.size) for info in infos]


def flip(path: Path, offset: int) -> None:
    with open(path, "r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)[0]
        fh.seek(offset)
        fh.write(bytes([byte ^ 0xFF]))


# ----------------------------------------------------------------------------- round trip


@pytest.mark.parametrize("kind", KINDS)
def test_every_dataset_is_checksummed_and_round_trips(tmp_path, kind):
    path = saved(kind, tmp_path / "a.h5")
    with h5py.File(path, "r") as f:
        for name in datasets(path):
            assert f[name].fletcher32, name
    back, orig = load(kind, path), KINDS[kind][0]()
    if kind == "trajectory":
        assert np.array_equal(back.x, orig.x) and back.stats == orig.stats
    elif kind == "branch":
        for key in ("p", "nodes", "period", "multipliers", "stable", "n_impacts"):
            assert np.array_equal(getattr(back, key), getattr(orig, key)), key
        assert back.points[0].kind == "flip" and back.state_names == orig.state_names
        assert np.array_equal(back.points[0].multipliers, orig.points[0].multipliers)
    else:
        assert np.array_equal(back.points, orig.points, equal_nan=True)
        assert back.errors == orig.errors and back.directions == orig.directions
    assert sorted(os.listdir(tmp_path)) == ["a.h5"]


# ----------------------------------------------------------------------------- checksums


@pytest.mark.parametrize("kind", KINDS)
def test_every_flipped_byte_in_every_dataset_is_detected(tmp_path, kind):
    """One byte flipped at a time, at both ends and 8 places between of every stored piece
    of every dataset; the file is restored between flips (a flip twice is the identity)."""
    path = saved(kind, tmp_path / "a.h5")
    silent, tried = [], 0
    for name in datasets(path):
        for offset, size in stored_bytes(path, name):
            for at in sorted({offset + int(k) for k in np.linspace(0, size - 1, 10)}):
                flip(path, at)
                tried += 1
                try:
                    load(kind, path)
                except ModelError as exc:
                    assert f"'{name}'" in str(exc) and "checksum" in str(exc), str(exc)
                else:
                    silent.append((name, at))
                flip(path, at)
    assert not silent, f"{len(silent)} of {tried} flips loaded silently: {silent[:5]}"
    assert tried >= 4 * len(datasets(path))           # the smallest piece: 8 bytes + 4 of sum
    load(kind, path)                                   # restored: loads again


# ----------------------------------------------------------------------------- bad files


@pytest.mark.parametrize("kind", KINDS)
def test_missing_file_is_file_not_found(tmp_path, kind):
    with pytest.raises(FileNotFoundError, match="^path: no .* file at"):
        load(kind, tmp_path / "nope.h5")


@pytest.mark.parametrize("kind", KINDS)
def test_text_and_empty_files(tmp_path, kind):
    path = tmp_path / "run.h5"
    path.write_text("p,x\n0,1\n")
    assert_model_error(lambda: load(kind, path), "path:", "not an HDF5 file", ".save")
    path.write_bytes(b"")
    assert_model_error(lambda: load(kind, path), "path:", "empty")


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("fraction", [0.05, 0.3, 0.6, 0.95])
def test_truncated_file(tmp_path, kind, fraction):
    path = saved(kind, tmp_path / "run.h5")
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    assert_model_error(lambda: load(kind, path), "path:")


MEMBERS = {
    "trajectory": ["t", "x", "signals", "events/pre", "stats"],
    "branch": ["p", "nodes", "period", "multipliers", "stable", "n_impacts", "points",
               "points/0", "points/0/nodes", "points/0/multipliers"],
    "diagram": ["values", "points", "multiplicity", "error_direction", "error_index",
                "error_message"],
}


@pytest.mark.parametrize(("kind", "member"),
                         [(k, m) for k, members in MEMBERS.items() for m in members])
def test_file_missing_a_group_or_dataset(tmp_path, kind, member):
    path = saved(kind, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        del f[member]
    assert_model_error(lambda: load(kind, path), "path:", "missing", ".save")


ATTRIBUTES = {
    "trajectory": [("/", "status"), ("/", "state_names"), ("stats/0", "key")],
    "branch": [("/", "parameter_name"), ("/", "stop_reason"), ("/", "n_steps"),
               ("/", "state_names"), ("points/0", "kind"), ("points/0", "uncertainty")],
    "diagram": [("/", "parameter_name"), ("/", "directions"), ("/", "chunk_size")],
}


@pytest.mark.parametrize(("kind", "owner", "attribute"),
                         [(k, o, a) for k, attrs in ATTRIBUTES.items() for o, a in attrs])
def test_file_missing_an_attribute(tmp_path, kind, owner, attribute):
    path = saved(kind, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        del f[owner].attrs[attribute]
    assert_model_error(lambda: load(kind, path), "path:", f"attribute {attribute!r}",
                       "missing")


@pytest.mark.parametrize("kind", KINDS)
def test_hdf5_file_of_another_kind(tmp_path, kind):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.arange(3)
    assert_model_error(lambda: load(kind, path), "path:", "format")
    other = next(k for k in KINDS if k != kind)       # another result type's file
    saved(other, path)
    assert_model_error(lambda: load(kind, path), "path:", "format", ".save")


def test_error_table_of_unequal_lengths(tmp_path):
    path = saved("diagram", tmp_path / "bd.h5")
    with h5py.File(path, "a") as f:
        del f["error_index"]
        f["error_index"] = np.array([3, 4])
    assert_model_error(lambda: load("diagram", path), "path:", "error table", "malformed")


# ----------------------------------------------------------------------------- save paths


@pytest.mark.parametrize("kind", KINDS)
def test_save_into_missing_folder_or_onto_a_folder(tmp_path, kind):
    obj = KINDS[kind][0]()
    with pytest.raises(FileNotFoundError, match="path: folder .* does not exist"):
        obj.save(tmp_path / "missing" / "run.h5")  # type: ignore[attr-defined]
    with pytest.raises(IsADirectoryError, match="is a folder"):
        obj.save(tmp_path)  # type: ignore[attr-defined]
    assert os.listdir(tmp_path) == []


def run_child(code: str, folder: Path, timeout: float = 300.0
              ) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter, ``folder`` its last argument."""
    env = dict(os.environ, PYTHONPATH=str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), str(folder)],
                          capture_output=True, text=True, timeout=timeout, env=env)


FILE_LIMIT = 256 * 1024     # bytes: above each small sample file, far below each big one

CHILD_FULL_DISK = f"""
    import errno, resource, signal, sys
    from pathlib import Path
    import numpy as np
    from nscontrol.analysis.bifurcation import BifurcationDiagram
    from nscontrol.analysis.continuation import Branch
    from nscontrol.simulate.trajectory import Trajectory

    folder = Path(sys.argv[-1])
    n = 100_000                                   # 2.4 MB of states: over the limit
    p = np.linspace(1.0, 2.0, n)
    big = {{
        "trajectory.h5": Trajectory(t=p, x=np.column_stack([p, p, p])),
        "branch.h5": Branch("F", p, np.stack([np.column_stack([p, p, p])], axis=1), p,
                            np.column_stack([p, p, p]) + 0j, p > 1.5, np.ones(n, int), (),
                            "end"),
        "diagram.h5": BifurcationDiagram("F", p[:1000], ("up",),
                                         np.random.default_rng(0).random((1, 1000, 200, 2)),
                                         np.ones((1, 1000), int), (), 1),
    }}
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # writes past the limit fail with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, ({FILE_LIMIT}, {FILE_LIMIT}))
    for attempt in range(2):
        for name, result in big.items():
            try:
                result.save(folder / name)
            except OSError as exc:
                assert exc.errno == errno.EFBIG, exc
                assert any("unchanged" in note for note in exc.__notes__), exc.__notes__
                print("failed", name, flush=True)
            else:
                print("saved", name, flush=True)
    print("done", flush=True)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX file size limits")
def test_failed_save_on_a_full_disk_leaves_the_process_and_the_file_whole(tmp_path):
    """Two failed saves of each result type, then a normal exit (it died with SIGSEGV)."""
    before = {}
    for name, kind in (("trajectory.h5", "trajectory"), ("branch.h5", "branch"),
                       ("diagram.h5", "diagram")):
        before[name] = saved(kind, tmp_path / name).read_bytes()
        assert len(before[name]) < FILE_LIMIT
    res = run_child(CHILD_FULL_DISK, tmp_path)
    assert res.returncode == 0, (res.returncode, res.stdout, res.stderr[-3000:])
    assert res.stdout.split("\n").count("done") == 1
    assert res.stdout.count("failed") == 6 and "saved" not in res.stdout, res.stdout
    for name, data in before.items():
        assert (tmp_path / name).read_bytes() == data, name
    assert sorted(os.listdir(tmp_path)) == sorted(before)          # no temporary file


CHILD_KILLED_BEFORE_RENAME = """
    import os, signal, sys
    from pathlib import Path
    import numpy as np
    from nscontrol.simulate.trajectory import Trajectory

    def killed(*args):                 # SIGKILL with the temporary file written, not renamed
        os.kill(os.getpid(), signal.SIGKILL)

    os.replace = killed
    Trajectory(t=np.arange(3.0), x=np.zeros((3, 1))).save(Path(sys.argv[-1]) / "run.h5")
"""

CHILD_KILLED_MID_WRITE = """
    import resource, signal, sys
    from pathlib import Path
    import numpy as np
    from nscontrol.simulate.trajectory import Trajectory

    big = Trajectory(t=np.arange(100_000.0), x=np.zeros((100_000, 3)))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    # past the limit the kernel sends SIGXFSZ, whose default action (Python ignores it)
    # ends the process at once: a save killed in the middle of writing a 3.2 MB file
    signal.signal(signal.SIGXFSZ, signal.SIG_DFL)
    resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))
    big.save(Path(sys.argv[-1]) / "run.h5")
"""


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX signals")
@pytest.mark.parametrize(("child", "sig"), [(CHILD_KILLED_BEFORE_RENAME, "SIGKILL"),
                                            (CHILD_KILLED_MID_WRITE, "SIGXFSZ")])
def test_killed_save_leaves_an_orphan_the_next_save_removes(tmp_path, child, sig):
    target = tmp_path / "run.h5"
    saved("trajectory", target)
    before = target.read_bytes()
    res = run_child(child, tmp_path)
    assert res.returncode == -getattr(signal, sig), (res.returncode, res.stderr[-2000:])
    assert target.read_bytes() == before
    orphans = [n for n in os.listdir(tmp_path) if n != "run.h5"]
    assert len(orphans) == 1 and orphans[0].startswith(".run.h5.")
    assert orphans[0].endswith(".tmp"), orphans
    # the orphans of other targets, other hosts and live processes stay
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        host = orphans[0].split(".")[3]
        dead = 999_999_999                      # above any pid_max (2**22): no such process
        keep = [f".other.h5.{host}.{dead}.0123abcd.tmp",        # another target
                f".run.h5.another-host.{dead}.0123abcd.tmp",    # another machine
                f".run.h5.{host}.{live.pid}.0123abcd.tmp"]      # a save under way
        for name in keep:
            (tmp_path / name).write_bytes(b"partial")
        saved("branch", target)                 # any result type: the same mechanism
        assert sorted(os.listdir(tmp_path)) == sorted(["run.h5", *keep])
        assert load("branch", target).parameter_name == "F"
    finally:
        live.kill()
        live.wait()
    # the live process has ended: its orphan goes with the next save
    saved("trajectory", target)
    assert sorted(os.listdir(tmp_path)) == sorted(["run.h5", *keep[:2]])

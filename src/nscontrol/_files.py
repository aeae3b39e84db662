"""Files that keep their data, and the one HDF5 mechanism of every result type.

A write goes to a temporary file beside the target and replaces it only once complete, so a
failed write never destroys the previous file (:func:`replaced_atomically`). The temporary
file is named after its target, host and process (``.NAME.HOST.PID.TOKEN.tmp``), so that
the orphan of a save killed mid-way (``SIGKILL``, a power cut) is recognised and removed by
the next save to the same target once its process is gone.

The result types (``Trajectory``, ``Branch``, ``BifurcationDiagram``) save and load through
:func:`save_hdf5` and :func:`load_hdf5`:

- every non-empty dataset carries a Fletcher-32 checksum (:func:`put`), so flipped bytes
  make ``load`` raise ``ModelError`` naming the dataset, never return wrong numbers;
- the file is built in memory (HDF5's ``core`` driver, no backing store) and its bytes are
  written by Python into the temporary file. HDF5 itself never writes to disk: when HDF5
  2.0 meets a failed write (a full disk, a quota, ``RLIMIT_FSIZE``) while closing a dataset,
  h5py's ``__dealloc__`` swallows the error and the dataset stays in HDF5's identifier table
  half torn down; the next flush of any file, or the library's shutdown at exit, walks it
  (``H5D__flush_all_cb``) and the process dies with SIGSEGV or SIGBUS. A failed Python
  ``write`` is an ``OSError`` with nothing left open;
- ``load`` raises ``FileNotFoundError`` for a missing path and ``ModelError`` saying what is
  wrong for a text file, an empty or truncated one, a missing group, dataset or attribute,
  another format, or a failed checksum (:class:`Reader`).
"""

from __future__ import annotations

import itertools
import os
import re
import secrets
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from .errors import DimensionError, ModelError

__all__ = ["replaced_atomically", "remove_orphans", "save_hdf5", "load_hdf5", "put", "Reader",
           "CHUNK_BYTES", "HDF5_SIGNATURE"]

T = TypeVar("T")

#: Target size of a checksummed chunk (bytes). h5py's automatic chunks are tens of KB (more
#: chunk lookups); checking the sums costs little: 200000 x 6 states load in ~0.022 s,
#: ~0.006 s unchecked.
CHUNK_BYTES = 1 << 20

#: First bytes of every HDF5 file (its superblock signature).
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"

_TMP_SUFFIX = ".tmp"


def _host() -> str:
    """This machine's name, reduced to letters, digits and ``-`` (a temporary file's name
    must parse back: the name may hold dots, the pid and token follow dots)."""
    return re.sub(r"[^A-Za-z0-9-]", "", socket.gethostname()) or "host"


def _orphan_pattern(target: Path) -> re.Pattern[str]:
    """Names of the temporary files of ``target`` (the host part is absent in files written
    before it was added: they are taken as this host's)."""
    return re.compile(rf"^\.{re.escape(target.name)}\.(?:(?P<host>[A-Za-z0-9-]+)\.)?"
                      rf"(?P<pid>\d+)\.[0-9a-f]{{8}}{re.escape(_TMP_SUFFIX)}$")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` of this machine exists (a reused pid counts as alive: the
    orphan is then kept, and removed by a later save)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True                    # another user's process, or no such pid to signal
    return True


def remove_orphans(target: Path) -> list[Path]:
    """Remove the temporary files of ``target`` left by saves whose process died on this
    machine (killed mid-way); files of live processes and of other hosts are kept. Returns
    the removed paths."""
    if os.name != "posix":             # os.kill(pid, 0) does not probe elsewhere
        return []
    pattern, host, removed = _orphan_pattern(target), _host(), []
    try:
        names = os.listdir(target.parent)
    except OSError:
        return []
    for name in names:
        match = pattern.match(name)
        if match is None or match["host"] not in (None, host):
            continue
        pid = int(match["pid"])
        if pid == os.getpid() or _alive(pid):
            continue
        orphan = target.with_name(name)
        try:
            orphan.unlink()
        except FileNotFoundError:      # another save removed it first
            continue
        removed.append(orphan)
    return removed


@contextmanager
def replaced_atomically(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a fresh temporary path in ``path``'s folder; on success it is flushed to disk
    (``fsync``) and replaces ``path`` (``os.replace``, atomic on one file system), on any
    exception it is removed. Orphans of earlier saves to ``path`` whose process died are
    removed first.

    Parameters
    ----------
    path : str or path-like
        The file to write.
    """
    path = Path(path)
    remove_orphans(path)
    # a fresh name, not a created file: writers may open it exclusively
    tmp = path.with_name(f".{path.name}.{_host()}.{os.getpid()}.{secrets.token_hex(4)}"
                         f"{_TMP_SUFFIX}")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)               # the bytes on disk before the name points at them
        finally:
            os.close(fd)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


_in_memory = itertools.count()


def save_hdf5(path: str | os.PathLike[str], write: Callable[[Any], None]) -> Path:
    """Write an HDF5 file atomically: ``write(f)`` fills an in-memory ``h5py.File`` ``f``,
    whose bytes then replace ``path`` (:func:`replaced_atomically`).

    Parameters
    ----------
    path : str or path-like
        The file to write; its folder must exist.
    write : callable
        Fills the open file (datasets through :func:`put`); any exception it raises leaves
        ``path`` untouched.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    FileNotFoundError
        The folder of ``path`` does not exist.
    IsADirectoryError
        ``path`` is a folder.
    OSError
        Writing the bytes failed (a full disk, a quota): nothing is left open, the previous
        file is unchanged and no temporary file remains.
    """
    import h5py

    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"path: folder {str(path.parent)!r} does not exist; create "
                                "it first (e.g. Path(...).mkdir(parents=True))")
    if path.is_dir():
        raise IsADirectoryError(f"path: {str(path)!r} is a folder; pass a file name")
    # in memory: HDF5 never meets a failed disk write (see the module docstring); the name
    # only has to differ from every other open in-memory file
    f = h5py.File(f"nscontrol-in-memory-{os.getpid()}-{next(_in_memory)}", "w",
                  driver="core", backing_store=False)
    try:
        write(f)
        f.flush()
        image = f.id.get_file_image()
    finally:
        f.close()
    try:
        with replaced_atomically(path) as tmp, open(tmp, "xb") as fh:
            fh.write(image)
    except OSError as exc:
        exc.add_note(f"nscontrol: {str(path)!r} was not written ({len(image)} bytes); the "
                     "previous file, if any, is unchanged; free space or choose another "
                     "folder and save again")
        raise
    return path


def put(group: Any, name: str, data: Any, **options: Any) -> Any:
    """Create dataset ``name`` of ``group`` holding ``data``, with a Fletcher-32 checksum.

    The checksum needs chunked storage; chunks are whole rows of about :data:`CHUNK_BYTES`.
    An empty or scalar array, with nothing to corrupt, is stored plainly.

    Parameters
    ----------
    group : h5py.Group
        Where the dataset goes.
    name : str
        Its name.
    data : array_like
        Its values.
    **options
        Passed on to ``create_dataset`` (e.g. ``compression="gzip"``; the checksum is then
        taken over the compressed bytes).

    Returns
    -------
    h5py.Dataset
        The new dataset.
    """
    data = np.asarray(data)
    if data.ndim == 0 or data.size == 0:
        return group.create_dataset(name, data=data)
    row_bytes = max(1, data.itemsize * int(np.prod(data.shape[1:])))
    rows = int(min(data.shape[0], max(1, CHUNK_BYTES // row_bytes)))
    return group.create_dataset(name, data=data, fletcher32=True,
                                chunks=(rows,) + data.shape[1:], **options)


def _unreadable_reason(path: Path) -> str:
    """Why h5py could not open ``path``: empty, not HDF5, or truncated/damaged HDF5."""
    with open(path, "rb") as fh:
        head = fh.read(len(HDF5_SIGNATURE))
    if not head:
        return "is empty (0 bytes): the save did not complete"
    if head != HDF5_SIGNATURE:
        return "is not an HDF5 file (a text or other file)"
    return "is a truncated or damaged HDF5 file"


class Reader:
    """Reads groups, datasets and attributes of an open result file; :meth:`run` turns h5py's
    errors into ``ModelError`` that name the member and say what is wrong.

    Parameters
    ----------
    file : h5py.File
        The open file.
    path : Path
        Its path (for the messages).
    what : str
        What the file holds (``"trajectory"``, ``"branch"``...).
    writer : str
        The method that writes such files (``"Trajectory.save"``...).
    """

    def __init__(self, file: Any, path: Path, what: str, writer: str) -> None:
        self.file, self.path, self.what, self.writer = file, path, what, writer
        self.where = "the file"

    def group(self, name: str) -> Any:
        """The group ``name``."""
        self.where = f"group {name!r}"
        return self.file[name]

    def data(self, name: str) -> np.ndarray:
        """The values of dataset ``name`` (its checksum verified)."""
        self.where = f"dataset {name!r}"
        return self.file[name][()]

    def attr(self, name: str, of: str = "/", default: Any = ...) -> Any:
        """Attribute ``name`` of the object ``of`` (the file by default); ``default``, when
        given, stands for a missing one."""
        self.where = f"attribute {name!r}" + ("" if of == "/" else f" of {of!r}")
        attrs = self.file[of].attrs
        if default is not ... and name not in attrs:
            return default
        return attrs[name]

    def run(self, body: Callable[[], T]) -> T:
        """``body()``, with h5py's and decoding errors turned into ``ModelError``."""
        where = lambda: f"path: {self.where} of {str(self.path)!r}"   # noqa: E731
        try:
            return body()
        except KeyError as exc:
            raise ModelError(f"{where()} is missing ({exc.args[0] if exc.args else exc}): the "
                             f"file is incomplete or not written by {self.writer}") from None
        except OSError as exc:
            text = str(exc)
            if "filter" in text or "checksum" in text.lower():
                raise ModelError(f"{where()} fails its Fletcher-32 checksum: the file is "
                                 "corrupted (flipped bytes); restore it from a copy or "
                                 "compute it again") from None
            raise ModelError(f"{where()} cannot be read ({text}): the file is truncated or "
                             "damaged; restore it from a copy or compute it again") from None
        except (ValueError, TypeError, IndexError, UnicodeDecodeError) as exc:
            if isinstance(exc, ModelError | DimensionError):
                raise ModelError(f"path: {str(self.path)!r} holds an invalid {self.what}: "
                                 f"{exc}") from None
            raise ModelError(f"{where()} is malformed ({type(exc).__name__}: {exc}): the file "
                             f"was not written by {self.writer} or is damaged") from None


def load_hdf5(path: str | os.PathLike[str], read: Callable[[Reader, str], T], *,
              formats: tuple[str, ...], what: str, writer: str) -> T:
    """Open a result file, check its ``format`` attribute and return ``read(reader, format)``
    with every error of the reading turned into ``ModelError`` (:meth:`Reader.run`).

    Parameters
    ----------
    path : str or path-like
        The file.
    read : callable
        Builds the result from a :class:`Reader` and the file's format string.
    formats : tuple of str
        The formats ``read`` understands, the current one first.
    what : str
        What the file holds, for the messages (``"trajectory"``).
    writer : str
        The method that writes such files, for the messages (``"Trajectory.save"``).

    Returns
    -------
    object
        What ``read`` returns.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ModelError
        Not an HDF5 file (a text file), empty, truncated, of another format, missing a
        group, dataset or attribute, or failing a checksum; the message says which.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no {what} file at {str(path)!r}")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ModelError(f"path: {str(path)!r} {_unreadable_reason(path)} (h5py: {exc}); "
                         f"load a file written by {writer}") from None
    with f:
        reader = Reader(f, path, what, writer)
        fmt = reader.run(lambda: f.attrs.get("format"))
        if isinstance(fmt, bytes):
            fmt = fmt.decode(errors="replace")
        if fmt not in formats:
            raise ModelError(f"path: expected an nscontrol {what} file (format "
                             f"{formats[0]!r}), got {str(path)!r} with format {fmt!r}; load "
                             f"a file written by {writer}")
        return reader.run(lambda: read(reader, fmt))

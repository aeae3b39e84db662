"""Files that keep their data: a write goes to a temporary file beside the target and
replaces it only once complete, so a failed write never destroys the previous file."""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["replaced_atomically"]


@contextmanager
def replaced_atomically(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a fresh temporary path in ``path``'s folder; on success it replaces ``path``
    (``os.replace``, atomic on one file system), on any exception it is removed.

    Parameters
    ----------
    path : str or path-like
        The file to write.
    """
    path = Path(path)
    # a fresh name, not a created file: writers may open it exclusively
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)

"""Keep numba's on-disk cache of the compiled kernels consistent with their sources.

numba stamps a cached kernel with the content of the file that defines it, and only that
file. A kernel that calls a kernel of another module compiles the callee into its own machine
code, so after the callee's module changes (an edit, a ``pip install --upgrade`` that leaves
``__pycache__`` behind) numba would load the caller's old code: the library would silently
run yesterday's arithmetic. :func:`refresh` closes that gap. For every kernel module it hashes
the sources of the kernel modules it imports, directly or through others, writes that digest
beside numba's index (``__pycache__/<module>.nscontrol-deps``) and, when the digest changed
(or was never written), deletes the module's cached kernels so numba compiles them again.

It runs once per process, on ``import nscontrol``: it reads the kernel modules' sources (a few
hundred kB, about a millisecond) and imports nothing. The cache folders are numba's own: the
module's ``__pycache__``, or the folder under ``NUMBA_CACHE_DIR`` that numba derives from the
module's directory. A folder that cannot be written is left alone (numba then caches
elsewhere, or not at all).
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Iterable
from pathlib import Path

__all__ = ["KERNEL_GLOBS", "kernel_modules", "reached_kernels", "dependency_digests", "refresh"]

#: The compiled-kernel modules (numba, ``cache=True``), relative to the package folder: in a
#: subpackage (``simulate/_block_kernels.py``) or in a method's folder inside one
#: (``simulate/implicit_euler/_lure_kernels.py``).
KERNEL_GLOBS = ("*/_*_kernels.py", "*/_*_kernel.py", "*/*/_*_kernels.py", "*/*/_*_kernel.py")

#: The stamp written beside numba's index of each kernel module.
STAMP_SUFFIX = ".nscontrol-deps"

# ``from ._x_kernels import f`` / ``from ..numerics._x_kernels import f`` /
# ``from . import _x_kernels as k``: the relative imports of another kernel module
_FROM_MODULE = re.compile(r"^[ \t]*from[ \t]+(\.+)([\w.]*)[ \t]+import[ \t]+([^\n#]+)",
                          re.MULTILINE)


def kernel_modules(root: Path) -> list[Path]:
    """The kernel modules under the package folder ``root``, sorted."""
    return sorted({p for pattern in KERNEL_GLOBS for p in root.glob(pattern)})


def _imported_kernels(module: Path, source: str, known: set[Path]) -> set[Path]:
    """The kernel modules that ``module`` imports (relative imports only: the package's)."""
    found: set[Path] = set()
    for dots, dotted, names in _FROM_MODULE.findall(source):
        if "kernel" not in dotted + names:
            continue
        base = module.parent
        for _ in range(len(dots) - 1):
            base = base.parent
        parts = [p for p in dotted.split(".") if p]
        candidates = [base.joinpath(*parts).with_suffix(".py")] if parts else []
        # ``from . import _x_kernels``: the names are modules
        candidates += [base.joinpath(*parts, name.split()[0].strip("(), ") + ".py")
                       for name in names.split(",") if name.strip("(), ")]
        found.update(c for c in candidates if c in known)
    found.discard(module)
    return found


def reached_kernels(modules: Iterable[Path]) -> dict[Path, set[Path]]:
    """For each kernel module, the kernel modules it reaches through its imports, directly
    or through others (itself excluded). ``modules`` are paths under one resolved root."""
    paths = list(modules)
    known = set(paths)
    direct = {p: _imported_kernels(p, p.read_text(encoding="utf-8", errors="replace"), known)
              for p in paths}
    reached = {}
    for p in paths:
        seen: set[Path] = set()
        todo = list(direct[p])
        while todo:                      # the transitive closure (cycles are harmless)
            q = todo.pop()
            if q not in seen and q != p:
                seen.add(q)
                todo.extend(direct[q])
        reached[p] = seen
    return reached


def dependency_digests(modules: Iterable[Path]) -> dict[Path, str]:
    """For each kernel module, a digest of the sources of every kernel module it reaches
    (:func:`reached_kernels`; itself excluded: numba stamps its own file)."""
    reached = reached_kernels(modules)
    sources = {p: p.read_bytes() for p in reached}
    digests = {}
    for p, seen in reached.items():
        h = hashlib.sha256()
        for q in sorted(seen):
            h.update(str(q.name).encode() + b"\0" + sources[q] + b"\0")
        digests[p] = h.hexdigest()
    return digests


def cache_folder(module: Path) -> Path:
    """Where numba caches the kernels of ``module`` (its ``__pycache__``, or the folder it
    derives under ``NUMBA_CACHE_DIR``)."""
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    if not cache_dir:
        return module.parent / "__pycache__"
    folder = str(module.resolve().parent)
    hashed = hashlib.sha1(folder.encode()).hexdigest()
    return Path(cache_dir) / f"{os.path.basename(folder)}_{hashed}"


def refresh(root: Path | None = None) -> list[str]:
    """Delete the cached kernels of every module whose imported kernels changed since they
    were cached; returns the modules whose caches were deleted (``package.module`` names).

    Parameters
    ----------
    root : Path, optional
        The package folder (default: this package's).
    """
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return []
    root = Path(__file__).resolve().parent if root is None else root.resolve()
    cleared = []
    try:
        digests = dependency_digests(kernel_modules(root))
    except OSError:                      # pragma: no cover - an unreadable install
        return []
    for module, digest in digests.items():
        folder = cache_folder(module)
        stamp = folder / (module.stem + STAMP_SUFFIX)
        try:
            if stamp.read_text() == digest:
                continue
        except OSError:
            pass                         # no stamp yet: the cache (if any) is of unknown age
        try:
            stale = [*folder.glob(f"{module.stem}.*.nbi"), *folder.glob(f"{module.stem}.*.nbc")]
            for path in stale:
                path.unlink(missing_ok=True)
            if stale:
                cleared.append(f"{module.parent.name}.{module.stem}")
            folder.mkdir(parents=True, exist_ok=True)    # numba's own folder, made ahead
            _write_atomically(stamp, digest)
        except OSError:                  # a read-only install: numba caches elsewhere
            continue
    return cleared


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)

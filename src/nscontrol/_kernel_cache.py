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
hundred kB, about a millisecond) and imports nothing. A folder that cannot be written is left
alone (numba then caches elsewhere, or not at all).

Where the kernels are cached
----------------------------
numba keys its cache folder by the source file's *path* (the module's ``__pycache__``, or a
folder under ``NUMBA_CACHE_DIR`` derived from the module's directory), so a new virtual
environment or a reinstall elsewhere compiled every kernel again (minutes). :func:`install`
registers with numba a locator of our own (:class:`UserCacheLocator`) for the kernel modules:
they are cached in a per-user folder (:func:`user_cache_root`: ``$NSCONTROL_CACHE_DIR``, else
``$XDG_CACHE_HOME/nscontrol/numba``, else ``~/.cache/nscontrol/numba``) under a name made of
the numba version and a digest of the module's source *and* of every kernel module it reaches
(:func:`module_digests`). Any environment with the same sources and numba finds the same
folder; a changed callee changes its callers' folders, so a stale caller can never be loaded
from there (the guarantee :func:`refresh` gives the path-keyed folders). numba itself keys each
entry by the CPU and the Python version. An explicit ``NUMBA_CACHE_DIR`` is honoured (numba's
own locator comes first); an unwritable per-user folder falls back to numba's locators.

Old folders
-----------
Every edit of a kernel module (and every numba upgrade) starts new folders; the old ones are
pruned (:func:`prune`, at most once a day, on ``import nscontrol``). A folder's time is its
last use: the locator touches the folder of each kernel module a process imports. A folder not
in use by this process is deleted when it has not been used for :data:`PRUNE_UNUSED_DAYS`
days, or, beyond the :data:`PRUNE_KEEP` most recently used versions of its module, for a day:
a process that may still read or write it (another environment with other sources) touches it
when it starts, so only folders no process has started with for a day go.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["KERNEL_GLOBS", "kernel_modules", "reached_kernels", "dependency_digests", "refresh",
           "cache_folder", "user_cache_root", "module_digests", "install", "prune"]

#: The package folder of nscontrol's kernel modules.
PACKAGE_ROOT = Path(__file__).resolve().parent

#: The compiled-kernel modules (numba, ``cache=True``), relative to the package folder, at any
#: depth (a method's package keeps its kernels inside: ``simulate/<method>/_x_kernels.py``).
KERNEL_GLOBS = ("**/_*_kernels.py", "**/_*_kernel.py")

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


def user_cache_root() -> Path | None:
    """The per-user folder of the compiled kernels: ``$NSCONTROL_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/nscontrol/numba``, else ``~/.cache/nscontrol/numba``; None when
    ``NSCONTROL_CACHE_DIR`` is set empty (numba's own folders are then used)."""
    explicit = os.environ.get("NSCONTROL_CACHE_DIR")
    if explicit is not None:
        return Path(explicit).expanduser() if explicit else None
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "nscontrol" / "numba"


@functools.lru_cache(maxsize=8)
def module_digests(root: Path) -> dict[Path, str]:
    """For each kernel module under the package folder ``root`` (resolved), a digest of its
    own source and of every kernel module it reaches: the name of its per-user cache folder
    (computed once per process; the sources do not change under a running process)."""
    deps = dependency_digests(kernel_modules(root))
    return {p: hashlib.sha256(p.read_bytes() + b"\0" + d.encode()).hexdigest()[:20]
            for p, d in deps.items()}


@functools.lru_cache(maxsize=1)
def _numba_version() -> str:
    """numba's version, read without importing it (an import costs about a second)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("numba")
    except PackageNotFoundError:     # pragma: no cover - numba is a dependency
        return "unknown"


#: Package folders whose kernel modules go to the per-user cache (:func:`install`).
_ROOTS: set[Path] = set()


def _user_folder(module: Path) -> Path | None:
    """The per-user cache folder of ``module`` (a resolved path), or None when it is not a
    kernel module of an installed root or there is no per-user folder."""
    base = user_cache_root()
    if base is None:
        return None
    for root in _ROOTS:
        if module.is_relative_to(root):
            digest = module_digests(root).get(module)
            if digest is None:
                return None
            return base / f"numba-{_numba_version()}" / f"{module.stem}-{digest}"
    return None


def cache_folder(module: Path) -> Path:
    """Where numba caches the kernels of ``module``: the folder under ``NUMBA_CACHE_DIR`` it
    derives, else the per-user folder (:func:`install`), else the module's ``__pycache__``."""
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    if not cache_dir:
        user = _user_folder(module.resolve()) if _ROOTS else None
        return module.parent / "__pycache__" if user is None else user
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
                cleared.append(".".join(module.relative_to(root).with_suffix("").parts))
            folder.mkdir(parents=True, exist_ok=True)    # numba's own folder, made ahead
            _write_atomically(stamp, digest)
        except OSError:                  # a read-only install: numba caches elsewhere
            continue
    return cleared


#: A per-user folder unused for this many days is deleted (:func:`prune`).
PRUNE_UNUSED_DAYS = 30.0
#: Of one kernel module's folders, the most recently used this many stay up to
#: :data:`PRUNE_UNUSED_DAYS`; the older ones go once a day has passed without use.
PRUNE_KEEP = 3
#: The file whose time says when the per-user cache was last pruned.
PRUNE_STAMP = ".nscontrol-pruned"
_DAY = 86400.0
_VERSION_FOLDER = re.compile(r"^numba-[\w.+-]+$")
_MODULE_FOLDER = re.compile(r"^(?P<stem>_\w+)-[0-9a-f]{20}$")
_touched: set[Path] = set()


def _touch(folder: Path) -> None:
    """Mark ``folder`` as used now (once per process): :func:`prune` keeps what is used."""
    if folder not in _touched:
        _touched.add(folder)
        try:
            os.utime(folder)
        except OSError:
            pass


def prune(root: Path | None = None, *, now: float | None = None,
          in_use: Iterable[Path] = ()) -> list[Path]:
    """Delete the per-user cache folders no process has used for a while; returns them.

    A folder ``<root>/numba-<version>/<module>-<digest>`` (nothing else is ever touched) is
    deleted when it is not in ``in_use`` (nor touched by this process) and was last used
    more than :data:`PRUNE_UNUSED_DAYS` days ago, or more than a day ago while
    :data:`PRUNE_KEEP` folders of the same module (any numba version) were used after it.
    Emptied ``numba-<version>`` folders go too. A folder that cannot be deleted is left.

    Parameters
    ----------
    root : Path, optional
        The per-user cache root (default :func:`user_cache_root`; None there: nothing to do).
    now : float, optional
        The present, in seconds since the epoch (default: the clock).
    in_use : iterable of Path
        Folders to keep whatever their age.
    """
    root = user_cache_root() if root is None else root
    if root is None or not root.is_dir():
        return []
    now = time.time() if now is None else now
    keep = {p.resolve() for p in [*in_use, *_touched]}
    by_module: dict[str, list[tuple[float, Path]]] = {}
    for version in root.iterdir():
        if not (_VERSION_FOLDER.match(version.name) and version.is_dir()):
            continue
        for folder in version.iterdir():
            match = _MODULE_FOLDER.match(folder.name)
            if match and folder.is_dir() and not folder.is_symlink():
                used = folder.stat().st_mtime
                by_module.setdefault(match["stem"], []).append((used, folder))
    deleted = []
    for folders in by_module.values():
        folders.sort(reverse=True)                    # most recently used first
        for rank, (used, folder) in enumerate(folders):
            idle_days = (now - used) / _DAY
            stale = idle_days > PRUNE_UNUSED_DAYS or (rank >= PRUNE_KEEP and idle_days > 1.0)
            if stale and folder.resolve() not in keep:
                shutil.rmtree(folder, ignore_errors=True)
                if not folder.exists():
                    deleted.append(folder)
    for version in {f.parent for f in deleted}:
        try:
            version.rmdir()                           # only when emptied
        except OSError:
            pass
    return deleted


def _prune_daily() -> None:
    """:func:`prune` the per-user cache if it was not pruned in the last day (one stat)."""
    root = user_cache_root()
    if root is None:
        return
    stamp = root / PRUNE_STAMP
    try:
        if time.time() - stamp.stat().st_mtime < _DAY:
            return
    except OSError:
        pass                                          # never pruned (or no cache yet)
    try:
        if not root.is_dir():
            return
        stamp.touch()
        in_use = [f for f in (_user_folder(m) for r in _ROOTS for m in module_digests(r))
                  if f is not None]
        prune(root, in_use=in_use)
    except OSError:                                   # a read-only cache: nothing to prune
        pass


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _locator_class() -> Any:
    """numba's locator base, subclassed (imported only once numba is)."""
    from numba.core import caching

    class UserCacheLocator(caching._CacheLocator):
        """numba cache locator of the kernel modules: the per-user folder keyed by the
        sources (see the module docstring). numba stamps the index with
        :meth:`get_source_stamp` (the same digest: a file's time is never looked at)."""

        def __init__(self, py_func: Any, folder: Path, digest: str) -> None:
            self._lineno = py_func.__code__.co_firstlineno
            self._folder, self._digest = folder, digest

        def get_cache_path(self) -> str:
            return str(self._folder)

        def get_source_stamp(self) -> str:
            return self._digest

        def get_disambiguator(self) -> str:
            return str(self._lineno)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if os.environ.get("NUMBA_CACHE_DIR"):  # explicit: numba's own locator
                return None
            try:
                module = Path(py_file).resolve()
                folder = _user_folder(module)
                if folder is None:
                    return None
                self = cls(py_func, folder, folder.name)
                self.ensure_cache_path()
                _touch(folder)            # used now: prune() keeps it
            except OSError:           # not writable: numba's next locator
                return None
            return self

    return UserCacheLocator


def _register_locator() -> None:
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # type: ignore[attr-defined]
    classes = impl._locator_classes
    if not any(c.__name__ == "UserCacheLocator" for c in classes):
        classes.insert(1, _locator_class())   # after numba's NUMBA_CACHE_DIR locator


def _install_compile_hook() -> None:
    from ._compile_background import install_hook

    install_hook()


#: What to do once a numba module has been imported: register the locator; route the
#: compile-on-first-call of our kernels through :mod:`nscontrol._compile_background`.
_AFTER_IMPORT = {"numba.core.caching": _register_locator,
                 "numba.core.dispatcher": _install_compile_hook}


class _AfterImport:
    """A finder that runs :data:`_AFTER_IMPORT`'s action once its numba module has been
    imported (``import nscontrol`` must not import numba: it costs a second)."""

    def find_spec(self, name: str, path: Any, target: Any = None) -> Any:
        action = _AFTER_IMPORT.get(name)
        if action is None:
            return None
        from importlib.machinery import PathFinder

        spec = PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return None
        loader = spec.loader
        exec_module = loader.exec_module

        def exec_then_act(module: Any) -> None:
            exec_module(module)
            if all(n in sys.modules for n in _AFTER_IMPORT):
                try:
                    sys.meta_path.remove(self)
                except ValueError:
                    pass
            action()

        loader.exec_module = exec_then_act  # type: ignore[method-assign]
        return spec


def install(root: Path | None = None) -> None:
    """Cache the kernel modules under the package folder ``root`` (default: nscontrol's)
    in the per-user folder (:func:`user_cache_root`), by content, and compile a first call's
    kernels in the background (:mod:`nscontrol._compile_background`). Registers both with
    numba now if numba is imported, else when it is."""
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return
    _ROOTS.add(PACKAGE_ROOT if root is None else root.resolve())
    _prune_daily()
    for name, action in _AFTER_IMPORT.items():
        if name in sys.modules:
            action()
    if not all(n in sys.modules for n in _AFTER_IMPORT) and \
            not any(isinstance(f, _AfterImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterImport())

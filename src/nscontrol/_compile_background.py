"""A first run that does not wait for numba: the kernels it needs compile in the background.

Compiling the kernels of one run takes 10-30 s of CPU (numba's typing and lowering, then
LLVM); the same run, interpreted, takes 1.2-1.5 s of CPU (the README's bouncing ball).
So when a kernel of nscontrol is called with argument types that are neither compiled in this
process nor in the on-disk cache, this module (mode ``"background"``, the default):

1. asks a detached helper process (``python -m nscontrol._warm``, one per process, fed on its
   stdin) to compile that specialisation into the cache, and
2. runs the SAME kernel's source as Python (``kernel.py_func``: one source, no twin) for this
   call. The kernels it calls are called as kernels: those compiled or cached run compiled,
   the others are interpreted too, without a look in the cache (and not requested: the
   caller's compile covers them).

Each later call of a pending specialisation looks in the cache again (at most every
:data:`RECHECK_S` seconds): as soon as the helper has written it, the run goes on compiled.
When the helper has exited and the cache still lacks it (an unwritable cache, a failed
compile), the call compiles in the foreground, as numba would: a run is never left
interpreted for good. Specialisations whose argument types cannot be sent to another process
(anything but arrays of numbers, numbers, booleans, strings, ``None`` and tuples of those)
compile in the foreground too, and so do kernels whose source cannot run as Python (they
name a numba intrinsic, or read structured records: :func:`_interpretable`).

Mode ``"wait"`` (``NSCONTROL_COMPILE=wait``; set by the command line, the test suite and the
benches) is numba's own behaviour: compile in the foreground, then run. With
``NUMBA_DISABLE_JIT=1`` nothing is compiled and this module does nothing. Which cache is
written (``NUMBA_CACHE_DIR``, the per-user folder of :mod:`nscontrol._kernel_cache`) is
decided by the same environment in the helper as here.

The library says what happens, once per process (:mod:`nscontrol._progress`): the first
specialisation requested prints the notice, and the progress bar counts the kernels this run
waits for.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import pickle
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["MODES", "mode", "install_hook", "requested", "helper_pid", "wait_for_exit",
           "cache_lock"]

#: The values of ``NSCONTROL_COMPILE``.
MODES = ("background", "wait")
#: Seconds between two looks in the cache for a specialisation being compiled.
RECHECK_S = 0.25

_lock = threading.RLock()
_local = threading.local()          # depth: how many interpreted kernels are on the stack
_pending: dict[tuple[int, tuple[Any, ...]], float] = {}   # (dispatcher, types) -> next look
_requested: list[str] = []          # "module.kernel" requested from the helper, in order
_helper: subprocess.Popen[bytes] | None = None
_original: Any = None


def mode() -> str:
    """``NSCONTROL_COMPILE`` (default ``"background"``).

    Raises
    ------
    ModelError
        A value that is not one of :data:`MODES`.
    """
    value = os.environ.get("NSCONTROL_COMPILE", "").strip().lower() or "background"
    if value not in MODES:
        from .errors import ModelError

        raise ModelError(f"NSCONTROL_COMPILE: expected one of {', '.join(MODES)}, got "
                         f"{value!r}; unset it for the default (background)")
    return value


def requested() -> list[str]:
    """The kernels (``module.kernel``) this process asked the helper to compile, in order."""
    with _lock:
        return list(_requested)


def helper_pid() -> int | None:
    """The helper process's id (None before the first request)."""
    return None if _helper is None else _helper.pid


def wait_for_exit(pid: int, timeout: float, poll: float = 0.2) -> bool:
    """Wait until another process's helper ``pid`` has exited (a zombie counts: its parent
    is gone); ``False`` if it still runs after ``timeout`` seconds. Linux only (reads
    ``/proc``), for the new-user trial and the cold-start bench."""
    stat = Path(f"/proc/{pid}/stat")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if stat.read_text().rsplit(")", 1)[1].split()[0] == "Z":
                return True
        except OSError:
            return True
        time.sleep(poll)
    return False


def install_hook() -> None:
    """Route numba's compile-on-first-call of nscontrol's cached kernels through
    :func:`_compile_for_args` (idempotent; needs ``numba.core.dispatcher`` imported)."""
    global _original
    from numba.core import dispatcher

    if _original is not None:
        return
    cls: Any = dispatcher.Dispatcher
    _original = cls._compile_for_args
    cls._compile_for_args = _compile_for_args
    from numba.core import event

    event.register("numba:compile", _compile_listener())


def _compile_listener() -> Any:
    """A numba event listener: the start of a compile of one of our kernels that no other
    compile encloses (its callees compile inside it) is announced (:mod:`nscontrol._progress`)."""
    from numba.core import event

    class Announce(event.Listener):
        depth = 0

        def on_start(self, ev: Any) -> None:
            Announce.depth += 1
            disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
            if Announce.depth == 1 and disp is not None and _ours(disp):
                from ._progress import compiling_now

                py = disp.py_func
                compiling_now(f"{py.__module__.removeprefix('nscontrol.')}.{py.__qualname__}")

        def on_end(self, ev: Any) -> None:
            Announce.depth -= 1

    return Announce()


def _ours(disp: Any) -> bool:
    """A kernel of the package, cached on disk (the helper can hand its code over)."""
    module = getattr(disp.py_func, "__module__", "") or ""
    return module.startswith("nscontrol.") and type(disp._cache).__name__ != "NullCache"


def _compile_for_args(self: Any, *args: Any, **kws: Any) -> Any:
    """numba's ``Dispatcher._compile_for_args`` (a call whose argument types have no compiled
    specialisation yet): load it from the cache, or run the kernel's source while the helper
    compiles it, or compile it here (a kernel whose source cannot run as Python:
    :func:`_interpretable`). Returns the callable numba then calls with ``args``."""
    depth = getattr(_local, "depth", 0)
    if kws or not _ours(self) or not _interpretable(self, args):
        return _original(self, *args, **kws)
    if depth:                       # called by an interpreted kernel: its compile covers it
        return _Interpreted(self.py_func)
    if mode() == "wait":
        return _original(self, *args)
    try:
        types = tuple(_arg_type(self, a) for a in args)
    except Exception:  # noqa: BLE001 - a value numba cannot type: numba says why
        return _original(self, *args, **kws)
    key = (id(self), types)
    now = time.monotonic()
    with _lock:
        due = _pending.get(key)
        if due is None or now >= due:
            if _load_cached(self, types):
                _pending.pop(key, None)
                return _original(self, *args)    # found in the cache: numba installs it
            if due is not None and _helper_finished():
                _pending.pop(key, None)          # the helper could not: compile it here
                return _original(self, *args)
            if due is None and (not _portable(types) or not _request(self, types)):
                return _original(self, *args)
            _pending[key] = now + RECHECK_S
    return _Interpreted(self.py_func)


_source_ok: dict[int, bool] = {}     # id(dispatcher) -> its source can run as Python


def _interpretable(disp: Any, args: tuple[Any, ...]) -> bool:
    """Whether the kernel's source runs as Python on these arguments: it names no numba
    intrinsic (compiled-only code, e.g. a first-class function table), takes no structured
    record or array of them and makes no view (the kernels read a parameter record with
    ``p.view(dtype)[0]`` and its fields as attributes, which numba allows and numpy does
    not). Conservative: a kernel refused here compiles in the foreground, as numba does."""
    import numpy as np

    for a in args:
        if isinstance(a, np.void) or (isinstance(a, np.ndarray) and a.dtype.fields is not None):
            return False
    key = id(disp)
    ok = _source_ok.get(key)
    if ok is None:
        ok = _source_ok[key] = not _compiled_only(disp.py_func.__code__,
                                                  disp.py_func.__globals__)
    return ok


def _compiled_only(code: Any, namespace: dict[str, Any]) -> bool:
    from numba.core.extending import _Intrinsic

    if "view" in code.co_names or any(isinstance(namespace.get(n), _Intrinsic)
                                      for n in code.co_names):
        return True
    return any(_compiled_only(c, namespace) for c in code.co_consts if hasattr(c, "co_names"))


class _Interpreted:
    """The kernel's source run as Python, arguments as numba passes them."""

    __slots__ = ("py_func",)

    def __init__(self, py_func: Any) -> None:
        self.py_func = py_func

    def __call__(self, *args: Any) -> Any:
        values = [a.value if type(a).__name__ == "OmittedArg" else a for a in args]
        _local.depth = getattr(_local, "depth", 0) + 1
        try:
            return self.py_func(*values)
        finally:
            _local.depth -= 1


def _arg_type(disp: Any, value: Any) -> Any:
    from numba.core import types
    from numba.core.dispatcher import OmittedArg

    return types.Omitted(value.value) if isinstance(value, OmittedArg) else \
        disp.typeof_pyval(value)


def _load_cached(disp: Any, argtypes: tuple[Any, ...]) -> bool:
    """Whether the specialisation is in the on-disk cache (numba's own load, without
    compiling: the first half of ``Dispatcher.compile``)."""
    from numba.core.compiler_lock import global_compiler_lock

    with global_compiler_lock:
        cres = disp._cache.load_overload(argtypes, disp.targetctx)
    return cres is not None


def _portable(argtypes: tuple[Any, ...]) -> bool:
    """Types the helper can rebuild from their pickle: arrays of numbers, numbers, booleans,
    strings, None and tuples of those."""
    from numba.core import types

    def ok(t: Any) -> bool:
        if isinstance(t, types.Array):
            return isinstance(t.dtype, (types.Number, types.Boolean))
        if isinstance(t, types.BaseTuple):
            return all(ok(s) for s in getattr(t, "types", ()))
        return isinstance(t, (types.Number, types.Boolean, types.NoneType, types.UnicodeType))

    return all(ok(t) for t in argtypes)


def _helper_finished() -> bool:
    return _helper is None or _helper.poll() is not None


def _request(disp: Any, argtypes: tuple[Any, ...]) -> bool:
    """Send one specialisation to the helper (started at the first request); False when it
    cannot be sent (then the caller compiles it in the foreground)."""
    global _helper
    py = disp.py_func
    line = json.dumps({"module": py.__module__, "kernel": py.__qualname__,
                       "types": base64.b64encode(pickle.dumps(argtypes)).decode()}) + "\n"
    for _ in range(2):                  # a helper that has exited is started again once
        if _helper is None or _helper.poll() is not None:
            _helper = _start_helper()
            if _helper is None:
                return False
        try:
            assert _helper.stdin is not None
            _helper.stdin.write(line.encode())
            _helper.stdin.flush()
        except (OSError, ValueError):
            _helper = None
            continue
        name = f"{py.__module__.removeprefix('nscontrol.')}.{py.__qualname__}"
        _requested.append(name)
        from ._progress import compiling_in_background

        compiling_in_background(name, len(_requested))
        return True
    return False


def _start_helper() -> subprocess.Popen[bytes] | None:
    """``python -m nscontrol._warm``, detached (a new session: it outlives this process and
    a Ctrl-C here), compiling what it reads on stdin; its messages go to a log beside the
    cache."""
    env = dict(os.environ, NSCONTROL_COMPILE="wait")
    src = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join([src, *filter(None, [env.get("PYTHONPATH")])])
    log = _log_path()
    try:
        err: Any = open(log, "ab") if log is not None else subprocess.DEVNULL  # noqa: SIM115
        try:
            return subprocess.Popen([sys.executable, "-m", "nscontrol._warm"], env=env,
                                    stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                    stderr=err, start_new_session=True, close_fds=True)
        finally:
            if err is not subprocess.DEVNULL:
                err.close()
    except OSError:
        return None


def lock_path() -> Path | None:
    """The file the helpers lock while compiling (one compiles at a time per cache): in
    ``NUMBA_CACHE_DIR``, else the per-user cache folder; None when there is neither."""
    from ._kernel_cache import user_cache_root

    explicit = os.environ.get("NUMBA_CACHE_DIR")
    root = Path(explicit) if explicit else user_cache_root()
    if root is None:
        return None
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return root / "nscontrol-compile.lock"


@contextlib.contextmanager
def cache_lock() -> Iterator[None]:
    """Hold the cache's lock (:func:`lock_path`; an exclusive ``flock``, released when the
    block ends or the process dies): the helper holds it while it compiles, and
    ``nscontrol warmup``'s processes while they write numba's cache index."""
    path = lock_path()
    if path is None:
        yield
        return
    import fcntl

    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _log_path() -> Path | None:
    lock = lock_path()
    return None if lock is None else lock.with_name("nscontrol-compile.log")

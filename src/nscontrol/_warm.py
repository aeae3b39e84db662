"""``python -m nscontrol._warm``: the helper process of :mod:`nscontrol._compile_background`.

Reads one JSON line per kernel specialisation on stdin (``module``, ``kernel``, ``types``: the
base64 pickle of numba's argument types), compiles each into numba's on-disk cache (the same
environment as the process that started it: the same cache folder) and checks that the cache
now holds it. Compiles one at a time per cache (an exclusive lock on
:func:`nscontrol._compile_background.lock_path`), so that several processes starting cold do
not compile the same kernels side by side. Stops at the end of its input (the process that
started it has exited or closed it); exits with status 3 at the first specialisation it could
not compile or cache, so that the requesting process compiles it itself.
"""

from __future__ import annotations

import base64
import importlib
import json
import os
import pickle
import sys
from typing import Any


def compile_one(request: dict[str, Any]) -> bool:
    """Compile one requested specialisation; whether the cache now holds it."""
    from numba.core.compiler_lock import global_compiler_lock

    from ._compile_background import cache_lock

    disp: Any = importlib.import_module(request["module"])
    for part in request["kernel"].split("."):
        disp = getattr(disp, part)
    argtypes = pickle.loads(base64.b64decode(request["types"]))
    with cache_lock():
        disp.compile(argtypes)
    with global_compiler_lock:
        return disp._cache.load_overload(argtypes, disp.targetctx) is not None


def main() -> int:
    """Compile what stdin asks for; 0 when all of it is cached, 3 at the first failure."""
    os.environ["NSCONTROL_COMPILE"] = "wait"
    import nscontrol  # noqa: F401 - the kernel cache's locator and refresh

    for line in sys.stdin:
        if not line.strip():
            continue
        request = json.loads(line)
        try:
            ok = compile_one(request)
        except Exception as exc:  # noqa: BLE001 - reported, then the requester compiles
            print(f"nscontrol._warm: {request.get('module')}.{request.get('kernel')}: {exc!r}",
                  file=sys.stderr, flush=True)
            return 3
        if not ok:
            print(f"nscontrol._warm: {request['module']}.{request['kernel']}: compiled but not "
                  f"in the cache (is it writable?)", file=sys.stderr, flush=True)
            return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())

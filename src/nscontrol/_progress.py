"""Progress bars on stderr that appear only for runs longer than a couple of seconds."""

from __future__ import annotations

import sys
import time
from typing import Any

from ._kernel_cache import KERNEL_GLOBS
from ._validation import check_bool

#: Seconds before an iterable's bar appears (shorter runs show none).
ITER_DELAY = 2.0


class TimeProgress:
    """A progress bar over simulated time ``[t0, tf]``, shown on stderr after ``delay`` seconds.

    ``enable=None`` shows it only when stderr is a terminal or the run is long; ``False`` never.
    Updates are cheap: call :meth:`update` as often as convenient. The bar itself (tqdm) is
    built at the first update after ``delay`` seconds of wall time, so a short run (most
    calls of a sweep) pays one clock reading per update and never imports or starts tqdm.
    """

    def __init__(self, t0: float, tf: float, *, desc: str = "simulate",
                 enable: bool | None = None, delay: float = 2.0) -> None:
        self.t0, self.tf = float(t0), float(tf)
        self._bar: Any = None
        self._desc = desc
        self._last = 0
        # wall time after which the bar appears; None: never
        self._due: float | None = None
        if check_bool("progress", enable, allow_none=True) is not False:
            self._start = time.perf_counter()
            self._due = self._start + delay

    def _open(self) -> None:
        from tqdm.auto import tqdm

        # the simulated time goes into the description: tqdm prefixes a postfix with ", "
        self._bar = tqdm(total=1000, desc=self._desc, file=sys.stderr, leave=False,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]")
        self._bar.start_t = self._start   # the elapsed time counts from the run's start
        self._due = None

    def update(self, t: float) -> None:
        """Advance the bar to simulated time ``t`` (cheap; redraws at most 1000 times)."""
        if self._bar is None:
            if self._due is None or time.perf_counter() < self._due:
                return
            self._open()
        k = int(1000 * (t - self.t0) / (self.tf - self.t0))
        if k > self._last:
            self._bar.set_description_str(f"{self._desc} t={t:.4g}", refresh=False)
            self._bar.update(min(k, 1000) - self._last)
            self._last = min(k, 1000)

    def close(self) -> None:
        """Remove the bar (idempotent)."""
        self._due = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> TimeProgress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def progress_iter(iterable: Any, *, total: int | None = None, desc: str = "",
                  enable: bool | None = None, label: Any = None) -> Any:
    """Wrap an iterable in a tqdm bar on stderr (shown after 2 s), or return it unchanged.

    The items may take very different times (an example, a benchmark), so the bar shows the
    count and the elapsed time but no ETA: an estimate from the fast items would freeze at
    "2 s left" during a slow one. ``label(item)`` names the item in progress.
    """
    if check_bool("progress", enable, allow_none=True) is False:
        return iterable
    from tqdm.auto import tqdm

    bar = tqdm(iterable, total=total, desc=desc, file=sys.stderr, delay=ITER_DELAY, leave=False,
               bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| {elapsed}")
    if label is None:
        return bar
    return _labelled(bar, desc, label)


def _labelled(bar: Any, desc: str, label: Any) -> Any:
    # the label goes into the description: tqdm would print a postfix after a stray ", "
    for item in bar:
        bar.set_description_str(f"{desc} (running {label(item)})", refresh=True)
        yield item



_announced = False


def uncompiled_kernel_modules() -> list[str]:
    """The kernel modules with no numba cache index yet (``[]`` once compiled).

    Looks at files only (nothing is imported): a module ``m.py`` is compiled when its
    ``__pycache__`` holds an ``m.*.nbi`` index, or when numba caches elsewhere
    (``NUMBA_CACHE_DIR``), which this check cannot see and so assumes done.
    """
    import os
    from pathlib import Path

    if os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("NUMBA_DISABLE_JIT"):
        return []
    root = Path(__file__).resolve().parent
    missing = []
    for pattern in KERNEL_GLOBS:
        for module in sorted(root.glob(pattern)):
            if not any((module.parent / "__pycache__").glob(f"{module.stem}.*.nbi")):
                missing.append(".".join(module.relative_to(root).with_suffix("").parts))
    return missing


def announce_compilation(stream: Any = None) -> bool:
    """Say once per process, on stderr, that the kernels are about to be compiled (first run
    of an install only). Returns whether the message was printed."""
    global _announced
    if _announced or not uncompiled_kernel_modules():
        return False
    _announced = True
    print("nscontrol: compiling the numerical kernels (numba) - this happens once per install "
          "and takes tens of seconds;\n           later runs load them from the cache "
          "(`nscontrol warmup` does it ahead).", file=stream or sys.stderr, flush=True)
    return True

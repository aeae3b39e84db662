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
        self._start = time.perf_counter()
        self._compiles = _compile_count()   # this run's compiles: those counted from here
        self._note = ""
        if check_bool("progress", enable, allow_none=True) is not False:
            self._due = self._start + delay
        _running.append(self)

    def compiling(self, note: str) -> None:
        """Say in the bar's text why it stands still or runs slow (``note``: what this run
        compiles), and show the bar now."""
        self._note = note
        if self._due is None and self._bar is None:
            return                          # progress=False, or closed
        if self._bar is None:
            self._open()
        self._bar.set_description_str(f"{self._desc} ({note})", refresh=True)

    def _open(self) -> None:
        if not _is_terminal(sys.stderr):
            self._bar = LineBar(total=1000, desc=self._desc, percent=True)
        else:
            from tqdm.auto import tqdm

            # the simulated time goes into the description: tqdm prefixes a postfix with ", "
            self._bar = tqdm(total=1000, desc=self._desc, file=sys.stderr, leave=False,
                             bar_format="{desc}: {percentage:3.0f}%|{bar}| "
                                        "[{elapsed}<{remaining}]")
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
            note = f" ({self._note})" if self._note else ""
            self._bar.set_description_str(f"{self._desc}{note} t={t:.4g}", refresh=False)
            self._bar.update(min(k, 1000) - self._last)
            self._last = min(k, 1000)

    def close(self) -> None:
        """Remove the bar (idempotent); after the first run that had kernels compiled in the
        background, say how many (once per process)."""
        self._due = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self in _running:
            _running.remove(self)
            _report_background(_compile_count() - self._compiles)

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
    if not _is_terminal(sys.stderr):
        bar: Any = LineBar(iterable, total=total, desc=desc, delay=ITER_DELAY)
    else:
        from tqdm.auto import tqdm

        bar = tqdm(iterable, total=total, desc=desc, file=sys.stderr, delay=ITER_DELAY,
                   leave=False, bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| {elapsed}")
    if label is None:
        return bar
    return _labelled(bar, desc, label)


def count_bar(total: int, *, desc: str, delay: float) -> Any:
    """A bar counting ``total`` items (``update(n)``, ``close()``): tqdm on a terminal, plain
    lines (:class:`LineBar`) in a log, shown after ``delay`` seconds."""
    if not _is_terminal(sys.stderr):
        return LineBar(total=total, desc=desc, delay=delay)
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, file=sys.stderr, leave=False, delay=delay)


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):   # no isatty, or a closed stream
        return False


class LineBar:
    """Progress as plain lines, for a stderr that is a file or a pipe (a CI log): tqdm's
    carriage returns and cursor moves (nested bars) would leave escape codes there. A line
    is written when the progress passes a tenth of the total, or 30 s after the last one.

    Parameters
    ----------
    iterable : iterable, optional
        Items to pass through (counted), as ``tqdm(iterable)``.
    total : int, optional
        The count at 100 %.
    desc : str
        The label.
    delay : float
        Seconds before the first line (shorter runs write none).
    percent : bool
        Write the progress as a percentage (of simulated time) instead of ``n/total``.
    """

    def __init__(self, iterable: Any = None, *, total: int | None = None, desc: str = "",
                 delay: float = 0.0, percent: bool = False) -> None:
        self.iterable, self.desc, self.percent = iterable, desc, percent
        self.total = total if total is not None or iterable is None else _length(iterable)
        self.n = 0
        self.start_t = time.perf_counter()
        self._quiet_until = self.start_t + delay
        self._last = (-1, self.start_t)   # (tenth, time) of the last line
        self._labelled = False            # a line per labelled item, none after it

    def __iter__(self) -> Any:
        for item in self.iterable:
            yield item
            if self._labelled:
                self.n += 1
            else:
                self.update(1)

    def set_description_str(self, desc: str, refresh: bool = False) -> None:
        """Change the label (``refresh=True`` writes a line now, if one is due)."""
        self.desc = desc
        if refresh:
            self._labelled = True
            self._write(force=True)

    def update(self, n: int = 1) -> None:
        """Advance the count by ``n``."""
        self.n += n
        self._write()

    def _write(self, force: bool = False) -> None:
        now = time.perf_counter()
        if now < self._quiet_until:
            return
        tenth = int(10 * self.n / self.total) if self.total else self.n
        if not force and tenth == self._last[0] and now - self._last[1] < 30.0:
            return
        self._last = (tenth, now)
        if self.percent and self.total:
            done = f"{100 * self.n / self.total:3.0f}%"
        else:
            done = f"{self.n}/{self.total}" if self.total else f"{self.n}"
        print(f"{self.desc}: {done} [{now - self.start_t:.0f} s]", file=sys.stderr,
              flush=True)

    def close(self) -> None:
        """Nothing to erase (a line stays in the log)."""


def _length(iterable: Any) -> int | None:
    try:
        return len(iterable)
    except TypeError:
        return None


def _labelled(bar: Any, desc: str, label: Any) -> Any:
    # the label goes into the description: tqdm would print a postfix after a stray ", "
    for item in bar:
        bar.set_description_str(f"{desc} (running {label(item)})", refresh=True)
        yield item



_announced = False
#: The time-progress bars open (innermost last): the one a compile notice goes to.
_running: list[TimeProgress] = []
#: Kernels compiled in the foreground by this process (top-level compiles, in order).
_compiled_here: list[str] = []
_reported_background = False


def _compile_count() -> int:
    from . import _compile_background

    return len(_compiled_here) + len(_compile_background.requested())


def compiling_in_background(name: str, count: int) -> None:
    """Called when kernel ``name`` (``module.kernel``) is sent to the background compiler,
    the ``count``-th of this process: says so once per process on stderr, and in the
    running bar's text."""
    global _announced
    if not _announced:
        _announced = True
        print(f"nscontrol: kernel {name} is not compiled yet: compiling it (and any other this "
              f"run needs) in the background, once per install (numba, typically 10-30 s of "
              f"CPU);\n           this run uses the interpreted path meanwhile (the same "
              f"code, slower) and switches to the compiled kernels as they become ready. "
              f"NSCONTROL_COMPILE=wait compiles in the foreground instead.",
              file=sys.stderr, flush=True)
    if _running:
        verb = "compiles" if count == 1 else "compile"
        _running[-1].compiling(f"interpreted while {_kernels(count)} {verb} in the "
                               f"background")


def compiling_now(name: str) -> None:
    """Called when kernel ``name`` starts compiling in the foreground (``NSCONTROL_COMPILE=
    wait``, or a kernel whose arguments the background compiler cannot take): says so once
    per process on stderr, and in the running bar's text with this process's count."""
    global _announced
    _compiled_here.append(name)
    if not _announced:
        _announced = True
        print(f"nscontrol: compiling kernel {name} (numba; typically 10-30 s for the kernels "
              f"a run needs, once per install; later runs load them from the cache).",
              file=sys.stderr, flush=True)
    if _running:
        _running[-1].compiling(f"compiling kernels, first run only: {len(_compiled_here)} "
                               f"so far, now {name}")


def _kernels(n: int) -> str:
    return "1 kernel" if n == 1 else f"{n} kernels"


def _report_background(n_run: int) -> None:
    """At the end of the first run that sent kernels to the background compiler: how many."""
    global _reported_background
    from . import _compile_background

    sent = len(_compile_background.requested())
    if _reported_background or not sent or n_run <= 0:
        return
    _reported_background = True
    print(f"nscontrol: this run needed {_kernels(n_run)} not yet compiled; the background "
          f"compiler (pid {_compile_background.helper_pid()}) writes them to the cache, "
          f"later runs use them compiled.", file=sys.stderr, flush=True)


def uncompiled_kernel_modules() -> list[str]:
    """The kernel modules with no numba cache index yet (``[]`` once compiled).

    Looks at files only (nothing is imported): a module ``m.py`` is compiled when numba's
    cache folder for it (its ``__pycache__``, or the folder numba derives under
    ``NUMBA_CACHE_DIR``) holds an ``m.*.nbi`` index.
    """
    import os
    from pathlib import Path

    from ._kernel_cache import cache_folder

    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return []
    root = Path(__file__).resolve().parent
    missing = []
    for pattern in KERNEL_GLOBS:
        for module in sorted(root.glob(pattern)):
            if not any(cache_folder(module).glob(f"{module.stem}.*.nbi")):
                missing.append(".".join(module.relative_to(root).with_suffix("").parts))
    return missing


def announce_compilation(stream: Any = None) -> bool:
    """Say once per process, on stderr, that the kernels are about to be compiled (first run
    of an install only). Returns whether the message was printed."""
    global _announced
    if _announced:
        return False
    missing = uncompiled_kernel_modules()
    if not missing:
        return False
    _announced = True
    print(f"nscontrol: compiling numerical kernels (numba; {len(missing)} modules not yet in "
          f"the cache) - a run compiles those it uses, typically 10-30 s, once per install;\n"
          f"           later runs load them from the cache (`nscontrol warmup` compiles all "
          f"ahead, 2-4 min on two cores).", file=stream or sys.stderr, flush=True)
    return True

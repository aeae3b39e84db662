"""Progress bars on stderr that appear only for runs longer than a couple of seconds."""

from __future__ import annotations

import sys
from typing import Any


class TimeProgress:
    """A progress bar over simulated time ``[t0, tf]``, shown on stderr after ``delay`` seconds.

    ``enable=None`` shows it only when stderr is a terminal or the run is long; ``False`` never.
    Updates are cheap: call :meth:`update` as often as convenient.
    """

    def __init__(self, t0: float, tf: float, *, desc: str = "simulate",
                 enable: bool | None = None, delay: float = 2.0) -> None:
        self.t0, self.tf = float(t0), float(tf)
        self._bar: Any = None
        if enable is False:
            return
        from tqdm.auto import tqdm

        # the simulated time goes into the description: tqdm prefixes a postfix with ", "
        self._desc = desc
        self._bar = tqdm(total=1000, desc=desc, file=sys.stderr, delay=delay, leave=False,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]")
        self._last = 0

    def update(self, t: float) -> None:
        """Advance the bar to simulated time ``t`` (cheap; redraws at most 1000 times)."""
        if self._bar is None:
            return
        k = int(1000 * (t - self.t0) / (self.tf - self.t0))
        if k > self._last:
            self._bar.set_description_str(f"{self._desc} t={t:.4g}", refresh=False)
            self._bar.update(min(k, 1000) - self._last)
            self._last = min(k, 1000)

    def close(self) -> None:
        """Remove the bar (idempotent)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> TimeProgress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def progress_iter(iterable: Any, *, total: int | None = None, desc: str = "",
                  enable: bool | None = None) -> Any:
    """Wrap an iterable in a tqdm bar on stderr (shown after 2 s), or return it unchanged."""
    if enable is False:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, total=total, desc=desc, file=sys.stderr, delay=2.0, leave=False)

"""Shared timing and Siconos-driving helpers for the benchmarks in this folder.

Each ``bench_<name>.py`` defines ``run(quick: bool) -> Iterator[dict]`` yielding one record per
scenario with at least: ``scenario``, ``size``, ``ours_steps_per_s`` (or
``ours_s_per_solve``), ``reference``, ``reference_steps_per_s`` (or
``reference_s_per_solve``), ``ratio`` (our speed / reference speed, > 1 = faster) and
``accuracy`` (figures showing both sides computed the same thing).

``reference`` is ``None`` (with the reference speed and ``ratio``) when no reference ran for a
scenario; ``note`` then says why (Siconos not installed, or no counterpart of that solver).
``nscontrol bench`` prints such a line as ``ref[none]=— (reason)``. Records may hold numpy
scalars: the command converts them to plain JSON numbers before printing, so stdout carries
one clean JSON object per line and progress bars go to stderr.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

SICONOS_PYTHON = "/usr/bin/python3"
SICONOS_DIR = Path(__file__).resolve().parent / "siconos"


def time_per_call(fn: Callable[[], Any], *, budget: float = 0.5, min_calls: int = 3,
                  max_calls: int = 100_000) -> float:
    """Median-of-batches seconds per call of ``fn`` within about ``budget`` seconds."""
    fn()  # warm-up (compilation, caches)
    start = time.perf_counter()
    fn()
    once = max(time.perf_counter() - start, 1e-9)
    per_batch = max(1, min(max_calls, int(budget / 5 / once)))
    samples = []
    deadline = time.perf_counter() + budget
    while len(samples) < min_calls or time.perf_counter() < deadline:
        t0 = time.perf_counter()
        for _ in range(per_batch):
            fn()
        samples.append((time.perf_counter() - t0) / per_batch)
        if len(samples) >= 50:
            break
    samples.sort()
    return samples[len(samples) // 2]


def siconos_available() -> tuple[bool, str]:
    """Whether Debian's python3-siconos imports under /usr/bin/python3 (and why not)."""
    if shutil.which(SICONOS_PYTHON) is None:
        return False, f"{SICONOS_PYTHON} not found"
    proc = subprocess.run([SICONOS_PYTHON, "-c", "import siconos.kernel, siconos.numerics"],
                          capture_output=True, text=True, timeout=60)
    if proc.returncode != 0:
        lines = proc.stderr.strip().splitlines()
        return False, ("python3-siconos not importable by /usr/bin/python3 (install: apt-get "
                       "install -y python3-siconos python3-scipy)"
                       + (f": {lines[-1]}" if lines else ""))
    return True, ""


def run_siconos(script: str, payload: dict[str, Any], *, timeout: float = 300
                ) -> list[dict[str, Any]]:
    """Run ``bench/siconos/<script>`` under /usr/bin/python3 with ``payload`` as JSON on stdin.

    Returns the JSON lines it printed (Siconos prints solver warnings on stdout too: lines that
    are not JSON objects are dropped). Raises RuntimeError with its stderr when it fails.
    """
    proc = subprocess.run([SICONOS_PYTHON, str(SICONOS_DIR / script)],
                          input=json.dumps(payload), capture_output=True, text=True,
                          timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"siconos script {script} failed:\n{proc.stderr[-2000:]}")
    records = []
    for line in proc.stdout.splitlines():
        line = line.strip()
        if line.startswith("{"):
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return records


def siconos_version() -> str:
    return "siconos-4.4"


@contextmanager
def dask_client(workers: int = 2) -> Iterator[Any]:
    """A ``Client`` of a fresh ``LocalCluster`` of ``workers`` worker processes, one thread
    each, their stack profiler off (it samples every 10 ms, about 15 % of these Python-heavy
    tasks; see ``docs/sweep.md``); ``None`` when ``dask.distributed`` is not installed."""
    try:
        from dask import config as dask_config
        from distributed import Client, LocalCluster
    except ImportError:
        yield None
        return
    with dask_config.set({"distributed.worker.profile.enabled": False}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                         dashboard_address=None) as cluster, Client(cluster) as client:
        yield client


def warm_workers(client: Any, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
    """Run ``fn(*args, **kwargs)`` once on every worker of ``client`` (imports, compiled
    kernels loaded from the cache), so that no timed task pays a worker's first call."""
    workers = list(client.scheduler_info()["workers"])
    client.gather([client.submit(fn, *args, workers=[w], pure=False,
                                 allow_other_workers=False, **kwargs) for w in workers])


def efficiency(serial: float, parallel: float, workers: int = 2) -> float:
    """Parallel efficiency ``serial / (workers × parallel)`` (1: the workers never wait)."""
    return serial / (workers * parallel)

"""numba's cache is stamped with a kernel's own file only: a kernel whose imported kernel
changed must be recompiled, not loaded stale (``nscontrol._kernel_cache``)."""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from nscontrol import _kernel_cache as kc


def write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text))


def fake_package(root: Path) -> None:
    """``a._x`` imports ``b._y``; ``a._z`` imports ``a._x`` (so ``b._y`` through it)."""
    write(root / "b" / "_y_kernels.py", "Y = 1\n")
    write(root / "a" / "_x_kernels.py", "from ..b._y_kernels import Y\n")
    write(root / "a" / "_z_kernels.py", "from . import _x_kernels as xk\n")
    write(root / "b" / "_w_kernels.py", "W = 1\n")              # imports nothing


def cached(root: Path) -> set[str]:
    return {p.name for p in root.glob("*/__pycache__/*.nb?")}


def fake_cache(root: Path) -> None:
    for sub, stem in (("b", "_y_kernels"), ("a", "_x_kernels"), ("a", "_z_kernels"),
                      ("b", "_w_kernels")):
        for ext in ("nbi", "1.nbc"):
            write(root / sub / "__pycache__" / f"{stem}.f-1.py311.{ext}", "")


def test_dependencies_are_followed_transitively(tmp_path):
    fake_package(tmp_path)
    digests = kc.dependency_digests(kc.kernel_modules(tmp_path.resolve()))
    by_name = {p.stem: d for p, d in digests.items()}
    empty = kc.dependency_digests([])          # nothing reached: the digest of no source
    assert by_name["_y_kernels"] == by_name["_w_kernels"]         # both reach nothing
    assert by_name["_x_kernels"] != by_name["_y_kernels"]
    assert by_name["_z_kernels"] != by_name["_x_kernels"]         # x and y, not y alone
    assert empty == {}


def test_only_the_importers_of_a_changed_kernel_are_cleared(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    fake_package(tmp_path)
    fake_cache(tmp_path)
    kc.refresh(tmp_path)           # no stamps yet: caches of unknown age are all dropped
    assert cached(tmp_path) == set()
    fake_cache(tmp_path)
    assert kc.refresh(tmp_path) == []        # stamped and unchanged: everything kept
    assert len(cached(tmp_path)) == 8
    write(tmp_path / "b" / "_y_kernels.py", "Y = 2\n")
    cleared = kc.refresh(tmp_path)
    assert sorted(cleared) == ["a._x_kernels", "a._z_kernels"]   # y itself: numba's stamp
    assert {n.split(".")[0] for n in cached(tmp_path)} == {"_y_kernels", "_w_kernels"}


NUMBA_PACKAGE = {
    "__init__.py": "",
    "sub/__init__.py": "",
    "sub/_y_kernels.py": """
        from numba import njit

        @njit(cache=True)
        def f():
            return {value}
        """,
    "sub/_x_kernels.py": """
        from numba import njit

        from ._y_kernels import f

        @njit(cache=True)
        def g():
            return f() + 1.0
        """,
}


def run_g(root: Path, env: dict[str, str], refresh: bool, user_cache: bool = False,
          package: str = "pkg") -> tuple[float, int]:
    """Import the package in a fresh process (refreshing its caches first, as
    ``import nscontrol`` does for its own kernels; with ``user_cache``, caching its kernel
    modules in the per-user folder as ``import nscontrol`` does) and call the compiled
    ``g``; returns its value and how many of ``g``'s signatures were loaded from a cache."""
    code = textwrap.dedent(f"""
        import sys; sys.path.insert(0, {str(root)!r})
        from pathlib import Path
        from nscontrol import _kernel_cache
        if {user_cache}:
            _kernel_cache.install(Path({str(root / package)!r}))
        if {refresh}:
            _kernel_cache.refresh(Path({str(root / package)!r}))
        import {package}.sub._x_kernels as m
        print(m.g(), sum(m.g.stats.cache_hits.values()))
        """)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=300, check=True)
    value, hits = out.stdout.split()[-2:]
    return float(value), int(hits)


def write_package(root: Path, value: float) -> None:
    for name, text in NUMBA_PACKAGE.items():
        write(root / name, text.format(value=value))


@pytest.mark.parametrize("where", ["in-tree", "NUMBA_CACHE_DIR", "per-user"])
def test_a_changed_callee_is_recompiled_into_its_caller(tmp_path, where):
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR",
                                                             "NUMBA_DISABLE_JIT")}
    env["NSCONTROL_CACHE_DIR"] = str(tmp_path / "user")
    if where == "NUMBA_CACHE_DIR":
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    user = where == "per-user"
    for value in (1.0, 10.0):
        write_package(tmp_path / "pkg", value)
        # g = f + 1: 2.0 first, then 11.0 (exact in binary: no tolerance to choose)
        # per-user: no refresh needed, a changed callee changes the folder
        assert run_g(tmp_path, env, refresh=not user, user_cache=user) == (value + 1.0, 0)
    # and loaded from the cache
    assert run_g(tmp_path, env, refresh=not user, user_cache=user) == (11.0, 1)
    if user:   # in the per-user folder, by content: nothing beside the sources
        assert not list((tmp_path / "pkg").rglob("*.nb?"))
        assert len(list((tmp_path / "user").rglob("_x_kernels.g-*.nbi"))) == 2


def test_the_per_user_cache_survives_a_new_environment(tmp_path):
    """The same sources at another path (a new virtual environment) load the kernels the
    first copy compiled; numba's path-keyed ``__pycache__`` would compile them again."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR",
                                                             "NUMBA_DISABLE_JIT")}
    env["NSCONTROL_CACHE_DIR"] = str(tmp_path / "user")
    write_package(tmp_path / "one" / "pkg", 1.0)
    write_package(tmp_path / "two" / "pkg", 1.0)
    assert run_g(tmp_path / "one", env, refresh=True, user_cache=True) == (2.0, 0)
    assert run_g(tmp_path / "two", env, refresh=True, user_cache=True) == (2.0, 1)
    # without the per-user cache the second copy compiles (the test can fail)
    env["NSCONTROL_CACHE_DIR"] = ""
    write_package(tmp_path / "three" / "pkg", 1.0)
    write_package(tmp_path / "four" / "pkg", 1.0)
    assert run_g(tmp_path / "three", env, refresh=True, user_cache=True) == (2.0, 0)
    assert run_g(tmp_path / "four", env, refresh=True, user_cache=True) == (2.0, 0)


def test_the_per_user_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("NSCONTROL_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert kc.user_cache_root() == tmp_path / "nscontrol" / "numba"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert kc.user_cache_root() == Path.home() / ".cache" / "nscontrol" / "numba"
    monkeypatch.setenv("NSCONTROL_CACHE_DIR", str(tmp_path / "x"))
    assert kc.user_cache_root() == tmp_path / "x"
    monkeypatch.setenv("NSCONTROL_CACHE_DIR", "")
    assert kc.user_cache_root() is None


def _folder(root: Path, version: str, stem: str, k: int, idle_days: float, now: float) -> Path:
    folder = root / f"numba-{version}" / f"{stem}-{k:020x}"
    folder.mkdir(parents=True)
    (folder / f"{stem}.f-1.py311.nbi").write_bytes(b"index")
    os.utime(folder, (now - idle_days * 86400, now - idle_days * 86400))
    return folder


def test_old_per_user_folders_are_pruned_and_recent_or_used_ones_kept(tmp_path):
    now = 2_000_000_000.0
    root = tmp_path / "user"
    mk = functools.partial(_folder, root, now=now)
    current = mk("0.68.1", "_a_kernels", 1, idle_days=60.0)     # old, but in use here
    recent = [mk("0.68.1", "_a_kernels", k, idle_days=0.1 * k) for k in (2, 3, 4)]
    beyond_keep_fresh = mk("0.68.1", "_a_kernels", 5, idle_days=0.9)   # 4th newest, < 1 day
    beyond_keep_old = mk("0.68.1", "_a_kernels", 6, idle_days=2.0)     # 6th, > 1 day idle
    other_module = mk("0.68.1", "_b_kernels", 7, idle_days=20.0)       # its module's newest
    old_numba = mk("0.60.0", "_b_kernels", 8, idle_days=31.0)          # past 30 days
    strangers = [root / "numba-0.68.1" / "notes", root / "mine-0123"]   # not our pattern
    for p in strangers:
        p.mkdir(parents=True)
        os.utime(p, (0, 0))
    deleted = kc.prune(root, now=now, in_use=[current])
    assert sorted(deleted) == sorted([beyond_keep_old, old_numba])
    for kept in [current, *recent, beyond_keep_fresh, other_module, *strangers]:
        assert kept.is_dir(), kept
    assert not (root / "numba-0.60.0").exists()       # emptied version folder removed
    assert kc.prune(root, now=now, in_use=[current]) == []   # nothing left to prune


def test_a_folder_a_process_uses_is_touched_so_pruning_keeps_it(tmp_path):
    folder = tmp_path / "numba-x" / f"_a_kernels-{1:020x}"
    folder.mkdir(parents=True)
    os.utime(folder, (0, 0))
    kc._touched.discard(folder)
    kc._touch(folder)
    assert time.time() - folder.stat().st_mtime < 3600
    assert kc.prune(tmp_path) == []                    # touched now: kept

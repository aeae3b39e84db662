"""numba's cache is stamped with a kernel's own file only: a kernel whose imported kernel
changed must be recompiled, not loaded stale (``nscontrol._kernel_cache``)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
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


def run_g(root: Path, env: dict[str, str], refresh: bool) -> float:
    """Import the package in a fresh process (refreshing its caches first, as
    ``import nscontrol`` does for its own kernels) and call the compiled ``g``."""
    code = textwrap.dedent(f"""
        import sys; sys.path.insert(0, {str(root)!r})
        from pathlib import Path
        if {refresh}:
            from nscontrol import _kernel_cache
            _kernel_cache.refresh(Path({str(root / 'pkg')!r}))
        import pkg.sub._x_kernels as m
        print(m.g())
        """)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=300, check=True)
    return float(out.stdout.split()[-1])


@pytest.mark.parametrize("cache_dir", [False, True], ids=["in-tree", "NUMBA_CACHE_DIR"])
def test_a_changed_callee_is_recompiled_into_its_caller(tmp_path, cache_dir):
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR",
                                                             "NUMBA_DISABLE_JIT")}
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    for value in (1.0, 10.0):
        for name, text in NUMBA_PACKAGE.items():
            write(tmp_path / "pkg" / name, text.format(value=value))
        # g = f + 1: 2.0 first, then 11.0 (exact in binary: no tolerance to choose)
        assert run_g(tmp_path, env, refresh=True) == value + 1.0
    assert run_g(tmp_path, env, refresh=True) == 11.0           # and loaded from the cache

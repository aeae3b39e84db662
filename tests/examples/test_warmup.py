"""``nscontrol warmup`` compiles every numba kernel module of the package.

The fast tests compare the warm-up's declared coverage (``COMPILES``) with the kernel modules
found on disk; the slow one runs the warm-up in a fresh interpreter and asks numba which
kernels it compiled (or loaded from the cache) during each step.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import nscontrol
from nscontrol import _kernel_cache, _progress
from nscontrol.examples.warmup import COMPILES, STEPS

ROOT = Path(nscontrol.__file__).resolve().parent


def _kernel_modules_on_disk():
    """Every ``_*_kernel*.py`` under the package, as ``subpackage._module``."""
    return {".".join(p.relative_to(ROOT).with_suffix("").parts)
            for p in ROOT.rglob("_*_kernel*.py")}


def test_there_are_kernel_modules():
    assert {"numerics._lcp_kernels", "simulate.implicit_euler._lure_lcp_kernels",
            "simulate.moreau_jean._linearised_kernels"} <= _kernel_modules_on_disk()


def test_warmup_declares_every_kernel_module():
    covered = {m for modules in COMPILES.values() for m in modules}
    assert covered == _kernel_modules_on_disk()


def test_every_declared_step_exists():
    assert set(COMPILES) == {what for what, _ in STEPS}


def test_first_run_notice_sees_every_kernel_module(tmp_path, monkeypatch):
    """``uncompiled_kernel_modules`` (the first-run notice, ``nscontrol warmup``) globs for
    kernel files: its patterns must find every one of them."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    found = {".".join(p.relative_to(ROOT).with_suffix("").parts)
             for pattern in _progress.KERNEL_GLOBS for p in ROOT.glob(pattern)}
    assert found == _kernel_modules_on_disk()


_PROBE = r"""
import importlib, json, sys
from numba.core.registry import CPUDispatcher
from nscontrol.examples.warmup import STEPS

modules = json.loads(sys.argv[1])
mods = {m: importlib.import_module("nscontrol." + m) for m in modules}

def compiled():  # kernels defined in the module (not those it imports from another)
    return {m: sum(len(v.signatures) for v in vars(mod).values()
                   if isinstance(v, CPUDispatcher) and v.py_func.__module__ == mod.__name__)
            for m, mod in mods.items()}

before, gained, failed = compiled(), {}, []
for what, step in STEPS:
    try:
        step()
    except Exception as exc:
        failed.append(f"{what}: {exc!r}")
    after = compiled()
    gained[what] = sorted(m for m in modules if after[m] > before[m])
    before = after
print(json.dumps({"gained": gained, "failed": failed, "final": before}))
"""


@pytest.mark.slow
def test_warmup_compiles_every_kernel_module(tmp_path):
    # a cold cache of its own: loading a caller from a warm cache does not load the kernels it
    # calls (a module reached only that way, e.g. moreau_jean._linearised_kernels, showed 0
    # signatures)
    modules = sorted(_kernel_modules_on_disk())
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(modules)],
                         capture_output=True, text=True, check=True, timeout=1800, env=env)
    data = json.loads(out.stdout.strip().splitlines()[-1])
    assert data["failed"] == []
    assert [m for m, n in data["final"].items() if n == 0] == []
    # each step reaches only kernels it declares (a module compiled by an earlier step for
    # the same types gains nothing later, so the declaration may list more), or kernels that
    # those import: compiling a caller compiles its callees' signatures too, loading it from
    # the cache does not, so a cold cache shows them and a warm one does not
    reached = _kernel_cache.reached_kernels(_kernel_cache.kernel_modules(ROOT))
    name = {p: ".".join(p.relative_to(ROOT).with_suffix("").parts) for p in reached}
    for what, gained in data["gained"].items():
        allowed = set(COMPILES[what]) | {name[q] for p in reached if name[p] in COMPILES[what]
                                         for q in reached[p]}
        assert set(gained) <= allowed, (what, gained)


def test_a_fresh_numba_cache_dir_counts_every_module_uncompiled(tmp_path, monkeypatch):
    """A new ``NUMBA_CACHE_DIR`` pays the compile again: the notice must see it (it assumed
    such a cache was complete)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    assert set(_progress.uncompiled_kernel_modules()) == _kernel_modules_on_disk()

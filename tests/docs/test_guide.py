"""The user guide's code runs as written: each page's Python blocks, in order, in a scratch
folder (what a reader pasting them would do)."""

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide"
# Pages whose code runs a Python-level sampled block for 10^4 steps or starts a Dask cluster.
SLOW_PAGES = {"controllers", "sweeps"}
# Pages whose code imports an optional extra: skipped when it is not installed.
NEEDS = {"python_control": "control", "mpc": "casadi"}


def _page_code(page: str) -> str:
    text = (GUIDE / f"{page}.md").read_text()
    return "\n".join(re.findall(r"```python\n(.*?)```", text, flags=re.S))


@pytest.mark.parametrize("page", [
    pytest.param(p.stem, marks=[pytest.mark.slow] if p.stem in SLOW_PAGES else [])
    for p in sorted(GUIDE.glob("*.md"))])
def test_guide_page_runs(page, tmp_path):
    extra = NEEDS.get(page)
    if extra is not None and importlib.util.find_spec(extra) is None:
        pytest.skip(f"{page}.md needs the optional package {extra!r}")
    code = _page_code(page)
    assert code.strip(), f"{page}.md has no Python block"
    env = {**os.environ, "MPLBACKEND": "Agg", "OPENBLAS_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(GUIDE.parents[1] / "src"),
                                                       os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_every_guide_page_is_in_the_index():
    index = (GUIDE.parent / "index.md").read_text()
    missing = [p.stem for p in GUIDE.glob("*.md") if f"guide/{p.stem}\n" not in index]
    assert not missing, f"guide pages not in docs/index.md's toctree: {missing}"


def test_optional_pages_name_their_extra():
    """A page importing an optional package must be listed in NEEDS (else it fails, not
    skips, on an install without it)."""
    for p in GUIDE.glob("*.md"):
        if re.search(r"^import control$|^from control\b", _page_code(p.stem), flags=re.M):
            assert NEEDS.get(p.stem) == "control", p.name

"""The package is typed: ``mypy`` (configured in pyproject.toml) finds nothing in ``src``, and
the public surface accepts ordinary user code and rejects the usual mistakes.

Type-checking runs mypy from scratch (no cache) on the whole package: tens of seconds, so
these are ``slow``; ``make lint`` (run by ``.ci/run`` before the tests) runs the same check
on ``src`` on every CI run.
"""

from __future__ import annotations

from pathlib import Path

import pytest

api = pytest.importorskip("mypy.api")

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = Path(__file__).resolve().parent / "typing_samples"

pytestmark = pytest.mark.slow


def _mypy(*targets: Path, tmp_path: Path) -> tuple[str, int]:
    """mypy with the project's configuration, a private cache, on ``targets``."""
    stdout, stderr, status = api.run([
        "--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", str(tmp_path / "cache"),
        "--no-error-summary", "--hide-error-context", *map(str, targets)])
    return stdout + stderr, status


def test_src_is_clean(tmp_path: Path) -> None:
    out, status = _mypy(ROOT / "src" / "nscontrol", tmp_path=tmp_path)
    assert status == 0, out


def test_public_surface_accepts_user_code(tmp_path: Path) -> None:
    out, status = _mypy(SAMPLES / "public_surface_ok.py", tmp_path=tmp_path)
    assert status == 0, out


def test_public_surface_rejects_mistakes(tmp_path: Path) -> None:
    sample = SAMPLES / "public_surface_bad.py"
    expected = {i for i, line in enumerate(sample.read_text().splitlines(), 1)
                if line.rstrip().endswith("# error")}
    out, status = _mypy(sample, tmp_path=tmp_path)
    # mypy names the file relative to the working directory: match on the file's name
    reported = {int(line.split(":")[1]) for line in out.splitlines()
                if line.split(":")[0].endswith(sample.name) and ": error:" in line}
    assert status == 1 and reported == expected, out

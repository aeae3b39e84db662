"""What the docs tests share: run the ``python`` block that follows a heading of a page."""

from __future__ import annotations

import contextlib
import io
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"


def python_block_after(heading: str, page: str = "architecture.md") -> str:
    """The source of the first fenced ``python`` block after ``heading`` in ``docs/page``."""
    text = (DOCS / page).read_text()
    assert heading in text, f"docs/{page} has no heading {heading!r}"
    match = re.search(r"```python\n(.*?)```", text[text.index(heading):], re.S)
    assert match is not None, f"docs/{page}: no python block after {heading!r}"
    return match.group(1)


def run_python_block(heading: str, page: str = "architecture.md") -> tuple[dict, str]:
    """Run that block in a fresh namespace; returns (namespace, what it printed)."""
    scope: dict[str, Any] = {}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(python_block_after(heading, page), str(DOCS / page), "exec"),  # noqa: S102
             scope)
    return scope, out.getvalue()


@pytest.fixture
def doc_block() -> Callable[..., tuple[dict, str]]:
    """``doc_block(heading, page="architecture.md")``: :func:`run_python_block`."""
    return run_python_block


@pytest.fixture
def doc_source() -> Callable[..., str]:
    """``doc_source(heading, page="architecture.md")``: :func:`python_block_after`."""
    return python_block_after

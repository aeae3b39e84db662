"""The chapter-12 example: listed with its captions, and every acceptance check passes."""

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("ch12-corner-control")
    assert ex.chapter == "ch12" and ex.key_figure in ex.captions


@pytest.mark.slow
def test_example_checks_pass(tmp_path):
    res = get_example("ch12-corner-control").run(tmp_path)
    assert res.passed, [c for c in res.checks if not c.passed]
    keys = {c.key for c in res.checks}
    assert {f"check_{i}" for i in range(1, 11)} <= keys     # one per acceptance check
    assert len(res.figures) == 5 and all(f.exists() for f in res.figures)

"""The smc-implicit example: listed, and (slow) every check passes, with its figures."""

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("smc-implicit")
    assert ex.key_figure in ex.captions


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("smc-implicit").run(tmp_path)
    assert {c.key for c in res.checks} == {f"check_{k}" for k in range(1, 13)}
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 3 and all(p.exists() for p in res.figures)

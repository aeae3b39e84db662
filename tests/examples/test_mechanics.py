"""The mechanics examples run, write their figures and pass their conformance checks."""

import pytest

from nscontrol.examples import get_example


@pytest.mark.parametrize("name", ["bouncing-ball", "newtons-cradle"])
def test_mechanics_example(name: str, tmp_path) -> None:
    result = get_example(name).run(tmp_path)
    failed = [c.name for c in result.checks if not c.passed]
    assert not failed
    assert len(result.checks) >= 6
    assert result.figures and all(p.exists() for p in result.figures)

"""The set-valued examples run, write their figures, pass every conformance check and are
listed by the command line."""

import pytest
from click.testing import CliRunner

from nscontrol.cli import main
from nscontrol.examples import get_example


@pytest.mark.parametrize("name", ["relay-feedback", "pwa-oscillator"])
def test_setvalued_example_runs_and_passes_its_checks(name, tmp_path):
    result = get_example(name).run(tmp_path)
    failed = [(c.name, c.value) for c in result.checks if not c.passed]
    assert not failed
    assert len(result.checks) == 5
    assert result.figures and all(p.exists() and p.stat().st_size > 0 for p in result.figures)
    assert all(p.parent == tmp_path for p in result.figures)


def test_setvalued_examples_are_listed():
    out = CliRunner().invoke(main, ["list"])
    assert out.exit_code == 0
    assert "relay-feedback" in out.output and "pwa-oscillator" in out.output

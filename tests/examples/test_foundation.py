"""The foundation example runs, passes its own checks, writes its figures, and is reachable
through the CLI (``list``, ``run --json`` with the issue's JSON schema)."""

import json

import pytest
from click.testing import CliRunner

from nscontrol.cli import main
from nscontrol.examples import get_example


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("foundation")
    return get_example("foundation").run(out), out


def test_every_check_passes_and_figures_exist(result):
    res, out = result
    assert res.checks and all(c.passed for c in res.checks), [c for c in res.checks
                                                              if not c.passed]
    names = {p.name for p in res.figures}
    assert {"foundation_lcp_stack.png", "foundation_lti_oscillator.png",
            "foundation_lti_error.png"} <= names
    for path in res.figures:
        assert path.parent == out and path.stat().st_size > 1000
    assert res.metrics["lti_events"] >= 10  # the guard search found every crossing


def test_cli_list_and_run_json(tmp_path, monkeypatch):
    runner = CliRunner()
    listed = runner.invoke(main, ["list"])
    assert listed.exit_code == 0 and "foundation" in listed.output
    monkeypatch.chdir(tmp_path)          # figures go to out/foundation by default
    ran = runner.invoke(main, ["run", "foundation", "--json"])
    assert ran.exit_code == 0, ran.output
    assert list((tmp_path / "out" / "foundation").glob("*.png"))
    payload = json.loads(ran.output.strip().splitlines()[-1])
    assert payload["example"] == "foundation"
    assert isinstance(payload["metrics"], dict) and payload["metrics"]
    assert payload["checks"]
    for c in payload["checks"]:
        assert {"name", "value", "threshold", "passed"} <= set(c)
        assert c["passed"] is True

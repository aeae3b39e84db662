"""`nscontrol report` runs every example, keeps going past a failing one, and writes HTML+JSON."""

import json

from click.testing import CliRunner

import nscontrol.report as report_mod
from nscontrol.cli import main
from nscontrol.examples import Example, ExampleResult, check
from nscontrol.examples._figures import new_figure, save_figure


def _good(out_dir):
    figures = []
    fig, ax = new_figure()
    ax.plot([0, 1], [0, 1])
    save_figure(fig, out_dir, "line", figures)
    return ExampleResult("good", {"err": 1e-13}, [check("err", 1e-13, 1e-10)], figures)


def _broken(out_dir):
    raise RuntimeError("deliberately broken example")


def test_report_writes_html_and_json_and_survives_failures(tmp_path, monkeypatch):
    fake = [Example("good", "a good one", "test", _good),
            Example("broken", "a broken one", "test", _broken)]
    monkeypatch.setattr(report_mod, "all_examples", lambda: fake)
    result = CliRunner().invoke(main, ["report", "--out", str(tmp_path)])
    assert result.exit_code == 1  # one example failed
    summary = json.loads((tmp_path / "report.json").read_text())
    by_name = {e["example"]: e for e in summary["examples"]}
    assert by_name["good"]["passed"] and not by_name["broken"]["passed"]
    assert "deliberately broken" in by_name["broken"]["error"]
    html = (tmp_path / "index.html").read_text()
    assert "good/line.png" in html and "deliberately broken" in html
    assert (tmp_path / "good" / "line.png").stat().st_size > 1000

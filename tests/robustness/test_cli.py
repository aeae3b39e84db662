"""Class 4: the command line refuses unknown example names and unwritable output folders
before anything runs, exits non-zero, and leaves a previous report untouched.

No numerical tolerance: exit codes, messages and bytes on disk are compared exactly.
"""

from __future__ import annotations

import json
import os

import pytest
from click.testing import CliRunner

import nscontrol.report as report_mod
from nscontrol.cli import main
from nscontrol.errors import ModelError
from nscontrol.examples import Example, ExampleResult, all_examples, check

RAN: list[str] = []


def _good(out_dir):
    RAN.append("good")
    return ExampleResult("good", {"err": 1e-13}, [check("err", 1e-13, 1e-10)], [])


def _other(out_dir):
    RAN.append("other")
    return ExampleResult("other", {}, [], [])


@pytest.fixture
def fake_examples(monkeypatch):
    RAN.clear()
    fake = [Example("good", "a good one", "test", _good),
            Example("other", "another", "test", _other)]
    monkeypatch.setattr(report_mod, "all_examples", lambda: fake)
    return fake


@pytest.fixture
def old_report(tmp_path):
    """A folder holding a previous report, and its bytes."""
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "report.json").write_text('{"passed": true, "examples": ["previous"]}')
    (folder / "index.html").write_text("<p>previous report</p>")
    return folder, {p.name: p.read_bytes() for p in folder.iterdir()}


def invoke(*args):
    return CliRunner().invoke(main, list(args))


@pytest.mark.parametrize("only", [["no-such"], ["good", "no-such"], ["GOOD"], ["good", ""]])
def test_unknown_example_refused_before_running(fake_examples, old_report, only):
    folder, before = old_report
    args = ["report", "--out", str(folder)] + [a for n in only for a in ("--only", n)]
    result = invoke(*args)
    assert result.exit_code == 2, result.output
    assert "--only: unknown example name(s)" in result.output
    assert "known examples: good, other" in result.output and "nscontrol list" in result.output
    assert RAN == []                                                   # nothing ran
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before   # old report kept


def test_known_example_runs(fake_examples, old_report):
    folder, _ = old_report
    result = invoke("report", "--out", str(folder), "--only", "good")
    assert result.exit_code == 0, result.output
    assert RAN == ["good"]
    summary = json.loads((folder / "report.json").read_text())
    assert [e["example"] for e in summary["examples"]] == ["good"]


@pytest.mark.parametrize("bad_out", ["/dev/null/x", "{file}", "{file}/sub"])
def test_unwritable_out_refused_before_running(fake_examples, tmp_path, bad_out):
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    out = bad_out.format(file=a_file)
    result = invoke("report", "--out", out)
    assert result.exit_code == 2, result.output
    assert "--out" in result.output   # ours or click's own check of a file path
    assert "folder" in result.output or "is a file" in result.output
    assert RAN == [] and a_file.read_text() == "keep me"


def test_run_checks_out_before_running(tmp_path):
    name = all_examples()[0].name
    result = invoke("run", name, "--out", "/dev/null/x")
    assert result.exit_code == 2 and "--out:" in result.output and "writable" in result.output


def test_run_unknown_example_lists_known():
    result = invoke("run", "no-such")
    assert result.exit_code == 2 and "available:" in result.output


def test_write_report_api_names_the_argument(fake_examples, tmp_path):
    with pytest.raises(ModelError, match=r"^only: unknown example name\(s\) \['x'\]"):
        report_mod.write_report(tmp_path, ["x"])
    with pytest.raises(ModelError, match=r"^out: .* is a file"):
        (tmp_path / "f").write_text("")
        report_mod.write_report(tmp_path / "f", ["good"])
    assert RAN == []


def test_failed_html_leaves_previous_index(fake_examples, old_report, monkeypatch):
    folder, before = old_report

    def broken(rows, out):
        raise RuntimeError("html broke")

    monkeypatch.setattr(report_mod, "_html", broken)
    with pytest.raises(RuntimeError, match="html broke"):
        report_mod.write_report(folder, ["good"])
    assert (folder / "index.html").read_bytes() == before["index.html"]
    assert not [n for n in os.listdir(folder) if n.endswith(".tmp")]


def test_bifurcation_help_lists_the_families_and_their_parameters():
    result = invoke("bifurcation", "--help")
    assert result.exit_code == 0
    text = " ".join(result.output.split())      # click wraps the table
    assert "impact-oscillator-bifurcation" in text
    assert all(p in text for p in ("forcing", "omega", "restitution"))

"""``nscontrol sweep``: an example's parameter over a grid, saved, failed points kept."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from nscontrol.cli import main
from nscontrol.errors import ModelError
from nscontrol.examples import get_example
from nscontrol.examples.sweeps import SweepSpec, example_sweeps, run_sweep


def test_the_corner_design_reaches_each_swept_multiplier(tmp_path):
    # chapter 12's leading-order theory: the designed multiplier is met to within 3|z_d|
    # (z_d = 0.005 here), the bound the example checks on its own designs
    ex = get_example("ch12-corner-control")
    json_path, png_path, res = run_sweep(ex, "lambda_d", [0.3, 0.7], executor="serial",
                                         out=tmp_path, progress=False)
    data = json.loads(json_path.read_text())
    assert res.ok and png_path.stat().st_size > 0
    measured = data["outputs"]["measured multiplier"]
    for target, got in zip(data["values"], measured, strict=True):
        assert abs(got - target) <= 3 * 0.005


def _fails_above_one(value: float) -> tuple[float]:
    if value > 1.0:
        raise ValueError("no design above one")
    return (2.0 * value,)


def test_a_failed_point_is_recorded_and_the_others_kept(tmp_path, monkeypatch):
    ex = get_example("ch07-friction-compensation")
    module = __import__(ex.run.__module__, fromlist=["SWEEPS"])
    monkeypatch.setattr(module, "SWEEPS", {"x": SweepSpec(_fails_above_one, ("twice x",),
                                                          "x [1]")})
    json_path, _, res = run_sweep(ex, "x", [0.5, 1.5, 0.75], executor="serial",
                                  out=tmp_path, progress=False)
    data = json.loads(json_path.read_text())
    assert data["outputs"]["twice x"] == [1.0, None, 1.5]
    assert len(data["errors"]) == 1 and data["errors"][0]["value"] == 1.5
    assert "no design above one" in data["errors"][0]["error"] and not res.ok


def test_unknown_parameter_names_the_offered_ones(tmp_path):
    ex = get_example("ch07-friction-compensation")
    assert "kappa" in example_sweeps(ex)
    with pytest.raises(ModelError, match="kappa"):
        run_sweep(ex, "gain", [1.0], executor="serial", out=tmp_path, progress=False)
    result = CliRunner().invoke(main, ["sweep", "ch07-friction-compensation", "--param",
                                       "gain=0:1:3", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--param" in result.output and "kappa" in result.output


def test_help_lists_the_sweepable_parameters():
    result = CliRunner().invoke(main, ["sweep", "--help"])
    text = " ".join(result.output.split())
    assert "ch07-friction-compensation kappa" in text and "lambda_d" in text

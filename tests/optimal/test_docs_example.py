"""docs/optimal.md's first plan runs as written and says what the page says it does."""

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("casadi")

PAGE = Path(__file__).resolve().parents[2] / "docs" / "optimal.md"


def test_first_plan_of_the_page_runs_and_replays(capsys):
    (code,) = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)[:1]
    namespace: dict = {}
    exec(compile(code, str(PAGE), "exec"), namespace)
    plan, traj, block = namespace["plan"], namespace["traj"], namespace["block"]
    # the page's comments: cost 36.0638 (the discrete closed form), residual ~1e-13, replay
    assert plan.cost == pytest.approx(block.effort_cost_discrete(1.0, 50), abs=1e-6)
    assert plan.residual <= 1e-8
    assert np.abs(traj.x - plan.x).max() <= 1e-6
    assert "36.06" in capsys.readouterr().out

"""The README's tour of the API runs as written (in a scratch folder), and says what it shows."""

import os
import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"


def _python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_has_one_tour_block():
    blocks = _python_blocks()
    assert len(blocks) == 1
    assert 10 <= len(blocks[0].strip().splitlines()) <= 30   # "a 20-line tour of the API"


def test_readme_tour_runs(tmp_path):
    code = _python_blocks()[0]
    env = {**os.environ, "MPLBACKEND": "Agg", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "solved" in out                                # the LCP line
    assert "x0:" in out                                   # the error names the argument
    assert (tmp_path / "ball.png").stat().st_size > 1000
    assert (tmp_path / "ball.h5").stat().st_size > 1000
    from nscontrol.simulate import Trajectory

    back = Trajectory.load(tmp_path / "ball.h5")
    assert back.event_times("impact").size >= 5 and back.status == 0

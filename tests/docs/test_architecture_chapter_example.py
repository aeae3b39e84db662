"""The worked chapter example of docs/architecture.md runs and does what it says: an
``Example`` of the user's own measures its claim (impact times of a bouncing ball on their
geometric series) and says its verdict."""

from __future__ import annotations

import numpy as np


def test_a_chapter_of_ones_own_measures_its_claim_and_says_its_verdict(doc_block):
    scope, printed = doc_block("### Worked example: a chapter of your own")
    result, example = scope["result"], scope["EXAMPLES"][0]
    assert result.passed and len(result.checks) == 2
    # impact n (from 0) is at t_inf - 4 t1 2^-(n+1) (e = 1/2): before 0.999 t_inf = t_inf -
    # 0.003 t1 exactly for n <= 9, so ten impacts
    assert result.metrics["impacts"] == 10
    # the first impact against sqrt(2H/g) computed here, independently of the example
    assert result.checks[0].value <= 10 * np.finfo(float).eps
    assert printed.startswith("Reproduced: impact times exact to")
    assert example.verdict_line(result) == printed.strip()

"""Brute-force bifurcation diagrams: known regimes, determinism across executors, failures."""

from dataclasses import dataclass

import numpy as np
import pytest

from nscontrol.analysis.bifurcation import BifurcationDiagram, bifurcation_diagram
from nscontrol.analysis.impact_oscillator import ImpactOscillator, OscillatorFamily
from nscontrol.errors import ModelError

BASE = ImpactOscillator(omega=2.5, stop=0.1)
FAM = OscillatorFamily(BASE, "forcing")
FG = BASE.grazing_forcing()
F_FLIP = 1.2829843287616467        # closed form (test_impact_oscillator)


@dataclass(frozen=True)
class _FailsAt:
    """Picklable factory raising at one parameter value."""

    bad: float

    def __call__(self, p):
        if p == self.bad:
            raise ValueError("no model here")
        return FAM(p)


def test_regimes_match_the_closed_forms():
    vals = np.array([0.5 * FG, 0.7 * FG, 1.15, 2.0, 2.5])
    bd = bifurcation_diagram(FAM, vals, n_transient=200, n_sample=12, chunk_size=5,
                             progress=False, parameter_name="F")
    up, m_up = bd.sweep("up")
    down, m_down = bd.sweep("down")
    # below grazing: the linear steady state (transient e^{-c·200T/2m} ~ 1e-11 of |x0|)
    for i in (0, 1):
        assert m_up[i] == 1
        assert np.allclose(up[i], BASE.with_(forcing=vals[i]).non_impacting_state(0),
                           atol=1e-9)
    # between grazing and flip the period-1 orbit is unstable: the period-2 attractor.
    # Coming up from the linear orbit it converges at about 10^-3.6 per 50 periods (the
    # distance to its 2000-period sample is 4e-9 after 100 periods, < 1e-12 after 150), so
    # 200 periods leave ~1e-15. Coming *down* from F = 2.0 the start lies in a transient
    # whose length round-off decides (multiplicity 2 or 0 for n_transient from 200 to 350
    # with the same code, only the rounding of the flights changed): no test on it.
    assert m_up[2] == 2
    # above the flip, coming down: the closed-form impacting orbit; |μ| = 0.71 over 200
    # periods leaves 0.71^200 ~ 1e-30
    for i in (3, 4):
        assert m_down[i] == 1
        assert np.allclose(down[i], BASE.with_(forcing=vals[i]).admissible_orbit().x0,
                           atol=1e-9)


def test_serial_and_processes_give_identical_arrays(tmp_path):
    vals = np.linspace(0.4, 1.6, 6)
    kw = dict(n_transient=50, n_sample=5, chunk_size=3, progress=False)
    a = bifurcation_diagram(FAM, vals, executor="serial", **kw)
    b = bifurcation_diagram(FAM, vals, executor=None, **kw)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.multiplicity, b.multiplicity)
    c = BifurcationDiagram.load(a.save(tmp_path / "bd.h5"))
    assert np.array_equal(c.points, a.points) and c.directions == a.directions
    assert len(a.to_pandas()) == 2 * 6 * 5


def test_a_failing_point_loses_nothing_else():
    vals = [0.3, 0.4, 0.5]
    bd = bifurcation_diagram(_FailsAt(0.4), vals, n_transient=20, n_sample=3, progress=False,
                             directions=("up",))
    assert [(d, i) for d, i, _ in bd.errors] == [("up", 1)]
    assert "no model here" in bd.errors[0][2]
    assert np.all(np.isnan(bd.points[0, 1])) and np.all(np.isfinite(bd.points[0, [0, 2]]))
    assert bd.multiplicity[0].tolist()[1] == -1


def test_refusals():
    with pytest.raises(ModelError, match="directions"):
        bifurcation_diagram(FAM, [0.3], directions=("sideways",))
    with pytest.raises(ModelError, match="chunk_size"):
        bifurcation_diagram(FAM, [0.3], chunk_size=0)


def test_cli_writes_the_diagram_and_its_figure(tmp_path):
    from click.testing import CliRunner

    from nscontrol.cli import main

    res = CliRunner().invoke(main, ["bifurcation", "impact-oscillator-bifurcation",
                                    "--param", "forcing=0.3:2.0:3", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    bd = BifurcationDiagram.load(tmp_path / "bifurcation.h5")
    assert bd.parameter_name == "forcing" and bd.points.shape[:2] == (2, 3)
    assert (tmp_path / "bifurcation.png").exists()
    bad = CliRunner().invoke(main, ["bifurcation", "impact-oscillator-bifurcation",
                                    "--param", "forcing=0.3"])
    assert bad.exit_code != 0 and "NAME=START:STOP:N" in bad.output

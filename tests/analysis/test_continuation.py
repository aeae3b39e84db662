"""Continuation of the impact oscillator's orbits: grazing and flip against the closed forms."""

from dataclasses import dataclass

import numpy as np
import pytest

from nscontrol.analysis.continuation import Branch, continue_orbit, switch_at_flip
from nscontrol.analysis.impact_oscillator import ImpactOscillator, OscillatorFamily
from nscontrol.analysis.orbits import Forced, find_orbit

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

BASE = ImpactOscillator(omega=2.5, stop=0.1)
FAM = OscillatorFamily(BASE, "forcing")
FG = BASE.grazing_forcing()
# Location: bracket width locate_tol = 1e-10 (relative) plus the corrector's error, the
# shooting residual tol = 1e-10 mapped to F through the monitors' slopes (|dF/dm| ~ 5 for
# the gap d - F/|k - mω² + icω|): 1e-10 + 5e-10 < 1e-9 relative.
LOCATED = 1e-9


@pytest.fixture(scope="module")
def impacting_branch():
    x0 = BASE.with_(forcing=4 * FG).admissible_orbit().x0
    return continue_orbit(FAM, 4 * FG, x0, p_range=(0.0, 3.0), step=0.05, step_max=0.2,
                          direction=-1, parameter_name="F")


def test_non_impacting_branch_stops_at_the_exact_grazing():
    b = continue_orbit(FAM, 0.5 * FG, [0.0, 0.0], p_range=(0.0, 3.0), step=0.05,
                       step_max=0.2, parameter_name="F")
    (g,) = b.points
    assert g.kind == "grazing" and b.stop_reason.startswith("grazing")
    assert g.parameter == pytest.approx(FG, rel=LOCATED)
    assert np.all(b.stable) and np.all(b.n_impacts == 0)


def test_impacting_branch_locates_flip_then_grazing(impacting_branch):
    b = impacting_branch
    kinds = [pt.kind for pt in b.points]
    assert kinds == ["flip", "grazing"]
    flip, graze = b.points
    F_flip = BASE.flip_forcing((1.1 * FG, 4 * FG))
    assert flip.parameter == pytest.approx(F_flip, rel=LOCATED)
    assert np.min(np.abs(flip.multipliers + 1.0)) <= 1e-8
    assert graze.parameter == pytest.approx(FG, rel=LOCATED)
    # stable above the flip, unstable between grazing and flip (the grazing point itself
    # carries the non-impacting side's multipliers: its orbit only touches the stop)
    above = b.p > F_flip * (1 + 1e-6)
    below = (b.p < F_flip * (1 - 1e-6)) & (b.n_impacts == 1)
    assert np.all(b.stable[above]) and not np.any(b.stable[below])
    # every branch point is the closed-form orbit (shooting error, see the oscillator tests)
    for p, x in zip(b.p[::4], b.x0[::4], strict=True):
        if p > FG * 1.01:
            assert np.allclose(x, BASE.with_(forcing=p).admissible_orbit().x0, atol=1e-9)


def test_branch_table_plot_and_hdf5_roundtrip(impacting_branch, tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    b = impacting_branch
    df = b.to_pandas()
    assert list(df["special"][df["special"] != ""]) == ["flip", "grazing"]
    ax = b.plot()
    assert ax.get_xlabel() == "F" and "q_mass" in ax.get_ylabel()
    styles = {line.get_linestyle() for line in ax.lines}
    assert {"-", "--"} <= styles
    path = b.save(tmp_path / "branch.h5")
    c = Branch.load(path)
    assert np.array_equal(c.p, b.p) and np.array_equal(c.multipliers, b.multipliers)
    assert [pt.kind for pt in c.points] == ["flip", "grazing"] and c.stop_reason == b.stop_reason
    assert not list(tmp_path.glob(".*tmp"))          # atomic write left no temporary


def test_stop_reason_when_the_corrector_cannot_follow():
    b = continue_orbit(FAM, 2.0, BASE.with_(forcing=2.0).admissible_orbit().x0,
                       p_range=(0.0, 3.0), step=0.05, max_steps=2, parameter_name="F")
    assert b.stop_reason.startswith("max_steps (2)")


def test_branch_switch_at_flip_gives_the_period_two_orbit(impacting_branch):
    b2 = switch_at_flip(FAM, impacting_branch, p_range=(1.0, 3.0), step=0.01,
                        step_max=0.05, max_steps=6)
    assert b2.nodes.shape[1] == 2 and np.all(b2.n_impacts[1:] == 2)
    # genuinely period two: the two nodes differ away from the flip point
    assert np.linalg.norm(b2.nodes[-1, 0] - b2.nodes[-1, 1]) > 1e-3
    # born stable below the flip (supercritical in decreasing F)
    assert np.all(b2.p[1:] < b2.p[0]) and np.all(b2.stable[1:])


@dataclass(frozen=True)
class _PwaFamily:
    """The chapter-11 one-sided oscillator driven at frequency ``omega`` (picklable)."""

    def __call__(self, omega):
        from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
        from nscontrol.numerics.lti import Exosystem

        return Forced(one_sided_oscillator(0.1), Exosystem.sinusoid(1.0, omega),
                      2 * np.pi / omega, method="switching")


@pytest.mark.slow
def test_pwa_oscillator_flip_and_the_period_two_branch():
    """ch11's oscillator: the period-1 orbit flips below ω = 2.9 (where its multiplier is
    -2.188) and the switched branch is the 2T orbit brute force settles on."""
    from nscontrol.analysis.periodic import brute_force_steady_state

    fam = _PwaFamily()
    x0 = find_orbit(fam(2.0), [0.0, 0.0]).x0
    b = continue_orbit(fam, 2.0, x0, p_range=(1.5, 3.0), step=0.05, step_max=0.1, stop_at=(),
                       parameter_name="omega")
    (flip,) = b.special("flip")
    assert 2.0 < flip.parameter < 2.9
    assert np.min(np.abs(flip.multipliers + 1.0)) <= 1e-8
    b2 = switch_at_flip(fam, b, p_range=(1.5, 3.0), step=0.01, step_max=0.1, max_steps=25,
                        stop_at=())
    w, nodes = b2.p[-1], b2.nodes[-1]
    assert b2.stable[-1] and np.linalg.norm(nodes[0] - nodes[1]) > 1e-2
    f = fam(w)
    bf = brute_force_steady_state(f.system, f.period, u=f.u, n_transient=400)
    assert bf.multiplicity == 2
    # brute force ends on the same 2T orbit (up to its phase): the transient after 400 T is
    # |μ|^200 of the 2T orbit's largest multiplier (< 0.9 here: 0.9^200 ~ 1e-9)
    end = bf.trajectory.x[-1]
    assert min(np.max(np.abs(end - nodes[0])), np.max(np.abs(end - nodes[1]))) <= 1e-6

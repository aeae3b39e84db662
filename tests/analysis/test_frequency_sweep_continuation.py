"""frequency_sweep on continuation: each sweep follows its attractor's orbit in ω (shot at
every frequency, multipliers included), locates where it loses stability, and where the
branch folds the continued branch carries the coexisting orbits."""

import numpy as np
import pytest

from nscontrol.analysis import periodic as pr
from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator

# The continuation inside the sweep locates to locate_tol = 1e-6 relative in ω
LOCATE = 1e-6


def test_sweep_shoots_every_orbit_and_locates_the_flip():
    plant = one_sided_oscillator(0.1)
    ws = [2.0, 2.1, 2.2, 2.3, 2.4]
    up = pr.frequency_sweep(plant, ws, directions=("up",), n_transient=150, n_record=6,
                            executor="serial", progress=False)["up"]
    assert up.multiplicity.tolist() == [1, 1, 1, 2, 2]
    assert np.all(up.max_floquet < 1.0)        # shot orbits: stable, multipliers known
    (flip,) = [pt for b in up.branches for pt in b.points if pt.kind == "flip"]
    assert 2.2 < flip.parameter < 2.3
    # at the located flip a multiplier is -1 to |dμ/dω|·LOCATE·ω (|dμ/dω| < 20 here)
    assert np.min(np.abs(flip.multipliers + 1.0)) <= 20 * LOCATE * 2.3
    # the same orbit as shooting alone, on the same 200-point grid: both within the
    # shooting tolerance (1e-10 relative) times 1/(1 - max|μ|) < 10 of the orbit
    shot = pr.frequency_response(plant, ws[:3], n_samples=200, executor="serial",
                                 progress=False)
    np.testing.assert_allclose(up.gamma[:3], shot.gamma, rtol=1e-8)
    np.testing.assert_allclose(up.max_floquet[:3], shot.max_floquet, rtol=1e-8)


@pytest.fixture(scope="module")
def hardening():
    """Example B (spring engaged beyond a gap), lightly damped and driven hard enough for
    the resonance to bend: two stable orbits coexist between two folds."""
    plant = one_sided_oscillator(0.05, gap=1.0)
    ws = np.linspace(1.0, 1.4, 9)
    return ws, pr.frequency_sweep(plant, ws, amplitude=0.2, n_transient=200, n_record=6,
                                  executor="serial", progress=False)


def test_sweep_sees_both_orbits_where_the_branch_folds(hardening):
    ws, res = hardening
    up, down = res["up"], res["down"]
    jump = up.gamma > 2 * down.gamma          # up stays on the resonant orbit, down does not
    assert np.any(jump) and np.all(up.gamma >= down.gamma * (1 - 1e-6))
    folds = sorted({round(pt.parameter, 5) for d in (up, down) for b in d.branches
                    for pt in b.points if pt.kind == "fold"})
    assert len(folds) == 2
    lo, hi = folds
    # the jumps of the two sweeps lie between the folds (within one grid step)
    assert ws[jump].min() > lo - 0.05 and ws[jump].max() < hi + 0.05
    # one continued branch passes both folds: stable up to the first, unstable between
    # them (the orbits coexisting with the two attractors), stable again past the second
    both = [b for d in (up, down) for b in d.branches if len(b.special("fold")) == 2]
    assert both, "no branch carried the coexisting orbits through both folds"
    b = both[0]
    i, j = (pt.index for pt in b.special("fold"))
    assert np.all(b.stable[:i]) and not np.any(b.stable[i + 1:j]) and np.all(b.stable[j + 1:])
    assert np.all((b.p[i + 1:j] > lo) & (b.p[i + 1:j] < hi))
    # the folds located from the two directions agree to the location tolerance
    ups = [pt.parameter for bb in up.branches for pt in bb.special("fold")]
    downs = [pt.parameter for bb in down.branches for pt in bb.special("fold")]
    for f in ups:
        assert min(abs(f - g) for g in downs) <= 2 * LOCATE * f

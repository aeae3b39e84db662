"""A periodic gait found as a periodic optimal control problem (nscontrol.optimal.periodic):
the least paddle amplitude that juggles a ball once per period with a stability margin. The
closed forms (optimum, orbit, Floquet multipliers) against the transcription, the plan
replayed through Moreau–Jean, and the planned paddle's orbit found and its multipliers
computed by the library's orbit tools (event-driven with saltation matrices)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.analysis.orbits import Forced, find_orbit  # noqa: E402
from nscontrol.errors import ModelError  # noqa: E402
from nscontrol.optimal import JugglerProblem, VibratingTable, ZeroOrderHold  # noqa: E402

TABLE = VibratingTable()          # e = 0.6, T = 1 s, margin κ = 0.5
IPOPT_TOL = 1e-10                 # Relaxation().tol: each step's constraint is met to this


@pytest.fixture(scope="module")
def plans():
    return {n: TABLE.problem(n).solve() for n in (100, 200)}


def planned_orbit(jp):
    """The period-1 orbit of the planned paddle (exact sinusoid, event-driven), with its
    nodes at mid-flight (a node on the contact would start on an impact)."""
    p = jp.plan
    k = p.u.shape[0] // 2
    forced = Forced(TABLE.system(), TABLE.paddle(jp.amplitude, jp.phase + TABLE.omega * k * p.h),
                    TABLE.period, method="event_driven")
    return find_orbit(forced, p.x[k], tol=1e-12), k


def test_closed_forms_agree_with_each_other():
    A, psi = TABLE.optimum()
    e, k = TABLE.restitution, TABLE.margin
    # the optimum sits on the periodicity condition and on the margin
    assert A * np.cos(psi) == pytest.approx(TABLE.fold_amplitude, rel=1e-14)
    assert A * TABLE.omega ** 2 * np.sin(psi) == pytest.approx(k * TABLE.g, rel=1e-14)
    mu = TABLE.multipliers(A)
    assert np.sort_complex(mu) == pytest.approx(
        np.sort_complex(np.roots([1.0, -(1 + e ** 2 - k * (1 + e) ** 2), e ** 2])), abs=1e-14)
    # the closed-form state is periodic across the impact: take-off = e × arrival, reversed
    x0, xT = TABLE.state(A, [0.0, TABLE.period])
    assert x0[0] == pytest.approx(0.0, abs=1e-15) and xT[0] == pytest.approx(0.0, abs=1e-14)
    assert x0[1] == pytest.approx(-TABLE.restitution * xT[1], rel=1e-14)


def test_optimum_converges_at_first_order(plans):
    """Moreau–Jean is first order through an impact: the error in A halves with h (ratio
    2 + O(h)), and the Richardson combination 2 A_{2N} - A_N is second order, bounded by
    h_N² times the paddle's acceleration scale ω² A*."""
    A, psi = TABLE.optimum()
    err = {n: plans[n].amplitude - A for n in plans}
    assert 1.8 <= err[100] / err[200] <= 2.2
    h = TABLE.period / 100
    assert abs(2 * plans[200].amplitude - plans[100].amplitude - A) <= TABLE.omega ** 2 * A * h ** 2
    ph = {n: plans[n].phase - psi for n in plans}
    assert 1.8 <= ph[100] / ph[200] <= 2.2
    for jp in plans.values():
        assert jp.plan.residual <= 1e-8 and jp.plan.stats["active_set_consistent"]
        assert np.flatnonzero(jp.plan.active[:, 0]).tolist() == [0]   # one impact, on step 0


def test_plan_is_periodic_and_replays_through_moreau_jean(plans):
    """From the first state after the impact step that is not penetrated (step 2; Moreau–Jean's
    θ = ½ position update dips below the paddle on step 1) over one period, with the inputs
    held periodically: the replay crosses the next impact and comes back to the plan. Each
    step's constraints hold to IPOPT's tolerance, so the plan is within N × tol of the run."""
    for n, jp in plans.items():
        p = jp.plan
        assert np.max(np.abs(p.x[-1] - p.x[0])) <= IPOPT_TOL
        u = ZeroOrderHold(0.0, p.h, np.vstack([p.u, p.u]))
        run = nsc.simulate(TABLE.system(), p.x[2], (2 * p.h, (n + 2) * p.h),
                           method="moreau_jean", h=p.h, u=u)
        assert run.t.shape == (n + 1,)
        assert np.max(np.abs(run.x - np.vstack([p.x[2:], p.x[1:3]]))) <= n * IPOPT_TOL


def test_library_orbit_and_multipliers_of_the_planned_gait(plans):
    """The orbit tools find the period-1 orbit of the planned paddle (Newton to 1e-12 on the
    shooting residual) and its multipliers; both against the closed forms for that paddle,
    to the shooting tolerance times the map's Jacobian norm (≲ 10) over the multipliers'
    separation (≈ 1.2): 1e-9 allowed."""
    for jp in plans.values():
        orb, k = planned_orbit(jp)
        assert orb.n_impacts == 1 and orb.stable
        assert np.sort_complex(orb.multipliers) == pytest.approx(
            np.sort_complex(TABLE.multipliers(jp.amplitude)), abs=1e-9)
        # det = e² (Liouville on a divergence-free flight times Newton's e at the impact)
        assert abs(np.prod(orb.multipliers)) == pytest.approx(TABLE.restitution ** 2, abs=1e-9)
        # the orbit's node is the closed-form gait of that paddle, at the node's time after
        # its impact (which the plan put at t = 0 up to the phase error)
        t_node = k * jp.plan.h + (jp.phase - TABLE.impact_phase(jp.amplitude)) / TABLE.omega
        assert np.max(np.abs(orb.nodes[0] - TABLE.state(jp.amplitude, t_node)[0])) <= 1e-9
        # and the plan's state there is the orbit's to first order: within 10 h × |v| scale
        assert np.max(np.abs(orb.nodes[0] - jp.plan.x[k])) <= 10 * jp.plan.h * TABLE.g


def test_multipliers_converge_to_the_optimums(plans):
    """The planned paddle's multipliers approach those of the closed-form optimum at the
    rate of A (first order): |Δμ| ≤ |dμ/dA| |ΔA| with |dμ/dA| bounded by a difference."""
    A = TABLE.optimum()[0]
    mu = TABLE.multipliers(A)
    slope = np.max(np.abs(TABLE.multipliers(A * 1.01) - mu)) / (0.01 * A)
    for jp in plans.values():
        orb, _ = planned_orbit(jp)
        gap = np.max(np.abs(np.sort_complex(orb.multipliers) - np.sort_complex(mu)))
        assert gap <= 2 * slope * abs(jp.amplitude - A) + 1e-9


def test_bad_juggler_input_is_refused():
    with pytest.raises(ModelError, match="^restitution"):
        VibratingTable(restitution=1.0)
    with pytest.raises(ModelError, match="^steps"):
        JugglerProblem(TABLE, 2)
    with pytest.raises(ModelError, match="^amplitude"):
        TABLE.multipliers(0.5 * TABLE.fold_amplitude)

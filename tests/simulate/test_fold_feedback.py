"""Continuous state feedback ``u = K x + k`` folded into the forces of impacting bodies and of
any Lagrangian plant (:mod:`nscontrol.simulate.lowering.fold`,
:class:`~nscontrol.simulate.lowering.impacting_bodies.FeedbackOnLagrangianForm`): the loop
runs as the plant's own model, checked against closed forms and against the same law run as
a Python block."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.optimize import brentq

import nscontrol as nsc
from nscontrol.numerics.lti import Exosystem
from nscontrol.simulate.driver import integrator_for
from nscontrol.simulate.lowering import lower, lowerings
from nscontrol.simulate.lowering.fold import folded_plant
from nscontrol.systems.feedback import StateFeedback, StaticLaw
from nscontrol.systems.impacting_bodies import ImpactingBodies
from nscontrol.systems.lagrangian import LagrangianSystem

EPS = float(np.finfo(float).eps)
#: The loop of every test: u = -KP q1 - KD v1 + K0 on mass 1 (unit masses): between impacts
#: q1'' + KD q1' + KP q1 = K0, an underdamped oscillator about q1 = K0 / KP = 1.
KP, KD, K0 = 4.0, 0.4, 4.0
SIGMA, WD = KD / 2.0, np.sqrt(KP - (KD / 2.0) ** 2)


def oscillator(t: np.ndarray | float, q0: float, v0: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed form of ``q'' + KD q' + KP q = K0`` from ``(q0, v0)`` at ``t = 0``."""
    a = q0 - K0 / KP
    b = (v0 + SIGMA * a) / WD
    e, c, s = np.exp(-SIGMA * t), np.cos(WD * t), np.sin(WD * t)
    q = K0 / KP + e * (a * c + b * s)
    v = e * ((b * WD - SIGMA * a) * c - (a * WD + SIGMA * b) * s)
    return q, v


def first_crossing(q0: float, v0: float, level: float) -> float:
    """The first time ``t > 0`` the closed form reaches ``level`` from below (bracketed on a
    fine grid, then Brent's method to the last bit)."""
    t = np.linspace(0.0, 10.0, 100001)
    q, _ = oscillator(t, q0, v0)
    i = 1 + int(np.flatnonzero((q[1:] >= level) & (q[:-1] < level))[0])
    return brentq(lambda s: oscillator(s, q0, v0)[0] - level, t[i - 1], t[i], xtol=1e-16,
                  rtol=4 * EPS)


@dataclass(frozen=True)
class PythonLaw(StaticLaw):
    """The same law written as code: it runs as a block (``blocks=``)."""

    column: int = 0
    n_outputs: int = 1
    period: None = None

    def output(self, t, xc, m):
        return np.array([-KP * m.x[self.column] - KD * m.x[self.column + 1] + K0])


def _bodies() -> ImpactingBodies:
    # body a: mass 1 driven by u, body b: a free unit mass at rest at q2 = 0.5 (e = 1: equal
    # masses exchange their velocities at the impact)
    return ImpactingBodies([1.0], [[0.0]], [1.0], [[0.0]], restitution=1.0)


def _gain_loop(bodies: ImpactingBodies) -> nsc.systems.closed_loop.ClosedLoop:
    return nsc.closed_loop(bodies, StateFeedback([[-KP, -KD, 0.0, 0.0]], k=[K0]))


X0 = np.array([0.0, 0.0, 0.5, 0.0])     # [q1, v1, q2, v2]


def test_state_feedback_on_impacting_bodies_is_folded_and_exact_to_the_closed_form():
    bodies = _bodies()
    loop = _gain_loop(bodies)
    assert loop.composition == "folded"          # "blocks" before: DOP853 beside the law
    applied = lower(loop, integrator_for(loop, "event_driven"), X0, {})[3]
    assert [lw.name for lw, _ in applied] == [
        "state feedback on impacting bodies", "fold state feedback"]
    tr = nsc.simulate(loop, X0, (0.0, 3.0), method="event_driven", dt=0.01, progress=False)
    assert tr.state_names == bodies.state_names
    t1 = first_crossing(0.0, 0.0, 0.5)
    ti = tr.event_times("impact")
    assert ti.size == 1
    # the event is located on the exact flow: its error is the flow's roundoff over the
    # closing speed, ~ε|q|/|q'| = 1.4e-16; a factor 1e3 covers the root finder's bracket
    _, v1 = oscillator(t1, 0.0, 0.0)
    assert abs(ti[0] - t1) <= 1e3 * EPS / abs(v1)
    # between 0 and the impact the samples are the closed form (exact flow: e^{At} to a few
    # ulps of the state, |x| <= 2 here; factor 64)
    before = tr.t < ti[0]
    q, v = oscillator(tr.t[before], 0.0, 0.0)
    assert np.abs(tr.x[before, 0] - q).max() <= 64 * EPS * 2
    assert np.abs(tr.x[before, 1] - v).max() <= 64 * EPS * 2
    # after it: e = 1 and equal masses swap velocities, body a restarts from (0.5, 0)
    after = tr.t > ti[0]
    qa, va = oscillator(tr.t[after] - ti[0], 0.5, 0.0)
    # the restart carries the impact time's error times the speed (~1e-13 over 2.5 s of
    # decaying flow, factor 10)
    tol = 10 * (1e3 * EPS / abs(v1)) * abs(v1) + 64 * EPS * 2
    assert np.abs(tr.x[after, 0] - qa).max() <= tol
    assert np.abs(tr.x[after, 3] - v1).max() <= tol          # body b carries v1 away
    # the loop's signal u is the law at every sample
    np.testing.assert_allclose(tr.signal("u")[:, 0], -KP * tr.x[:, 0] - KD * tr.x[:, 1] + K0,
                               rtol=0, atol=1e-13)


def test_the_folded_bodies_agree_with_the_law_as_a_block():
    """Event-driven: the block runs on DOP853 (rtol 1e-10): impact times agree to that
    tolerance times the flight (1e3·rtol). Moreau–Jean: the folded law is implicit in the
    θ-method, the block is held over each step: both are first order, so their difference
    halves with h (ratio 2 ± 0.4) and falls below 3 h."""
    bodies = _bodies()
    folded, block = _gain_loop(bodies), nsc.closed_loop(bodies, PythonLaw())
    assert block.composition == "blocks"
    a = nsc.simulate(folded, X0, (0.0, 3.0), method="event_driven", progress=False)
    b = nsc.simulate(block, X0, (0.0, 3.0), method="event_driven", progress=False)
    assert np.abs(a.event_times("impact") - b.event_times("impact")).max() < 1e3 * 1e-10
    diffs = []
    for h in (2e-3, 1e-3, 5e-4):
        run = dict(method="moreau_jean", h=h, progress=False)
        fa = nsc.simulate(folded, X0, (0.0, 3.0), **run)
        fb = nsc.simulate(block, X0, (0.0, 3.0), **run)
        diffs.append(np.abs(fa.x[-1] - fb.x[-1]).max())
        assert diffs[-1] < 3 * h
        # both converge to the exact run (first order: within 3 h of it)
        assert np.abs(fa.x[-1] - a.x[-1]).max() < 3 * h
    for coarse, fine in zip(diffs, diffs[1:], strict=False):
        assert 1.6 < coarse / fine < 2.4


def test_a_damped_oscillator_against_a_wall_bounces_at_the_closed_form_times():
    """A 1-DOF Lagrangian plant: u = -KP q - KD v + K0 pulls the mass towards q = 1 beyond a
    wall at q = 0.5 (restitution 0.5). Each flight is the closed form from the wall; the
    impact times follow, each to the event location's roundoff."""
    e = 0.5
    plant = LagrangianSystem([[1.0]], gap_matrix=[[-1.0]], gap_offset=[0.5], restitution=e,
                             actuation=[[1.0]])
    loop = nsc.closed_loop(plant, StateFeedback([[-KP, -KD]], k=[K0]))
    tr = nsc.simulate(loop, [0.0, 0.0], (0.0, 4.0), method="event_driven", progress=False)
    ti = tr.event_times("impact")
    assert ti.size >= 3
    t, q, v = 0.0, 0.0, 0.0
    for k in range(3):
        tk = t + first_crossing(q, v, 0.5)
        _, vk = oscillator(tk - t, q, v)
        # each restart inherits the previous impact's error: k + 1 locations, factor 1e3
        assert abs(ti[k] - tk) <= (k + 1) * 1e3 * EPS * max(1.0, tk) / abs(vk), k
        t, q, v = tk, 0.5, -e * vk


def test_the_exosystem_of_a_folded_loop_drives_the_plant():
    """A constant reference w = 3 through the actuation is the constant force 3: the folded
    loop with the exosystem runs the same flow (before, the exosystem was dropped)."""
    kw = dict(stiffness=[[1.0]], gap_matrix=[[1.0]], gap_offset=[10.0], restitution=0.5)
    exo = Exosystem(S=[[0.0]], Cu=[[1.0]], w0=[3.0])
    loop = nsc.closed_loop(LagrangianSystem([[1.0]], actuation=[[1.0]], **kw),
                           StateFeedback([[-4.0, -1.0]]), exosystem=exo)
    by_hand = LagrangianSystem([[1.0]], constant_force=[3.0], **kw)
    gain = nsc.closed_loop(by_hand, StateFeedback([[-4.0, -1.0]]))
    for method, opts in (("event_driven", {"dt": 0.1}), ("moreau_jean", {"h": 1e-2})):
        a = nsc.simulate(loop, [0.0, 0.0], (0.0, 20.0), method=method, progress=False, **opts)
        b = nsc.simulate(gain, [0.0, 0.0], (0.0, 20.0), method=method, progress=False, **opts)
        # the same flow, one with the input as an augmented state: 1e3 ε per unit time
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e3 * EPS * 20)
        assert abs(a.x[-1, 0] - 3.0 / 5.0) < 1e-3            # q* = 3 / (1 + 4)
        assert "u" in a.signals


def test_a_nonlinear_plant_keeps_its_terms_and_gets_the_gain_as_linear_forces():
    curved = LagrangianSystem(lambda q: np.eye(1), gap_matrix=[[-1.0]], gap_offset=[0.5],
                              restitution=0.7, actuation=[[1.0]], constant_force=[2.0],
                              force=lambda t, q, v: -0.1 * q ** 3)
    loop = nsc.closed_loop(curved, StateFeedback([[-4.0, -0.3]], k=[1.0]))
    assert loop.composition == "folded"
    model, _ = folded_plant(loop)
    assert model.force is curved.force and model.mass is curved.mass
    np.testing.assert_array_equal(model.stiffness, [[4.0]])
    np.testing.assert_array_equal(model.damping, [[0.3]])
    np.testing.assert_array_equal(model.constant_force, [3.0])


def test_the_new_lowering_is_registered_after_the_bodies_own_form():
    names = [lw.name for lw in lowerings()]
    assert names.index("state feedback on impacting bodies") > \
        names.index("Lagrangian form of impacting bodies")


def test_a_gain_of_the_wrong_shape_on_bodies_is_refused():
    with pytest.raises(nsc.DimensionError, match=r"^controller: K must have shape \(1, 4\)"):
        nsc.closed_loop(_bodies(), StateFeedback([[-1.0, 0.0]]))

"""The lowerings: the registry, the rule that a closed loop is always lowered (whatever the
method's ``supports`` says), chains of lowerings, and partial trajectories mapped back."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.simulate import Integrator, Lowering, Trajectory, register_lowering
from nscontrol.simulate.driver import check_run
from nscontrol.simulate.lowering import lowerings
from nscontrol.systems.closed_loop import ClosedLoop
from nscontrol.systems.feedback import StateFeedback
from nscontrol.systems.impacting_bodies import ImpactingBodies
from nscontrol.systems.lagrangian import LagrangianSystem


def _bodies() -> ImpactingBodies:
    return ImpactingBodies.from_springs([1.0, 2.0], [3.0], {(0, 0): 1.0, (0, 1): 0.5},
                                        {(0, 0): 2.0}, E=[0.0, 1.0], restitution=0.7)


class Damper:
    """A static law ``u = -c x[i]`` on the state the block reads (``m.x``)."""

    n_states, n_outputs, period = 0, 1, None

    def __init__(self, c: float, index: int) -> None:
        self.c, self.index = c, index

    def output(self, t, xc, m):
        return np.array([-self.c * m.x[self.index]])

    def update(self, t, xc, m):
        return xc

    def reset(self, t, xc, jump):
        return xc


def test_a_closed_loop_is_lowered_even_for_a_method_that_claims_it():
    """Feedback reaches an integrator one way: a method whose ``supports`` says yes to a
    closed loop is still handed the lowered model (here the folded plant), never the loop."""
    seen = []

    class LoopRunner(Integrator):
        name = "loop_runner"

        @classmethod
        def supports(cls, system):
            return True

        def integrate(self, system, x0, t_span, **options):
            seen.append(system)
            x = np.asarray(x0, float)
            return Trajectory(t=np.array(t_span, float), x=np.vstack([x, x]))

    plant = LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0],
                             constant_force=[-1.0])
    loop = nsc.closed_loop(plant, nsc.systems.StateFeedback([[-4.0, -1.0]], k=[5.0]))
    traj = nsc.simulate(loop, [0.2, 0.0], (0.0, 1.0), method=LoopRunner)
    assert len(seen) == 1 and not isinstance(seen[0], ClosedLoop)
    assert isinstance(seen[0], LagrangianSystem)       # the plant, the law folded in
    np.testing.assert_array_equal(seen[0].stiffness, [[4.0]])   # - S K_q
    assert "u" in traj.signals           # the fold's invert ran: the law's output added


def test_python_blocks_around_impacting_bodies_chain_two_lowerings():
    """Python blocks -> the bodies with their blocks= -> their Lagrangian form: the blocks
    read the bodies' own state order, the trajectory comes back in it. The same loop written
    on the Lagrangian form (the block reading the same entry there) is the same arithmetic."""
    bodies = _bodies()
    perm = bodies.lagrangian_permutation()
    back = np.argsort(perm)
    x0 = np.array([0.0, 0.1, 0.3, 0.0, 1.0, -0.5])     # [x_a; x_b]
    i = 3                                              # v2 in the bodies' order
    run = dict(method="moreau_jean", h=1e-3)
    traj = nsc.simulate(nsc.closed_loop(bodies, Damper(2.0, i)), x0, (0.0, 3.0), **run)
    ref = nsc.simulate(nsc.closed_loop(bodies.lagrangian(), Damper(2.0, back[i])), x0[perm],
                       (0.0, 3.0), **run)
    assert traj.state_names == bodies.state_names
    assert len(traj.events) > 0 or np.any(traj.signal("impulse"))   # impacts happened
    np.testing.assert_array_equal(traj.x, ref.x[:, back])
    np.testing.assert_array_equal(traj.signal("u"), ref.signal("u"))


def test_one_lowering_gives_both_integrators_the_bodies_order():
    """Listeners receive the states in the bodies' order from event_driven and moreau_jean
    alike (the gap ``q_{na+1} - q_na`` of the bodies' order closes at every impact), and a
    closed loop's law on ``[x_a; x_b]`` acts on the entries it names."""
    bodies = _bodies()
    x0 = np.array([0.0, 0.1, 0.3, 0.0, 1.0, -0.5])
    h = 1e-3
    # event_driven: the gain as a closed loop on [x_a; x_b] (its law evaluated along the flow);
    # moreau_jean: a Python block on the same entry (stepped with the plant)
    gain = nsc.closed_loop(bodies, StateFeedback([[0.0, 0.0, 0.0, -0.5, 0.0, 0.0]]))
    for method, system, opts in (
            ("event_driven", gain, {}),
            ("moreau_jean", nsc.closed_loop(bodies, Damper(0.5, 3)), {"h": h})):
        jumps = []
        traj = nsc.simulate(system, x0, (0.0, 3.0), method=method, progress=False,
                            listeners=[lambda t, a, b, c, p, seen=jumps: seen.append(b)],
                            **opts)
        assert jumps, method
        np.testing.assert_array_equal(traj.x[0], x0)
        speed = np.max(np.abs(traj.x[:, [2, 3, 5]]))
        # event-driven: at the located impact, to the location's roundoff; Moreau–Jean:
        # the contact is captured within a step, so the gap is within h times the speed
        tol = 1e-9 if method == "event_driven" else 2 * h * speed
        gaps = [bodies.gap(x) for x in jumps]
        assert max(abs(g) for g in gaps) <= tol, (method, gaps)


def test_a_failed_loop_keeps_its_signals_in_the_partial_trajectory():
    class Failing(Damper):
        def output(self, t, xc, m):
            return np.array([np.nan if t > 0.2 else 0.0])

    plant = LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[100.0],
                             actuation=[[1.0]])
    loop = nsc.closed_loop(plant, Failing(1.0, 0))
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite") as info:
        nsc.simulate(loop, [0.0, 0.0], (0.0, 1.0), h=0.01)
    partial = info.value.trajectory
    assert partial.t[-1] >= 0.19
    assert partial.signal("u").shape == (len(partial.t), 1)
    assert np.all(partial.signal("u") == 0.0)


def test_what_no_lowering_runs_is_refused_and_the_registry_checks_its_entries():
    with pytest.raises(ModelError, match=r"^switching: integrates .*got ImpactingBodies; "
                                         r"use method='event_driven'"):
        nsc.simulate(_bodies(), np.zeros(6), (0.0, 1.0), method="switching")
    assert check_run(_bodies(), "moreau_jean", {"h": 1e-3}).name == "moreau_jean"

    class Nameless(Lowering):
        pass

    with pytest.raises(ModelError, match=r"^lowering: expected an instance"):
        register_lowering(Nameless)
    with pytest.raises(ModelError, match=r"^lowering: Nameless.name is empty"):
        register_lowering(Nameless())
    names = [lowering.name for lowering in lowerings()]
    assert names[:4] == ["stack linear blocks", "fold state feedback", "run Python blocks",
                         "Lagrangian form of impacting bodies"]


def test_sensitivity_of_impacting_bodies_is_refused_with_what_to_do():
    bodies = _bodies()
    x0 = np.array([0.0, 0.1, 0.3, 0.0, 1.0, -0.5])
    with pytest.raises(ModelError, match=r"^sensitivity: event_driven computes the state "
                                         r"transition of a LagrangianSystem.*\.lagrangian\(\)"):
        nsc.simulate(bodies, x0, (0.0, 1.0), sensitivity=True)
    with pytest.raises(ModelError, match=r"^sensitivity: method 'moreau_jean' does not "):
        nsc.simulate(bodies, x0, (0.0, 1.0), method="moreau_jean", h=1e-3, sensitivity=True)

"""check_system covers frictional contacts: the impulses of a short run lie in the Coulomb
cone and oppose the slip."""

import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.systems import brick_stack, brick_stack_rest_state, inclined_block, rolling_sphere
from nscontrol.testing import check_system


@pytest.mark.parametrize("system, x0", [
    (inclined_block(0.3, 0.5), [0.0, 0.0, 1.0, 0.0]),                         # sliding
    (rolling_sphere(0.3), [0, 0, 0.1, 0, 0, 0, 2.0, 0.5, 0, 1.0, 10.0, 0]),    # spatial slip
    (brick_stack(3, 0.5, angle=0.1), brick_stack_rest_state(3)),              # stick
])
def test_frictional_systems_pass_with_the_friction_checks(system, x0):
    report = check_system(system, x0=x0)   # h = span / 100 by default
    names = [item.name for item in report.items]
    assert any("Coulomb cone" in n for n in names) and any("oppose the slip" in n for n in names)


def test_frictional_systems_default_to_moreau_jean_and_event_driven_takes_one_planar_contact():
    import nscontrol as nsc

    block = inclined_block(0.3, 0.5)
    assert block.default_method == "moreau_jean"
    # one planar contact held closed: event-driven integrates it (stick/slip located exactly)
    slide = nsc.simulate(block, [0.0, 0.0, 1.0, 0.0], (0.0, 0.1), method="event_driven")
    assert np.isfinite(slide.x).all()
    # a spatial contact (two tangent directions) is refused, naming the way that works
    sphere = rolling_sphere(0.3)
    with pytest.raises(ModelError, match="moreau_jean"):
        nsc.simulate(sphere, [0, 0, 0.1, 0, 0, 0, 2.0, 0.5, 0, 1.0, 10.0, 0], (0.0, 0.1),
                     method="event_driven")
    assert np.isfinite(nsc.simulate(block, [0.0] * 4, (0.0, 0.01), h=1e-3).x).all()

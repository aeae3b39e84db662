"""The worked example of docs/architecture.md runs and does what it says: a user-written
sampled controller on a Moreau–Jean plant, reading the contact multiplier."""

from __future__ import annotations

import numpy as np


def test_the_sampled_force_controller_of_the_architecture_page(doc_block):
    scope, _ = doc_block("### Worked example: a sampled force controller")
    traj = scope["traj"]
    u = traj.signal("u")[:, 0]
    lam_hat = traj.signal("impulse")[:, 0] / 1e-3
    # at rest against the wall the contact force balances the actuator: lambda = u = f_ref.
    # The integral loop contracts by (1 - T ki) = 0.8 a sample once in contact; after the
    # landing transient (< 1 s) 200 samples leave 0.8^200 ~ 4e-20 of the error: roundoff.
    assert abs(u[-1] - 3.0) < 1e-9 and abs(lam_hat[-1] - 3.0) < 1e-9
    # Moreau–Jean captures the landing within a step: penetration <= h |v-| (landing speed)
    assert np.max(traj.x[:, 0]) <= 1e-3 * np.max(np.abs(traj.x[:, 1]))

"""Speed of the exact LTI numerics: first_event per call and propagation per time point.

No Siconos counterpart is run here (its event-driven scheme locates events with its own ODE
integrator, measured in the mechanics benchmark); ``reference`` is null. Accuracy figures
say what each call computed (error of the event time against the closed form).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import time_per_call

from nscontrol.numerics.lti import Exosystem, LTIFlow, augment, first_event

HARMONIC = np.array([[0.0, 1.0], [-1.0, 0.0]])
GRAVITY = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -9.81], [0.0, 0.0, 0.0]])


def _record(scenario: str, size: int, seconds: float, accuracy: dict[str, Any]) -> dict:
    return {"scenario": scenario, "size": size, "ours_s_per_solve": seconds,
            "reference": None, "reference_s_per_solve": None, "ratio": None,
            "accuracy": accuracy}


def run(quick: bool = False) -> Iterator[dict]:
    budget = 0.2 if quick else 1.0
    flow = LTIFlow(HARMONIC)
    ev = first_event(flow, [1.0, 0.0], [[1.0, 0.0]], [0.0], 10.0)
    yield _record("lti_first_event_crossing_eig", 2,
                  time_per_call(lambda: first_event(flow, [1.0, 0.0], [[1.0, 0.0]], [0.0], 10.0),
                                budget=budget), {"t_error": abs(ev.t - np.pi / 2)})
    ev = first_event(flow, [1.0, 0.0], [[1.0, 0.0]], [1.0 - 1e-8], 10.0)
    t_ex = np.pi - 2 * np.arcsin(np.sqrt(0.5e-8))
    yield _record("lti_first_event_close_double_root", 2,
                  time_per_call(lambda: first_event(flow, [1.0, 0.0], [[1.0, 0.0]],
                                                    [1.0 - 1e-8], 10.0), budget=budget),
                  {"t_error": abs(ev.t - t_ex)})
    fall = LTIFlow(GRAVITY)
    ev = first_event(fall, [1.0, 0.0, 1.0], [[1.0, 0.0, 0.0]], [0.0], 10.0)
    yield _record("lti_first_event_free_fall_expm", 3,
                  time_per_call(lambda: first_event(fall, [1.0, 0.0, 1.0], [[1.0, 0.0, 0.0]],
                                                    [0.0], 10.0), budget=budget),
                  {"t_error": abs(ev.t - np.sqrt(2 / 9.81))})
    A = np.array([[0.0, 1.0], [-4.0, -0.2]])
    big = augment(A, [[0.0], [1.0]], Exosystem.sinusoid(1.0, 1.3, offset=0.1))
    bflow = LTIFlow(big)
    X0 = np.array([0.5, 0.0, 0.0, 1.0, 1.0])
    ts = np.linspace(0.0, 30.0, 1000)
    yield _record("lti_propagate_1000_times", 5,
                  time_per_call(lambda: bflow.propagate(X0, ts), budget=budget) / 1000,
                  {"method": bflow.method})

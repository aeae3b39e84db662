"""event_driven and switching run through the one loop (``simulate/loop.py``'s ``drive``):
its progress bar sees one update per piece (a flight and its event), in time order, up to the
end of the span — the methods own no bar and no run loop of their own."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from nscontrol.simulate import loop, simulate
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.testing.mechanics_problems import BouncingBall


class _Bar:
    """Stands for the loop's progress bar: keeps the times it is given."""

    made: list[_Bar] = []

    def __init__(self, t0: float, tf: float, *, desc: str, enable: Any) -> None:
        self.desc, self.span, self.times = desc, (t0, tf), []
        _Bar.made.append(self)

    def __enter__(self) -> _Bar:
        return self

    def __exit__(self, *exc: Any) -> None:
        return None

    def update(self, t: float) -> None:
        self.times.append(t)


@pytest.fixture
def bars(monkeypatch: pytest.MonkeyPatch) -> list[_Bar]:
    _Bar.made = []
    monkeypatch.setattr(loop, "TimeProgress", _Bar)
    return _Bar.made


def test_event_driven_advances_one_flight_and_its_event_at_a_time(bars) -> None:
    ball = BouncingBall(restitution=0.5)
    # a ball of restitution 0.5 under gravity, t in [0, 0.5]: a few bounces, no accumulation
    traj = simulate(ball.system(), ball.x0, (0.0, 0.5), max_events=1000)
    (bar,) = bars
    assert bar.desc == "event_driven" and bar.span == (0.0, 0.5)
    # every impact settled by Python or by the compiled loop ends at most one piece; the last
    # piece reaches tf
    assert 1 <= len(bar.times) <= len(traj.events) + 1
    assert bar.times == sorted(bar.times) and bar.times[-1] == 0.5


def test_switching_advances_one_piece_at_a_time(bars) -> None:
    # a relay-like PWA oscillator, crossings at x1 = 0: the compiled PWA loop is one piece
    A = np.array([[0.0, 1.0], [-1.0, -0.1]])
    pwa = PiecewiseAffineSystem.bimodal([[0.0, 1.0], [-2.0, -0.1]], A, [1.0, 0.0])
    traj = simulate(pwa, [1.0, 0.0], (0.0, 20.0))
    (bar,) = bars
    assert bar.desc == "switching" and bar.times[-1] == 20.0
    assert len(traj.events_of("crossing")) > 3
    # a Filippov system: one DOP853 piece per event (crossing, sliding start or exit); the
    # relay example's fields as Python callables (given as data it runs in the compiled loop)
    from nscontrol.systems.switched import FilippovSystem
    from nscontrol.testing.setvalued_problems import relay_feedback

    p = relay_feedback(T=2.0)
    A, g, c = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0]), np.ones(2)
    f = FilippovSystem.two_sided(lambda t, x: A @ x + g, lambda t, x: A @ x - g,
                                 lambda x: float(c @ x), 2, gradient=lambda x: c)
    traj = simulate(f, p.x0, p.t_span, method="switching")
    assert traj.stats["propagation"] == "dop853"
    bar = bars[-1]
    assert len(bar.times) == traj.stats["pieces"] and bar.times == sorted(bar.times)
    assert bar.times[-1] == p.t_span[1]

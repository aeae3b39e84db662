"""Chattering measures on signals with known answers."""

import numpy as np
import pytest

from nscontrol.analysis import (
    chattering_amplitude,
    fitted_order,
    reaching_time,
    switching_frequency,
)
from nscontrol.errors import ModelError


def test_switching_frequency_of_a_square_wave():
    t = np.linspace(0.0, 10.0, 10001)
    u = np.sign(np.sin(2 * np.pi * 3.0 * t + 0.1))
    # 3 Hz square wave: 6 sign changes per unit time; the window's end effects change the
    # count by at most one change over 10 time units
    assert abs(switching_frequency(t, u) - 6.0) <= 0.1 + 1e-12


def test_amplitude_and_reaching_time():
    t = np.linspace(0.0, 2.0, 201)
    s = np.where(t < 1.0, 1.0 - t, 1e-3 * np.cos(50 * t))
    assert chattering_amplitude(t, s, after=1.0) <= 1e-3
    assert reaching_time(t, s, tol=2e-3) == pytest.approx(t[np.argmax(1.0 - t <= 2e-3)])


def test_fitted_order_recovers_a_power_law_exactly():
    h = np.array([1e-1, 1e-2, 1e-3])
    fit = fitted_order(h, 5.0 * h ** 1.5)
    # least squares on exact logs: error a few eps x |log h| ~ 1e-14
    assert abs(fit.order - 1.5) <= 1e-12 and fit.residual <= 1e-12


def test_fitted_order_refuses_non_positive_values():
    with pytest.raises(ModelError, match="^h, values: expected at least two positive"):
        fitted_order([1e-2, 1e-3], [1e-4, 0.0])

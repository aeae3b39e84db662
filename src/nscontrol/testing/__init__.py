"""Canonical problems with known answers (a conformance suite every integrator and solver
runs) and :func:`check_system` for user-defined systems and laws.

Modules: :mod:`~nscontrol.testing.lcp_problems` (LCPs with known solutions, random P- and
PSD-matrices), :mod:`~nscontrol.testing.mechanics_problems` (bouncing ball, resting stack,
Newton's cradle, impact oscillator), :mod:`~nscontrol.testing.setvalued_problems` (relay and
Lur'e problems), :mod:`~nscontrol.testing.cycle_problems` (smooth limit cycles known exactly
or as series: polar normal forms, Van der Pol), :mod:`~nscontrol.testing.check`
(:func:`check_system`).
"""

from .check import CheckItem, CheckReport, check_system

__all__ = ["check_system", "CheckReport", "CheckItem"]

"""The result of a trajectory optimisation: the planned states, inputs and contact forces on
the time-stepping grid, the complementarity residual, the solver's record, and views as the
library's :class:`~nscontrol.simulate.Trajectory` and as an input signal for replay."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray

__all__ = ["ContactPlan", "ZeroOrderHold"]


@dataclass(frozen=True)
class ZeroOrderHold:
    """An input held constant over each step: ``u(t) = values[k]`` on ``[t0 + k h,
    t0 + (k+1) h)``, the last value after the grid; what a time-stepping integrator reads at
    its step starts ``t0 + k h`` (a time within ``1e-7 h`` below a grid point counts as that
    point, so the rounding of ``t0 + k h`` never selects the previous step).

    Parameters
    ----------
    t0 : float
        Start of the grid.
    h : float
        Step.
    values : ndarray, shape (N, p)
        One input per step.
    """

    t0: float
    h: float
    values: FloatArray

    def __call__(self, t: float) -> FloatArray:
        k = int(np.floor((float(t) - self.t0) / self.h + 1e-7))
        return self.values[min(max(k, 0), self.values.shape[0] - 1)].copy()


@dataclass(frozen=True)
class ContactPlan:
    """A planned motion on the time-stepping grid ``t_k = k h`` (``k = 0..N``).

    Attributes
    ----------
    t : ndarray, shape (N + 1,)
        Grid times.
    x : ndarray, shape (N + 1, 2 n)
        Planned states ``[q; v]``.
    u : ndarray, shape (N, p)
        Inputs, held over each step.
    normal : ndarray, shape (N, m)
        Normal contact forces of each step (the step's impulse over ``h``).
    friction : ndarray, shape (N, m)
        Tangential (friction) forces of each step (zeros without friction).
    active : ndarray of bool, shape (N, m)
        The contacts the Moreau–Jean test ``g + γ h G v <= tol`` closes at each step.
    h : float
        The step (a decision variable of a minimum-time problem).
    cost : float
        The objective at the plan.
    residual : float
        Complementarity residual: the largest ``|min(a, b)|`` over the pairs
        ``0 <= a ⟂ b >= 0`` of the active contacts (force and velocity units).
    stats : dict
        ``stages`` (one record per IPOPT solve: ``sigma``, ``iterations``, ``status``,
        ``solve_time`` in seconds), ``solve_time`` (their sum), ``iterations``,
        ``polished``, ``active_set_rounds``, ``active_set_consistent``.
    state_names : tuple of str
        The system's state names.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    normal: FloatArray
    friction: FloatArray
    active: np.ndarray
    h: float
    cost: float
    residual: float
    stats: dict[str, Any] = field(default_factory=dict)
    state_names: tuple[str, ...] = ()

    @property
    def duration(self) -> float:
        """``N h``, the planned horizon."""
        return float(self.t[-1] - self.t[0])

    def input(self) -> ZeroOrderHold:
        """The planned inputs as the signal ``u=`` of ``simulate`` (zero-order hold)."""
        return ZeroOrderHold(float(self.t[0]), self.h, self.u)

    def trajectory(self) -> Any:
        """The plan as a :class:`~nscontrol.simulate.Trajectory` (``method="optimal"``), laid
        out as Moreau–Jean records a run: row ``k + 1`` holds step ``k``'s impulses
        (signals ``impulse``, ``friction_impulse``; row 0 zeros) and ``u`` the input held
        from row ``k`` (the last row repeats the last input).

        Returns
        -------
        Trajectory
        """
        from ..simulate.trajectory import Trajectory

        m = self.normal.shape[1]
        zero = np.zeros((1, m))
        u = np.vstack([self.u, self.u[-1:]]) if self.u.shape[0] else self.u
        signals = {"u": u, "impulse": np.vstack([zero, self.h * self.normal]),
                   "friction_impulse": np.vstack([zero, self.h * self.friction])}
        return Trajectory(t=self.t, x=self.x, signals=signals,
                          stats={**self.stats, "h": self.h, "cost": self.cost,
                                 "residual": self.residual},
                          method="optimal", state_names=self.state_names,
                          message="planned by nscontrol.optimal")

"""The one-link robot with set-valued Stribeck friction (chapter 7) as a Lur'e system.

The link angle ``theta`` and velocity ``omega`` obey ``J omega' = u - T_f``,
``T_f in F(omega)``, with ``F`` a set-valued Stribeck law (``nscontrol.laws.Stribeck``;
``F(0) = [-T_s, T_s]``). ``F`` is not monotone when the curve falls (``sigma_tan > 0``), so
the Lur'e model carries its monotone part ``F_m = F + sigma I`` and the slope ``sigma/J``
moves into the linear part (the loop transformation of chapter 8)::

    x = (theta, omega),  x' = A x + G w + B u,  w in -F_m(omega)
    A = [[0, 1], [0, sigma/J]],  G = B = [0, 1/J]^T,  H = [0, 1],  C = [1, 0]

Backward Euler on this model (``simulate(..., method="implicit_euler", h=h)``) is exactly
the friction step with its stick and slip branches: with ``omega_free = omega_k + h u/J``,
the link sticks (``omega_{k+1} = 0``) when ``|omega_free| <= h T_s/J``, otherwise
``J v + h s f(|v|) = J omega_free`` (``s = sign(omega_free)``). The step has one solution
when ``h sigma_tan < J`` (its left side then increases strictly);
:meth:`OneLinkRobot.check_step` refuses larger steps with the bound.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import FloatArray, check_positive
from ..errors import ModelError

__all__ = ["OneLinkRobot"]


@dataclass(frozen=True, eq=False)
class OneLinkRobot:
    """A rigid link on a motor with velocity-dependent set-valued friction, angle measured.

    Parameters
    ----------
    J
        Total inertia ``J > 0`` [kg m^2] (motor, gearbox and link).
    friction
        The friction law ``F`` (a one-component ``Stribeck`` or ``AsymmetricStribeck``,
        or any one-component law of :mod:`nscontrol.laws`, e.g. ``Coulomb``).

    Attributes
    ----------
    sigma
        The slope moved into the linear part: the law's ``sigma_tan`` (0 for a monotone law).
    """

    J: float
    friction: Any
    sigma: float = 0.0

    def __post_init__(self) -> None:
        from ..laws.base import SetValuedLaw

        object.__setattr__(self, "J", check_positive("J", self.J))
        if not isinstance(self.friction, SetValuedLaw) or self.friction.dim != 1:
            raise ModelError(f"friction: expected a one-component set-valued law (Stribeck, "
                             f"Coulomb), got {self.friction!r}")
        sig = float(np.asarray(getattr(self.friction, "sigma_tan", 0.0)).reshape(-1)[0])
        if not np.isfinite(sig):
            raise ModelError("friction: its curve falls infinitely steeply at 0+ (delta < 1, "
                             "sigma_tan = inf): no time step resolves it uniquely; use "
                             "delta >= 1")
        object.__setattr__(self, "sigma", sig)

    def max_step(self) -> float:
        """``J / sigma_tan``: backward Euler needs ``h < J / sigma_tan`` (inf if monotone)."""
        return np.inf if self.sigma == 0.0 else self.J / self.sigma

    def check_step(self, h: float) -> float:
        """``h`` if the one-step friction problem has a unique solution, else ``ModelError``.

        Parameters
        ----------
        h
            Time step ``> 0``.

        Raises
        ------
        ModelError
            ``h sigma_tan >= J`` (the step may have several solutions); the message gives
            the bound.
        """
        h = check_positive("h", h)
        if h * self.sigma >= self.J:
            raise ModelError(f"h: the implicit friction step needs h * sigma_tan < J, got "
                             f"h * sigma_tan = {h * self.sigma:.6g} >= J = {self.J:.6g}; use "
                             f"h < J / sigma_tan = {self.max_step():.6g} s")
        return h

    def lure_system(self) -> Any:
        """The loop-transformed Lur'e model (module docstring): state ``(theta, omega)``,
        input the motor torque ``u``, output ``y = theta``.

        Returns
        -------
        LureSystem
        """
        from .lure import LureSystem

        J = self.J
        A = np.array([[0.0, 1.0], [0.0, 0.0]])
        G = np.array([[0.0], [1.0 / J]])
        H = np.array([[0.0, 1.0]])
        law = self.friction
        if not law.monotone:
            lt = law.loop_transformation(self.sigma)
            A, law = lt.transform_A(A, G, H), lt.monotone_part
        return LureSystem(A, G, H, law, B=G.copy(), C=np.array([[1.0, 0.0]]),
                          state_names=("theta", "omega"))

    def friction_torque(self, omega: FloatArray, w: FloatArray) -> FloatArray:
        """The friction torque ``T_f in F(omega)`` from the Lur'e multiplier ``w``.

        ``w in -F_m(omega)`` and ``F = F_m - sigma I``, so ``T_f = -w - sigma omega``.
        """
        return -np.asarray(w, float) - self.sigma * np.asarray(omega, float)

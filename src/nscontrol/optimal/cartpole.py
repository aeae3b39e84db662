r"""A cart-pole balanced between two walls: the example of contact-implicit MPC.

A cart of mass ``m_c`` on a horizontal track carries a pole, a massless rod of length ``l``
with a point mass ``m_p`` at its tip, pushed by a horizontal force ``u`` on the cart. With
``q = (x, θ)`` (cart position, pole angle from upright, positive when the tip moves towards
``+x``) and linearised about the upright pole (kinetic energy
``½ (m_c + m_p) ẋ² + m_p l ẋ θ̇ + ½ m_p l² θ̇²``, potential ``m_p g l cos θ ≈ m_p g l (1 - θ²/2)``),

    M = [[m_c + m_p, m_p l], [m_p l, m_p l²]],     K = [[0, 0], [0, -m_p g l]],

a linear :class:`~nscontrol.systems.LagrangianSystem` whose stiffness is negative: the upright
pole is unstable. Two rigid walls stand at ``x = ±d`` at the height of the tip; the tip's
horizontal position is ``x + l θ`` (linearised), so the gaps are

    g₁ = d - (x + l θ) >= 0 (right wall),     g₂ = d + (x + l θ) >= 0 (left wall),

with Newton restitution ``e`` at the impacts. Since the walls and the small-angle model are
the same kind of idealisation, this is the linear complementarity model of the published
cart-pole-with-walls benchmarks of contact-implicit MPC, with rigid walls and impacts in
place of their soft walls.

:meth:`CartPole.nonlinear_system` is the same cart-pole without the small-angle
approximation: ``M(θ) = [[m_c + m_p, m_p l cos θ], [m_p l cos θ, m_p l²]]``, the force
``(m_p l sin θ θ̇², m_p g l sin θ)`` (centrifugal and gravity) and the gaps
``d ∓ (x + l sin θ)``, the walls being vertical planes that the tip (and only the tip) meets.
It is the plant on which the example checks that a controller planned on the linear model
still works.

The wall-free model (:meth:`CartPole.free_system`) is what a linear MPC ignoring the contacts
plans with; its Moreau–Jean step without contacts is the linear map
``x_{k+1} = A x_k + B u_k`` of :meth:`CartPole.step_matrices`, and :meth:`CartPole.lqr` the
infinite-horizon LQR of the MPC's stage cost on that map (its value ``xᵀ P x`` is the terminal
cost of both controllers of the example).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import FloatArray, as_vector, check_in_interval, check_positive
from ..systems.lagrangian import LagrangianSystem

__all__ = ["CartPole"]


@dataclass(frozen=True)
class CartPole:
    """The cart-pole between two walls, linearised about the upright pole (the module
    docstring).

    Parameters
    ----------
    cart_mass : float
        ``m_c > 0`` [kg].
    pole_mass : float
        ``m_p > 0``, the point mass at the tip [kg].
    length : float
        ``l > 0`` [m].
    wall : float
        ``d > 0``: the walls stand at ``x = ±d`` [m].
    restitution : float
        Newton's ``e`` in ``[0, 1]`` at the walls.
    g : float
        Gravity [m/s²].
    """

    cart_mass: float = 1.0
    pole_mass: float = 0.5
    length: float = 0.5
    wall: float = 0.1
    restitution: float = 0.5
    g: float = 9.81

    def __post_init__(self) -> None:
        for name in ("cart_mass", "pole_mass", "length", "wall", "g"):
            check_positive(name, getattr(self, name))
        check_in_interval("restitution", self.restitution, 0.0, 1.0)

    def _matrices(self) -> tuple[FloatArray, FloatArray]:
        mc, mp, l = self.cart_mass, self.pole_mass, self.length
        M = np.array([[mc + mp, mp * l], [mp * l, mp * l * l]])
        K = np.array([[0.0, 0.0], [0.0, -mp * self.g * l]])
        return M, K

    def system(self) -> LagrangianSystem:
        """The cart-pole with the two walls (contacts: right wall, left wall)."""
        M, K = self._matrices()
        l, d = self.length, self.wall
        return LagrangianSystem(M, stiffness=K, gap_matrix=[[-1.0, -l], [1.0, l]],
                                gap_offset=[d, d], restitution=self.restitution,
                                actuation=[[1.0], [0.0]], names=("x", "theta"))

    def free_system(self) -> LagrangianSystem:
        """The same cart-pole without walls (what a linear MPC ignoring contacts plans
        with)."""
        M, K = self._matrices()
        return LagrangianSystem(M, stiffness=K, gap_matrix=np.zeros((0, 2)),
                                actuation=[[1.0], [0.0]], names=("x", "theta"))

    def nonlinear_system(self) -> LagrangianSystem:
        """The cart-pole with the walls, without the small-angle approximation (the module
        docstring): configuration-dependent mass, nonlinear force and gaps, with their
        analytic Jacobians."""
        mc, mp, l, g, d = self.cart_mass, self.pole_mass, self.length, self.g, self.wall

        def mass(q: FloatArray) -> FloatArray:
            c = np.cos(q[1])
            return np.array([[mc + mp, mp * l * c], [mp * l * c, mp * l * l]])

        def force(t: float, q: FloatArray, v: FloatArray) -> FloatArray:
            s = np.sin(q[1])
            return np.array([mp * l * s * v[1] ** 2, mp * g * l * s])

        def force_jacobian(t: float, q: FloatArray, v: FloatArray
                           ) -> tuple[FloatArray, FloatArray]:
            s, c = np.sin(q[1]), np.cos(q[1])
            return (np.array([[0.0, mp * l * c * v[1] ** 2], [0.0, mp * g * l * c]]),
                    np.array([[0.0, 2.0 * mp * l * s * v[1]], [0.0, 0.0]]))

        def gap(q: FloatArray) -> FloatArray:
            tip = q[0] + l * np.sin(q[1])
            return np.array([d - tip, d + tip])

        def jacobian(q: FloatArray) -> FloatArray:
            c = np.cos(q[1])
            return np.array([[-1.0, -l * c], [1.0, l * c]])

        return LagrangianSystem(mass, force=force, force_jacobian=force_jacobian, gap=gap,
                                jacobian=jacobian, restitution=self.restitution,
                                actuation=[[1.0], [0.0]], names=("x", "theta"))

    def tip(self, x: FloatArray, linear: bool = True) -> FloatArray:
        """Horizontal position of the tip, ``x + l θ`` (``x + l sin θ`` when not
        ``linear``), of states ``(..., 4)``."""
        x = np.asarray(x, float)
        return x[..., 0] + self.length * (x[..., 1] if linear else np.sin(x[..., 1]))

    def step_matrices(self, h: float, theta: float = 0.5) -> tuple[FloatArray, FloatArray]:
        """``A, B`` of the wall-free Moreau–Jean step ``x_{k+1} = A x_k + B u_k``
        (``M̂ (v⁺ - v) = h (-K (q + hθ v) + S u)``, ``q⁺ = q + h ((1 - θ) v + θ v⁺)``,
        ``M̂ = M + h²θ² K``).

        Parameters
        ----------
        h : float
            The step.
        theta : float
            θ of the step (the integrator's default ½).

        Returns
        -------
        (ndarray (4, 4), ndarray (4, 1))
        """
        h = check_positive("h", h)
        theta = check_in_interval("theta", theta, 0.5, 1.0)
        M, K = self._matrices()
        S = np.array([[1.0], [0.0]])
        Mi = np.linalg.inv(M + (h * theta) ** 2 * K)
        dv_dq, dv_dv, dv_du = -h * Mi @ K, np.eye(2) - h * h * theta * Mi @ K, h * Mi @ S
        I2 = np.eye(2)
        A = np.block([[I2 + h * theta * dv_dq, h * (1 - theta) * I2 + h * theta * dv_dv],
                      [dv_dq, dv_dv]])
        B = np.vstack([h * theta * dv_du, dv_du])
        return A, B

    def lqr(self, h: float, state_weight: object, effort: float, theta: float = 0.5
            ) -> tuple[FloatArray, FloatArray]:
        """The LQR of the MPC's stage cost ``h ((x_{k+1})ᵀ W x_{k+1} + effort u_k²)`` on the
        wall-free step: the gain ``K`` (``u = -K x``) and the value matrix ``P`` (the cost to
        go from ``x`` is ``xᵀ P x``).

        Parameters
        ----------
        h : float
            The step.
        state_weight : array_like (4,)
            Diagonal of ``W``.
        effort : float
            Weight of ``u²``, ``> 0``.
        theta : float
            θ of the step.

        Returns
        -------
        (ndarray (1, 4), ndarray (4, 4))
        """
        from scipy.linalg import solve_discrete_are

        A, B = self.step_matrices(h, theta)
        W = np.diag(as_vector("state_weight", state_weight, 4))
        effort = check_positive("effort", effort)
        Q, R, N = h * A.T @ W @ A, h * (B.T @ W @ B + effort * np.eye(1)), h * A.T @ W @ B
        P = solve_discrete_are(A, B, Q, R, s=N)
        K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A + N.T)
        return K, 0.5 * (P + P.T)

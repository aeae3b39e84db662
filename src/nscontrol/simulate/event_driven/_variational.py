"""The variational equation of a nonlinear Lagrangian flow and the saltation of its impacts.

With ``x = [q; v]`` and ``x' = f(t, x) = [v; M(q)⁻¹ F(t, q, v)]``, the state transition
``Φ = ∂x(t)/∂x(t0)`` obeys ``Φ' = A(t, x) Φ``, ``A = ∂f/∂x``, integrated with the state (one
augmented vector ``[x; vec Φ]``, row-major). ``A`` comes from the system's own force
Jacobians when they are analytic (constant mass matrix, no law evaluated along the flow, no
``force`` or its ``force_jacobian`` given): ``A = [[0, I], [M⁻¹ ∂F/∂q, M⁻¹ ∂F/∂v]]``
(:meth:`LagrangianSystem.force_jacobians`). Otherwise (``M(q)``, whose derivative the model
does not give, a force without its Jacobian, a closed loop's law) ``A`` is a central
difference of the whole field, fourth order
(:func:`~nscontrol.numerics.differences.central_difference_jacobian` with ``order=4``: about
``5e-13`` relative). Second-order differences (``1e-10``) would not do: their rounding noise
enters ``Φ'``, and DOP853's error controller at ``rtol = 1e-10`` chases it with ever smaller
steps (on a two-link arm, some forty times the steps).

At an impact of one contact ``j`` the transition is multiplied by the saltation matrix of
Newton's law with the guard ``h(x) = g_j(q)`` (``∇h = [∇g_j; 0]``, rate ``∇g_j·v-``):
:func:`~nscontrol.numerics.saltation.saltation_matrix` of the jump Jacobian
:func:`~nscontrol.numerics.saltation.impact_jump_jacobian` (with its ``∂v+/∂q`` block when
``M`` or the gap depends on ``q``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import SolverError
from ...numerics.differences import central_difference_jacobian
from ...numerics.saltation import impact_jump_jacobian, saltation_matrix

Field = Callable[[float, FloatArray], FloatArray]


class Variational:
    """``A(t, x)``, the augmented right-hand side and the impact saltation of one run."""

    def __init__(self, system: Any, field: Field, has_controller: bool) -> None:
        self.s, self.field = system, field
        self.N = system.n_states
        self.own_jacobians = (system.constant_mass and not has_controller
                              and (system.force is None or system.force_jacobian is not None))
        if self.own_jacobians:
            self.Minv = np.linalg.inv(system.mass_matrix())

    def jacobian(self, t: float, x: FloatArray) -> FloatArray:
        """``A = ∂f/∂x`` at ``(t, x)``."""
        if not self.own_jacobians:
            return central_difference_jacobian(lambda y: self.field(t, y), x, order=4)
        n = self.s.n_dof
        Jq, Jv, _ = self.s.force_jacobians(t, x[:n], x[n:])
        A = np.zeros((self.N, self.N))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = self.Minv @ Jq
        A[n:, n:] = self.Minv @ Jv
        return A

    def rhs(self, t: float, z: FloatArray) -> FloatArray:
        """``[f(t, x); vec(A Φ)]`` for ``z = [x; vec Φ]``."""
        N = self.N
        x = z[:N]
        Phi = z[N:].reshape(N, N)
        return np.concatenate([self.field(t, x), (self.jacobian(t, x) @ Phi).ravel()])

    @staticmethod
    def augment(x: FloatArray, Phi: FloatArray) -> FloatArray:
        """The augmented vector ``[x; vec Φ]``."""
        return np.concatenate([x, Phi.ravel()])

    def transition(self, z: FloatArray) -> FloatArray:
        """``Φ`` from the augmented vector."""
        return z[self.N:].reshape(self.N, self.N)

    def impact_saltation(self, t: float, x_minus: FloatArray, x_plus: FloatArray,
                         contacts: list[int]) -> FloatArray:
        """The saltation matrix of Newton's law on one contact at time ``t``.

        Raises
        ------
        SolverError
            Several contacts at once (the jump is not differentiable there) or a grazing
            impact (no saltation matrix).
        """
        if len(contacts) != 1:
            raise SolverError(f"sensitivity: contacts {contacts} close together at t = {t:.12g}; "
                              "a simultaneous impact has no saltation matrix (the map is not "
                              "differentiable there)")
        s, n, j = self.s, self.s.n_dof, contacts[0]
        q = x_minus[:n]
        e = float(s.restitution[j])
        w = s.gap_jacobian(q)[j]
        if s.constant_mass and s.gap is None:
            J = impact_jump_jacobian(s.mass_matrix(q), w, e)
        else:
            J = impact_jump_jacobian(s.mass_matrix, lambda qq: s.gap_jacobian(qq)[j], e,
                                     state=x_minus)
        grad = np.concatenate([w, np.zeros(n)])
        return saltation_matrix(J, self.field(t, x_minus), self.field(t, x_plus), grad)

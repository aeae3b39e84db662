"""The planar two-link arm in task coordinates, and a one-degree-of-freedom twin (chapter 3).

Joint model (angles ``θ = (θ1, θ2)``, ``θ1`` from the horizontal, ``θ2`` relative)::

    M(θ) θ'' + C(θ, θ') θ' + G(θ) = U + ∇F(θ) λ,   0 <= F(θ) = y(θ) ⟂ λ >= 0,

with ``C`` in Christoffel form (``Ṁ - 2C`` skew-symmetric) and Newton restitution on the
end effector's normal velocity ``ẏ``. The tracking controller works in the task coordinates
``q = (y, x)`` of the end effector (normal coordinate first), where the ground is ``q1 >= 0``::

    M_q = J⁻ᵀ M J⁻¹,   C_q = J⁻ᵀ (C - M J⁻¹ J̇) J⁻¹,   g_q = J⁻ᵀ G,   U = Jᵀ τ,

``J = ∂(y, x)/∂θ``. The change of coordinates keeps ``Ṁ_q - 2 C_q`` skew-symmetric, which is
what the passivity-based controller needs. The elbow branch ``θ2 ∈ (-π, 0)`` is the one the
inverse map returns (``det J = l1 l2 sin θ2`` vanishes only at the stretched and folded arm).

:class:`OneDofMass` is the same interface for a unit mass on a vertical line above the ground
``q >= 0`` (the identity task map): the closed forms of the transition phase hold for it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from .._validation import FloatArray, check_in_interval, check_positive
from ..errors import InadmissibleStateError
from .lagrangian import LagrangianSystem, _f64

__all__ = ["TwoLinkParams", "TwoLinkArm", "OneDofMass"]


@dataclass(frozen=True)
class TwoLinkParams:
    """Geometry and inertia of the two-link arm (masses at mid-link).

    Attributes
    ----------
    l1, l2
        Link lengths (m).
    m1, m2
        Link masses (kg).
    I1, I2
        Moments of inertia about the links' centres of mass (kg m²).
    g
        Gravity along ``-y`` (m/s²).
    """

    l1: float = 0.5
    l2: float = 0.5
    m1: float = 1.0
    m2: float = 1.0
    I1: float = 1.0
    I2: float = 1.0
    g: float = 9.8

    def __post_init__(self) -> None:
        for name in ("l1", "l2", "m1", "m2", "I1", "I2"):
            check_positive(name, getattr(self, name))
        check_positive("g", self.g, allow_zero=True)

    @cached_property
    def array(self) -> FloatArray:
        """The parameters as the compiled kernels' record ``ARM`` (flat, in its order)."""
        from ._two_link_kernels import arm_array

        return arm_array(self.l1, self.l2, self.m1, self.m2, self.I1, self.I2, self.g)

    def inertial(self) -> dict[str, float]:
        """The keyword arguments of the joint-space functions (without ``g``)."""
        return dict(l1=self.l1, l2=self.l2, m1=self.m1, m2=self.m2, I1=self.I1, I2=self.I2)


@dataclass(frozen=True)
class TwoLinkArm:
    """The two-link arm with its end-effector task map and ground constraint ``y >= 0``.

    Parameters
    ----------
    params : TwoLinkParams
        Geometry, inertia, gravity.

    Examples
    --------
    >>> arm = TwoLinkArm()
    >>> y, x = arm.position(np.array([0.9, -1.6]))
    >>> round(float(x), 6), round(float(y), 6)
    (0.693226, 0.069555)
    >>> theta = arm.inverse(np.array([y, x]))
    >>> bool(np.allclose(theta, [0.9, -1.6], atol=1e-12))
    True
    """

    params: TwoLinkParams = field(default_factory=TwoLinkParams)
    #: Number of joints.
    n_dof: int = field(default=2, init=False)

    # -- joint space ---------------------------------------------------------------------
    def mass(self, theta: FloatArray) -> FloatArray:
        """``M(θ)``, symmetric positive definite.

        Parameters
        ----------
        theta : (2,) ndarray
            Joint angles.
        """
        from . import _two_link_kernels as tk

        return tk.mass(_f64(theta), self.params.array)

    def coriolis(self, theta: FloatArray, dtheta: FloatArray) -> FloatArray:
        """``C(θ, θ')`` in Christoffel form.

        Parameters
        ----------
        theta, dtheta : (2,) ndarray
            Joint angles and velocities.
        """
        from . import _two_link_kernels as tk

        return tk.coriolis(_f64(theta), _f64(dtheta), self.params.array)

    def gravity(self, theta: FloatArray) -> FloatArray:
        """``G(θ) = ∂P/∂θ``.

        Parameters
        ----------
        theta : (2,) ndarray
            Joint angles.
        """
        from . import _two_link_kernels as tk

        return tk.gravity(_f64(theta), self.params.array)

    def system(self, restitution: float = 0.7) -> LagrangianSystem:
        """The plant for the integrators: gravity on, ground ``y >= 0``, fully actuated.

        The same (immutable) system for the same parameters and coefficient: the
        integrators keep their set-ups per system, so repeated runs skip them.

        Parameters
        ----------
        restitution : float
            Newton coefficient of the ground, in ``[0, 1]``.
        """
        e = check_in_interval("restitution", restitution, 0.0, 1.0)
        return _kept(("two-link", self.params, e), lambda: LagrangianSystem.two_link_arm(
            l1=self.params.l1, l2=self.params.l2, m1=self.params.m1, m2=self.params.m2,
            I1=self.params.I1, I2=self.params.I2, g=self.params.g, restitution=e))

    # -- task map ------------------------------------------------------------------------
    def position(self, theta: FloatArray) -> FloatArray:
        """End-effector task coordinates ``q = (y, x)``.

        Parameters
        ----------
        theta : (2,) ndarray
            Joint angles.
        """
        from . import _two_link_kernels as tk

        return tk.position(_f64(theta), self.params.array)

    def jacobian(self, theta: FloatArray) -> FloatArray:
        """``J = ∂(y, x)/∂θ``.

        Parameters
        ----------
        theta : (2,) ndarray
            Joint angles.
        """
        from . import _two_link_kernels as tk

        return tk.jacobian(_f64(theta), self.params.array)

    def jacobian_rate(self, theta: FloatArray, dtheta: FloatArray) -> FloatArray:
        """``J̇ = d/dt J(θ(t))``.

        Parameters
        ----------
        theta, dtheta : (2,) ndarray
            Joint angles and velocities.
        """
        from . import _two_link_kernels as tk

        return tk.jacobian_rate(_f64(theta), _f64(dtheta), self.params.array)

    def inverse(self, q: FloatArray) -> FloatArray:
        """Joint angles of the end-effector position ``q = (y, x)`` on the elbow branch
        ``θ2 ∈ (-π, 0)``.

        Parameters
        ----------
        q : (2,) ndarray
            Task coordinates ``(y, x)``.

        Raises
        ------
        InadmissibleStateError
            ``q`` out of reach (``|l1 - l2| <= |q| <= l1 + l2`` is needed).
        """
        l1, l2 = self.params.l1, self.params.l2
        y, x = float(q[0]), float(q[1])
        c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
        if not -1.0 <= c2 <= 1.0:
            raise InadmissibleStateError(f"q: the point (x, y) = ({x:.6g}, {y:.6g}) is out of "
                                         f"the arm's reach [{abs(l1 - l2):.6g}, {l1 + l2:.6g}]")
        t2 = -np.arccos(c2)
        t1 = np.arctan2(y, x) - np.arctan2(l2 * np.sin(t2), l1 + l2 * np.cos(t2))
        return np.array([t1, t2])

    def task_state(self, theta: FloatArray, dtheta: FloatArray
                   ) -> tuple[FloatArray, FloatArray]:
        """``(q, q')`` in task coordinates.

        Parameters
        ----------
        theta, dtheta : (2,) ndarray
            Joint angles and velocities.
        """
        return self.task_model(theta, dtheta)[:2]

    def task_dynamics(self, theta: FloatArray, dtheta: FloatArray
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(M_q, C_q, g_q, J)`` of the task-space model (module docstring).

        Parameters
        ----------
        theta, dtheta : (2,) ndarray
            Joint angles and velocities.
        """
        return self.task_model(theta, dtheta)[2:]

    def task_model(self, theta: FloatArray, dtheta: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                              FloatArray]:
        """``(q, q', M_q, C_q, g_q, J)`` in one evaluation (what a controller needs per step).

        The closed form is the compiled kernel the tracking controller runs
        (``nscontrol.systems._two_link_kernels.task_model``): one source for both.

        Parameters
        ----------
        theta, dtheta : (2,) ndarray
            Joint angles and velocities.
        """
        from . import _two_link_kernels as tk

        x = np.concatenate((np.asarray(theta, float).ravel(),
                            np.asarray(dtheta, float).ravel()))
        return tk.task_model_of(x, self.params.array)


@dataclass(frozen=True)
class OneDofMass:
    """A mass on a vertical line above the ground ``q >= 0``, under gravity (§4.4 of the
    chapter's test systems). The task map is the identity.

    Parameters
    ----------
    m : float
        Mass (kg).
    g : float
        Gravity (m/s²).

    Examples
    --------
    >>> plant = OneDofMass()
    >>> plant.task_dynamics(np.array([0.1]), np.array([0.0]))[2]
    array([9.81])
    """

    m: float = 1.0
    g: float = 9.81
    #: One coordinate.
    n_dof: int = field(default=1, init=False)

    def __post_init__(self) -> None:
        check_positive("m", self.m)
        check_positive("g", self.g, allow_zero=True)

    def system(self, restitution: float = 0.7) -> LagrangianSystem:
        """The plant: ``m q'' = -m g + u + λ``, ``0 <= q ⟂ λ >= 0``.

        The same (immutable) system for the same mass, gravity and coefficient (see
        :meth:`TwoLinkArm.system`).

        Parameters
        ----------
        restitution : float
            Newton coefficient, in ``[0, 1]``.
        """
        e = check_in_interval("restitution", restitution, 0.0, 1.0)
        return _kept(("one-dof", float(self.m), float(self.g), e), lambda: LagrangianSystem(
            [[self.m]], constant_force=[-self.m * self.g], gap_matrix=[[1.0]],
            restitution=e, names=("q",)))

    def position(self, theta: FloatArray) -> FloatArray:
        """Task coordinate (the position itself).

        Parameters
        ----------
        theta : (1,) ndarray
            Position.
        """
        return np.asarray(theta, float).copy()

    def inverse(self, q: FloatArray) -> FloatArray:
        """The identity.

        Parameters
        ----------
        q : (1,) ndarray
            Position.
        """
        return np.asarray(q, float).copy()

    def task_state(self, theta: FloatArray, dtheta: FloatArray
                   ) -> tuple[FloatArray, FloatArray]:
        """``(q, q')``.

        Parameters
        ----------
        theta, dtheta : (1,) ndarray
            Position and velocity.
        """
        return np.asarray(theta, float).copy(), np.asarray(dtheta, float).copy()

    def task_dynamics(self, theta: FloatArray, dtheta: FloatArray
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(M, C, g, J) = (m, 0, m g, 1)``.

        Parameters
        ----------
        theta, dtheta : (1,) ndarray
            Position and velocity.
        """
        return self.task_model(theta, dtheta)[2:]

    def task_model(self, theta: FloatArray, dtheta: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                              FloatArray]:
        """``(q, q', M, C, g, J)`` in one evaluation (the tracking controller's kernel).

        Parameters
        ----------
        theta, dtheta : (1,) ndarray
            Position and velocity.
        """
        from ._two_link_kernels import one_dof_task_model

        q, dq, gq = np.empty(1), np.empty(1), np.empty(1)
        Mq, Cq, J = np.empty((1, 1)), np.empty((1, 1)), np.empty((1, 1))
        x = np.array([float(np.asarray(theta).ravel()[0]), float(np.asarray(dtheta).ravel()[0])])
        one_dof_task_model(x, float(self.m), float(self.g), q, dq, Mq, Cq, gq, J)
        return q, dq, Mq, Cq, gq, J


_SYSTEMS: dict[tuple[Any, ...], LagrangianSystem] = {}


def _kept(key: tuple[Any, ...], make: Callable[[], LagrangianSystem]) -> LagrangianSystem:
    """The system made for ``key``, kept (the 64 most recently used)."""
    system = _SYSTEMS.pop(key, None)
    if system is None:
        system = make()
        if len(_SYSTEMS) >= 64:
            del _SYSTEMS[next(iter(_SYSTEMS))]
    _SYSTEMS[key] = system
    return system

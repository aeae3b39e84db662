"""Actuated mechanical models with non-permanent contacts, for posture regulation (ch04).

An :class:`ActuatedContactModel` is what a posture regulator and its stability certificate
need beyond the equations of motion: the potential ``V(q)`` with its gradient and Hessian, the
gaps ``g(q) >= 0`` with their Jacobian and Hessians, the actuated coordinates ``θ = S q``
(``S`` of shape ``(p, n)``, the input entering as ``Sᵀ τ``) and the symmetry directions
(coordinates that neither the potential nor the constraints see, e.g. a horizontal
translation on frictionless flat ground). :meth:`ActuatedContactModel.lagrangian` gives the
:class:`~nscontrol.systems.LagrangianSystem` the integrators run.

Two models:

* :func:`foot_body_model` — a planar foot with heel and toe contacts on frictionless flat
  ground and a body on an actuated ankle, ``q = (x, y, φ, θ)``;
* :func:`wall_mass_model` — one mass pushed against a wall, ``g(q) = -q >= 0``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import FloatArray, as_matrix, check_positive, named_record
from ..errors import DimensionError, ModelError

__all__ = ["ActuatedContactModel", "FootBodyParameters", "foot_body_model", "foot_body_points",
           "wall_mass_model"]

VectorFn = Callable[[FloatArray], FloatArray]

#: Moreau–Jean's index-set threshold for the foot + body [m]. Its gaps are nonlinear in φ: a
#: contact held closed at velocity level drifts by ½ δqᵀ∇²g δq ≈ 1e-12 m per step at
#: h = 1e-3, enough to leave Moreau–Jean's default threshold (1e-12 (1 + ‖q₀‖)); the light foot
#: then turns freely for one step and the toe sinks by 0.3 mm, which velocity-level
#: constraints never undo (Example A's rest offset grows 4×). 1 µm is far above that drift
#: and far below a landing's drift h ‖U⁻‖ ≈ 1e-4 m.
FOOT_BODY_ACTIVATION = 1e-6


@dataclass(frozen=True, eq=False)
class ActuatedContactModel:
    """An underactuated Lagrangian model with unilateral contacts and its derivatives.

    Attributes
    ----------
    n_dof
        Number of generalised coordinates ``n``.
    mass
        ``q -> M(q)``, symmetric positive definite ``(n, n)``.
    coriolis_force
        ``(q, v) -> C(q, v) v``, ``(n,)``.
    coriolis_jacobians
        ``(q, v) -> (∂(Cv)/∂q, ∂(Cv)/∂v)``.
    potential
        ``q -> V(q)``.
    potential_gradient, potential_hessian
        ``∇V(q)`` ``(n,)`` and ``∇²V(q)`` ``(n, n)``.
    gaps, gap_jacobian, gap_hessians
        ``g(q)`` ``(m,)``, ``∂g/∂q`` ``(m, n)`` and ``∇²g_α(q)`` stacked ``(m, n, n)``.
    actuation
        ``S`` ``(p, n)``: the actuated coordinates are ``S q``, the input enters as ``Sᵀ τ``.
    symmetry
        ``(k, n)`` rows: directions along which neither ``V`` nor ``g`` changes (cyclic
        coordinates), removed from the strict-minimum test; ``(0, n)`` when none.
    names
        Coordinate names.
    contact_names
        Contact names (one per gap).
    support_abscissae
        ``q -> (m,)`` horizontal positions of the contact points (flat ground), or ``None``:
        the centre of pressure (the static ZMP) of a force distribution is computed from it.
    parameters
        The physical parameters the model was built from (for drawings and reports).
    contact_activation
        The index-set threshold [m] Moreau–Jean needs for these gaps (``activation=``), or
        ``None`` for its own default. Curved gaps need more than that default (1e-12 m): a
        contact held closed at velocity level drifts by the curvature term
        ``½ δqᵀ ∇²g δq`` each step (``δq = h v``), and a contact that drifts out of the
        threshold turns free for a step, an error velocity-level constraints never undo.
        :func:`foot_body_model` sets 1e-6 m; the chapter-4 runs use it by default.
    """

    n_dof: int
    mass: VectorFn
    coriolis_force: Callable[[FloatArray, FloatArray], FloatArray]
    coriolis_jacobians: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]
    potential: Callable[[FloatArray], float]
    potential_gradient: VectorFn
    potential_hessian: VectorFn
    gaps: VectorFn
    gap_jacobian: VectorFn
    gap_hessians: VectorFn
    actuation: FloatArray
    symmetry: FloatArray
    names: tuple[str, ...]
    contact_names: tuple[str, ...]
    support_abscissae: VectorFn | None = None
    parameters: Any = None
    contact_activation: float | None = None

    def __post_init__(self) -> None:
        S = as_matrix("actuation", self.actuation, cols=self.n_dof)
        if np.linalg.matrix_rank(S) != S.shape[0]:
            raise ModelError(f"actuation: S must have full row rank (independent actuated "
                             f"coordinates), got rank {np.linalg.matrix_rank(S)} for "
                             f"{S.shape[0]} rows")
        object.__setattr__(self, "actuation", S)
        sym = np.zeros((0, self.n_dof)) if self.symmetry is None or np.size(self.symmetry) == 0 \
            else as_matrix("symmetry", self.symmetry, cols=self.n_dof)
        object.__setattr__(self, "symmetry", sym)
        if len(self.names) != self.n_dof:
            raise DimensionError(f"names: expected {self.n_dof} names, got {len(self.names)}")
        if self.contact_activation is not None:
            object.__setattr__(self, "contact_activation", check_positive(
                "contact_activation", self.contact_activation, allow_zero=True))

    @property
    def n_contacts(self) -> int:
        """Number of contacts ``m``."""
        return len(self.contact_names)

    def smooth_force(self, t: float, q: FloatArray, v: FloatArray) -> FloatArray:
        """``-C(q, v) v - ∇V(q)`` (no actuation)."""
        return -self.coriolis_force(q, v) - self.potential_gradient(q)

    def smooth_force_jacobian(self, t: float, q: FloatArray, v: FloatArray
                              ) -> tuple[FloatArray, FloatArray]:
        """``(∂/∂q, ∂/∂v)`` of :meth:`smooth_force`."""
        Jq, Jv = self.coriolis_jacobians(q, v)
        return -Jq - self.potential_hessian(q), -Jv

    def lagrangian(self, restitution: Any = 0.0) -> Any:
        """The :class:`~nscontrol.systems.LagrangianSystem` of this model, actuated by ``Sᵀ``.

        Parameters
        ----------
        restitution : float or array_like (m,)
            Newton coefficients of the contacts, in ``[0, 1]``.
        """
        from .lagrangian import LagrangianSystem

        return LagrangianSystem(self.mass, force=self.smooth_force,
                                force_jacobian=self.smooth_force_jacobian, gap=self.gaps,
                                jacobian=self.gap_jacobian, restitution=restitution,
                                actuation=self.actuation.T, potential=self.potential,
                                names=self.names, compiled=self.compiled_model())

    def compiled_model(self) -> Any:
        """The compiled form of :meth:`lagrangian`'s callables
        (:class:`~nscontrol.systems.lagrangian.CompiledModel`), for the models that have one
        (:func:`foot_body_model`), else ``None``."""
        if not isinstance(self.parameters, FootBodyParameters):
            return None
        from . import _foot_body_kernels as fk
        from .lagrangian import CompiledModel

        return CompiledModel(fk.mass, fk.force, fk.force_jacobian, fk.gaps, fk.gap_jacobian,
                             self.parameters.record(), potential=fk.potential)


@dataclass(frozen=True)
class FootBodyParameters:
    """Parameters of the planar foot + body model (SI units).

    Attributes
    ----------
    m_f, I_f
        Foot mass (at the ankle) and inertia.
    a, b, d
        Heel at ``(-a, -d)`` and toe at ``(b, -d)`` in the foot frame, from the ankle.
    m_b, L, I_b
        Body mass, ankle-to-CoM distance and inertia about the CoM.
    g
        Gravity.
    """

    m_f: float = 1.0
    I_f: float = 0.01
    a: float = 0.08
    b: float = 0.17
    d: float = 0.05
    m_b: float = 20.0
    L: float = 0.8
    I_b: float = 1.0
    g: float = 9.81

    def __post_init__(self) -> None:
        for key in ("m_f", "I_f", "a", "b", "m_b", "L", "I_b"):
            check_positive(key, getattr(self, key))
        check_positive("d", self.d, allow_zero=True)
        check_positive("g", self.g, allow_zero=True)

    @property
    def total_mass(self) -> float:
        """``m = m_f + m_b``."""
        return self.m_f + self.m_b

    def record(self) -> FloatArray:
        """The parameters as the model's kernels read them: the named record
        ``FOOT_BODY`` of :mod:`nscontrol.systems._foot_body_kernels`, as its flat
        ``float64`` view."""
        from ._foot_body_kernels import FOOT_BODY

        return named_record(FOOT_BODY, m=self.total_mass, m_b=self.m_b, L=self.L, I_f=self.I_f,
                            a=self.a, b=self.b, d=self.d, g=self.g,
                            I_b=self.I_b).view(np.float64)


def _configuration(q: Any, name: str = "q") -> FloatArray:
    """``q`` as the kernels take it (contiguous ``float64``, 4 entries)."""
    arr = np.ascontiguousarray(q, dtype=np.float64)
    if arr.shape != (4,):
        raise DimensionError(f"{name}: expected 4 coordinates (x, y, phi, theta), got shape "
                             f"{arr.shape}")
    return arr


def foot_body_model(**parameters: Any) -> ActuatedContactModel:
    """The planar foot + ankle-actuated body on frictionless flat ground (Example A of ch04).

    ``q = (x, y, φ, θ)``: ankle position, foot angle (counter-clockwise, 0 = flat) and body
    angle from the vertical (counter-clockwise: a forward lean is ``θ < 0``). Body CoM at
    ``(x - L sin θ, y + L cos θ)``; heel and toe gaps
    ``g = y - a sin φ - d cos φ`` and ``y + b sin φ - d cos φ``; the ankle torque acts on
    ``ψ = θ - φ`` (``S = [0, 0, -1, 1]``). ``x`` is cyclic (the symmetry direction).

    Its :attr:`~ActuatedContactModel.contact_activation` is :data:`FOOT_BODY_ACTIVATION`.

    Parameters
    ----------
    **parameters
        Fields of :class:`FootBodyParameters` to override.

    Examples
    --------
    >>> model = foot_body_model()
    >>> q = np.array([0.0, 0.05, 0.0, -0.1])
    >>> model.gaps(q).round(15).tolist()                # both contacts closed, foot flat
    [0.0, 0.0]
    """
    from . import _foot_body_kernels as fk

    p = FootBodyParameters(**parameters)
    rec = p.record()

    def at(kernel: Any) -> Callable[[Any], Any]:
        """``q -> kernel(q, rec)``."""
        return lambda q: kernel(_configuration(q), rec)

    def at_state(kernel: Any) -> Callable[[Any, Any], Any]:
        """``(q, v) -> kernel(q, v, rec)``."""
        return lambda q, v: kernel(_configuration(q), _configuration(v, "v"), rec)

    mass, potential = at(fk.mass), at(fk.potential)
    coriolis_force, coriolis_jacobians = at_state(fk.coriolis_force), \
        at_state(fk.coriolis_jacobians)
    potential_gradient, potential_hessian = at(fk.potential_gradient), \
        at(fk.potential_hessian)
    gaps, gap_jacobian, gap_hessians = at(fk.gaps), at(fk.gap_jacobian), at(fk.gap_hessians)
    support_abscissae = at(fk.support_abscissae)

    return ActuatedContactModel(
        4, mass, coriolis_force, coriolis_jacobians, potential, potential_gradient,
        potential_hessian, gaps, gap_jacobian, gap_hessians,
        actuation=np.array([[0.0, 0.0, -1.0, 1.0]]), symmetry=np.array([[1.0, 0.0, 0.0, 0.0]]),
        names=("x", "y", "phi", "theta"), contact_names=("heel", "toe"),
        support_abscissae=support_abscissae, parameters=p,
        contact_activation=FOOT_BODY_ACTIVATION)


def foot_body_points(model: ActuatedContactModel, q: Any) -> dict[str, FloatArray]:
    """Ankle, heel, toe and body CoM of the foot + body model at ``q`` (for drawings).

    Parameters
    ----------
    model : ActuatedContactModel
        A model built by :func:`foot_body_model`.
    q : array_like (4,)
        Configuration ``(x, y, φ, θ)``.
    """
    p = model.parameters
    q = np.asarray(q, float)
    s, c = np.sin(q[2]), np.cos(q[2])
    ankle = q[:2]
    heel = ankle + np.array([-p.a * c + p.d * s, -p.a * s - p.d * c])
    toe = ankle + np.array([p.b * c + p.d * s, p.b * s - p.d * c])
    com = ankle + p.L * np.array([-np.sin(q[3]), np.cos(q[3])])
    return {"ankle": ankle, "heel": heel, "toe": toe, "com": com}


def wall_mass_model(mass: float = 1.0) -> ActuatedContactModel:
    """One actuated mass left of a wall: ``q ∈ R``, ``g(q) = -q >= 0`` (Example C of ch04).

    Parameters
    ----------
    mass : float
        The mass, ``> 0``.

    Examples
    --------
    >>> wall_mass_model().gap_jacobian(np.zeros(1)).tolist()
    [[-1.0]]
    """
    mass = check_positive("mass", mass)
    zero1 = np.zeros(1)
    return ActuatedContactModel(
        1, lambda q: np.array([[mass]]), lambda q, v: zero1.copy(),
        lambda q, v: (np.zeros((1, 1)), np.zeros((1, 1))), lambda q: 0.0,
        lambda q: zero1.copy(), lambda q: np.zeros((1, 1)), lambda q: -np.asarray(q, float),
        lambda q: np.array([[-1.0]]), lambda q: np.zeros((1, 1, 1)),
        actuation=np.eye(1), symmetry=np.zeros((0, 1)), names=("q",), contact_names=("wall",),
        parameters={"mass": mass})


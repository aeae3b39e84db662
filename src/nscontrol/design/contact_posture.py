"""Posture regulation with non-permanent contacts: joint PD plus a constant feed-forward torque.

For an underactuated robot standing on frictionless contacts (chapter 4), the law

    τ = -K_p (S q - θ*) - K_d S v + τ*

makes a chosen posture ``q*`` an equilibrium with *chosen, strictly positive* contact forces
``λ*`` on the contacts kept closed (``I*``): the static balance
``∇V(q*) = Sᵀ τ* + G_{I*}(q*)ᵀ λ*`` fixes ``λ*`` on the unactuated directions (``ker S``) and
then ``τ* = (S Sᵀ)⁻¹ S (∇V(q*) - G_{I*}ᵀ λ*)``. Position and contact force are both regulated:
at rest ``q = q*`` the contacts carry ``λ*``. When no ``λ* > 0`` exists the posture cannot be
held on those contacts (on flat ground: the centre of mass does not project strictly inside
the support); :func:`static_contact_forces` raises :class:`~nscontrol.errors.InfeasibleDesignError`
saying so.

The feed-forward is *constant* on purpose: the closed-loop smooth forces are then
``-∇W - Sᵀ K_d S v - C(q, v) v`` with the total potential

    W(q) = V(q) + ½ (S q - θ*)ᵀ K_p (S q - θ*) - τ*ᵀ S q,

and ``E = ½ vᵀ M(q) v + W(q)`` never increases, whatever contacts open, close or impact
(a state-dependent gravity compensation is in general not a gradient and loses this).
Whether ``q*`` is a strict minimum of ``W`` on the admissible set — the stability condition —
is checked by :func:`nscontrol.analysis.posture_certificate`.

References
----------
S. Chareyron, P.-B. Wieber, *Stability and regulation of nonsmooth dynamical systems*,
INRIA RR-5408 (2004); *Position and force control of nonsmooth Lagrangian dynamical systems
without friction*, HSCC 2005, LNCS 3414.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_square,
    as_vector,
    check_bool,
    check_positive,
    check_symmetric,
    check_type,
)
from ..errors import DimensionError, InfeasibleDesignError, ModelError, NscontrolWarning
from ..systems.feedback import StaticLaw
from ..systems.foot_body import ActuatedContactModel

__all__ = ["StaticPostureDesign", "ContactRegulator", "static_contact_forces",
           "design_contact_regulator"]

_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True, eq=False)
class StaticPostureDesign:
    """The equilibrium a posture regulator makes: posture, contact forces, feed-forward.

    Attributes
    ----------
    q_star
        The posture ``q*``.
    active
        Indices of the contacts kept closed, ``I*``.
    lam_star
        Contact forces on ``I*`` (``(|I*|,)``), all ``> 0`` for a feasible design.
    tau_star
        Constant feed-forward torque ``τ*`` (``(p,)``).
    theta_star
        Actuated coordinates at the posture, ``S q*``.
    center_of_pressure
        Horizontal position of the resultant contact force (the static ZMP) on flat ground;
        ``None`` when the model gives no contact abscissae.
    support
        ``(min, max)`` abscissae of the contacts of ``I*`` (the support), or ``None``.
    balance_residual
        ``‖∇V(q*) - Sᵀ τ* - G_{I*}ᵀ λ*‖``: the static balance's residual.
    feasible
        ``λ* >= lam_min`` on every contact of ``I*``.
    """

    q_star: FloatArray
    active: tuple[int, ...]
    lam_star: FloatArray
    tau_star: FloatArray
    theta_star: FloatArray
    center_of_pressure: float | None
    support: tuple[float, float] | None
    balance_residual: float
    feasible: bool


def static_contact_forces(model: Any, q_star: ArrayLike, active: Any, *,
                          lam_ref: ArrayLike | None = None, lam_min: float = 1e-6,
                          require_positive: bool = True) -> StaticPostureDesign:
    """Contact forces ``λ* > 0`` and feed-forward ``τ*`` that hold the posture ``q*``.

    Parameters
    ----------
    model : ActuatedContactModel
        The robot (:mod:`nscontrol.systems.foot_body`).
    q_star : array_like (n,)
        The posture; the contacts of ``active`` must be closed there (``|g| <= 1e-9``), the
        others open.
    active : sequence of int
        The contacts to keep closed, ``I*``.
    lam_ref : array_like, shape (n_active,), optional
        A preferred force distribution when several balance the posture (projected on the
        feasible set); default: the minimum-norm one.
    lam_min : float
        Smallest accepted contact force, ``> 0``.
    require_positive : bool
        ``False`` returns the balancing forces even when some is ``< lam_min`` (to simulate
        or certify an infeasible posture); ``feasible`` then says which case it is.

    Returns
    -------
    StaticPostureDesign

    Raises
    ------
    InfeasibleDesignError
        No contact forces balance the unactuated directions, or none with ``λ >= lam_min``
        (``status`` ``"unbalanced"`` or ``"negative_contact_force"``); the message gives the
        centre of pressure and the support on flat ground.
    ModelError
        A contact of ``active`` is open at ``q*`` or one outside it is closed; ``model`` not
        an :class:`~nscontrol.systems.foot_body.ActuatedContactModel`; a non-bool
        ``require_positive``.
    DimensionError
        Wrong lengths, an index out of range.

    Examples
    --------
    >>> from nscontrol.systems.foot_body import foot_body_model
    >>> d = static_contact_forces(foot_body_model(), [0.0, 0.05, 0.0, -0.1], [0, 1])
    >>> np.round(d.lam_star, 4).tolist(), np.round(d.tau_star, 4).tolist()
    ([77.4074, 128.6026], [15.6699])
    """
    check_type("model", model, ActuatedContactModel)
    require_positive = check_bool("require_positive", require_positive)
    q_star = as_vector("q_star", q_star, model.n_dof)
    idx = _active_indices(active, model.n_contacts)
    lam_min = check_positive("lam_min", lam_min)
    _check_posture_contacts(model, q_star, idx)
    S = model.actuation
    grad_V = np.asarray(model.potential_gradient(q_star), float)
    G = np.asarray(model.gap_jacobian(q_star), float)[list(idx)]
    _warn_if_dependent(G, idx)
    Z = _null_space(S)                            # unactuated directions
    A, rhs = Z.T @ G.T, Z.T @ grad_V
    lam, residual = _balancing_forces(A, rhs, G, grad_V, idx, lam_ref, lam_min)
    tau = np.linalg.solve(S @ S.T, S @ (grad_V - G.T @ lam))
    cop, support = _center_of_pressure(model, q_star, idx, lam)
    feasible = bool(np.all(lam >= lam_min))
    design = StaticPostureDesign(q_star, idx, lam, tau, S @ q_star, cop, support,
                                 float(np.linalg.norm(grad_V - S.T @ tau - G.T @ lam)), feasible)
    if require_positive and not feasible:
        raise InfeasibleDesignError(_infeasible_message(model, design, lam_min),
                                    status="negative_contact_force")
    return design


def _balancing_forces(A: FloatArray, rhs: FloatArray, G: FloatArray, grad_V: FloatArray,
                      idx: tuple[int, ...], lam_ref: Any, lam_min: float
                      ) -> tuple[FloatArray, float]:
    """``λ`` with ``A λ = rhs`` (the unactuated rows of the balance): minimum-norm, or the
    closest to ``lam_ref`` / the most positive one when the minimum-norm one is not ``> 0``."""
    lam = np.asarray(np.linalg.lstsq(A, rhs, rcond=None)[0], dtype=np.float64)
    residual = float(np.linalg.norm(A @ lam - rhs))
    sv = np.linalg.svd(A, compute_uv=False)
    # least squares is backward stable: a consistent system leaves a residual of about
    # (rows) ε ‖A‖ ‖λ‖ + ε ‖rhs‖; a factor 100 of margin
    scale = (sv.max(initial=0.0) * np.linalg.norm(lam) + np.linalg.norm(rhs))
    if residual > 100 * max(A.shape) * _EPS * max(scale, np.linalg.norm(grad_V)):
        raise InfeasibleDesignError(
            f"active: no contact forces on contacts {list(idx)} balance the unactuated "
            f"directions at q_star (residual {residual:.3g}); the posture needs other "
            "contacts or another configuration", status="unbalanced")
    rank = int(np.sum(sv > max(A.shape) * _EPS * sv.max(initial=0.0)))
    free = A.shape[1] - rank                    # dimensions of the balancing set
    if lam_ref is not None:
        lam_ref = as_vector("lam_ref", lam_ref, len(idx))
    if free == 0 or (lam_ref is None and np.all(lam >= lam_min)):
        return lam, residual
    return _project_forces(A, rhs, lam, lam_ref, lam_min), residual


def _project_forces(A: FloatArray, rhs: FloatArray, lam0: FloatArray, lam_ref: Any,
                    lam_min: float) -> FloatArray:
    """The balancing forces closest to ``lam_ref`` (default ``lam0``) with ``λ >= lam_min``
    (a small QP), started from the most positive balancing forces (a linear program)."""
    from scipy.optimize import linprog, minimize

    k = A.shape[1]
    bound = 10.0 * (np.abs(lam0).max(initial=0.0) + 1.0)
    # maximise t subject to A λ = rhs, λ_i >= t (t bounded so the LP is bounded)
    lp = linprog(np.r_[np.zeros(k), -1.0], A_ub=np.hstack([-np.eye(k), np.ones((k, 1))]),
                 b_ub=np.zeros(k), A_eq=np.hstack([A, np.zeros((A.shape[0], 1))]), b_eq=rhs,
                 bounds=[(None, None)] * k + [(None, bound)], method="highs")
    if not lp.success or lp.x[-1] < lam_min:
        return lam0 if not lp.success else lp.x[:k]
    target = lam0 if lam_ref is None else lam_ref
    res = minimize(lambda x: 0.5 * float((x - target) @ (x - target)), lp.x[:k],
                   jac=lambda x: x - target, method="SLSQP",
                   constraints=[{"type": "eq", "fun": lambda x: A @ x - rhs,
                                 "jac": lambda x: A}], bounds=[(lam_min, None)] * k)
    return np.asarray(res.x if res.success else lp.x[:k], float)


def _center_of_pressure(model: Any, q: FloatArray, idx: tuple[int, ...], lam: FloatArray
                        ) -> tuple[float | None, tuple[float, float] | None]:
    if model.support_abscissae is None or abs(lam.sum()) == 0.0:
        return None, None
    x = np.asarray(model.support_abscissae(q), float)[list(idx)]
    return float(lam @ x / lam.sum()), (float(x.min()), float(x.max()))


def _infeasible_message(model: Any, design: StaticPostureDesign, lam_min: float) -> str:
    names = [model.contact_names[i] for i in design.active]
    worst = int(np.argmin(design.lam_star))
    msg = (f"q_star: no contact forces >= {lam_min:.3g} on {names} hold this posture; the "
           f"balancing force of {names[worst]} is {design.lam_star[worst]:.6g} N")
    if design.center_of_pressure is not None and design.support is not None:
        lo, hi = design.support
        msg += (f"; the centre of pressure needed, x = {design.center_of_pressure:.6g} m, lies "
                f"outside the support [{lo:.6g}, {hi:.6g}] m (the centre of mass must project "
                "strictly inside it)")
    return msg + "; choose a posture closer to balance or keep other contacts closed"


def _check_posture_contacts(model: Any, q: FloatArray, idx: tuple[int, ...]) -> None:
    g = np.asarray(model.gaps(q), float)
    tol = 1e-9 * (1.0 + float(np.abs(q).max(initial=0.0)))
    for j in range(g.size):
        name = model.contact_names[j]
        if j in idx and abs(g[j]) > tol:
            raise ModelError(f"q_star: contact {name!r} should be closed (it is in active) "
                             f"but its gap is {g[j]:.3g}; move q_star onto the contact")
        if j not in idx and g[j] <= tol:
            raise ModelError(f"q_star: contact {name!r} is closed (gap {g[j]:.3g}) but not in "
                             "active; add it to active or open it")


def _warn_if_dependent(G: FloatArray, idx: tuple[int, ...]) -> None:
    rank = np.linalg.matrix_rank(G) if G.size else 0
    if rank < len(idx):
        warnings.warn(f"active: the gradients of the {len(idx)} active contacts are linearly "
                      f"dependent (rank {rank}; more contacts than independent directions): "
                      "the contact forces are not unique and the Delassus matrix is singular; "
                      "the design picks one distribution", NscontrolWarning, stacklevel=3)


def _active_indices(active: Any, m: int) -> tuple[int, ...]:
    a = np.atleast_1d(np.asarray(active))
    if a.size == 0:
        raise ModelError("active: expected at least one contact kept closed")
    if not np.issubdtype(a.dtype, np.integer) or a.ndim != 1:
        raise DimensionError(f"active: expected contact indices, got {active!r}")
    if np.any((a < 0) | (a >= m)) or np.unique(a).size != a.size:
        raise DimensionError(f"active: expected distinct indices in [0, {m}), got {a.tolist()}")
    return tuple(int(i) for i in np.sort(a))


def _null_space(S: FloatArray) -> FloatArray:
    """Orthonormal basis of ``ker S`` (columns)."""
    from scipy.linalg import null_space

    return np.asarray(null_space(S), float)


@dataclass(frozen=True, eq=False)
class ContactRegulator(StaticLaw):
    """The posture regulator ``τ = -K_p (S q - θ*) - K_d S v + τ*`` as a static
    :class:`~nscontrol.systems.Controller`.

    Run it with :func:`nscontrol.closed_loop` (a Python block held over each Moreau–Jean step;
    the measurement also carries the contact-force estimate ``λ̂``), or fold it into the
    plant's forces with :meth:`folded` (linear in ``(q, v)``: the θ-method then treats it
    implicitly, which keeps the discrete energy non-increasing).

    Parameters
    ----------
    model : ActuatedContactModel
        The robot.
    design : StaticPostureDesign
        Posture, contact forces and feed-forward (:func:`static_contact_forces`).
    Kp : array_like (p, p)
        Symmetric positive definite stiffness.
    Kd : array_like (p, p)
        Symmetric positive semi-definite damping.
    """

    model: Any
    design: StaticPostureDesign
    Kp: Any
    Kd: Any
    n_states: int = field(default=0, init=False)
    period: float | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        check_type("model", self.model, ActuatedContactModel)
        check_type("design", self.design, StaticPostureDesign,
                   hint="compute it with static_contact_forces(model, q_star, active)")
        p = self.model.actuation.shape[0]
        Kp = as_square("Kp", np.atleast_2d(self.Kp), p)
        Kd = as_square("Kd", np.atleast_2d(self.Kd), p)
        check_symmetric("Kp", Kp)
        check_symmetric("Kd", Kd)
        if np.linalg.eigvalsh(Kp).min() <= 0.0:
            raise ModelError(f"Kp: expected a positive definite stiffness, smallest eigenvalue "
                             f"{np.linalg.eigvalsh(Kp).min():.3g}")
        if np.linalg.eigvalsh(Kd).min() < -1e-12 * max(1.0, float(np.abs(Kd).max())):
            raise ModelError(f"Kd: expected a positive semi-definite damping, smallest "
                             f"eigenvalue {np.linalg.eigvalsh(Kd).min():.3g}")
        object.__setattr__(self, "Kp", Kp)
        object.__setattr__(self, "Kd", Kd)

    # -- the Controller protocol -----------------------------------------------------------
    @property
    def n_outputs(self) -> int:
        """Number of torques ``p``."""
        return int(self.model.actuation.shape[0])

    def output(self, t: float, xc: FloatArray, m: Any) -> FloatArray:
        """``τ`` at the plant state ``m.x = [q; v]``."""
        n = self.model.n_dof
        return self.torque(m.x[:n], m.x[n:])

    def compiled(self) -> Any:
        """The compiled form (a :class:`~nscontrol.systems.feedback.CompiledBlock`): the law
        as the affine feedback :meth:`state_feedback`."""
        return self.state_feedback().compiled()

    # -- the law and its potential ---------------------------------------------------------
    def torque(self, q: ArrayLike, v: ArrayLike) -> FloatArray:
        """``τ = -K_p (S q - θ*) - K_d S v + τ*``."""
        S = self.model.actuation
        return (-self.Kp @ (S @ np.asarray(q, float) - self.design.theta_star)
                - self.Kd @ (S @ np.asarray(v, float)) + self.design.tau_star)

    def total_potential(self, q: ArrayLike) -> float:
        """``W(q) = V(q) + ½ (S q - θ*)ᵀ K_p (S q - θ*) - τ*ᵀ S q``."""
        q = np.asarray(q, float)
        e = self.model.actuation @ q - self.design.theta_star
        return float(self.model.potential(q) + 0.5 * e @ self.Kp @ e
                     - self.design.tau_star @ (self.model.actuation @ q))

    def total_potential_gradient(self, q: ArrayLike) -> FloatArray:
        """``∇W(q) = ∇V(q) + Sᵀ K_p (S q - θ*) - Sᵀ τ*``."""
        q = np.asarray(q, float)
        S = self.model.actuation
        return (np.asarray(self.model.potential_gradient(q), float)
                + S.T @ (self.Kp @ (S @ q - self.design.theta_star) - self.design.tau_star))

    def total_potential_hessian(self, q: ArrayLike) -> FloatArray:
        """``∇²W(q) = ∇²V(q) + Sᵀ K_p S``."""
        S = self.model.actuation
        return np.asarray(self.model.potential_hessian(np.asarray(q, float)), float) \
            + S.T @ self.Kp @ S

    def energy(self, q: ArrayLike, v: ArrayLike) -> float:
        """The closed loop's Lyapunov function ``E = ½ vᵀ M(q) v + W(q)``."""
        q, v = np.asarray(q, float), np.asarray(v, float)
        return float(0.5 * v @ self.model.mass(q) @ v + self.total_potential(q))

    def state_feedback(self) -> Any:
        """The law as :class:`~nscontrol.systems.StateFeedback` ``u = K [q; v] + k`` (which
        :func:`nscontrol.closed_loop` folds into a linear plant's forces)."""
        from ..systems.feedback import StateFeedback

        S = self.model.actuation
        return StateFeedback(np.hstack([-self.Kp @ S, -self.Kd @ S]),
                             self.Kp @ self.design.theta_star + self.design.tau_star)

    def folded(self, plant: Any) -> Any:
        """``plant`` (a LagrangianSystem actuated by ``Sᵀ``) with the law as its linear forces:
        stiffness ``Sᵀ K_p S``, damping ``Sᵀ K_d S``, constant force ``Sᵀ (K_p θ* + τ*)``.

        Its :meth:`~nscontrol.systems.LagrangianSystem.energy` is ``E`` up to the constant
        ``½ θ*ᵀ K_p θ*``. Moreau–Jean's θ-method then integrates the law implicitly. It is
        the model ``simulate(closed_loop(plant, self.state_feedback()), ...)`` runs (the fold
        lowering, :mod:`nscontrol.simulate.lowering.fold`).
        """
        from ..simulate.lowering.fold import folded_plant
        from ..systems.closed_loop import closed_loop

        n = self.model.n_dof
        if plant.n_dof != n:
            raise DimensionError(f"plant: expected {n} coordinates, got {plant.n_dof}")
        return folded_plant(closed_loop(plant, self.state_feedback()))[0]


def design_contact_regulator(model: Any, q_star: ArrayLike, active: Any, Kp: Any, Kd: Any, *,
                             lam_ref: ArrayLike | None = None,
                             lam_min: float = 1e-6) -> ContactRegulator:
    """Design the posture regulator of ``q*`` on the contacts ``active`` (see the module).

    Parameters
    ----------
    model : ActuatedContactModel
        The robot.
    q_star : array_like (n,)
        The posture.
    active : sequence of int
        Contacts kept closed.
    Kp, Kd : array_like (p, p) or float
        Joint stiffness (positive definite) and damping (positive semi-definite).
    lam_ref : array_like, optional
        Preferred contact-force distribution when it is not unique.
    lam_min : float
        Smallest accepted contact force.

    Returns
    -------
    ContactRegulator

    Raises
    ------
    InfeasibleDesignError
        No ``λ* >= lam_min`` holds the posture (see :func:`static_contact_forces`).

    Examples
    --------
    >>> from nscontrol.systems.foot_body import foot_body_model
    >>> from nscontrol.errors import InfeasibleDesignError
    >>> try:        # leaning so far that the centre of mass is beyond the toe
    ...     design_contact_regulator(foot_body_model(), [0.0, 0.05, 0.0, -0.25], [0, 1],
    ...                              400.0, 30.0)
    ... except InfeasibleDesignError as err:
    ...     print(err.status, "outside the support [-0.08, 0.17]" in str(err))
    negative_contact_force True
    """
    design = static_contact_forces(model, q_star, active, lam_ref=lam_ref, lam_min=lam_min)
    return ContactRegulator(model, design, Kp, Kd)

"""Stability certificate of a posture-regulation law with non-permanent contacts (ch04).

A regulated posture ``q*`` is a Lyapunov-stable equilibrium, whatever sequence of contact
openings, closings and impacts follows a perturbation, when ``q*`` is a **strict local
minimum of the total potential** ``W`` on the admissible set ``Φ = {q : g(q) >= 0}``
(a nonsmooth Lagrange–Dirichlet theorem: ``E = ½ vᵀMv + W`` is positive definite about
``(q*, 0)`` and never increases). The checkable sufficient conditions at ``q*`` with the
contacts ``I*`` closed are those of constrained optimisation:

1. **KKT**: ``∇W(q*) = G_{I*}ᵀ λ`` (least squares) with a residual at round-off level and
   ``λ >= 0``;
2. **strict complementarity**: ``λ_α > 0`` on every contact of ``I*``;
3. **second-order sufficient condition (SOSC)**: ``Zᵀ [∇²W - Σ λ_α ∇²g_α] Z ≻ 0`` with ``Z`` a
   basis of ``ker G_{I*}`` orthogonal to the symmetry directions (cyclic coordinates).

:func:`gain_threshold` gives the smallest stiffness ``k̄`` such that ``K_p = k I`` satisfies 3
for every ``k > k̄`` (Debreu's lemma), and :func:`kinetic_angle_condition` the condition on the
Delassus matrix under which simultaneous and sequential inelastic impacts agree (the
continuity with respect to initial conditions that the invariance principle needs).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_matrix, as_square, as_vector, check_type
from ..errors import ModelError
from ..systems.foot_body import ActuatedContactModel

__all__ = ["PostureCertificate", "posture_certificate", "gain_threshold",
           "KineticAngleReport", "kinetic_angle_condition", "ConstrainedMinimum",
           "constrained_minimum"]

_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True, eq=False)
class PostureCertificate:
    """The strict-minimum test of ``W`` on ``Φ`` at a posture.

    Attributes
    ----------
    kkt_residual
        ``‖∇W(q*) - G_{I*}ᵀ λ‖ / (‖∇W‖ + ‖G‖ ‖λ‖)`` (relative).
    kkt_tolerance
        The bound the residual is compared with (from the least-squares error estimate).
    multipliers
        ``λ`` on the contacts of ``I*``.
    kkt_ok
        Residual below tolerance and ``λ >= -tol``.
    strictly_complementary
        Every ``λ_α > tol``.
    degenerate
        Some ``λ_α`` is zero to tolerance; the SOSC was then tested on the larger space
        ``ker G`` of the strictly positive contacts only (a sufficient test).
    reduced_hessian_eigs
        Eigenvalues of the reduced Hessian ``Zᵀ H Z`` (ascending).
    sosc_ok
        The smallest of them is ``> tol``.
    is_strict_min
        ``kkt_ok and sosc_ok``.
    verdict
        ``"strict minimum"`` or what failed, in words.
    failed
        The first condition that failed (``"kkt_residual"``, ``"multiplier_sign"``,
        ``"sosc"``) or ``""``.
    margin
        By how much: the most negative multiplier, the smallest reduced eigenvalue, or the
        residual over its tolerance; positive when the condition holds.
    """

    kkt_residual: float
    kkt_tolerance: float
    multipliers: FloatArray
    kkt_ok: bool
    strictly_complementary: bool
    degenerate: bool
    reduced_hessian_eigs: FloatArray
    sosc_ok: bool
    is_strict_min: bool
    verdict: str
    failed: str
    margin: float

    def to_json(self) -> dict[str, Any]:
        """The certificate as JSON-compatible values."""
        return {"kkt_residual": self.kkt_residual, "kkt_tolerance": self.kkt_tolerance,
                "multipliers": self.multipliers.tolist(), "kkt_ok": self.kkt_ok,
                "strictly_complementary": self.strictly_complementary,
                "degenerate": self.degenerate,
                "reduced_hessian_eigs": self.reduced_hessian_eigs.tolist(),
                "sosc_ok": self.sosc_ok, "is_strict_min": self.is_strict_min,
                "verdict": self.verdict, "failed": self.failed, "margin": self.margin}


def posture_certificate(model: Any, q_star: ArrayLike, active: Any, Kp: ArrayLike,
                        tau_star: ArrayLike, *, theta_star: ArrayLike | None = None
                        ) -> PostureCertificate:
    """Certify that ``q*`` is a strict local minimum of ``W`` on ``Φ`` (module docstring).

    Parameters
    ----------
    model : ActuatedContactModel
        The robot (potential and gap derivatives, actuation ``S``, symmetry directions).
    q_star : array_like (n,)
        The posture.
    active : sequence of int
        The contacts closed at ``q*``.
    Kp : array_like (p, p) or float
        Joint stiffness of the law.
    tau_star : array_like (p,)
        The law's constant feed-forward.
    theta_star : array_like (p,), optional
        The law's joint set-point (default ``S q*``).

    Returns
    -------
    PostureCertificate

    Raises
    ------
    DimensionError
        Wrong lengths.

    Examples
    --------
    >>> from nscontrol.systems.foot_body import foot_body_model
    >>> from nscontrol.design.contact_posture import static_contact_forces
    >>> model, q = foot_body_model(), [0, 0.05, 0, -0.1]
    >>> tau = static_contact_forces(model, q, [0, 1]).tau_star
    >>> c = posture_certificate(model, q, [0, 1], 120.0, tau)
    >>> c.failed, round(c.margin, 3)      # k_p = 120 below k̄ = 156.176
    ('sosc', -36.176)
    """
    check_type("model", model, ActuatedContactModel)
    S = model.actuation
    n, p = model.n_dof, S.shape[0]
    q = as_vector("q_star", q_star, n)
    idx = [int(i) for i in np.atleast_1d(active)]
    Kp = as_square("Kp", np.atleast_2d(np.asarray(Kp, float)), p)
    tau = as_vector("tau_star", tau_star, p)
    th = S @ q if theta_star is None else as_vector("theta_star", theta_star, p)
    grad_W = (np.asarray(model.potential_gradient(q), float) + S.T @ (Kp @ (S @ q - th) - tau))
    G = np.asarray(model.gap_jacobian(q), float)[idx]
    lam, *_ = np.linalg.lstsq(G.T, grad_W, rcond=None)
    scale = np.linalg.norm(grad_W) + np.linalg.norm(G, 2) * np.linalg.norm(lam)
    residual = float(np.linalg.norm(G.T @ lam - grad_W) / scale) if scale > 0 else 0.0
    # least squares is backward stable: a consistent system leaves a relative residual of
    # about n ε (times the condition number of G for the multipliers); a factor 100
    sv = np.linalg.svd(G, compute_uv=False) if G.size else np.zeros(0)
    cond = float(sv.max() / sv.min()) if sv.size and sv.min() > 0 else 1.0 / _EPS
    tol = 100.0 * n * _EPS * cond
    lam_tol = tol * max(1.0, float(np.abs(lam).max(initial=0.0)))
    kkt_ok = residual <= tol and bool(np.all(lam >= -lam_tol))
    positive = lam > lam_tol
    degenerate = bool(kkt_ok and not np.all(positive))
    # SOSC on ker G_I (on ker G of the strictly positive contacts when degenerate: sufficient)
    rows = [i for i, pos in zip(idx, positive, strict=True) if pos] if degenerate else idx
    H = (np.asarray(model.potential_hessian(q), float) + S.T @ Kp @ S
         - np.einsum("a,aij->ij", lam, np.asarray(model.gap_hessians(q), float)[idx]))
    Z = _reduced_basis(np.asarray(model.gap_jacobian(q), float)[rows], model.symmetry, n)
    eigs = np.linalg.eigvalsh(Z.T @ H @ Z) if Z.shape[1] else np.zeros(0)
    h_scale = max(1.0, float(np.abs(H).max(initial=0.0)))
    sosc_ok = bool(eigs.size == 0 or eigs[0] > 100 * n * _EPS * h_scale)
    failed, margin, verdict = _verdict(model, idx, residual, tol, lam, kkt_ok, sosc_ok, eigs,
                                       degenerate)
    return PostureCertificate(residual, tol, lam, bool(kkt_ok), bool(np.all(positive)),
                              degenerate, eigs, sosc_ok, bool(kkt_ok and sosc_ok), verdict,
                              failed, margin)


def _verdict(model: Any, idx: list[int], residual: float, tol: float, lam: FloatArray,
             kkt_ok: bool, sosc_ok: bool, eigs: FloatArray, degenerate: bool
             ) -> tuple[str, float, str]:
    names = [model.contact_names[i] for i in idx]
    min_eig = float(eigs[0]) if eigs.size else float("inf")
    if residual > tol:
        return ("kkt_residual", tol - residual,
                f"not an equilibrium: KKT residual {residual:.3g} > {tol:.3g} (the contacts "
                "cannot balance the potential's gradient)")
    if not kkt_ok:
        j = int(np.argmin(lam))
        return ("multiplier_sign", float(lam[j]),
                f"not a minimum on the admissible set: multiplier of {names[j]} is "
                f"{lam[j]:.6g} < 0 (that contact pulls; opening it lowers W)")
    if not sosc_ok:
        return ("sosc", min_eig,
                f"second-order condition fails: smallest reduced-Hessian eigenvalue "
                f"{min_eig:.6g} <= 0 (W is not strictly convex along the motions that keep "
                "the contacts closed)")
    word = "strict minimum (degenerate: some multiplier is zero)" if degenerate \
        else "strict minimum"
    return "", min(float(lam.min(initial=np.inf)), min_eig), word


def _reduced_basis(G: FloatArray, symmetry: FloatArray, n: int) -> FloatArray:
    """Orthonormal basis of ``ker G`` orthogonal to the symmetry directions."""
    from scipy.linalg import null_space

    rows = np.vstack([G, symmetry]) if symmetry.size else G
    if rows.size == 0:
        return np.eye(n)
    # the symmetry directions lie in ker G (neither V nor g sees them): stacking them as
    # rows removes them from the kernel
    return np.asarray(null_space(rows), float)


def gain_threshold(model: Any, q_star: ArrayLike, active: Any, lam_star: ArrayLike, *,
                   rtol: float = 1e-12) -> float:
    """``k̄``: ``K_p = k I`` satisfies the SOSC for every ``k > k̄`` (Debreu's lemma).

    With ``H0 = ∇²V - Σ λ*_α ∇²g_α`` and ``Z`` the reduced basis of :func:`posture_certificate`,
    ``k̄ = inf {k >= 0 : Zᵀ (H0 + k SᵀS) Z ⪰ 0}``, found by bisection to ``rtol``. It exists
    when ``H0`` is positive definite on ``ker S`` within the reduced space (the frozen robot
    standing on its contacts is stable); otherwise no stiffness helps.

    Parameters
    ----------
    model : ActuatedContactModel
        The robot.
    q_star : array_like (n,)
        The posture.
    active : sequence of int
        The contacts closed at ``q*``.
    lam_star : array_like, shape (n_active,)
        The contact forces at ``q*``.
    rtol : float
        Relative accuracy of the bisection.

    Returns
    -------
    float
        ``k̄ >= 0``.

    Raises
    ------
    ModelError
        ``H0`` is not positive definite on ``ker S`` (reduced): no gain threshold exists.

    Examples
    --------
    >>> from nscontrol.systems.foot_body import foot_body_model
    >>> k = gain_threshold(foot_body_model(), [0, 0.05, 0, -0.1], [0, 1], [77.4074, 128.6026])
    >>> round(k, 3)                        # m_b g L cos θ*
    156.176
    """
    check_type("model", model, ActuatedContactModel)
    n = model.n_dof
    q = as_vector("q_star", q_star, n)
    idx = [int(i) for i in np.atleast_1d(active)]
    lam = as_vector("lam_star", lam_star, len(idx))
    H0 = (np.asarray(model.potential_hessian(q), float)
          - np.einsum("a,aij->ij", lam, np.asarray(model.gap_hessians(q), float)[idx]))
    Z = _reduced_basis(np.asarray(model.gap_jacobian(q), float)[idx], model.symmetry, n)
    A, B = Z.T @ H0 @ Z, Z.T @ model.actuation.T @ model.actuation @ Z
    if A.size == 0:
        return 0.0
    wB, VB = np.linalg.eigh(B)
    kernel = VB[:, wB <= 1e3 * _EPS * max(1.0, float(wB.max(initial=0.0)))]
    if kernel.shape[1] and np.linalg.eigvalsh(kernel.T @ A @ kernel)[0] <= 0.0:
        raise ModelError("model: the potential is not strictly convex along the unactuated "
                         "motions that keep the contacts closed; no joint stiffness makes the "
                         "posture a strict minimum")

    def ok(k: float) -> bool:
        return bool(np.linalg.eigvalsh(A + k * B)[0] >= 0.0)

    if ok(0.0):
        return 0.0
    hi = 1.0
    while not ok(hi):
        hi *= 2.0
    lo = 0.0
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return hi


@dataclass(frozen=True, eq=False)
class KineticAngleReport:
    """The kinetic angles between contacts: ``cos = W_ij / √(W_ii W_jj)`` of the Delassus
    matrix ``W = G M⁻¹ Gᵀ``.

    Attributes
    ----------
    holds
        Every off-diagonal ``W_ij <= 0`` to round-off (kinetic angles ``>= 90°``): simultaneous
        and sequential inelastic impacts then give the same post-impact velocity.
    delassus
        ``W``.
    cosines
        The matrix of kinetic-angle cosines.
    worst
        The largest off-diagonal cosine (``<= 0`` when the condition holds).
    """

    holds: bool
    delassus: FloatArray
    cosines: FloatArray
    worst: float


def kinetic_angle_condition(M: ArrayLike, G: ArrayLike) -> KineticAngleReport:
    """Whether the contacts' kinetic angles are all ``>= 90°`` (off-diagonal ``W_ij <= 0``).

    Parameters
    ----------
    M : array_like (n, n)
        Symmetric positive definite mass matrix at the contact configuration.
    G : array_like (k, n)
        Jacobian of the closed contacts' gaps (one row per contact).

    Returns
    -------
    KineticAngleReport

    Raises
    ------
    ModelError
        ``M`` not positive definite, a zero contact gradient.

    Examples
    --------
    >>> r = kinetic_angle_condition(np.eye(2), [[1.0, 0.0], [-1.0, 1.0]])
    >>> r.holds, round(r.worst, 6)
    (True, -0.707107)
    """
    M = as_square("M", M)
    G = as_matrix("G", G, cols=M.shape[0])
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        raise ModelError("M: expected a symmetric positive definite mass matrix") from None
    X = np.linalg.solve(L, G.T)
    W = X.T @ X
    d = np.sqrt(np.diag(W))
    if np.any(d == 0.0):
        raise ModelError("G: a contact has a zero gradient (no normal direction)")
    cos = W / np.outer(d, d)
    off = cos[~np.eye(cos.shape[0], dtype=bool)]
    worst = float(off.max(initial=-1.0))
    # W is computed to about n ε relative (a Cholesky solve): a factor 100
    return KineticAngleReport(bool(worst <= 100 * M.shape[0] * _EPS), W, cos, worst)



@dataclass(frozen=True, eq=False)
class ConstrainedMinimum:
    """A local minimiser of a potential on ``Φ = {g(q) >= 0}`` (symmetry directions fixed).

    Attributes
    ----------
    q
        The minimiser.
    active
        Contacts closed there (``g <= gap_tol``).
    multipliers
        Their contact forces ``λ`` (``∇W = G_activeᵀ λ``, least squares).
    value
        The potential there.
    kkt_residual
        ``‖Nᵀ(∇W - G_activeᵀ λ)‖ / ‖∇W‖`` (``N``: the non-symmetry directions).
    success
        The optimiser converged, or stopped at its precision limit (SLSQP's "positive
        directional derivative") with ``kkt_residual <= 1e-8`` and ``λ >= 0``.
    """

    q: FloatArray
    active: tuple[int, ...]
    multipliers: FloatArray
    value: float
    kkt_residual: float
    success: bool


def constrained_minimum(model: Any, potential: Any, gradient: Any, q0: ArrayLike, *,
                        gap_tol: float = 1e-9) -> ConstrainedMinimum:
    """Minimise ``potential`` on ``{g(q) >= 0}`` from ``q0``, the symmetry coordinates fixed.

    Sequential quadratic programming (SciPy's SLSQP) on the coordinates orthogonal to the
    symmetry directions; the multipliers are then recomputed by least squares on the
    contacts found closed.

    Parameters
    ----------
    model : ActuatedContactModel
        Gaps, their Jacobian and the symmetry directions.
    potential, gradient : callable
        ``q -> W(q)`` and ``q -> ∇W(q)`` (e.g. a :class:`ContactRegulator`'s
        ``total_potential`` and ``total_potential_gradient`` on the *true* model).
    q0 : array_like (n,)
        Starting point (admissible).
    gap_tol : float
        A contact with ``g <= gap_tol`` counts as closed.

    Returns
    -------
    ConstrainedMinimum
    """
    from scipy.linalg import null_space
    from scipy.optimize import minimize

    q0 = as_vector("q0", q0, model.n_dof)
    N = np.eye(model.n_dof) if not model.symmetry.size else null_space(model.symmetry)

    def to_q(z: FloatArray) -> FloatArray:
        return q0 + N @ z

    res = minimize(lambda z: float(potential(to_q(z))), np.zeros(N.shape[1]),
                   jac=lambda z: N.T @ np.asarray(gradient(to_q(z)), float), method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda z: model.gaps(to_q(z)),
                                 "jac": lambda z: model.gap_jacobian(to_q(z)) @ N}],
                   options={"ftol": 1e-12, "maxiter": 500})
    z = res.x
    active = tuple(int(i) for i in np.flatnonzero(model.gaps(to_q(z)) <= gap_tol))
    if active:   # polish: Newton on the KKT equations of the contacts found closed
        z = _polish_kkt(model, gradient, to_q, N, z, list(active))
    q = to_q(z)
    G = np.asarray(model.gap_jacobian(q), float)[list(active)]
    lam = np.linalg.lstsq(G.T, np.asarray(gradient(q), float), rcond=None)[0] if active \
        else np.zeros(0)
    grad = np.asarray(gradient(q), float)
    kkt = float(np.linalg.norm(N.T @ (grad - G.T @ lam))) / max(float(np.linalg.norm(grad)), 1e-300)
    # SLSQP stops with "positive directional derivative" when the line search cannot
    # improve W in floating point: accept it when the point satisfies KKT (1e-8: the
    # optimiser's ftol of 1e-12 on W translates into about √ftol on the gradient)
    ok = bool(res.success or (kkt <= 1e-8 and np.all(lam >= 0.0)))
    return ConstrainedMinimum(q, active, lam, float(potential(q)), kkt, ok)


def _polish_kkt(model: Any, gradient: Any, to_q: Any, N: FloatArray, z: FloatArray,
                active: list[int]) -> FloatArray:
    """Newton on ``Nᵀ(∇W - G_Aᵀ λ) = 0, g_A = 0`` (central-difference Jacobian), a few
    iterations from SLSQP's point; returns it unchanged if Newton does not reduce the
    residual."""
    from ..numerics.differences import central_difference_jacobian

    k = len(active)

    def residual(x: FloatArray) -> FloatArray:
        zz, lam = x[:-k], x[-k:]
        q = to_q(zz)
        G = np.asarray(model.gap_jacobian(q), float)[active]
        return np.concatenate([N.T @ (np.asarray(gradient(q), float) - G.T @ lam),
                               np.asarray(model.gaps(q), float)[active]])

    q = to_q(z)
    G = np.asarray(model.gap_jacobian(q), float)[active]
    lam = np.linalg.lstsq(G.T, np.asarray(gradient(q), float), rcond=None)[0]
    x = np.concatenate([z, lam])
    r = residual(x)
    for _ in range(20):
        J = central_difference_jacobian(residual, x)
        try:
            x_new = x - np.linalg.solve(J, r)
        except np.linalg.LinAlgError:
            break
        r_new = residual(x_new)
        if not np.linalg.norm(r_new) < np.linalg.norm(r):
            break
        x, r = x_new, r_new
    return np.asarray(x[:-k], float)

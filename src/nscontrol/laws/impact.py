"""Newton's impact law: restitution of the normal relative velocity, one or many contacts.

Conventions: contact ``i`` has a gap ``g_i(q) >= 0`` with gradient ``W[:, i]``, so
``W^T v`` are the normal relative velocities (negative = approaching) and the impulse ``P >= 0``
acts on the generalised velocities as ``M (v+ - v-) = W P``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_square,
    as_vector,
    check_in_interval,
    check_positive,
    check_positive_definite,
    check_symmetric,
)
from ..errors import DimensionError, ModelError, SolverError

__all__ = ["NewtonImpactLaw", "ImpactResult", "restitution_matrix", "delassus_matrix",
           "impact_energy_change"]


def restitution_matrix(m1: Any, m2: Any, e: Any) -> FloatArray:
    """The 2x2 map ``[v1+; v2+] = R [v1-; v2-]`` of a central impact of two point masses (ch02).

    ``R = [[m1 - e m2, (1 + e) m2], [(1 + e) m1, m2 - e m1]] / (m1 + m2)``: momentum is
    conserved and the relative velocity is reversed and scaled by ``e``,
    ``v2+ - v1+ = -e (v2- - v1-)``. Apply it only to approaching bodies (``v1- > v2-`` when
    body 1 is on the left).

    Parameters
    ----------
    m1, m2
        Masses ``> 0``.
    e
        Restitution coefficient in ``[0, 1]``.

    Examples
    --------
    >>> restitution_matrix(1.0, 1.0, 1.0) @ [1.0, 0.0]   # equal masses, elastic: swap
    array([0., 1.])
    """
    m1 = check_positive("m1", m1)
    m2 = check_positive("m2", m2)
    e = check_in_interval("e", e, 0.0, 1.0)
    return np.array([[m1 - e * m2, (1.0 + e) * m2],
                     [(1.0 + e) * m1, m2 - e * m1]]) / (m1 + m2)


@dataclass(frozen=True, eq=False)
class ImpactResult:
    """Outcome of a (multi-contact) impact.

    Attributes
    ----------
    v_plus
        Post-impact generalised velocities.
    impulse
        Normal impulses ``P >= 0``, one per contact (zero for inactive contacts).
    normal_velocity
        Post-impact normal relative velocities ``W^T v+`` (all contacts).
    """

    v_plus: FloatArray
    impulse: FloatArray
    normal_velocity: FloatArray


@dataclass(frozen=True, eq=False)
class NewtonImpactLaw:
    """Newton's restitution law ``W^T v+ = -e W^T v-`` where contacts stay closed.

    Multi-contact form (velocity level, one LCP on the active contacts)::

        0 <= P  ⟂  W^T v+ + e W^T v-  >= 0,      v+ = v- + M^{-1} W P

    i.e. ``0 <= P ⟂ Delta P + (1 + e) W^T v- >= 0`` with the Delassus matrix
    ``Delta = W^T M^{-1} W``. For one contact the closed form
    ``P = max(0, -(1 + e) u- / Delta)`` is used. With one ``e`` for all contacts the kinetic
    energy changes by ``(1 - e) / 2 * P^T W^T v- <= 0`` (complementarity gives
    ``P^T Delta P = -(1 + e) P^T W^T v-``): it never grows, and is conserved for ``e = 1``.
    With different ``e`` per contact this bound is not guaranteed. Exactly, for one ``e``
    (:func:`impact_energy_change`)::

        T+ - T- = -(1 - e) / (2 (1 + e)) · Pᵀ Delta P   (T = ½ vᵀ M v)

    This is the impact law of Moreau–Jean time-stepping for several simultaneous contacts
    (one LCP per step over the contacts predicted to close; for ``e = 0`` the post-impact
    velocity is the ``M``-metric projection of ``v-`` on the tangent cone of the contacts).

    Parameters
    ----------
    e
        Restitution coefficient(s) in ``[0, 1]``: a scalar or one per contact.

    Examples
    --------
    Three touching unit balls, the first arriving at speed 1 (simultaneous impact):

    >>> import numpy as np
    >>> W = np.array([[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]])   # gaps q2 - q1, q3 - q2
    >>> res = NewtonImpactLaw(1.0).apply(np.eye(3), W, [1.0, 0.0, 0.0])
    >>> np.round(res.v_plus, 12).tolist()
    [-0.333333333333, 0.666666666667, 0.666666666667]

    References
    ----------
    Ch. 2 (Martinelli, Menini, Tornambè) for the two-body map; M. Frémond / B. Brogliato,
    *Nonsmooth Mechanics*, Springer, for the multi-contact Newton law at velocity level.
    """

    e: Any = 1.0

    def __post_init__(self) -> None:
        e = np.atleast_1d(as_float_array("e", self.e, finite=False))
        if e.ndim != 1 or e.size == 0:
            raise DimensionError(f"e: expected a scalar or a vector, got shape {e.shape}")
        if not np.all(np.isfinite(e)) or np.any((e < 0.0) | (e > 1.0)):
            raise ModelError(f"e: expected restitution coefficients in [0, 1], got {e.tolist()}")
        object.__setattr__(self, "e", e)

    def coefficients(self, n_contacts: int) -> FloatArray:
        """The restitution coefficient of each of ``n_contacts`` contacts."""
        if self.e.size == 1:
            return np.full(n_contacts, self.e[0])
        if self.e.size != n_contacts:
            raise DimensionError(f"e: expected one coefficient or {n_contacts} (one per "
                                 f"contact: the columns of W), got {self.e.size}")
        return self.e

    def apply(self, M: ArrayLike, W: Any, v_minus: Any, active: Any = None) -> ImpactResult:
        """Post-impact velocities and impulses.

        Parameters
        ----------
        M
            ``(n, n)`` symmetric positive definite mass matrix.
        W
            ``(n, k)`` contact gradients (one column per contact); a 1-d ``W`` is one contact.
        v_minus
            ``(n,)`` pre-impact velocities.
        active
            Contacts taking part (closed gaps): boolean mask of length ``k`` or indices;
            default all.

        Returns
        -------
        ImpactResult

        Raises
        ------
        ModelError
            ``M`` not symmetric positive definite, NaN/inf entries.
        DimensionError
            Shapes disagree.
        SolverError
            The impact LCP has no solution found (should not happen for SPD ``M``).
        """
        M = as_square("M", M)
        inverse_times = _mass_inverse(M)
        n = M.shape[0]
        if np.ndim(W) == 1:                          # one contact: a gradient vector
            W = as_vector("W", W, n).reshape(n, 1)
        W = as_matrix("W", W, n)
        v_minus = as_vector("v_minus", v_minus, n)
        k = W.shape[1]
        e = self.coefficients(k)
        idx = _active_indices(active, k)
        impulse = np.zeros(k)
        v_plus = v_minus.copy()
        if idx.size:
            Wa = W[:, idx]
            MinvW = inverse_times(Wa)
            q = (1.0 + e[idx]) * (Wa.T @ v_minus)
            impulse[idx] = _impact_lcp(Wa.T @ MinvW, q)
            v_plus += MinvW @ impulse[idx]
        return ImpactResult(v_plus=v_plus, impulse=impulse, normal_velocity=W.T @ v_plus)


def delassus_matrix(M: ArrayLike, W: ArrayLike) -> FloatArray:
    """The Delassus matrix ``Delta = Wᵀ M⁻¹ W`` of the contacts (columns of ``W``).

    Parameters
    ----------
    M
        ``(n, n)`` symmetric positive definite mass matrix.
    W
        ``(n, k)`` contact gradients, one column per contact.

    Raises
    ------
    ModelError
        ``M`` not symmetric positive definite.

    Examples
    --------
    >>> delassus_matrix(2.0 * np.eye(2), [[1.0], [1.0]])
    array([[1.]])
    """
    M = as_square("M", M)
    n = M.shape[0]
    W = as_vector("W", W, n).reshape(n, 1) if np.ndim(W) == 1 else as_matrix("W", W, n)
    D = W.T @ _mass_inverse(M)(W)
    return np.asarray(0.5 * (D + D.T), float)


def impact_energy_change(delassus: ArrayLike, impulse: ArrayLike, e: float) -> float:
    """Kinetic energy change of a Newton impact, ``-(1 - e) / (2 (1 + e)) Pᵀ Delta P``.

    Exact for one restitution coefficient ``e`` on every contact: complementarity gives
    ``Pᵀ Delta P = -(1 + e) Pᵀ Wᵀ v-``, and ``T+ - T- = Pᵀ Wᵀ v- + ½ Pᵀ Delta P``.

    Parameters
    ----------
    delassus
        ``(k, k)`` Delassus matrix of the contacts (:func:`delassus_matrix`).
    impulse
        ``(k,)`` impulses ``P >= 0`` of the impact.
    e
        The common restitution coefficient, in ``[0, 1]``.

    Examples
    --------
    >>> res = NewtonImpactLaw(0.5).apply(np.eye(1), [1.0], [-2.0])   # T- = 2, v+ = 1
    >>> impact_energy_change(np.eye(1), res.impulse, 0.5)               # T+ - T- = 0.5 - 2
    -1.5
    """
    e = check_in_interval("e", e, 0.0, 1.0)
    P = as_vector("impulse", impulse)
    D = as_square("delassus", delassus, P.shape[0])
    return float(-(1.0 - e) / (2.0 * (1.0 + e)) * (P @ D @ P))


def _mass_inverse(M: FloatArray) -> Callable[[FloatArray], FloatArray]:
    """``X -> M^{-1} X`` for a symmetric positive definite ``M`` (checked on the way)."""
    check_symmetric("M", M)
    d = np.diag(M).copy()
    if not np.any(M - np.diag(d)):                  # point masses: no factorisation
        if np.any(d <= 0.0):
            raise ModelError(f"M: expected a symmetric positive definite mass matrix, got "
                             f"diagonal entries with min {d.min():.3g}")
        return lambda X: X / d[:, None]
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        check_positive_definite("M", M)             # raises with the smallest eigenvalue
        raise
    from scipy.linalg import solve_triangular

    return lambda X: solve_triangular(L.T, solve_triangular(L, X, lower=True), lower=False)


def _active_indices(active: Any, k: int) -> np.ndarray:
    if active is None:
        return np.arange(k)
    a = np.asarray(active)
    if a.dtype == bool:
        if a.shape != (k,):
            raise DimensionError(f"active: expected a boolean mask of length {k}, got shape "
                                 f"{a.shape}")
        return np.flatnonzero(a)
    if a.ndim > 1 or (a.size and not np.issubdtype(a.dtype, np.integer)):
        raise DimensionError(f"active: expected contact indices or a boolean mask, got {active!r}")
    a = a.astype(int).ravel()
    if np.any((a < 0) | (a >= k)) or np.unique(a).size != a.size:
        raise DimensionError(f"active: expected distinct indices in [0, {k}), got {a.tolist()}")
    return np.sort(a)


def _impact_lcp(delassus: FloatArray, q: FloatArray) -> FloatArray:
    """Impulses ``0 <= P ⟂ Delta P + q >= 0``; closed form for one contact."""
    if q.size == 1:
        if delassus[0, 0] <= 0.0:
            raise ModelError("W: the contact direction is zero (Delassus entry "
                             f"{delassus[0, 0]:.3g}); a contact needs a nonzero gradient")
        return np.maximum(0.0, -q / delassus[0, 0])
    from ..numerics.lcp import solve_lcp

    result = solve_lcp(delassus, q)
    if not result.success:
        raise SolverError(f"NewtonImpactLaw.apply: the impact LCP on the Delassus matrix has no "
                          f"verified solution ({result.status}); check W for dependent contact "
                          "directions", status=result.status)
    return result.z

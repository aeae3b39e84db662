"""The one-step frictional contact problem of Coulomb's law (planar and spatial contacts).

Given the Delassus matrix ``W`` and the free local velocity ``q`` (unknowns ordered per
contact: normal, then ``dim - 1`` tangents), find the impulses ``r`` and velocities
``u = W r + q`` with, for every contact ``i``::

    r_i ∈ K_μ = {|r_T| <= μ r_N},   û_i = u_i + μ |u_{T,i}| e_N ∈ K_μ*,   r_i ⟂ û_i,

De Saxcé's form of Coulomb's law: take-off (``r = 0``, ``u_N >= 0``), stick (``u = 0``,
``r`` in the cone) or slip (``u_N = 0``, ``r`` on the cone's boundary opposite to ``u_T``).
The term ``μ |u_T|`` makes the problem a complementarity problem over a cone and its dual,
for which solutions exist whenever ``W`` is positive definite.

Two methods:

- ``"lcp"`` (``dim = 2`` only): the planar law is exactly a linear complementarity problem
  in ``(r_N, r_T⁺, r_T⁻, β)`` with ``r_T = r_T⁺ - r_T⁻`` and ``β`` the slip speed, solved by
  :func:`~nscontrol.numerics.lcp.solve_lcp` (Lemke: exact up to round-off).
- ``"nsgs"``: non-smooth Gauss–Seidel over contacts with exact local solvers (the three
  cases enumerated; the slip direction of a spatial contact as the root of a scalar
  equation in the slip angle, to machine precision); the relative natural-map error of the
  whole problem is computed after every sweep and must reach ``tol``.

The reported ``residual`` is ``‖r - P_K(r - û)‖ / max(‖q‖, ‖r‖, ‖u‖)`` (the scaling Siconos
uses, so that figures compare like with like).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from scipy import sparse

from .._validation import FloatArray, as_vector, check_integer, check_positive
from ..errors import DimensionError, ModelError, SolverError
from . import _friction_kernels as kernels

__all__ = ["FrictionContactResult", "solve_friction_contact", "friction_residual",
           "contact_states", "planar_friction_lcp", "frictionless_impulses", "CONTACT_STATES"]

#: Names of the contact states: index 0 open (take-off), 1 stick, 2 slip.
CONTACT_STATES = ("open", "stick", "slip")
#: ``auto`` solves planar problems up to this many contacts by the LCP (Lemke: O(m³)).
AUTO_LCP_MAX_CONTACTS = 40


@dataclass(frozen=True)
class FrictionContactResult:
    """Solution of one frictional contact problem.

    Attributes
    ----------
    r : ndarray (m dim,)
        Impulses, per contact (normal, tangents).
    u : ndarray (m dim,)
        Local velocities ``W r + q``.
    states : ndarray (m,) of int
        0 open, 1 stick, 2 slip (:data:`CONTACT_STATES`).
    residual : float
        Relative natural-map error (module docstring).
    iterations : int
        NSGS sweeps, or Lemke pivots (0 when not reported).
    method : str
        ``"lcp"`` or ``"nsgs"``.
    status : str
        ``"solved"``, ``"max_iter"`` or the LCP's status.
    """

    r: FloatArray
    u: FloatArray
    states: np.ndarray
    residual: float
    iterations: int
    method: str
    status: str

    @property
    def success(self) -> bool:
        """Whether the solve reached its tolerance."""
        return self.status == "solved"


def friction_residual(W: Any, q: Any, mu: Any, r: Any, dim: int) -> float:
    """Relative natural-map error of ``r`` for the problem ``(W, q, μ)``.

    Parameters
    ----------
    W : array_like or scipy.sparse matrix (m dim, m dim)
        Delassus matrix.
    q : array_like (m dim,)
        Free local velocity.
    mu : float or array_like (m,)
        Friction coefficients.
    r : array_like (m dim,)
        Candidate impulses.
    dim : int
        1 (frictionless), 2 (planar) or 3 (spatial).

    Examples
    --------
    >>> bool(friction_residual(np.eye(3), [-1.0, 0.2, 0.0], 0.5, [1.0, -0.2, 0.0], 3) == 0.0)
    True
    """
    Wc, qv, muv = _problem(W, q, mu, dim)
    rv = as_vector("r", r, qv.shape[0])
    u = np.asarray(Wc @ rv).ravel() + qv
    return float(kernels.relative_error(qv, rv, u, muv, dim))


def contact_states(r: Any, u: Any, dim: int, *, tol: float = 1e-9) -> np.ndarray:
    """Open (0), stick (1) or slip (2) per contact from impulses and velocities.

    Parameters
    ----------
    r, u : array_like (m dim,)
        Impulses and local velocities.
    dim : int
        Unknowns per contact.
    tol : float
        Slip speeds ``|u_T| <= tol max(1, max|u|)`` count as stick.

    Examples
    --------
    >>> contact_states([1.0, -0.5, 0.0, 0.0], [0.0, 0.5, 1.0, 0.0], 2).tolist()
    [2, 0]
    """
    r = np.asarray(r, float).reshape(-1, dim)
    u = np.asarray(u, float).reshape(-1, dim)
    slip = np.linalg.norm(u[:, 1:], axis=1) if dim > 1 else np.zeros(r.shape[0])
    threshold = tol * max(1.0, float(np.max(np.abs(u), initial=0.0)))
    states = np.where(slip > threshold, kernels.SLIP, kernels.STICK)
    return np.where(r[:, 0] > 0.0, states, kernels.OPEN).astype(np.int64)


def solve_friction_contact(W: Any, q: Any, mu: Any, *, dim: int,
                           method: Literal["auto", "lcp", "nsgs"] = "auto",
                           tol: float = 1e-12, max_sweeps: int = 100_000,
                           r0: Any = None) -> FrictionContactResult:
    """Solve ``u = W r + q`` with Coulomb's law (De Saxcé's form) at every contact.

    Parameters
    ----------
    W : array_like or scipy.sparse matrix (m dim, m dim)
        Delassus matrix (symmetric positive semidefinite; its diagonal blocks definite).
    q : array_like (m dim,)
        Free local velocity, per contact (normal, tangents).
    mu : float or array_like (m,)
        Friction coefficients ``>= 0``.
    dim : int
        1 (frictionless: an LCP), 2 (planar contacts) or 3 (spatial contacts).
    method : {"auto", "lcp", "nsgs"}
        ``"lcp"`` for planar problems; ``"auto"`` takes it up to
        :data:`AUTO_LCP_MAX_CONTACTS` contacts and NSGS otherwise, then the other method
        when the first does not reach ``tol``.
    tol : float
        Tolerance of the relative natural-map error.
    max_sweeps : int
        NSGS sweep limit.
    r0 : array_like (m dim,), optional
        NSGS starting impulses (a warm start); by default zeros, or for more than
        :data:`AUTO_LCP_MAX_CONTACTS` contacts the solution of the frictionless problem
        (normal impulses only, one LCP), which is exact when no tangential load acts.

    Returns
    -------
    FrictionContactResult

    Raises
    ------
    ModelError
        Negative ``μ``, an unknown method, ``"lcp"`` with ``dim != 2``.
    DimensionError
        Shapes that disagree.
    SolverError
        No method reached ``tol`` (``err.result`` in the message's figures).

    Examples
    --------
    One contact, ``W = I``, ``μ = 0.5``: a small tangential load sticks, a large one slides.

    >>> stick = solve_friction_contact(np.eye(3), [-1.0, 0.2, 0.0], 0.5, dim=3)
    >>> stick.r.round(12).tolist(), stick.states.tolist()
    ([1.0, -0.2, -0.0], [1])
    >>> slip = solve_friction_contact(np.eye(3), [-1.0, 1.0, 0.0], 0.5, dim=3)
    >>> slip.r.round(12).tolist(), slip.u.round(12).tolist(), slip.states.tolist()
    ([1.0, -0.5, -0.0], [0.0, 0.5, 0.0], [2])
    """
    dim = check_integer("dim", dim, minimum=1)
    if dim > 3:
        raise ModelError(f"dim: expected 1, 2 or 3 unknowns per contact, got {dim}")
    Wc, qv, muv = _problem(W, q, mu, dim)
    tol = check_positive("tol", tol)
    max_sweeps = check_integer("max_sweeps", max_sweeps, minimum=1)
    if method not in ("auto", "lcp", "nsgs"):
        raise ModelError(f"method: expected 'auto', 'lcp' or 'nsgs', got {method!r}")
    if method == "lcp" and dim != 2:
        raise ModelError(f"method: 'lcp' solves planar contacts (dim=2), got dim={dim}; use "
                         "'nsgs'")
    m = muv.shape[0]
    if m == 0:
        return FrictionContactResult(np.zeros(0), np.zeros(0), np.zeros(0, np.int64), 0.0, 0,
                                     "nsgs", "solved")
    order = [method] if method != "auto" else (
        ["lcp", "nsgs"] if dim == 2 and m <= AUTO_LCP_MAX_CONTACTS
        else ["nsgs", "lcp"] if dim == 2 and m <= 5 * AUTO_LCP_MAX_CONTACTS else ["nsgs"])
    attempts = []
    for name in order:
        result = (_solve_lcp(Wc, qv, muv) if name == "lcp"
                  else _solve_nsgs(Wc, qv, muv, dim, tol, max_sweeps, r0))
        if result.success:
            return result
        attempts.append(f"{name}: {result.status}, residual {result.residual:.3g} after "
                        f"{result.iterations} iterations")
    raise SolverError("solve_friction_contact: no method reached tol = "
                      f"{tol:.3g} ({'; '.join(attempts)}); raise max_sweeps or tol, or check "
                      "that W's diagonal blocks are positive definite", status=result.status)


def planar_friction_lcp(W: Any, q: Any, mu: Any) -> tuple[FloatArray, FloatArray]:
    """The planar problem as an LCP ``(M, q̃)`` in ``z = (r_N, r_T⁺, r_T⁻, β)`` (4 m unknowns).

    ``w = (u_N, β + u_T, β - u_T, μ r_N - r_T⁺ - r_T⁻)``: slip forward means ``r_T⁻ = μ r_N``
    and ``β = u_T``; stick ``β = 0``.

    Parameters
    ----------
    W : array_like (2 m, 2 m)
        Delassus matrix, per contact (normal, tangent).
    q : array_like (2 m,)
        Free local velocity.
    mu : float or array_like (m,)
        Friction coefficients.

    Examples
    --------
    >>> M, qq = planar_friction_lcp(np.eye(2), [-1.0, 0.2], 0.5)
    >>> M.shape, qq.tolist()
    ((4, 4), [-1.0, 0.2, -0.2, 0.0])
    """
    Wc, qv, muv = _problem(W, q, mu, 2)
    Wd = Wc.toarray()
    m = muv.shape[0]
    n_, t_ = np.arange(0, 2 * m, 2), np.arange(1, 2 * m, 2)
    Wnn, Wnt = Wd[np.ix_(n_, n_)], Wd[np.ix_(n_, t_)]
    Wtn, Wtt = Wd[np.ix_(t_, n_)], Wd[np.ix_(t_, t_)]
    eye, zero = np.eye(m), np.zeros((m, m))
    M = np.block([[Wnn, Wnt, -Wnt, zero],
                  [Wtn, Wtt, -Wtt, eye],
                  [-Wtn, -Wtt, Wtt, eye],
                  [np.diag(muv), -eye, -eye, zero]])
    return M, np.concatenate([qv[n_], qv[t_], -qv[t_], np.zeros(m)])


# -- methods ---------------------------------------------------------------------------------
def _solve_lcp(W: Any, q: FloatArray, mu: FloatArray) -> FrictionContactResult:
    from .lcp import solve_lcp

    m = mu.shape[0]
    M, qq = planar_friction_lcp(W, q, mu)
    res = solve_lcp(M, qq, method="lemke")
    z = res.z
    r = np.empty(2 * m)
    r[0::2] = z[:m]
    r[1::2] = z[m:2 * m] - z[2 * m:3 * m]
    u = np.asarray(W @ r).ravel() + q
    err = float(kernels.relative_error(q, r, u, mu, 2))
    # the LCP is solved and verified by solve_lcp (its own residual test): exact up to
    # round-off, so tol does not apply to it
    status = "solved" if res.success else res.status
    return FrictionContactResult(r, u, contact_states(r, u, 2), err,
                                 int(getattr(res, "iterations", 0) or 0), "lcp", status)


def _solve_nsgs(W: Any, q: FloatArray, mu: FloatArray, dim: int, tol: float,
                max_sweeps: int, r0: Any) -> FrictionContactResult:
    if r0 is not None:
        r = as_vector("r0", r0, q.shape[0]).copy()
    elif mu.shape[0] > AUTO_LCP_MAX_CONTACTS:   # a cold start of a large (stacked) set
        r = frictionless_impulses(W, q, dim)
    else:
        r = np.zeros_like(q)
    u = np.empty_like(q)
    states = np.zeros(mu.shape[0], np.int64)
    code, sweeps, err = kernels.nsgs_kernel(W.indptr, W.indices, W.data, q, mu, dim, r, u,
                                            states, tol, max_sweeps)
    if code == 3:
        raise ModelError("W: a diagonal entry of a contact's normal row is not positive; "
                         "every contact needs a normal direction some motion can change")
    return FrictionContactResult(r, u, states, float(err), int(sweeps), "nsgs",
                                 "solved" if code == 0 else "max_iter")


def frictionless_impulses(W: Any, q: Any, dim: int) -> FloatArray:
    """Impulses of the problem without friction (normal rows only, one LCP by
    :func:`~nscontrol.numerics.lcp.solve_lcp`), tangential impulses zero: NSGS's start, exact
    when no tangential load acts. Zeros when that LCP is not solved.

    Parameters
    ----------
    W : array_like or scipy.sparse matrix (m dim, m dim)
        Delassus matrix.
    q : array_like (m dim,)
        Free local velocity.
    dim : int
        Unknowns per contact.

    Examples
    --------
    >>> frictionless_impulses(np.eye(2), [-1.0, 0.3], 2).tolist()
    [1.0, 0.0]
    """
    from .lcp import solve_lcp

    W = sparse.csr_matrix(W, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    n_ = np.arange(0, q.shape[0], dim)
    r = np.zeros_like(q)
    if not np.any(q[n_] < 0.0):
        return r
    Wnn = W[n_][:, n_]
    res = solve_lcp(Wnn, q[n_])
    if res.success:
        r[n_] = res.z
    return r


def _problem(W: Any, q: Any, mu: Any, dim: int) -> tuple[Any, FloatArray, FloatArray]:
    """``W`` as sorted CSR float64, ``q`` and ``μ`` as vectors, shapes checked."""
    qv = as_vector("q", q)
    if qv.shape[0] % dim:
        raise DimensionError(f"q: expected a length divisible by dim = {dim}, got "
                             f"{qv.shape[0]}")
    m = qv.shape[0] // dim
    Wc = sparse.csr_matrix(W, dtype=np.float64)
    if Wc.shape != (qv.shape[0], qv.shape[0]):
        raise DimensionError(f"W: expected shape ({qv.shape[0]}, {qv.shape[0]}) to match q, "
                             f"got {Wc.shape}")
    Wc.sum_duplicates()
    Wc.sort_indices()
    if not np.all(np.isfinite(Wc.data)):
        raise ModelError("W: expected finite entries")
    muv = np.full(m, float(mu)) if np.ndim(mu) == 0 else as_vector("mu", mu, m)
    for i, mi in enumerate(muv):
        check_positive(f"mu[{i}]", mi, allow_zero=True)
    return Wc, qv, np.ascontiguousarray(muv)

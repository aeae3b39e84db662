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
uses, so that figures compare like with like), recomputed from ``r`` on every path; the
status is ``"solved"`` exactly when it is at most ``tolerance``: ``tol`` plus the round-off
bound of evaluating ``W r + q`` (:func:`~nscontrol.numerics._friction_kernels.certify`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from scipy import sparse

from .._validation import (
    FloatArray,
    as_float_array,
    as_vector,
    check_finite,
    check_integer,
    check_positive,
)
from ..errors import BudgetExceededError, DimensionError, ModelError, SolverError
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
        Relative natural-map error (module docstring), recomputed from ``r``.
    iterations : int
        NSGS sweeps, or Lemke pivots (0 when not reported).
    method : str
        ``"lcp"`` or ``"nsgs"``.
    status : str
        ``"solved"`` exactly when ``residual <= tolerance``; otherwise ``"max_iter"`` (NSGS
        spent ``max_sweeps``, or Lemke ``max_pivots``: :attr:`message` names the budget),
        the LCP's status, or ``"numerical_failure"`` (a method's claim the residual refutes).
    tolerance : float
        ``tol`` plus the round-off bound of ``W r + q`` (``-inf`` where nothing can be
        certified: ``|W||r|`` beyond ``1 / sqrt(eps)`` times the problem's scale).
    message : str
        Why the method stopped: the budget spent, or the LCP's message.
    """

    r: FloatArray
    u: FloatArray
    states: np.ndarray
    residual: float
    iterations: int
    method: str
    status: str
    tolerance: float = field(default=math.nan)
    message: str = field(default="")

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
    dim = _check_dim(dim)
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
    dim = _check_dim(dim)
    tol = check_positive("tol", tol)
    rv = _per_contact("r", as_vector("r", r), dim)
    return _states(rv, _per_contact("u", as_vector("u", u, rv.size), dim), tol)


def _states(r: FloatArray, u: FloatArray, tol: float = 1e-9) -> np.ndarray:
    """:func:`contact_states` of checked ``(m, dim)`` arrays."""
    dim = r.shape[1]
    slip = np.linalg.norm(u[:, 1:], axis=1) if dim > 1 else np.zeros(r.shape[0])
    threshold = tol * max(1.0, float(np.max(np.abs(u), initial=0.0)))
    states = np.where(slip > threshold, kernels.SLIP, kernels.STICK)
    return np.where(r[:, 0] > 0.0, states, kernels.OPEN).astype(np.int64)


def solve_friction_contact(W: Any, q: Any, mu: Any, *, dim: int,
                           method: Literal["auto", "lcp", "nsgs"] = "auto",
                           tol: float = 1e-12, max_sweeps: int = 100_000,
                           r0: Any = None, max_pivots: int | None = None,
                           max_local_iter: int = kernels.MAX_LOCAL_ITER
                           ) -> FrictionContactResult:
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
        Tolerance of the relative natural-map error (widened by the round-off bound of
        ``W r + q``: :attr:`FrictionContactResult.tolerance`).
    max_sweeps : int
        NSGS's budget of sweeps.
    r0 : array_like (m dim,), optional
        NSGS starting impulses (a warm start); by default zeros, or for more than
        :data:`AUTO_LCP_MAX_CONTACTS` contacts the solution of the frictionless problem
        (normal impulses only, one LCP), which is exact when no tangential load acts.
        Checked with every method (the planar LCP does not use it).
    max_pivots : int, optional
        Lemke's budget of pivots for ``"lcp"`` (default ``50 (4 m + 1)``).
    max_local_iter : int
        Budget of the projected fixed point a spatial contact falls back to when no slip
        direction is bracketed; a local solve that spends it keeps its last iterate, and the
        sweep's verified residual decides.

    Returns
    -------
    FrictionContactResult

    Raises
    ------
    ModelError
        ``μ`` negative or NaN, entries of ``W``, ``q``, ``μ`` or ``r0`` that are NaN,
        infinite, complex or strings, an unknown method, ``"lcp"`` with ``dim != 2``, a
        budget or ``tol`` that is not a positive number.
    DimensionError
        ``W`` not square, shapes that disagree (``q``'s length not a multiple of ``dim``,
        ``W``, ``μ`` or ``r0`` not matching it).
    BudgetExceededError
        No method reached ``tol`` and the last one spent its budget (``err.budget`` is
        ``"max_sweeps"`` or ``"max_pivots"``, ``err.partial`` the last result).
    SolverError
        No method reached ``tol`` for another reason (``err.status``).

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
    dim = _check_dim(dim)
    Wc, qv, muv = _problem(W, q, mu, dim)
    tol = check_positive("tol", tol)
    max_sweeps = check_integer("max_sweeps", max_sweeps, minimum=1)
    max_local_iter = check_integer("max_local_iter", max_local_iter, minimum=1)
    if max_pivots is not None:
        max_pivots = check_integer("max_pivots", max_pivots, minimum=1)
    r_start = None if r0 is None else as_vector("r0", r0, qv.shape[0])
    if not isinstance(method, str) or method not in ("auto", "lcp", "nsgs"):
        raise ModelError(f"method: expected 'auto', 'lcp' or 'nsgs', got {method!r}")
    if method == "lcp" and dim != 2:
        raise ModelError(f"method: 'lcp' solves planar contacts (dim=2), got dim={dim}; use "
                         "'nsgs'")
    m = muv.shape[0]
    if m == 0:
        return FrictionContactResult(np.zeros(0), np.zeros(0), np.zeros(0, np.int64), 0.0, 0,
                                     "nsgs", "solved", tol)
    order = [method] if method != "auto" else (
        ["lcp", "nsgs"] if dim == 2 and m <= AUTO_LCP_MAX_CONTACTS
        else ["nsgs", "lcp"] if dim == 2 and m <= 5 * AUTO_LCP_MAX_CONTACTS else ["nsgs"])
    attempts = []
    for name in order:
        result = (_solve_lcp(Wc, qv, muv, tol, max_pivots) if name == "lcp"
                  else _solve_nsgs(Wc, qv, muv, dim, tol, max_sweeps, r_start,
                                   max_local_iter))
        if result.success:
            return result
        attempts.append(f"{name}: {result.status}, residual {result.residual:.3g} "
                        f"(tolerance {result.tolerance:.3g}) after {result.iterations} "
                        f"iterations" + (f": {result.message}" if result.message else ""))
    text = (f"solve_friction_contact: no method reached tol = {tol:.3g} "
            f"({'; '.join(attempts)})")
    if result.status == "max_iter":
        budget, limit = (("max_sweeps", max_sweeps) if result.method == "nsgs"
                         else ("max_pivots", _pivot_limit(m, max_pivots)))
        raise BudgetExceededError(
            f"{budget}: {text}; raise {budget} or tol; the last result is in err.partial",
            budget=budget, limit=limit, used=result.iterations, partial=result)
    raise SolverError(f"{text}; raise tol, or check that W's diagonal blocks are positive "
                      "definite", status=result.status)


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
def _pivot_limit(m: int, max_pivots: int | None) -> int:
    """Lemke's budget on the planar LCP of ``m`` contacts (``4 m`` unknowns)."""
    return max_pivots or 50 * (4 * m + 1)


def _certified(W: Any, q: FloatArray, mu: FloatArray, dim: int, r: FloatArray, tol: float
               ) -> tuple[FloatArray, float, float, bool]:
    """``u = W r + q`` recomputed and :func:`kernels.certify`'s verdict."""
    u = np.empty_like(q)
    err, tolerance, ok = kernels.certify(W.indptr, W.indices, W.data, q, r, u, mu, dim, tol)
    return u, float(err), float(tolerance), bool(ok)


def _status(ok: bool, claimed: str) -> str:
    """A method's status reconciled with the residual test: solved exactly when it passes;
    a claim of "solved" it refutes is a numerical failure."""
    if ok:
        return "solved"
    return "numerical_failure" if claimed == "solved" else claimed


def _solve_lcp(W: Any, q: FloatArray, mu: FloatArray, tol: float, max_pivots: int | None
               ) -> FrictionContactResult:
    from .lcp import solve_lcp

    m = mu.shape[0]
    M, qq = planar_friction_lcp(W, q, mu)
    res = solve_lcp(M, qq, method="lemke", max_iter=_pivot_limit(m, max_pivots))
    z = res.z
    r = np.empty(2 * m)
    r[0::2] = z[:m]
    r[1::2] = z[m:2 * m] - z[2 * m:3 * m]
    u, err, tolerance, ok = _certified(W, q, mu, 2, r, tol)
    message = (f"budget max_pivots = {res.iterations} pivots spent"
               if res.status == "max_iter" else "" if res.success else res.message)
    return FrictionContactResult(r, u, _states(r.reshape(-1, 2), u.reshape(-1, 2)), err,
                                 int(res.iterations),
                                 "lcp", _status(ok, res.status), tolerance, message)


def _solve_nsgs(W: Any, q: FloatArray, mu: FloatArray, dim: int, tol: float,
                max_sweeps: int, r0: FloatArray | None, max_local_iter: int
                ) -> FrictionContactResult:
    if r0 is not None:
        r = r0.copy()
    elif mu.shape[0] > AUTO_LCP_MAX_CONTACTS:   # a cold start of a large (stacked) set
        r = frictionless_impulses(W, q, dim)
    else:
        r = np.zeros_like(q)
    u = np.empty_like(q)
    states = np.zeros(mu.shape[0], np.int64)
    code, sweeps, _ = kernels.nsgs_kernel(W.indptr, W.indices, W.data, q, mu, dim, r, u,
                                          states, tol, max_sweeps, max_local_iter)
    if code == 3:
        raise ModelError("W: a diagonal entry of a contact's normal row is not positive; "
                         "every contact needs a normal direction some motion can change")
    u, err, tolerance, ok = _certified(W, q, mu, dim, r, tol)
    status = _status(ok, "solved" if code == 0 else "max_iter")
    message = (f"budget max_sweeps = {max_sweeps} sweeps spent" if status == "max_iter"
               else "")
    return FrictionContactResult(r, u, states, err, int(sweeps), "nsgs", status, tolerance,
                                 message)


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

    dim = _check_dim(dim)
    q = _per_contact("q", as_vector("q", q), dim).ravel()
    W = _delassus(W, q.shape[0])
    n_ = np.arange(0, q.shape[0], dim)
    r = np.zeros_like(q)
    if not np.any(q[n_] < 0.0):
        return r
    Wnn = W[n_][:, n_]
    res = solve_lcp(Wnn, q[n_])
    if res.success:
        r[n_] = res.z
    return r


def _check_dim(dim: Any) -> int:
    dim = check_integer("dim", dim, minimum=1)
    if dim > 3:
        raise ModelError(f"dim: expected 1, 2 or 3 unknowns per contact, got {dim}")
    return dim


def _per_contact(name: str, v: FloatArray, dim: int) -> FloatArray:
    """``v`` as an ``(m, dim)`` array, its length checked to be a multiple of ``dim``."""
    if v.shape[0] % dim:
        raise DimensionError(f"{name}: expected a length divisible by dim = {dim}, got "
                             f"{v.shape[0]}")
    return v.reshape(-1, dim)


def _delassus(W: Any, n: int) -> Any:
    """``W`` as a finite real square ``(n, n)`` CSR float64 matrix, duplicates summed and
    indices sorted (the layout of the kernels); strings, complex and NaN are refused."""
    if sparse.issparse(W):
        Wc = sparse.csr_matrix(W)
        if Wc.dtype.kind not in "fiub":
            raise ModelError(f"W: expected a real sparse matrix, got dtype {Wc.dtype}")
        Wc = Wc.astype(np.float64)
        check_finite("W", Wc.data)
    else:
        Wc = sparse.csr_matrix(as_float_array("W", W, ndim=2))
    if Wc.shape != (n, n):
        raise DimensionError(f"W: expected shape ({n}, {n}) to match q, got {Wc.shape}")
    Wc.sum_duplicates()
    Wc.sort_indices()
    return Wc


def _problem(W: Any, q: Any, mu: Any, dim: int) -> tuple[Any, FloatArray, FloatArray]:
    """``W`` as sorted CSR float64, ``q`` and ``μ`` as vectors, shapes and values checked."""
    qv = as_vector("q", q)
    m = _per_contact("q", qv, dim).shape[0]
    Wc = _delassus(W, qv.shape[0])
    if np.ndim(mu) == 0:
        muv = np.full(m, check_positive("mu", mu, allow_zero=True))
    else:
        muv = as_vector("mu", mu, m)
        for i, mi in enumerate(muv):
            check_positive(f"mu[{i}]", mi, allow_zero=True)
    return Wc, qv, np.ascontiguousarray(muv)

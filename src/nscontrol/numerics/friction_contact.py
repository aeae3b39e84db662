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

:class:`FrictionContactSolver` is the reusable form of ``"nsgs"``: ``W`` and ``μ`` are
checked and prepared once (diagonal blocks and their inverses; ``W`` kept dense, or sparse
by columns), then :meth:`~FrictionContactSolver.solve` takes one ``q`` and optionally the
impulses to start from (a warm start, such as the previous time step's). Its sweep keeps
``u = W r + q`` current by adding a contact's columns times the change of its impulse, so
the error of the whole problem is known after every sweep without another product by ``W``.

The reported ``residual`` is ``‖r - P_K(r - û)‖ / max(‖q‖, ‖r‖, ‖u‖)`` (the scaling Siconos
uses, so that figures compare like with like), recomputed from ``r`` on every path; the
status is ``"solved"`` exactly when it is at most ``tolerance``: ``tol`` plus the round-off
bound of evaluating ``W r + q``
(:func:`~nscontrol.numerics._friction_kernels.certify_columns`).
"""

from __future__ import annotations

import math
from operator import itemgetter
from typing import Any, Literal, NoReturn

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

__all__ = ["FrictionContactResult", "FrictionContactSolver", "solve_friction_contact",
           "friction_residual",
           "contact_states", "planar_friction_lcp", "frictionless_impulses", "CONTACT_STATES"]

_tuple_new = tuple.__new__
#: :class:`FrictionContactResult`'s fields, in order.
_RESULT_FIELDS = ("r", "u", "states", "residual", "iterations", "method", "status",
                  "tolerance", "message")
#: The states' dtype (a dtype object: a type to convert on every call costs more).
_INT64 = np.dtype(np.int64)
#: Names of the contact states: index 0 open (take-off), 1 stick, 2 slip.
CONTACT_STATES = ("open", "stick", "slip")
#: ``auto`` solves planar problems up to this many contacts by the LCP (Lemke: O(m³)).
AUTO_LCP_MAX_CONTACTS = 40


class FrictionContactResult(tuple):
    """Solution of one frictional contact problem.

    An immutable record (built in a few tens of nanoseconds: it is what a one-contact
    call returns); its fields are read by name.

    Parameters
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

    Attributes
    ----------
    r, u, states, residual, iterations, method, status, tolerance, message
        The parameters, read-only.
    success : bool
        True when ``status == "solved"``.
    """

    __slots__ = ()

    def __new__(cls, r: FloatArray, u: FloatArray, states: np.ndarray, residual: float,
                iterations: int, method: str, status: str, tolerance: float = math.nan,
                message: str = "") -> FrictionContactResult:
        return _tuple_new(cls, (r, u, states, residual, iterations, method, status,
                                tolerance, message))

    r = property(itemgetter(0), doc="Impulses, per contact (normal, tangents).")
    u = property(itemgetter(1), doc="Local velocities ``W r + q``.")
    states = property(itemgetter(2), doc="0 open, 1 stick, 2 slip, per contact.")
    residual = property(itemgetter(3), doc="Relative natural-map error, recomputed from r.")
    iterations = property(itemgetter(4), doc="NSGS sweeps, or Lemke pivots.")
    method = property(itemgetter(5), doc="``\"lcp\"`` or ``\"nsgs\"``.")
    status = property(itemgetter(6), doc="How the solve ended (see the class docstring).")
    tolerance = property(itemgetter(7), doc="The threshold the residual was tested against.")
    message = property(itemgetter(8), doc="Why the method stopped.")

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name in _RESULT_FIELDS)
        return f"FrictionContactResult({fields})"

    def __getnewargs__(self) -> tuple[Any, ...]:
        return tuple(getattr(self, name) for name in _RESULT_FIELDS)

    # a record, not a sequence (as LCPResult): its fields are read by name
    def __iter__(self) -> Any:
        raise TypeError("FrictionContactResult: read its fields by name (res.r, res.status, "
                        "...)")

    def __len__(self) -> int:
        raise TypeError("FrictionContactResult: read its fields by name (res.r, res.status, "
                        "...)")

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


class FrictionContactSolver:
    """Non-smooth Gauss–Seidel for one Delassus matrix ``W`` and many right-hand sides ``q``.

    The constructor checks ``W`` and ``μ`` and prepares what every solve needs: ``W`` kept
    dense (its transpose, so that a column is contiguous) or sparse by columns (CSC), its
    diagonal blocks and their inverses. :meth:`solve` then checks ``q`` (finiteness inside
    the compiled kernel) and makes one compiled call: the sweeps, then the verification of
    the residual (``docs/frictional_contacts.md``). :func:`solve_friction_contact` with
    ``method="nsgs"`` is this class used once.

    Parameters
    ----------
    W : (m dim, m dim) array_like or scipy.sparse matrix
        Delassus matrix (its diagonal blocks positive definite). A writeable C-contiguous
        float64 array is used without a copy (do not modify it afterwards); sparse ``W`` is
        kept by ``dim x dim`` blocks.
    mu : float or array_like (m,)
        Friction coefficients ``>= 0``.
    dim : int
        Unknowns per contact: 1 (frictionless), 2 (planar) or 3 (spatial).
    max_local_iter : int
        Budget of a spatial contact's projected fixed point (as in
        :func:`solve_friction_contact`).

    Attributes
    ----------
    n, m, dim : int
        Unknowns, contacts and unknowns per contact.

    Raises
    ------
    ModelError
        ``W`` or ``μ`` with NaN, infinite, complex or string entries, ``μ < 0``, a contact
        whose normal diagonal entry of ``W`` is not positive, bad ``dim`` or budget.
    DimensionError
        ``W`` not square, its size not a multiple of ``dim``, ``μ`` of the wrong length.

    Examples
    --------
    One solver, three loads; the second starts from the first's impulses.

    >>> solver = FrictionContactSolver(np.eye(3), 0.5, dim=3)
    >>> stick = solver.solve(np.array([-1.0, 0.2, 0.0]))
    >>> stick.r.round(12).tolist(), stick.states.tolist()
    ([1.0, -0.2, -0.0], [1])
    >>> slip = solver.solve(np.array([-1.0, 1.0, 0.0]), stick.r)
    >>> slip.r.round(12).tolist(), slip.u.round(12).tolist(), slip.states.tolist()
    ([1.0, -0.5, -0.0], [0.0, 0.5, 0.0], [2])
    >>> solver.solve(np.array([1.0, 0.3, 0.0])).states.tolist()
    [0]
    """

    def __init__(self, W: Any, mu: Any, *, dim: int,
                 max_local_iter: int = kernels.MAX_LOCAL_ITER) -> None:
        dim = _check_dim(dim)
        max_local_iter = check_integer("max_local_iter", max_local_iter, minimum=1)
        Wc = _delassus(W, None)
        n = Wc.shape[0]
        if n % dim:
            raise DimensionError(f"W: expected a size divisible by dim = {dim}, got shape "
                                 f"{Wc.shape}")
        self._setup(Wc, _friction_coefficients(mu, n // dim), dim, max_local_iter)
        code, terms = kernels.prepare_columns(  # type: ignore[call-arg]  # numba's stub
            *self._columns, dim, self._blocks, self._inverses)
        self._raise_for(code)
        self._terms = int(terms)

    @classmethod
    def _checked(cls, W: Any, mu: FloatArray, dim: int, max_local_iter: int
                 ) -> FrictionContactSolver:
        """A solver of arguments already checked (by :func:`solve_friction_contact`), but for
        the finiteness of ``W``: the first solve prepares ``W`` and checks it."""
        solver = cls.__new__(cls)
        solver._setup(W, mu, dim, max_local_iter)
        return solver

    def _setup(self, W: Any, mu: FloatArray, dim: int, max_local_iter: int) -> None:
        self.n: int = int(W.shape[0])
        self.dim: int = dim
        self.m: int = self.n // dim
        self.mu = mu
        self._W = W
        self._max_local_iter = max_local_iter
        self._columns = _columns(W, dim)
        self._blocks = np.empty((self.m, dim, dim))
        self._inverses = np.empty((self.m, dim, dim))
        self._work = np.empty(kernels.work_size(self.n))   # the solves' scratch, reused
        self._terms = 0            # W not prepared yet: the next solve does it

    def _raise_for(self, code: int, q: Any = None, r: Any = None) -> None:
        """The error of a kernel's refusal code (nothing for the others)."""
        if code == kernels.W_NOT_FINITE:
            check_finite("W", self._W.data if sparse.issparse(self._W) else self._W)
        if code == kernels.MU_INVALID:
            _friction_coefficients(np.array(self.mu), self.m)
        if code >= kernels.BAD_DIAGONAL:
            i = code - kernels.BAD_DIAGONAL
            raise ModelError(f"W: the normal diagonal entry of contact {i} (row {i * self.dim})"
                             " is not positive; every contact needs a normal direction some "
                             "motion can change")
        if code == kernels.NOT_FINITE:
            check_finite("q", q)
            check_finite("r0", r)

    def __repr__(self) -> str:
        kind = "dense" if self._columns[0].shape[0] else "sparse"
        return f"FrictionContactSolver(m={self.m}, dim={self.dim}, {kind})"

    def solve(self, q: Any, r0: Any = None, *, tol: float = 1e-12,
              max_sweeps: int = 100_000) -> FrictionContactResult:
        """Solve ``u = W r + q`` with Coulomb's law at every contact, from ``r0``.

        Parameters
        ----------
        q : (n,) array_like
            Free local velocity (a writeable C-contiguous float64 array is not copied).
        r0 : (n,) array_like, optional
            Starting impulses (a warm start, e.g. the previous time step's); zeros by
            default. Copied: the result's ``r`` is a new array.
        tol : float
            Tolerance of the relative natural-map error.
        max_sweeps : int
            Budget of sweeps.

        Returns
        -------
        FrictionContactResult
            Its ``status`` says whether ``tol`` was reached (``"solved"``), the budget spent
            (``"max_iter"``) or the sweeps' claim refuted by the verification
            (``"numerical_failure"``); nothing is raised for these.

        Raises
        ------
        DimensionError
            ``q`` or ``r0`` not a vector of length :attr:`n`.
        ModelError
            ``q`` or ``r0`` with NaN, infinite, complex or string entries; ``tol`` or
            ``max_sweeps`` not a positive number.
        """
        n = self.n
        if not (type(q) is np.ndarray and q.dtype == np.float64 and q.ndim == 1
                and q.shape[0] == n and q.flags.c_contiguous and q.flags.writeable):
            q = np.array(as_vector("q", q, n))
        if not (type(tol) is float and 0.0 < tol < math.inf):
            tol = check_positive("tol", tol)
        if not (type(max_sweeps) is int and max_sweeps >= 1):
            max_sweeps = check_integer("max_sweeps", max_sweeps, minimum=1)
        if r0 is None:
            r = np.zeros(n)
        elif (type(r0) is np.ndarray and r0.dtype == np.float64 and r0.ndim == 1
              and r0.shape[0] == n):
            r = r0.copy()
        else:
            r = np.array(as_vector("r0", r0, n))
        u = np.empty(n)
        states = np.zeros(self.m, _INT64)
        code, sweeps, err, tolerance, ok, terms = kernels.solve_columns(
            *self._columns, self._blocks, self._inverses, self._terms, q, self.mu, r, u,
            states, tol, max_sweeps, self._max_local_iter, self._work)
        if ok:
            self._terms = terms
            return _tuple_new(FrictionContactResult, (r, u, states, err, sweeps, "nsgs",
                                                      "solved", tolerance, ""))
        if code > kernels.SWEEP_LIMIT:
            self._raise_for(code, q, r)
        self._terms = terms
        if code == kernels.CONVERGED:
            return FrictionContactResult(r, u, states, err, sweeps, "nsgs",
                                         "numerical_failure", tolerance, "")
        return FrictionContactResult(r, u, states, err, sweeps, "nsgs", "max_iter", tolerance,
                                     f"budget max_sweeps = {max_sweeps} sweeps spent")


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
    if (type(q) is np.ndarray and method != "lcp"
            and (type(W) is np.ndarray or type(W) in _SPARSE_ONCE)):
        once = _once(W, q, mu, dim, method, tol, max_sweeps, r0, max_local_iter)
        if once is not None:
            return once
    dim = _check_dim(dim)
    # the finiteness of W and q is checked by the compiled solve (NSGS), or before the LCP
    Wc, qv, muv = _problem(W, q, mu, dim, finite=False)
    if not (type(tol) is float and 0.0 < tol < math.inf):
        tol = check_positive("tol", tol)
    if not (type(max_sweeps) is int and max_sweeps >= 1):
        max_sweeps = check_integer("max_sweeps", max_sweeps, minimum=1)
    if not (type(max_local_iter) is int and max_local_iter >= 1):
        max_local_iter = check_integer("max_local_iter", max_local_iter, minimum=1)
    if max_pivots is not None:
        max_pivots = check_integer("max_pivots", max_pivots, minimum=1)
    n = qv.shape[0]
    r_start = (r0 if type(r0) is np.ndarray and r0.dtype == np.float64 and r0.shape == (n,)
               else None if r0 is None else as_vector("r0", r0, n))   # values: in the kernel
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
    results = []
    for name in order:
        if name == "lcp":
            check_finite("W", Wc.data if sparse.issparse(Wc) else Wc)
            check_finite("q", qv)
            _friction_coefficients(np.array(muv), m)      # the values (the LCP does not)
            if r_start is not None:
                check_finite("r0", r_start)
            result = _solve_lcp(Wc, qv, muv, tol, max_pivots)
        else:
            solver = FrictionContactSolver._checked(Wc, muv, dim, max_local_iter)
            if r_start is None and m > AUTO_LCP_MAX_CONTACTS:   # a cold start of a large set
                check_finite("W", Wc.data if sparse.issparse(Wc) else Wc)
                check_finite("q", qv)
                r_start = frictionless_impulses(Wc, qv, dim)
            result = solver.solve(qv, r_start, tol=tol, max_sweeps=max_sweeps)
        if result.success:
            return result
        results.append(result)
    _raise_unsolved(results, tol, max_sweeps, max_pivots)


def _raise_unsolved(results: list[FrictionContactResult], tol: float, max_sweeps: int,
                    max_pivots: int | None) -> NoReturn:
    """The error of :func:`solve_friction_contact` when no method (``results``, in the
    order tried) reached ``tol``: :class:`BudgetExceededError` when the last one spent its
    budget, else :class:`SolverError`."""
    attempts = [f"{res.method}: {res.status}, residual {res.residual:.3g} "
                f"(tolerance {res.tolerance:.3g}) after {res.iterations} "
                f"iterations" + (f": {res.message}" if res.message else "")
                for res in results]
    result = results[-1]
    text = (f"solve_friction_contact: no method reached tol = {tol:.3g} "
            f"({'; '.join(attempts)})")
    if result.status == "max_iter":
        budget, limit = (("max_sweeps", max_sweeps) if result.method == "nsgs"
                         else ("max_pivots", _pivot_limit(result.states.shape[0], max_pivots)))
        raise BudgetExceededError(
            f"{budget}: {text}; raise {budget} or tol; the last result is in err.partial",
            budget=budget, limit=limit, used=result.iterations, partial=result)
    raise SolverError(f"{text}; raise tol, or check that W's diagonal blocks are positive "
                      "definite", status=result.status)


#: The sparse types of ``W`` that :func:`_once` takes (their ``indptr, indices, data``).
_SPARSE_ONCE = frozenset((sparse.csr_matrix, sparse.csc_matrix, sparse.csr_array,
                          sparse.csc_array))


def _once(W: Any, q: np.ndarray, mu: Any, dim: Any, method: str, tol: Any,
          max_sweeps: Any, r0: Any, max_local_iter: Any) -> FrictionContactResult | None:
    """The short path of :func:`solve_friction_contact`: NSGS on a problem given as float64
    arrays (``W`` dense, or scipy CSR or CSC), started from ``r0`` or, up to
    :data:`AUTO_LCP_MAX_CONTACTS` contacts, from zero (beyond, the general path starts from
    the frictionless impulses), in one compiled call
    (:func:`~nscontrol.numerics._friction_kernels.solve_dense_once` or ``solve_sparse_once``,
    which check the values). None when the arguments are of another kind or refused: the
    general path then runs, and raises what it must. A solve that does not reach ``tol``
    raises here, as the general path would after the same sweeps
    (:func:`_raise_unsolved`)."""
    n = q.shape[0] if q.ndim == 1 else 0
    if not (type(dim) is int and 1 <= dim <= 3 and n and n % dim == 0
            and (method == "nsgs" or (method == "auto" and dim != 2))
            and (r0 is not None or n <= dim * AUTO_LCP_MAX_CONTACTS) and W.shape == (n, n)
            and type(tol) is float and 0.0 < tol < math.inf
            and type(max_sweeps) is int and max_sweeps >= 1
            and type(max_local_iter) is int and max_local_iter >= 1):
        return None
    m = n // dim
    if type(mu) is float:
        muv = np.full(m, mu)
    elif type(mu) is np.ndarray and mu.shape == (m,):
        muv = mu
    else:
        return None
    if r0 is None:
        r = np.zeros(n)
    elif type(r0) is np.ndarray and r0.shape == (n,):
        r = r0.copy()
    else:
        return None
    u = np.empty(n)
    states = np.empty(m, _INT64)
    dense = type(W) is np.ndarray
    entry = _ONCE_ENTRIES[0 if dense else 1] if _ONCE_ENTRIES else _load_once_entries(dense)
    # the entries' signatures check the types (float64 C-contiguous writeable arrays, int32
    # indices); any other kind raises TypeError and takes the general path. The arrays are
    # allocated here: returned from the entry, each would cost more than it does here
    # (numba wraps an array it returns in two Python objects, one built from an args tuple)
    try:
        if dense:
            code, sweeps, err, tolerance, ok = entry(W, q, muv, r, u, states, tol, max_sweeps,
                                                     max_local_iter)
        else:
            code, sweeps, err, tolerance, ok = entry(
                W.indptr, W.indices, W.data, W.format == "csr", q, muv, r, u, states, tol,
                max_sweeps, max_local_iter)
    except TypeError:
        return None
    if ok:
        return _tuple_new(FrictionContactResult, (r, u, states, err, sweeps, "nsgs", "solved",
                                                  tolerance, ""))
    if code > kernels.SWEEP_LIMIT:     # refused (a value of W, q, mu or r0): the general path
        return None
    # the general path would run the same sweeps from the same start (nsgs is the only method
    # here): say what they gave instead of spending them twice
    if code == kernels.CONVERGED:
        status, message = "numerical_failure", ""
    else:
        status, message = "max_iter", f"budget max_sweeps = {max_sweeps} sweeps spent"
    _raise_unsolved([FrictionContactResult(r, u, states, err, sweeps, "nsgs", status,
                                           tolerance, message)], tol, max_sweeps, None)


#: The compiled entries of :func:`_once` (dense, sparse), made on first use.
_ONCE_ENTRIES: list[Any] = []


def _load_once_entries(dense: bool) -> Any:
    """:func:`_once`'s entries: ``solve_dense_once`` and ``solve_sparse_once`` compiled for
    their one signature, compilation disabled
    (:func:`~nscontrol.numerics._lcp_dispatch_kernels.exact_entry`); the plain kernels when
    numba's JIT is disabled."""
    from ._lcp_dispatch_kernels import exact_entry

    entries = [exact_entry(kernels.solve_dense_once, kernels.SOLVE_DENSE_ONCE_SIGNATURE),
               exact_entry(kernels.solve_sparse_once, kernels.SOLVE_SPARSE_ONCE_SIGNATURE)]
    if entries[0] is None:
        entries = [kernels.solve_dense_once, kernels.solve_sparse_once]
    _ONCE_ENTRIES[:] = entries
    return entries[0 if dense else 1]


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
    Wd = Wc.toarray() if sparse.issparse(Wc) else Wc
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
    """``u = W r + q`` recomputed and :func:`kernels.certify_columns`'s verdict."""
    u = np.empty_like(q)
    columns = _columns(W, dim)
    m = mu.shape[0]
    _, terms = kernels.prepare_columns(*columns, dim, np.empty((m, dim, dim)),
                                       np.empty((m, dim, dim)))
    err, tolerance, ok = kernels.certify_columns(*columns, terms, q, r, u, mu, dim, tol,
                                                 np.empty(kernels.work_size(q.shape[0])))
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
    if type(dim) is int and 1 <= dim <= 3:
        return dim
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


def _delassus(W: Any, n: int | None, finite: bool = True) -> Any:
    """``W`` as a finite real square ``(n, n)`` float64 matrix: a C-contiguous array, or a
    scipy CSR or CSC matrix when sparse (not copied when it is one already, else converted
    to CSC); strings, complex and NaN are refused
    (NaN and infinities not with ``finite=False``: the caller checks them).
    ``n = None`` checks squareness only. A C-contiguous float64 array is not copied."""
    if sparse.issparse(W):
        if W.format in ("csr", "csc") and W.dtype == np.float64:
            Wc = W        # read as it is: the kernels sum duplicates and accept any order
        else:
            Wc = sparse.csc_matrix(W)
            if Wc.dtype.kind not in "fiub":
                raise ModelError(f"W: expected a real sparse matrix, got dtype {Wc.dtype}")
            Wc = Wc.astype(np.float64)
        if finite:
            check_finite("W", Wc.data)
    elif (type(W) is np.ndarray and W.dtype == np.float64 and W.ndim == 2
          and W.flags.c_contiguous):
        Wc = W
        if finite:
            check_finite("W", Wc)
    else:
        Wc = np.ascontiguousarray(as_float_array("W", W, ndim=2, finite=finite))
    rows, cols = Wc.shape
    if rows != cols or (n is not None and rows != n):
        want = f"({n}, {n}) to match q" if n is not None else "a square matrix"
        raise DimensionError(f"W: expected shape {want}, got {Wc.shape}")
    return Wc


_NO_DENSE = np.zeros((0, 0))
_NO_BLOCKS = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros((0, 1, 1)))


def _columns(W: Any, dim: int) -> tuple[FloatArray, np.ndarray, np.ndarray, FloatArray]:
    """``W`` (checked by :func:`_delassus`) as the kernels read it: ``(WT, bptr, brow,
    bdata)``, the dense C-contiguous transpose of ``W``
    (:func:`~nscontrol.numerics._friction_kernels.dense_columns`: ``W`` itself when
    symmetric) with empty block arrays, or an empty ``WT`` with
    ``W``'s ``dim x dim`` block columns
    (:func:`~nscontrol.numerics._friction_kernels.csc_to_blocks`, from CSC or CSR)."""
    if sparse.issparse(W):
        convert = kernels.csc_to_blocks if W.format == "csc" else kernels.csr_to_blocks
        return (_NO_DENSE, *convert(W.indptr, W.indices,
                                    np.ascontiguousarray(W.data, np.float64), W.shape[0], dim))
    return (kernels.dense_columns(W if W.flags.writeable else W.copy()), *_NO_BLOCKS)


def _friction_coefficients(mu: Any, m: int, checked_later: bool = False) -> FloatArray:
    """``μ`` as a contiguous vector of ``m`` finite coefficients ``>= 0`` (with
    ``checked_later``, a float64 vector of length ``m`` is taken as it is: the compiled
    solve checks its values, code ``MU_INVALID``)."""
    if type(mu) is float and 0.0 <= mu < math.inf:
        return np.full(m, mu)
    if (checked_later and type(mu) is np.ndarray and mu.dtype == np.float64
            and mu.shape == (m,) and mu.flags.c_contiguous and mu.flags.writeable):
        return mu
    if np.ndim(mu) == 0:
        return np.full(m, check_positive("mu", mu, allow_zero=True))
    muv = as_vector("mu", mu, m)
    negative = np.flatnonzero(muv < 0.0)
    if negative.size:
        i = int(negative[0])
        check_positive(f"mu[{i}]", muv[i], allow_zero=True)
    return np.ascontiguousarray(muv)


def _problem(W: Any, q: Any, mu: Any, dim: int, finite: bool = True
             ) -> tuple[Any, FloatArray, FloatArray]:
    """``W`` checked (:func:`_delassus`), ``q`` and ``μ`` as vectors, shapes and values
    checked (but for NaN and infinities in ``W`` and ``q`` with ``finite=False``)."""
    if (type(q) is np.ndarray and q.dtype == np.float64 and q.ndim == 1
            and q.flags.c_contiguous and q.flags.writeable):
        if finite:
            check_finite("q", q)
        qv = q
    else:
        qv = np.atleast_1d(as_float_array("q", q, finite=finite))
        if qv.ndim != 1:
            raise DimensionError(f"q: expected a vector, got shape {qv.shape}")
    n = qv.shape[0]
    if n % dim:
        raise DimensionError(f"q: expected a length divisible by dim = {dim}, got {n}")
    Wc = _delassus(W, n, finite)
    return Wc, qv, _friction_coefficients(mu, n // dim, checked_later=not finite)

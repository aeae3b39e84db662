"""Linear matrix inequalities on CVXPY, with certificates that are checked, not trusted.

An :class:`LMIProblem` collects named variables and named constraints, each one a *strict*
LMI written with an explicit margin (``F(x) ⪰ margin·I``, the block symmetrised before CVXPY
sees it) or a linear equality. :meth:`LMIProblem.solve` runs Clarabel and falls back to SCS
(tight tolerances) when Clarabel errors out or is inaccurate, then **re-checks every
constraint in NumPy at the returned values**: the smallest eigenvalue of each LMI block and
the residual of each equality. The result is an :class:`LMIResult` (frozen) with the values,
the status, the solver that produced them and the margin of every constraint.

Decisions, in order:

* solver status ``infeasible``/``unbounded`` (or no solver succeeding) ->
  :class:`~nscontrol.errors.InfeasibleDesignError` naming the problem, its constraints and the
  status;
* a block whose smallest eigenvalue is below ``recheck_fraction · margin`` (default 0.5;
  for a zero margin: below ``-1e-9·scale``) or an equality residual above ``eq_tol`` ->
  ``InfeasibleDesignError(status="recheck_failed")`` naming the constraint;
* a block that passes but with less than 0.9 of its requested margin, or a solution from an
  ``*_inaccurate`` status -> :class:`~nscontrol.errors.InaccurateCertificateWarning`.

Badly scaled data (mechanical models with stiffnesses ~1e5) is handled by
:class:`~nscontrol.numerics.scaling.Scaling`: a diagonal similarity and a time scale
``ω = max ||Ã_i||``, under which Lyapunov-type LMIs are invariant (``P = Sᵀ P̃ S``, decay
rates ``α = ω α̃``). :func:`recheck_lyapunov` is the one NumPy re-check of a quadratic
Lyapunov certificate ``A_iᵀP + PA_i + 2σP ⪯ 0`` that every design and analysis uses.
:func:`bisect_max` maximises a scalar (a decay rate) over a quasi-convex family of problems;
:func:`max_lyapunov_decay_rate` is its self-check on a single matrix.

References
----------
D5.3 chapter 8, section 2.3 and chapter 11, section 3.5 (LMI numerics); Boyd, El Ghaoui,
Feron, Balakrishnan, *Linear Matrix Inequalities in System and Control Theory*, SIAM 1994.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from .._validation import (
    FloatArray,
    as_finite_scalar,
    as_real_scalar,
    as_square,
    check_bool,
    check_positive,
)
from ..errors import InaccurateCertificateWarning, InfeasibleDesignError, ModelError
from .scaling import Scaling

__all__ = ["LMIProblem", "LMIResult", "BisectionResult", "LyapunovCheck",
           "LYAPUNOV_RECHECK_RTOL", "bisect_max", "lyapunov_certificate",
           "max_lyapunov_decay_rate", "recheck_lyapunov", "sym", "SDP_SOLVERS", "solver_order",
           "solver_options", "fallback_hint", "SCS_INSTALL_HINT"]

SolverName = Literal["auto", "CLARABEL", "SCS", "MOSEK", "CVXOPT", "SDPA", "COPT"]
_ACCEPTED = ("optimal", "optimal_inaccurate")
_SCS_OPTIONS = {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 20_000}

#: Relative threshold of :meth:`LyapunovCheck.holds` for a certificate that was solved in
#: scaled coordinates and mapped back: ``λ_max(A_iᵀP + PA_i + 2σP) <= 1e-8·‖P‖₂``. It sits far
#: above the rounding of forming ``A_iᵀP + PA_i`` (about ``n·u·‖A_i‖‖P‖``) for the well-scaled
#: closed loops the designs return, and far below the strictness margins they ask for.
LYAPUNOV_RECHECK_RTOL = 1e-8

#: CVXPY solvers that handle the semidefinite cones of an LMI problem (CVXPY's spelling).
SDP_SOLVERS = ("CLARABEL", "SCS", "MOSEK", "CVXOPT", "SDPA", "COPT")
#: ``solver="auto"``: Clarabel, then SCS (tight tolerances) as the fallback.
_AUTO_ORDER = ("CLARABEL", "SCS")
#: How to get the fallback solver, which is an optional extra (106 MB installed).
SCS_INSTALL_HINT = "pip install 'nscontrol[scs]'"


def fallback_hint(order: list[str]) -> str:
    """What to append to a failure when ``solver="auto"`` had to do without SCS.

    Parameters
    ----------
    order : list of str
        The solvers tried (:func:`solver_order`).

    Returns
    -------
    str
        ``"; the fallback solver SCS is not installed (pip install 'nscontrol[scs]')"`` when
        Clarabel was tried alone, else ``""``.
    """
    if "SCS" in order or order != ["CLARABEL"]:
        return ""
    return f"; the fallback solver SCS is not installed ({SCS_INSTALL_HINT})"


def solver_order(solver: str | None) -> list[str]:
    """The SDP solvers to try, in order, for a ``solver=`` argument (checked once, up front).

    Parameters
    ----------
    solver : str or None
        ``None`` or ``"auto"``: Clarabel, then SCS (those of the two that are installed);
        otherwise one name of :data:`SDP_SOLVERS` (any case), which must be installed.

    Returns
    -------
    list of str
        CVXPY solver names.

    Raises
    ------
    ModelError
        An unknown name (a misspelling is bad input, not an infeasible design), a solver that
        is not installed, or no default solver installed.

    Examples
    --------
    >>> solver_order("auto")
    ['CLARABEL', 'SCS']
    >>> solver_order("scs")
    ['SCS']
    >>> solver_order("BOGUS")
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: solver: expected one of 'auto', 'CLARABEL', 'SCS', 'MOSEK', \
'CVXOPT', 'SDPA', 'COPT', got 'BOGUS'
    """
    import cvxpy as cp

    installed = set(cp.installed_solvers())
    if solver is None or (isinstance(solver, str) and solver.lower() == "auto"):
        order = [name for name in _AUTO_ORDER if name in installed]
        if not order:
            raise ModelError(f"solver: 'auto' needs CLARABEL or SCS, and neither is installed "
                             f"(installed: {sorted(installed)}); install clarabel or pass an "
                             f"installed SDP solver")
        return order
    name = solver.upper() if isinstance(solver, str) else None
    if name not in SDP_SOLVERS:
        names = ", ".join(repr(s) for s in ("auto", *SDP_SOLVERS))
        raise ModelError(f"solver: expected one of {names}, got {solver!r}")
    if name not in installed:
        how = f"; install it with {SCS_INSTALL_HINT}" if name == "SCS" else ""
        raise ModelError(f"solver: {name!r} is an SDP solver but it is not installed "
                         f"(installed: {sorted(installed)}){how}")
    return [name]


def solver_options(name: str) -> dict[str, Any]:
    """Keyword options passed to CVXPY for solver ``name`` (tight tolerances for SCS).

    Parameters
    ----------
    name : str
        A CVXPY solver name of :data:`SDP_SOLVERS`.
    """
    return dict(_SCS_OPTIONS) if name == "SCS" else {}


def sym(expr: Any) -> Any:
    """``(M + Mᵀ)/2`` of a square CVXPY expression or array.

    Parameters
    ----------
    expr : CVXPY expression or ndarray
        A square matrix ``M``.
    """
    return 0.5 * (expr + expr.T)


@dataclass(frozen=True)
class LMIResult:
    """A solved and re-checked LMI problem.

    Attributes
    ----------
    values : dict of str to ndarray
        Value of every declared variable (symmetric ones exactly symmetrised).
    status : str
        CVXPY status of the accepted solve (``"optimal"`` or ``"optimal_inaccurate"``).
    solver : str
        The solver that produced the values.
    margins : dict of str to float
        Smallest eigenvalue of each LMI block in its ``F ⪰ 0`` orientation (for
        ``F ⪯ -m·I`` that is ``-λ_max(F)``), re-computed in NumPy.
    required : dict of str to float
        The margin each LMI asked for.
    residuals : dict of str to float
        Relative Frobenius residual of each equality constraint.
    objective : float or None
        Optimal value (None for a feasibility problem).
    """

    values: dict[str, FloatArray]
    status: str
    solver: str
    margins: dict[str, float]
    required: dict[str, float]
    residuals: dict[str, float] = field(default_factory=dict)
    objective: float | None = None

    def __getitem__(self, name: str) -> FloatArray:
        return self.values[name]

    @property
    def min_slack(self) -> float:
        """Smallest ``margin - required`` over the LMIs (``inf`` when there are none)."""
        return min((self.margins[k] - self.required[k] for k in self.margins),
                   default=float("inf"))


@dataclass
class _Block:
    name: str
    expr: Any           # CVXPY expression F with F ⪰ margin I required
    margin: Any         # float or scalar CVXPY expression


@dataclass
class _Equality:
    name: str
    lhs: Any
    rhs: FloatArray


class LMIProblem:
    """A builder for LMI feasibility/optimisation problems with strict margins.

    Parameters
    ----------
    name : str
        Used in error messages (e.g. ``"Lur'e observer (ch08 eq. 1-2)"``).

    Examples
    --------
    >>> A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    >>> prob = LMIProblem("Lyapunov")
    >>> P = prob.symmetric("P", 2)
    >>> prob.positive("P > 0", P, margin=1.0)
    >>> prob.negative("A'P + PA < 0", A.T @ P + P @ A, margin=1e-3)
    >>> res = prob.solve()
    >>> bool(np.all(np.linalg.eigvalsh(A.T @ res["P"] + res["P"] @ A) < 0))
    True
    """

    def __init__(self, name: str = "LMI problem") -> None:
        self.name = name
        self._vars: dict[str, Any] = {}
        self._symmetric: set[str] = set()
        self._blocks: list[_Block] = []
        self._equalities: list[_Equality] = []

    # -- variables ---------------------------------------------------------------------------
    def symmetric(self, name: str, n: int) -> Any:
        """A new symmetric ``n × n`` variable."""
        import cvxpy as cp

        self._symmetric.add(name)
        return self._declare(name, cp.Variable((n, n), symmetric=True, name=name))

    def variable(self, name: str, shape: int | tuple[int, ...] = ()) -> Any:
        """A new unstructured variable (``shape=()`` for a scalar)."""
        import cvxpy as cp

        return self._declare(name, cp.Variable(shape, name=name))

    def _declare(self, name: str, var: Any) -> Any:
        if name in self._vars:
            raise ModelError(f"name: variable {name!r} is already declared in {self.name}")
        self._vars[name] = var
        return var

    # -- constraints -------------------------------------------------------------------------
    def positive(self, name: str, expr: Any, margin: Any = 0.0) -> None:
        """Require ``sym(expr) ⪰ margin·I`` (``margin`` a float ≥ 0 or a scalar variable)."""
        self._add_block(name, expr, margin, sign=1.0)

    def negative(self, name: str, expr: Any, margin: Any = 0.0) -> None:
        """Require ``sym(expr) ⪯ -margin·I``."""
        self._add_block(name, expr, margin, sign=-1.0)

    def equal(self, name: str, lhs: Any, rhs: Any = 0.0) -> None:
        """Require ``lhs == rhs`` (``rhs`` numeric data)."""
        self._check_name(name)
        self._equalities.append(_Equality(name, lhs, np.asarray(rhs, dtype=float)))

    def _add_block(self, name: str, expr: Any, margin: Any, sign: float) -> None:
        self._check_name(name)
        shape = tuple(getattr(expr, "shape", np.shape(expr)))
        if len(shape) != 2 or shape[0] != shape[1]:
            raise ModelError(f"{name}: expected a square matrix expression, got shape {shape}")
        if _is_number(margin):
            check_positive(f"margin of {name!r}", margin, allow_zero=True)
        self._blocks.append(_Block(name, sign * sym(expr), margin))

    def _check_name(self, name: str) -> None:
        taken = {b.name for b in self._blocks} | {e.name for e in self._equalities}
        if name in taken:
            raise ModelError(f"name: constraint {name!r} is already used in {self.name}")

    # -- solve -------------------------------------------------------------------------------
    def solve(self, *, minimize: Any = None, maximize: Any = None,
              solver: SolverName = "auto", recheck_fraction: float = 0.5,
              warn_fraction: float = 0.9, eq_tol: float = 1e-7) -> LMIResult:
        """Solve, then re-check every constraint at the returned values.

        Parameters
        ----------
        minimize, maximize : CVXPY scalar expression, optional
            Objective (at most one); feasibility problem when both are None.
        solver : str
            ``"auto"``: Clarabel, then SCS when Clarabel fails or is inaccurate; or one name
            of :data:`SDP_SOLVERS` (checked by :func:`solver_order`).
        recheck_fraction : float
            A block passes the re-check when its smallest eigenvalue is at least this
            fraction of its requested margin.
        warn_fraction : float
            Below this fraction of its margin (but above ``recheck_fraction``) a block passes
            with an :class:`~nscontrol.errors.InaccurateCertificateWarning`.
        eq_tol : float
            Largest accepted relative residual ``||lhs - rhs||_F / max(1, ||rhs||_F)``.

        Returns
        -------
        LMIResult

        Raises
        ------
        InfeasibleDesignError
            The solver reports infeasibility (``status`` holds its status), no solver
            succeeded, or the re-check failed (``status="recheck_failed"``).
        ModelError
            Unknown or uninstalled ``solver``; both objectives given.
        """
        import cvxpy as cp

        order = solver_order(solver)
        if minimize is not None and maximize is not None:
            raise ModelError("minimize, maximize: expected at most one objective, got both")
        objective = (cp.Minimize(minimize) if minimize is not None
                     else cp.Maximize(maximize) if maximize is not None else cp.Minimize(0))
        problem = cp.Problem(objective, self._constraints())
        status, used = self._run(problem, order)
        if status not in _ACCEPTED:
            raise InfeasibleDesignError(
                f"{self.name}: no certificate — solver {used} returned status {status!r} for "
                f"the constraints {', '.join(self._names())}; relax margins or bounds, or "
                "check the model (e.g. stabilisability/detectability)"
                f"{fallback_hint(order)}", status=status)
        result = self._recheck(status, used, recheck_fraction, warn_fraction, eq_tol,
                               None if minimize is None and maximize is None
                               else float(problem.value))
        if status != "optimal":
            warnings.warn(f"{self.name}: solver {used} returned {status!r}; the certificate "
                          f"passed the re-check (min slack {result.min_slack:.3g})",
                          InaccurateCertificateWarning, stacklevel=2)
        return result

    def _names(self) -> list[str]:
        return [b.name for b in self._blocks] + [e.name for e in self._equalities]

    def _constraints(self) -> list[Any]:
        out = []
        for b in self._blocks:
            k = b.expr.shape[0]
            out.append(b.expr - b.margin * np.eye(k) >> 0)
        out.extend(e.lhs == e.rhs for e in self._equalities)
        return out

    def _run(self, problem: Any, order: list[str]) -> tuple[str, str]:
        """Solve with the solvers of ``order`` in turn; return (status, solver used)."""
        import cvxpy as cp

        status, used = "solver_error", order[0]
        for name in order:
            options = solver_options(name)
            try:
                with warnings.catch_warnings():  # we judge accuracy ourselves (re-check)
                    warnings.filterwarnings("ignore", "Solution may be inaccurate")
                    problem.solve(solver=name, **options)
            except cp.error.SolverError:
                status, used = "solver_error", name
                continue
            status, used = str(problem.status), name
            if status == "optimal" or status in ("infeasible", "unbounded"):
                break  # a decision: no fallback needed
        return status, used

    def _recheck(self, status: str, used: str, fraction: float, warn_fraction: float,
                 eq_tol: float, objective: float | None) -> LMIResult:
        values = {}
        for name, var in self._vars.items():
            v = np.asarray(var.value, dtype=float)
            values[name] = 0.5 * (v + v.T) if name in self._symmetric else v
        margins, required, residuals = {}, {}, {}
        for b in self._blocks:
            F = np.asarray(b.expr.value, dtype=float)
            F = 0.5 * (F + F.T)
            lam = float(np.linalg.eigvalsh(F)[0])
            req = float(np.asarray(getattr(b.margin, "value", b.margin), dtype=float))
            margins[b.name], required[b.name] = lam, req
            tiny = 1e-9 * max(1.0, float(np.abs(F).max()))
            if _is_number(b.margin):
                floor = fraction * req if req > 0 else -tiny
            else:  # a decision variable (e.g. maximised margin t): hold to what it claims
                floor = req - abs(req) * (1.0 - fraction) - tiny
            if not np.isfinite(lam) or lam < floor:
                raise InfeasibleDesignError(
                    f"{self.name}: re-check failed for {b.name!r}: smallest eigenvalue "
                    f"{lam:.3g} < {floor:.3g} ({fraction} × requested margin {req:.3g}) at the "
                    f"values returned by {used} ({status}); the problem is at or beyond its "
                    "feasibility boundary — relax the design target or rescale the data",
                    status="recheck_failed")
            if _is_number(b.margin) and req > 0 and lam < warn_fraction * req:
                warnings.warn(f"{self.name}: {b.name!r} holds with smallest eigenvalue "
                              f"{lam:.3g}, less than {warn_fraction} × the requested margin "
                              f"{req:.3g}",
                              InaccurateCertificateWarning, stacklevel=3)
        for e in self._equalities:
            lhs = np.asarray(e.lhs.value, dtype=float)
            res = float(np.linalg.norm(lhs - e.rhs) / max(1.0, float(np.linalg.norm(e.rhs))))
            residuals[e.name] = res
            if not res <= eq_tol:
                raise InfeasibleDesignError(
                    f"{self.name}: re-check failed for equality {e.name!r}: relative "
                    f"residual {res:.3g} > {eq_tol:.3g} at the values returned by {used}",
                    status="recheck_failed")
        return LMIResult(values, status, used, margins, required, residuals, objective)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating))


# ----------------------------------------------------------------------------- Lyapunov
@dataclass(frozen=True)
class LyapunovCheck:
    """NumPy re-check of a quadratic Lyapunov certificate ``A_iᵀP + PA_i + 2σP ⪯ 0``, ``P ≻ 0``.

    Attributes
    ----------
    P_min_eig : float
        Smallest eigenvalue of ``sym(P)``.
    lyap_max_eig : float
        ``max_i λ_max(sym(A_iᵀP + PA_i + 2σP))`` over the matrices checked.
    P_norm : float
        ``‖P‖₂``.
    """

    P_min_eig: float
    lyap_max_eig: float
    P_norm: float

    @property
    def residual(self) -> float:
        """``lyap_max_eig / ‖P‖₂``: the inequality's violation relative to the certificate."""
        return self.lyap_max_eig / self.P_norm

    def holds(self, rtol: float = 0.0) -> bool:
        """``P ≻ 0`` and ``lyap_max_eig <= rtol·‖P‖₂`` (``rtol`` from the caller's rounding
        estimate, e.g. ``1e-8`` for a solver's certificate mapped back from scaled data)."""
        rtol = check_positive("rtol", rtol, allow_zero=True)
        return bool(self.P_min_eig > 0.0 and self.lyap_max_eig <= rtol * self.P_norm)


def recheck_lyapunov(As: Sequence[Any], P: Any, decay: float = 0.0) -> LyapunovCheck:
    """Re-check ``P`` as a common quadratic Lyapunov function of the matrices ``As``.

    Parameters
    ----------
    As : sequence of (n, n) array_like
        The matrices (modes, or closed loops) the certificate must hold for.
    P : (n, n) array_like
        The certificate (symmetrised before use).
    decay : float
        Rate ``σ``: ``V = xᵀPx`` must satisfy ``V' <= -2σV`` along every ``x' = A_i x``.

    Returns
    -------
    LyapunovCheck
        Its numbers; :meth:`LyapunovCheck.holds` decides.

    Raises
    ------
    ModelError, DimensionError
        ``P`` or an ``A_i`` not a finite square matrix of the same size; ``decay`` not a
        finite real number.

    Examples
    --------
    >>> A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    >>> chk = recheck_lyapunov([A], np.eye(2))
    >>> chk.P_min_eig, round(chk.lyap_max_eig, 6), chk.holds()
    (1.0, -1.171573, True)
    >>> recheck_lyapunov([A], np.eye(2), decay=1.0).holds()
    False
    """
    P = as_square("P", P)
    P = 0.5 * (P + P.T)
    decay = as_finite_scalar("decay", decay)
    worst = -np.inf
    for i, A in enumerate(As):
        A = as_square(f"As[{i}]", A, P.shape[0])
        M = A.T @ P + P @ A + 2.0 * decay * P
        worst = max(worst, float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1]))
    return LyapunovCheck(float(np.linalg.eigvalsh(P)[0]), float(worst),
                         float(np.linalg.norm(P, 2)))


def lyapunov_certificate(A: Any, *, decay: float = 0.0, margin: float = 1e-6,
                         scale: bool = True, solver: SolverName = "auto") -> LMIResult:
    """A quadratic Lyapunov function proving ``Re λ(A) < -decay``.

    Solves ``P ⪰ I``, ``AᵀP + PA + 2·decay·P ⪯ -margin·I`` (after
    :meth:`Scaling.balanced <nscontrol.numerics.scaling.Scaling.balanced>` when
    ``scale``), maps ``P`` back to the original coordinates and checks the unscaled
    inequalities once more (``P ≻ 0``, ``λ_max(AᵀP + PA + 2·decay·P) < 0``).

    Parameters
    ----------
    A : (n, n) array_like
        System matrix.
    decay : float
        Required exponential decay rate ``α`` of ``V(x) = xᵀPx`` (``V' ≤ -2αV``).
    margin : float
        Strictness margin of the (scaled) LMI.
    scale : bool
        Balance and time-scale ``A`` first (recommended for badly scaled data).
    solver : str
        ``"auto"`` (Clarabel, then SCS) or a name of :data:`SDP_SOLVERS`.

    Returns
    -------
    LMIResult
        ``values["P"]`` in the original coordinates; margins of the scaled problem.

    Raises
    ------
    InfeasibleDesignError
        No such ``P`` (e.g. ``A + decay·I`` not Hurwitz).

    Notes
    -----
    Hypotheses of the Lyapunov theorem: ``A`` constant; the LMI is feasible iff every
    eigenvalue has real part ``< -decay``. Scaling is a similarity plus a time scale, under
    which feasibility is invariant (``decay`` is divided by ``ω``).

    References
    ----------
    D5.3 chapter 11, section 3.5; Boyd et al. 1994, section 2.2.
    """
    A = as_square("A", A)
    decay = as_finite_scalar("decay", decay)
    n = A.shape[0]
    sc = Scaling.balanced([A]) if check_bool("scale", scale) else Scaling.identity(n)
    As, alpha = sc.matrix(A), decay / sc.omega
    prob = LMIProblem(f"Lyapunov certificate (decay {decay:.6g})")
    P = prob.symmetric("P", n)
    prob.positive("P >= I", P, margin=1.0)
    prob.negative("A'P + PA + 2 decay P < 0", As.T @ P + P @ As + 2.0 * alpha * P,
                  margin=margin)
    res = prob.solve(solver=solver)
    P_orig = sc.quadratic_back(res["P"])
    # re-verify the returned P itself; eigenvalues are taken on the congruent form
    # S⁻ᵀ(AᵀP + PA + 2αP)S⁻¹ / ω (S powers of two: exact), which has the same inertia and is
    # well conditioned even when A is not
    check = recheck_lyapunov([As], sc.quadratic_scaled(P_orig), alpha)
    if not (check.P_min_eig > 0.0 and check.lyap_max_eig < 0.0):
        raise InfeasibleDesignError(
            f"A: the certificate does not hold in the original coordinates "
            f"(λ_max of the scaled AᵀP + PA + 2αP = {check.lyap_max_eig:.3g}); decay {decay} "
            "is too close to the spectral abscissa", status="recheck_failed")
    return LMIResult({"P": P_orig}, res.status, res.solver, res.margins, res.required,
                     res.residuals, res.objective)


# ----------------------------------------------------------------------------- bisection
@dataclass(frozen=True)
class BisectionResult:
    """Largest feasible value found by :func:`bisect_max`.

    Attributes
    ----------
    value : float
        Largest value proven feasible (the lower end of the final bracket).
    upper : float
        Smallest value found infeasible (``value`` when the upper end was feasible).
    result : Any
        What the feasibility callback returned at ``value`` (e.g. an :class:`LMIResult`).
    iterations : int
        Number of problems solved.
    """

    value: float
    upper: float
    result: Any
    iterations: int


def bisect_max(feasible: Callable[[float], Any], lo: float, hi: float, *,
               tol: float = 1e-4, max_iter: int = 60) -> BisectionResult:
    """Largest ``s`` in ``[lo, hi]`` for which ``feasible(s)`` succeeds (quasi-convexity).

    ``feasible(s)`` returns a certificate, or raises :class:`InfeasibleDesignError` (or
    returns None) when ``s`` is infeasible. Feasibility must be monotone: feasible at ``s``
    implies feasible at every smaller ``s`` (e.g. a decay rate).

    Parameters
    ----------
    feasible : callable ``s -> certificate or None``
        Decides one value of ``s``.
    lo, hi : float
        The bracket, ``lo < hi`` (``lo`` must be feasible).
    tol : float
        Absolute width of the final bracket.
    max_iter : int
        Upper bound on the number of calls of ``feasible``.

    Raises
    ------
    InfeasibleDesignError
        Already infeasible at ``lo``.
    """
    lo, hi = as_real_scalar("lo", lo), as_real_scalar("hi", hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ModelError(f"lo, hi: expected finite lo < hi, got ({lo}, {hi})")
    check_positive("tol", tol)

    def attempt(s: float) -> Any:
        try:
            return feasible(s)
        except InfeasibleDesignError:
            return None

    best = attempt(lo)
    iterations = 1
    if best is None:
        raise InfeasibleDesignError(f"lo: the problem is infeasible already at the lower end "
                                    f"{lo}; lower it or check the model",
                                    status="infeasible_at_lower_bound")
    top = attempt(hi)
    iterations += 1
    if top is not None:
        return BisectionResult(hi, hi, top, iterations)
    while hi - lo > tol and iterations < max_iter:
        mid = 0.5 * (lo + hi)
        res = attempt(mid)
        iterations += 1
        if res is None:
            hi = mid
        else:
            lo, best = mid, res
    return BisectionResult(lo, hi, best, iterations)


def max_lyapunov_decay_rate(A: Any, *, tol: float = 1e-4, margin: float = 1e-6,
                            solver: SolverName = "CLARABEL") -> BisectionResult:
    """Largest ``α`` with a Lyapunov certificate ``AᵀP + PA + 2αP ≺ 0`` (bisection).

    For a constant ``A`` it approaches minus the spectral abscissa ``-max Re λ(A)`` from
    below; used as a self-check of the LMI machinery. Near the boundary solvers become
    inaccurate; an undecided solve counts as infeasible, so the value is a proven lower
    bound. Clarabel alone by default (the SCS fallback is slow there and decides nothing).

    Parameters
    ----------
    A : (n, n) array_like
        The matrix.
    tol : float
        Bisection tolerance on ``α``.
    margin : float
        Strictness margin of the LMIs (``≺ -margin I``).
    solver : str
        ``"auto"`` or one name of :data:`SDP_SOLVERS`.
    """
    A = as_square("A", A)
    bound = float(np.linalg.norm(A, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InaccurateCertificateWarning)
        return bisect_max(lambda a: lyapunov_certificate(A, decay=a, margin=margin,
                                                         solver=solver),
                          -bound - 1.0, bound + 1.0, tol=tol)

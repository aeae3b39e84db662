"""One linear Lur'e step: find ``(z, w)`` with ``z = M w + q`` and ``w in -phi(z)``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_square, as_vector
from ..errors import ModelError, SolverError
from .base import SetValuedLaw

if TYPE_CHECKING:   # imported where used at run time
    from ..numerics.lcp import Method as LCPMethod

__all__ = ["solve_inclusion", "InclusionSolution"]


@dataclass(frozen=True, eq=False)
class InclusionSolution:
    """Solution of ``z = M w + q``, ``w in -phi(z)``.

    Attributes
    ----------
    z, w
        The solution.
    residual
        ``law.graph_residual(z, -w)``: distance of ``(z, -w)`` from the law's graph.
    method
        ``"closed_form"`` (componentwise resolvent, diagonal ``M``) or ``"lcp"``.
    iterations
        LCP pivots/sweeps (0 for the closed form).
    """

    z: FloatArray
    w: FloatArray
    residual: float
    method: str
    iterations: int


def _positive_diagonal(M: FloatArray) -> FloatArray | None:
    d = np.diag(M)
    if np.count_nonzero(M - np.diag(d)) == 0 and np.all(d > 0.0):
        return d
    return None


def solve_inclusion(law: SetValuedLaw, M: ArrayLike, q: ArrayLike, *,
                    method: Literal["auto", "closed_form", "lcp"] = "auto",
                    lcp_method: LCPMethod = "lemke", tol: float = 1e-12) -> InclusionSolution:
    """Solve the one-step inclusion ``z = M w + q``, ``w in -phi(z)``.

    Parameters
    ----------
    law
        The law ``phi`` (dimension ``m``).
    M
        ``(m, m)`` step matrix (e.g. ``h H (I - h A)^{-1} G`` for implicit Euler); positive
        definite (not necessarily symmetric) for a unique solution.
    q
        ``(m,)`` free part of ``z``.
    method
        ``"closed_form"``: componentwise law and diagonal ``M > 0``, where
        ``z = (I + diag(M) phi)^{-1} q``; ``"lcp"``: through ``law.complementarity_form()`` and
        :func:`nscontrol.numerics.lcp.solve_lcp`; ``"auto"``: the first that applies.
    lcp_method
        ``method`` passed to ``solve_lcp`` (Lemke by default: the encoded LCP matrices are
        positive semidefinite, not P, and have zero diagonal entries).
    tol
        LCP acceptance tolerance.

    Returns
    -------
    InclusionSolution

    Raises
    ------
    ModelError
        No applicable path (a curved law with non-diagonal ``M``), or a forced ``method``
        that does not apply.
    SolverError
        The LCP solver found no solution (e.g. ``M`` not copositive-plus).

    Examples
    --------
    >>> from nscontrol.laws.relay import Relay
    >>> sol = solve_inclusion(Relay(1.0), [[2.0]], [3.0])
    >>> sol.z.tolist(), sol.w.tolist(), sol.method
    ([1.0], [-1.0], 'closed_form')
    """
    if not isinstance(law, SetValuedLaw):
        raise ModelError(f"law: expected a SetValuedLaw, got {type(law).__name__}")
    M = as_square("M", M, law.dim)
    q = as_vector("q", q, law.dim)
    if method not in ("auto", "closed_form", "lcp"):
        raise ModelError(f"method: expected 'auto', 'closed_form' or 'lcp', got {method!r}")
    diag = _positive_diagonal(M) if law.componentwise else None
    if method == "closed_form" or (method == "auto" and diag is not None):
        if diag is None:
            raise ModelError("method: 'closed_form' needs a componentwise law and a diagonal M "
                             f"with positive entries, got {law!r} and M = {M.tolist()}")
        # z = diag w + q and w in -phi(z)  <=>  q in z + diag phi(z)
        z = law._resolvent(q, diag)
        w = (z - q) / diag
        return InclusionSolution(z, w, law._graph_distance(z, -w), "closed_form", 0)
    from ..numerics.lcp import solve_lcp

    form = law.complementarity_form()
    if form.n_complementarity == 0:
        w = form.w0.copy()
        z = M @ w + q
        return InclusionSolution(z, w, law._graph_distance(z, -w), "lcp", 0)
    A, b = form.lcp(M, q)
    result = solve_lcp(A, b, method=lcp_method, tol=tol)
    if not result.success:
        raise SolverError(f"solve_inclusion: the LCP encoding of {law!r} has no verified "
                          f"solution ({result.status}); check that M is positive definite",
                          status=result.status)
    z, w = form.recover(result.z, M, q)
    return InclusionSolution(z, w, law._graph_distance(z, -w), "lcp", int(result.iterations))

"""Linear complementarity problems with known answers: a conformance suite for LCP solvers.

Each :class:`LCPProblem` carries ``M``, ``q`` and what a correct solver must return: the
solution (when unique), or the fact that there is none. Run every method on
:func:`canonical_lcps` and compare (see ``tests/test_lcp.py``). Random generators for
P-matrices and positive semidefinite matrices feed property tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._validation import check_bool, check_positive
from ..errors import ModelError

__all__ = ["LCPProblem", "canonical_lcps", "two_by_two_interior", "two_by_two_mixed",
           "nonnegative_q", "degenerate_ties", "degenerate_nonunique", "no_solution",
           "stack_delassus", "random_p_matrix", "random_psd_matrix"]


@dataclass(frozen=True)
class LCPProblem:
    """An LCP ``w = M z + q, 0 <= z ⟂ w >= 0`` with its known answer.

    Attributes
    ----------
    name : str
    M : ndarray or scipy.sparse matrix, shape (n, n)
    q : ndarray, shape (n,)
    z, w : ndarray or None
        The solution when it is unique (``w`` may be known even when ``z`` is not: for
        positive semidefinite ``M``, every solution has the same ``w``); None otherwise.
    solvable : bool
        False when the LCP has no solution (a correct solver reports failure).
    description : str
        Why the answer is what it is.
    """

    name: str
    M: object
    q: NDArray[np.float64]
    z: NDArray[np.float64] | None
    w: NDArray[np.float64] | None
    solvable: bool
    description: str


def two_by_two_interior() -> LCPProblem:
    """Both components active: ``z = M^{-1}(-q) = (4/3, 7/3)``, ``w = 0``."""
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    return LCPProblem("2x2 interior", M, np.array([-5.0, -6.0]), np.array([4 / 3, 7 / 3]),
                      np.zeros(2), True,
                      "symmetric positive definite; w = 0 forces z = -M^{-1} q >= 0")


def two_by_two_mixed() -> LCPProblem:
    """One component active: ``z = (1/2, 0)``, ``w = (0, 5/2)``."""
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    return LCPProblem("2x2 mixed", M, np.array([-1.0, 2.0]), np.array([0.5, 0.0]),
                      np.array([0.0, 2.5]), True,
                      "z1 = -q1 / M11 = 1/2, then w2 = M21 z1 + q2 = 5/2 > 0")


def nonnegative_q(n: int = 5) -> LCPProblem:
    """``q >= 0``: the trivial solution ``z = 0, w = q`` (a solver must not pivot)."""
    M = np.eye(n) + 0.5 * np.ones((n, n))
    q = np.linspace(0.0, 1.0, n)
    return LCPProblem("nonnegative q", M, q, np.zeros(n), q.copy(), True,
                      "P-matrix with q >= 0: z = 0 is the unique solution")


def degenerate_ties() -> LCPProblem:
    """All entries of ``q`` tie in Lemke's first ratio test (a degenerate path).

    ``M = [[1, 2, 0], [0, 1, 2], [2, 0, 1]]`` is a P-matrix (principal minors 1, 1, 1, 9);
    the unique solution is ``z = (1/3, 1/3, 1/3)``, ``w = 0``.
    """
    M = np.array([[1.0, 2.0, 0.0], [0.0, 1.0, 2.0], [2.0, 0.0, 1.0]])
    return LCPProblem("degenerate ties", M, -np.ones(3), np.full(3, 1 / 3), np.zeros(3), True,
                      "cyclic P-matrix with equal q_i: every basis on the path is degenerate")


def degenerate_nonunique() -> LCPProblem:
    """Rank-one PSD ``M = [[1, 1], [1, 1]]``, ``q = (-1, -1)``: every ``z >= 0`` with
    ``z1 + z2 = 1`` solves it; ``w = 0`` is unique."""
    M = np.ones((2, 2))
    return LCPProblem("degenerate non-unique", M, -np.ones(2), None, np.zeros(2), True,
                      "PSD and singular: a segment of solutions, all with w = 0")


def no_solution() -> LCPProblem:
    """``M = [[1, -1], [-1, 1]]`` (PSD), ``q = (-1, -1)``: infeasible, since
    ``w1 + w2 = -2`` for every ``z``. Lemke must end in a ray; PGS must not converge."""
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    return LCPProblem("no solution", M, -np.ones(2), None, None, False,
                      "w1 + w2 = -2 < 0 for all z: no feasible point (PSD, so Lemke's ray "
                      "is a certificate)")


def stack_delassus(n_masses: int, *, mass: float = 1.0, g: float = 9.81, h: float = 1e-3,
                   sparse: bool = True) -> LCPProblem:
    """Impulse LCP of one Moreau–Jean step for a stack of ``n_masses`` equal masses at rest
    on the ground (vertical, contacts between neighbours, e = 0).

    Contact 0 is ground–mass 0, contact i is mass i-1 – mass i; relative velocities
    ``u = W^T v`` with ``W^T`` bidiagonal (1 on the diagonal, -1 below). The Delassus matrix
    ``W^T M^{-1} W = (1/m) tridiag(-1, [1, 2, ..., 2], -1)`` is a Stieltjes matrix, and
    ``q = W^T v_free`` with ``v_free = -g h`` gives ``q = (-g h, 0, ..., 0)``. The impulse
    that stops every mass is ``z_i = (n - i) m g h`` (contact i carries the masses above it);
    all contacts stay closed, ``w = 0``.

    Parameters
    ----------
    n_masses : int
        Number of masses (= contacts).
    mass, g, h : float
        Mass of each body, gravity, time step (all > 0).
    sparse : bool
        Return ``M`` as a scipy.sparse CSR matrix (else dense).
    """
    if int(n_masses) < 1:
        raise ModelError(f"n_masses: expected an integer >= 1, got {n_masses!r}")
    n = int(n_masses)
    mass = check_positive("mass", mass)
    g = check_positive("g", g)
    h = check_positive("h", h)
    sparse = check_bool("sparse", sparse)
    diag = np.full(n, 2.0 / mass)
    diag[0] = 1.0 / mass
    off = np.full(n - 1, -1.0 / mass)
    import scipy.sparse as sp

    M = sp.diags([off, diag, off], [-1, 0, 1], format="csr")
    q = np.zeros(n)
    q[0] = -g * h
    z = np.asarray((n - np.arange(n)) * mass * g * h, dtype=float)
    return LCPProblem(f"stack of {n} masses", M if sparse else M.toarray(), q, z,
                      np.zeros(n), True,
                      "each contact impulse carries the weight-impulse m g h of the masses "
                      "above it")


def canonical_lcps() -> list[LCPProblem]:
    """The conformance suite: every method must solve the solvable ones it applies to and
    report failure (never a solution) on the unsolvable one."""
    return [two_by_two_interior(), two_by_two_mixed(), nonnegative_q(), degenerate_ties(),
            degenerate_nonunique(), no_solution(), stack_delassus(10, sparse=False),
            stack_delassus(200)]


def random_p_matrix(n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """A random P-matrix: ``A A^T / n + 0.1 I + (S - S^T)``.

    Its symmetric part is positive definite, so every principal minor is positive (the LCP
    has a unique solution for every q); the skew part makes it non-symmetric.
    """
    A = rng.standard_normal((n, n))
    S = rng.standard_normal((n, n))
    return A @ A.T / n + 0.1 * np.eye(n) + 0.5 * (S - S.T)


def random_psd_matrix(n: int, rank: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """A random symmetric positive semidefinite matrix ``B B^T`` of the given rank (<= n)."""
    B = rng.standard_normal((n, max(0, min(rank, n))))
    return B @ B.T

"""Linear-algebra tests of observability, decided on balanced, unit-norm matrices.

* :func:`pbh_observability` -- the Popov-Belevitch-Hautus test of a pair ``(C, A)``;
* :func:`krylov_basis` -- an orthonormal basis of the Krylov space ``span{b, A b, ...}``
  (Arnoldi with re-orthogonalisation), the reachable space of a single input.

Both work on the balanced copy ``A = omega D A_n D^{-1}`` of
:func:`~nscontrol.numerics.scaling.balanced_unit_norm`, so that their rank decisions do not
depend on the units of the model. The observability theorems of chapter 2 built on them are
in :mod:`nscontrol.design.impact_conditions`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import FloatArray, as_matrix, as_square
from .scaling import balanced_unit_norm

__all__ = ["RANK_RTOL", "pbh_observability", "krylov_basis"]

#: Relative tolerance below which a Krylov step, a projection or a PBH singular value (all
#: computed on the balanced, unit-norm matrices) counts as zero.
RANK_RTOL = 1e-9


def pbh_observability(A: Any, C: Any, *, rtol: float = RANK_RTOL
                      ) -> tuple[bool, float, tuple[complex, ...]]:
    """Popov-Belevitch-Hautus observability test of ``(C, A)``, independent of the units.

    Parameters
    ----------
    A : (N, N) array_like
    C : (p, N) array_like
    rtol : float
        Margins at or below ``rtol`` count as unobservable.

    Returns
    -------
    observable : bool
    margin : float
        ``min_lambda sigma_min([A_n - lambda I; C_n])`` over the eigenvalues ``lambda`` of
        ``A_n``, where ``A = omega D A_n D^{-1}`` (``D`` diagonal balancing, ``||A_n|| = 1``)
        and ``C_n = C D / ||C D||``. Rescaling time, or the units of individual states,
        leaves it unchanged.
    modes : tuple of complex
        Eigenvalues of ``A`` (model units) failing the test.

    Notes
    -----
    ``(C, A)`` is observable iff ``[A - lambda I; C]`` has full column rank at every eigenvalue
    (PBH). Better conditioned than the rank of the observability matrix (no powers of ``A``).

    References
    ----------
    Hautus, Proc. KNAW A 72 (1969); any linear-systems text (e.g. Kailath, *Linear Systems*,
    1980, section 2.4).

    Examples
    --------
    >>> import numpy as np
    >>> A = np.array([[0.0, 1.0], [-4.0, 0.0]])            # one oscillator
    >>> pbh_observability(A, [[1.0, 0.0]])[0]              # its position is measured
    True
    >>> ok, margin, modes = pbh_observability(np.diag([-1.0, -2.0]), [[1.0, 0.0]])
    >>> ok, [complex(m) for m in modes]
    (False, [(-2+0j)])
    """
    A = as_square("A", A)
    C = as_matrix("C", C, cols=A.shape[0])
    n = A.shape[0]
    An, d, omega = balanced_unit_norm(A)
    Cn = C * d[None, :]
    c_norm = float(np.linalg.norm(Cn, 2))
    Cn = Cn / c_norm if c_norm > 0.0 else Cn
    margin, modes = np.inf, []
    for lam in np.linalg.eigvals(An):
        stacked = np.vstack([An - lam * np.eye(n), Cn.astype(complex)])
        smin = float(np.linalg.svd(stacked, compute_uv=False)[-1])
        margin = min(margin, smin)
        if smin <= rtol:
            modes.append(complex(lam * omega))
    return not modes, float(margin), tuple(modes)



def krylov_basis(A: FloatArray, b: FloatArray, rtol: float) -> FloatArray:
    """Orthonormal basis of ``span{b, A b, A^2 b, ...}`` by Arnoldi with one full
    re-orthogonalisation per step (``||A|| = 1`` assumed: a new direction shorter than
    ``rtol`` ends the space).

    Parameters
    ----------
    A : (n, n) ndarray
        The matrix (balanced, unit norm).
    b : (n,) ndarray
        The starting vector.
    rtol : float
        Length below which a new direction counts as zero.

    Examples
    --------
    >>> A = np.diag([0.5, -0.5, 1.0])
    >>> krylov_basis(A, np.array([1.0, 1.0, 0.0]), 1e-9).shape     # e_3 is never reached
    (3, 2)
    """
    n = A.shape[0]
    beta = float(np.linalg.norm(b))
    if beta == 0.0:
        return np.zeros((n, 0))
    Q = [b / beta]
    for _ in range(n - 1):
        w = A @ Q[-1]
        basis = np.array(Q)
        for _pass in range(2):                   # classical Gram-Schmidt, twice
            w = w - basis.T @ (basis @ w)
        h = float(np.linalg.norm(w))
        if h <= rtol:
            break
        Q.append(w / h)
    return np.array(Q).T


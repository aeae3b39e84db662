"""The one converter from state-space objects (python-control's ``StateSpace``) to matrices.

Every constructor that needs a linear part (``LureSystem``, the modes of a
``PiecewiseAffineSystem``, ``LTIFlow``, the observer and convergent designs) accepts, besides
arrays, any object with ``A``, ``B``, ``C``, ``D`` and ``dt`` attributes and a continuous
time base — python-control's ``StateSpace`` in particular — through
:func:`state_space_matrices`. The check is by attributes, so ``control`` is never imported.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .._validation import FloatArray
from ..errors import DimensionError, ModelError

__all__ = ["StateSpaceMatrices", "is_state_space", "state_space_matrices", "state_matrix",
           "state_space_names"]


class StateSpaceMatrices(NamedTuple):
    """``x' = A x + B u``, ``y = C x + D u`` as float arrays.

    Parameters
    ----------
    A : (n, n) ndarray
        State matrix.
    B : (n, q) ndarray
        Input matrix (2-D even with a single input).
    C : (p, n) ndarray
        Output matrix (2-D even with a single output).
    D : (p, q) ndarray
        Feedthrough.
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    D: FloatArray


def is_state_space(obj: Any) -> bool:
    """Whether ``obj`` is a state-space model rather than a matrix.

    Parameters
    ----------
    obj
        Anything.

    Returns
    -------
    bool
        ``True`` for an object with ``A``, ``B``, ``C``, ``D`` and ``dt`` attributes
        (python-control's ``StateSpace``), ``False`` for arrays, nested lists, nscontrol's
        own models and everything else.

    Examples
    --------
    >>> is_state_space([[0.0, 1.0], [-1.0, 0.0]])
    False
    """
    if isinstance(obj, (np.ndarray, list, tuple, int, float)):
        return False
    # "dt" tells a state-space model from nscontrol's own models, which have A, B, C, D too
    return all(hasattr(obj, key) for key in ("A", "B", "C", "D", "dt"))


def state_space_matrices(ss: Any, name: str = "ss") -> StateSpaceMatrices:
    """The matrices of a continuous-time state-space model.

    Parameters
    ----------
    ss
        A python-control ``StateSpace`` (or any object with ``A``, ``B``, ``C``, ``D`` and
        ``dt``, the sampling period: 0 or ``None`` for continuous time).
    name : str
        The argument's name, for error messages.

    Returns
    -------
    StateSpaceMatrices
        ``A (n, n)``, ``B (n, q)``, ``C (p, n)``, ``D (p, q)``; single-input and
        single-output models give one-column ``B`` and one-row ``C``.

    Raises
    ------
    ModelError
        Not a state-space object, a discrete-time model (``dt`` not 0 or ``None``), or
        non-finite entries.
    DimensionError
        Matrices whose shapes disagree.

    Examples
    --------
    >>> class SS:  # what python-control's ss([[0, 1], [-2, -3]], [[0], [1]], [[1, 0]], 0) holds
    ...     A, B, C, D, dt = [[0, 1], [-2, -3]], [[0], [1]], [[1, 0]], [[0]], 0
    >>> m = state_space_matrices(SS())
    >>> m.A.shape, m.B.shape, m.C.shape, m.D.shape
    ((2, 2), (2, 1), (1, 2), (1, 1))
    """
    if not is_state_space(ss):
        raise ModelError(f"{name}: expected a state-space model (python-control StateSpace, "
                         f"with A, B, C, D, dt), got {type(ss).__name__}")
    dt = ss.dt
    if dt not in (0, None):
        raise ModelError(f"{name}: expected a continuous-time model (dt = 0), got dt = {dt}; "
                         f"the models of nscontrol are continuous-time")
    try:
        A, B, C, D = (np.atleast_2d(np.asarray(getattr(ss, k), dtype=float))
                      for k in ("A", "B", "C", "D"))
    except (TypeError, ValueError) as exc:
        raise ModelError(f"{name}: its matrices are not real arrays ({exc})") from None
    n = A.shape[0] if A.size else 0
    if A.size == 0:
        A = np.zeros((0, 0))
    q = B.shape[1] if B.size else (D.shape[1] if D.size else 0)
    p = C.shape[0] if C.size else (D.shape[0] if D.size else 0)
    B = B.reshape(n, q) if B.size == n * q else B
    C = C.reshape(p, n) if C.size == p * n else C
    if D.size <= 1 and not np.any(D):  # a scalar 0 stands for the zero feedthrough
        D = np.zeros((p, q))
    for key, mat, shape in (("A", A, (n, n)), ("B", B, (n, q)), ("C", C, (p, n)),
                            ("D", D, (p, q))):
        if mat.shape != shape:
            raise DimensionError(f"{name}.{key}: expected shape {shape}, got {mat.shape}")
        if not np.all(np.isfinite(mat)):
            raise ModelError(f"{name}.{key}: expected finite entries, got {mat.tolist()}")
    return StateSpaceMatrices(A, B, C, D)


def state_matrix(name: str, value: Any) -> Any:
    """The state matrix ``A`` of a state-space model, or ``value`` unchanged otherwise.

    Parameters
    ----------
    name : str
        The argument's name, for error messages.
    value
        A matrix (returned as is, for the caller to validate) or a state-space model.

    Returns
    -------
    ndarray or the input
        ``A`` of a state-space model; anything else unchanged.
    """
    return state_space_matrices(value, name).A if is_state_space(value) else value


def state_space_names(ss: Any) -> tuple[str, ...]:
    """The state names a state-space model carries (python-control's ``state_labels``), or
    ``()`` when it has none of its own (python-control's defaults ``x[0]``, ``x[1]``, ...).

    Parameters
    ----------
    ss
        A state-space model.

    Examples
    --------
    >>> class SS:
    ...     state_labels = ["pos", "vel"]
    >>> state_space_names(SS())
    ('pos', 'vel')
    """
    labels = tuple(str(s) for s in (getattr(ss, "state_labels", None) or ()))
    if all(label == f"x[{i}]" for i, label in enumerate(labels)):
        return ()
    return labels

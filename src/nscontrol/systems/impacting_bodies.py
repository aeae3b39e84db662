"""Two bodies of point masses on a line that collide (chapter 2).

Body a (``n_a`` masses, actuated by a scalar input through ``E``) and body b (``n_b`` masses)
move on one line, joined internally by springs of zero rest length and any sign; the last mass
of a stays left of the first mass of b (``q_na <= q_na+1``), with Newton restitution ``e``:

    H_a q_a'' + K_a q_a = E u,   H_b q_b'' + K_b q_b = 0,   y = q_1.

State ``x = [x_a; x_b]``, ``x_a = [q_a; v_a]``, ``x_b = [q_b; v_b]`` (the chapter 2 model,
docs/ch02.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_finite_scalar,
    as_square,
    as_vector,
    check_in_interval,
    check_positive,
    check_symmetric,
)
from ..errors import DimensionError, InadmissibleStateError, ModelError
from .hybrid import LinearHybridSystem

if TYPE_CHECKING:   # imported where used at run time
    from ..numerics.lti import Exosystem

__all__ = ["ImpactingBodies", "stiffness_from_springs"]


@dataclass(frozen=True, eq=False)
class ImpactingBodies:
    """The chapter-2 plant: two bodies of point masses, one unilateral contact between them.

    Parameters
    ----------
    H_a, H_b : array_like
        Diagonal mass matrices of bodies a and b (or the vectors of their masses), ``> 0``.
    K_a, K_b : array_like
        Symmetric stiffness matrices (any sign: negative stiffness = unstable modes).
    E : array_like (n_a,), optional
        Where the scalar input acts on body a (default: on the first mass).
    restitution : float
        Newton coefficient ``e`` in ``(0, 1]`` (the chapter uses ``e = 1``).

    Raises
    ------
    ModelError
        Non-positive masses, non-symmetric ``K``, ``e`` outside ``(0, 1]``.
    DimensionError
        Shapes that disagree.

    Notes
    -----
    Chapter 2 assumes no sustained contact (Assumption 1). A plastic impact (``e = 0``) makes
    the colliding masses leave with the same velocity, and with the springs pulling them
    together they stay in contact: the event-driven integrator then sees an accumulation of
    impacts (``ZenoError``). ``e = 0`` is therefore refused here; model a plastic contact as a
    :class:`~nscontrol.systems.lagrangian.LagrangianSystem` and integrate it with ``moreau_jean``.

    References
    ----------
    Martinelli, Menini, Tornambè, ASME J. Dyn. Sys. Meas. Control 125(4), 2003; spec
    ``ch02-impact-observer.md`` §1.

    Examples
    --------
    A worked example: masses 1 and 2 joined by ``k12 = 6``, mass 1 tied to
    the origin by ``k11 = 4``, mass 3 tied by ``k33 = 4``:

    >>> plant = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0, (0, 1): 6.0},
    ...                                      {(0, 0): 4.0})
    >>> plant.n_a, plant.n_b, plant.state_names
    (2, 1, ('q1', 'q2', 'v1', 'v2', 'q3', 'v3'))
    >>> plant.K_a.tolist(), plant.restitution_matrix.tolist()    # e = 1, equal masses: swap
    ([[10.0, -6.0], [-6.0, 6.0]], [[0.0, 1.0], [1.0, 0.0]])
    >>> plant.check_state([0.0, 0.6, 0.0, 0.0, 0.5, 0.0])   # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.InadmissibleStateError: x0: body a penetrates body b, q_3 - q_2 = -0.1 ...
    """

    H_a: Any
    K_a: Any
    H_b: Any
    K_b: Any
    E: Any = None
    restitution: float = 1.0
    n_a: int = field(init=False)
    n_b: int = field(init=False)

    default_method = "event_driven"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for body in ("a", "b"):
            H = _masses(f"H_{body}", getattr(self, f"H_{body}"))
            K = as_square(f"K_{body}", getattr(self, f"K_{body}"), H.shape[0])
            check_symmetric(f"K_{body}", K)
            set_(self, f"H_{body}", np.diag(H))
            set_(self, f"K_{body}", K)
            set_(self, f"n_{body}", int(H.shape[0]))
        E = np.eye(self.n_a)[0] if self.E is None else as_vector("E", self.E, self.n_a)
        set_(self, "E", E)
        e = check_in_interval("restitution", self.restitution, 0.0, 1.0)
        if e == 0.0:
            raise ModelError("restitution: expected a value in (0, 1], got 0: a plastic impact "
                             "leaves the bodies in sustained contact, which chapter 2 excludes "
                             "(Assumption 1); use a LagrangianSystem with method='moreau_jean' "
                             "for plastic contact")
        set_(self, "restitution", e)

    @classmethod
    def from_springs(cls, masses_a: ArrayLike, masses_b: ArrayLike,
                     springs_a: Mapping[tuple[int, int], float] | None = None,
                     springs_b: Mapping[tuple[int, int], float] | None = None, *,
                     E: ArrayLike | None = None, restitution: float = 1.0) -> ImpactingBodies:
        """Build the matrices from masses and springs ``{(h, j): k_hj}`` (0-based indices
        within each body; ``(h, h)`` ties mass ``h`` to the origin)."""
        ma, mb = as_vector("masses_a", masses_a), as_vector("masses_b", masses_b)
        return cls(ma, stiffness_from_springs(len(ma), springs_a or {}, "springs_a"),
                   mb, stiffness_from_springs(len(mb), springs_b or {}, "springs_b"),
                   E=E, restitution=restitution)

    # -- matrices of ch02 §1 -----------------------------------------------------------
    @property
    def n(self) -> int:
        return self.n_a + self.n_b

    @property
    def n_states(self) -> int:
        return 2 * self.n

    @property
    def A_a(self) -> FloatArray:
        return _first_order(self.H_a, self.K_a)

    @property
    def B_a(self) -> FloatArray:
        return np.concatenate([np.zeros(self.n_a), self.E / np.diag(self.H_a)])[:, None]

    @property
    def A_b(self) -> FloatArray:
        return _first_order(self.H_b, self.K_b)

    @property
    def C_a(self) -> FloatArray:
        C = np.zeros((1, 2 * self.n_a))
        C[0, 0] = 1.0
        return C

    @property
    def restitution_matrix(self) -> FloatArray:
        """The 2×2 map of the colliding velocities ``[v_na; v_na+1]``."""
        from ..laws.impact import restitution_matrix

        return np.asarray(restitution_matrix(self.H_a[-1, -1], self.H_b[0, 0],
                                             self.restitution), float)

    @property
    def state_names(self) -> tuple[str, ...]:
        a = [f"q{i + 1}" for i in range(self.n_a)]
        b = [f"q{self.n_a + i + 1}" for i in range(self.n_b)]
        return tuple(a + ["v" + s[1:] for s in a] + b + ["v" + s[1:] for s in b])

    # -- states --------------------------------------------------------------------------
    def gap(self, x: FloatArray) -> float:
        """``q_na+1 - q_na`` (>= 0 when admissible)."""
        return float(x[2 * self.n_a] - x[self.n_a - 1])

    def check_state(self, x0: ArrayLike, *, tol: float = 1e-12, name: str = "x0") -> FloatArray:
        """Validate ``x0 = [x_a; x_b]`` against the admissible set of ch02 §1.

        Parameters
        ----------
        x0 : (2 n,) array_like
            The state.
        tol : float
            Relative tolerance on the gap and the relative velocity.
        name : str
            The argument's name in the caller, used in the error messages.

        Returns
        -------
        ndarray
            ``x0`` as a float vector.

        Raises
        ------
        InadmissibleStateError
            Penetration ``q_na > q_na+1``, or contact with approaching velocities.
        """
        x0 = as_vector(name, x0, self.n_states)
        scale = max(1.0, float(np.max(np.abs(x0), initial=0.0)))
        g = self.gap(x0)
        if g < -tol * scale:
            raise InadmissibleStateError(
                f"{name}: body a penetrates body b, q_{self.n_a + 1} - q_{self.n_a} = {g:.3g} "
                "< 0; start with q_na <= q_na+1")
        rel = float(x0[2 * self.n_a + self.n_b] - x0[2 * self.n_a - 1])
        if abs(g) <= tol * scale and rel < -tol * scale:
            raise InadmissibleStateError(
                f"{name}: the bodies touch and approach (v_{self.n_a + 1} - v_{self.n_a} = "
                f"{rel:.3g} < 0); apply the restitution map first")
        return x0

    # -- conversions ---------------------------------------------------------------------
    def lagrangian(self) -> Any:
        """The same plant as a :class:`~nscontrol.systems.lagrangian.LagrangianSystem`
        (coordinates ``[q_a; q_b]``, input through ``[E; 0]``)."""
        from .lagrangian import LagrangianSystem

        n, na = self.n, self.n_a
        K = np.zeros((n, n))
        K[:na, :na], K[na:, na:] = self.K_a, self.K_b
        G = np.zeros((1, n))
        G[0, na - 1], G[0, na] = -1.0, 1.0
        masses = np.concatenate([np.diag(self.H_a), np.diag(self.H_b)])
        return LagrangianSystem(masses, stiffness=K, gap_matrix=G,
                                restitution=self.restitution,
                                actuation=np.concatenate([self.E, np.zeros(self.n_b)])[:, None],
                                names=tuple(str(i + 1) for i in range(n)))

    def lagrangian_permutation(self) -> np.ndarray:
        """Indices ``p`` with ``x_lagrangian = x[p]`` (from ``[x_a; x_b]`` to ``[q; v]``)."""
        na, nb = self.n_a, self.n_b
        qa, va = np.arange(na), na + np.arange(na)
        qb, vb = 2 * na + np.arange(nb), 2 * na + nb + np.arange(nb)
        return np.concatenate([qa, qb, va, vb])

    def hybrid(self, u: Exosystem | None = None) -> LinearHybridSystem:
        """The plant as a :class:`~nscontrol.systems.hybrid.LinearHybridSystem`.

        Parameters
        ----------
        u : Exosystem, optional
            Input generator; its state ``w`` is appended: the hybrid state is
            ``[x_a; x_b; w]`` (``w`` empty without input).

        Returns
        -------
        LinearHybridSystem
            Flow ``blockdiag(A_a, A_b, S)`` with ``B_a Cu`` coupling, guard
            ``q_na+1 - q_na >= 0``, jump = restitution map, outputs ``y`` and ``u``.
        """
        na2, nb2 = 2 * self.n_a, 2 * self.n_b
        S = np.zeros((0, 0)) if u is None else np.atleast_2d(np.asarray(u.S, float))
        Cu = np.zeros((1, 0)) if u is None else np.atleast_2d(np.asarray(u.Cu, float))
        nw = S.shape[0]
        N = na2 + nb2 + nw
        A = np.zeros((N, N))
        A[:na2, :na2] = self.A_a
        A[na2:na2 + nb2, na2:na2 + nb2] = self.A_b
        A[na2 + nb2:, na2 + nb2:] = S
        A[:na2, na2 + nb2:] = self.B_a @ Cu
        G = np.zeros((1, N))
        G[0, self.n_a - 1], G[0, na2] = -1.0, 1.0
        R = self.restitution_matrix
        ia, ib = na2 - 1, na2 + self.n_b  # v_na and v_na+1 in the hybrid state
        J = np.eye(N)  # the restitution acts on the two colliding velocities only
        J[np.ix_([ia, ib], [ia, ib])] = R

        y = np.zeros((1, N))
        y[0, 0] = 1.0
        uo = np.zeros((1, N))
        uo[0, na2 + nb2:] = Cu
        names = self.state_names + tuple(f"w{i + 1}" for i in range(nw))
        return LinearHybridSystem(A, G, [0.0], J, state_names=names,
                                  outputs={"y": y, "u": uo})


def stiffness_from_springs(n: int, springs: Mapping[tuple[int, int], float],
                           name: str = "springs") -> FloatArray:
    """``K[h,h] = k_hh + Σ_{j≠h} k_hj``, ``K[h,j] = -k_hj`` (ch02 §1).

    Parameters
    ----------
    n : int
        Number of masses.
    springs : mapping ``(h, j) -> k_hj``
        Spring constants: ``(h, h)`` to the ground, ``(h, j)`` between masses ``h`` and ``j``.
    name : str
        The argument's name, for error messages.
    """
    K = np.zeros((n, n))
    for (h, j), k in springs.items():
        if not (0 <= h < n and 0 <= j < n):
            raise DimensionError(f"{name}: spring ({h}, {j}) refers to a mass outside 0..{n - 1}")
        k = as_finite_scalar(f"{name}[({h}, {j})]", k)
        if h == j:
            K[h, h] += k
        else:
            K[h, h] += k
            K[j, j] += k
            K[h, j] -= k
            K[j, h] -= k
    return K


def _masses(name: str, H: Any) -> FloatArray:
    arr = np.asarray(H, float)
    if arr.ndim == 2:
        H2 = as_square(name, arr)
        if np.count_nonzero(H2 - np.diag(np.diag(H2))):
            raise ModelError(f"{name}: expected a diagonal mass matrix (point masses), got "
                             "off-diagonal entries")
        arr = np.diag(H2).copy()
    arr = as_vector(name, arr)
    for i, m in enumerate(arr):
        check_positive(f"{name}[{i}]", m)
    return arr


def _first_order(H: FloatArray, K: FloatArray) -> FloatArray:
    n = H.shape[0]
    return np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(H, K), np.zeros((n, n))]])

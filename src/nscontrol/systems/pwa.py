"""Piecewise-affine systems on polyhedral partitions: :class:`PiecewiseAffineSystem`.

::

    x' = A_i x + b_i + E u(t),      x ∈ Λ_i = {x : H_i x <= h_i},   i = 1..N

``u(t)`` is an external input (an :class:`~nscontrol.numerics.lti.Exosystem` for exact
propagation, or any function of time); ``E`` is common to all regions, so a field that is
continuous for ``u = 0`` stays continuous for every input.

The partition is checked at construction: interiors do not overlap (one LP per pair of
regions) and the regions cover the state space (or the given ``domain``) — checked on both
sides of every facet at random points, which is where a gap must show. A ``continuous=True``
flag is *checked*, not trusted: the fields of neighbouring regions must agree on their shared
facets to a stated tolerance.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_matrix, as_square, as_vector, check_bool
from ..errors import DimensionError, ModelError
from ..numerics.statespace import is_state_space, state_space_matrices
from .lure import as_input_function
from .protocols import InputSignal

__all__ = ["PiecewiseAffineSystem", "CONTINUITY_RTOL"]

#: Relative tolerance of the continuity check on shared facets (relative to the size of the
#: fields and of ``|A_i| |x|`` at the sample point).
CONTINUITY_RTOL = 1e-9
_FACET_SAMPLES = 24
_BOX = 1e3


@dataclass(frozen=True)
class _Facet:
    region: int
    row: int
    points: FloatArray  # sample points on the facet, (k, n)
    normal: FloatArray  # outward unit normal


@dataclass(frozen=True, eq=False)
class PiecewiseAffineSystem:
    """A piecewise-affine vector field on a polyhedral partition.

    Parameters
    ----------
    A : sequence of (n, n) array_like or StateSpace
        One state matrix per region; a python-control ``StateSpace`` mode gives its ``A``,
        and the modes' common ``B`` and ``C`` serve as ``E`` and ``C`` when those are not
        given.
    b : sequence of (n,) array_like, optional
        One offset per region (default zeros).
    regions : sequence of (H_i, h_i)
        Region ``i`` is ``{x : H_i x <= h_i}`` (``H_i`` of shape ``(k_i, n)``).
    E : (n, q) array_like, optional
        Input matrix (common to all regions); required with ``u``.
    u : Exosystem or callable or array_like, optional
        Default input ``u(t)``; ``simulate(..., u=...)`` overrides it.
    C : (p, n) array_like, optional
        Output ``y = C x`` recorded as a signal (default: none).
    continuous : bool
        Declare the field continuous; checked on every shared facet (``ModelError`` if not).
    domain : (H_d, h_d), optional
        A polyhedron the regions must cover (default: all of ``R^n``).
    state_names : tuple of str

    Raises
    ------
    DimensionError
        Inconsistent shapes.
    ModelError
        Overlapping interiors, a gap in the cover, or a discontinuous field declared
        continuous; the message names the regions and a witness point.

    Notes
    -----
    Overlap is decided exactly on all of ``R^n`` (an LP finds the largest ball inside
    ``Λ_i ∩ Λ_j`` with a free centre, radius capped at the data scale, overlap if it exceeds
    ``1e-9`` relative; an unbounded intersection reaches the cap). The cover is checked by
    stepping ``1e-7`` relative outside ``24`` random points of every facet (within
    ``|x| <= 1e3`` times the data scale): a gap's boundary consists of facets of the regions,
    so it shows there. Continuity is checked at the same points,
    ``|f_i - f_j| <= 1e-9 (|f_i| + |A_i| |x| + |b_i|)``.

    With a ``domain``, ``simulate`` refuses an ``x0`` outside it
    (``InadmissibleStateError``) and stops with ``status = 1`` and a ``domain_exit`` event
    where a trajectory leaves it.

    A system whose input is an Exosystem, a constant or a module-level function can be
    pickled (process pools, Dask); pickling one with a lambda input raises ``ModelError``.

    Examples
    --------
    A one-sided spring (stiffness 6 for ``q < 0``, 1 otherwise): continuous, two regions.

    >>> from nscontrol import simulate
    >>> pwa = PiecewiseAffineSystem.bimodal([[0, 1], [-6, -0.1]], [[0, 1], [-1, -0.1]],
    ...                                     [1.0, 0.0])
    >>> pwa.n_regions, pwa.mode([-1.0, 0.0]), pwa.mode([1.0, 0.0])
    (2, 0, 1)
    >>> tr = simulate(pwa, [1.0, 0.0], (0.0, 5.0))
    >>> [e.kind for e in tr.events][:2], tr.events[0].mode_from, tr.events[0].mode_to
    (['crossing', 'crossing'], 1, 0)
    """

    # The fields hold the validated float arrays; __init__ (below) accepts array_like.
    A: tuple[FloatArray, ...]
    b: tuple[FloatArray, ...] = None  # type: ignore[assignment]  # None -> zeros at init
    regions: tuple[tuple[FloatArray, FloatArray], ...] = ()
    E: FloatArray | None = None
    u: InputSignal = None
    C: FloatArray | None = None
    continuous: bool = True
    domain: tuple[FloatArray, FloatArray] | None = None
    state_names: tuple[str, ...] = ()
    _facets: tuple[_Facet, ...] = field(default=(), init=False, repr=False)
    _neighbours: tuple[tuple[int, int, int], ...] = field(default=(), init=False, repr=False)
    _u_fn: Callable[[ArrayLike], FloatArray] | None = field(default=None, init=False, repr=False)

    default_method = "switching"

    if TYPE_CHECKING:
        def __init__(self, A: Sequence[ArrayLike], b: Sequence[ArrayLike] | None = None,
                     regions: Sequence[tuple[ArrayLike, ArrayLike]] = (),
                     E: ArrayLike | None = None, u: InputSignal = None, C: ArrayLike | None = None,
                     continuous: bool = True,
                     domain: tuple[ArrayLike, ArrayLike] | None = None,
                     state_names: Sequence[str] = ()) -> None: ...

    def __post_init__(self) -> None:
        if len(self.A) == 0:
            raise DimensionError("A: expected one matrix per region, got none")
        object.__setattr__(self, "continuous", check_bool("continuous", self.continuous))
        self._take_state_space_modes()
        As = tuple(as_square(f"A[{i}]", a) for i, a in enumerate(self.A))
        n = As[0].shape[0]
        As = tuple(as_square(f"A[{i}]", a, n) for i, a in enumerate(As))
        N = len(As)
        bs = tuple(np.zeros(n) for _ in range(N)) if self.b is None else \
            tuple(as_vector(f"b[{i}]", v, n) for i, v in enumerate(self.b))
        if len(bs) != N:
            raise DimensionError(f"b: expected {N} offsets (one per region), got {len(bs)}")
        if len(self.regions) != N:
            raise DimensionError(f"regions: expected {N} regions (one per matrix in A), got "
                                 f"{len(self.regions)}")
        regs = []
        for i, reg in enumerate(self.regions):
            try:
                Hi, hi = reg
            except (TypeError, ValueError):
                raise DimensionError(f"regions[{i}]: expected a pair (H_i, h_i), got "
                                     f"{reg!r}") from None
            Hi = as_matrix(f"regions[{i}].H", Hi, cols=n)
            regs.append((Hi, as_vector(f"regions[{i}].h", hi, Hi.shape[0])))
        E = None if self.E is None else as_matrix("E", self.E, rows=n)
        if self.u is not None and E is None:
            raise ModelError("u: an input was given but E is None; pass E (n, q)")
        C = None if self.C is None else as_matrix("C", self.C, cols=n)
        dom = None
        if self.domain is not None:
            Hd, hd = self.domain
            Hd = as_matrix("domain.H", Hd, cols=n)
            dom = (Hd, as_vector("domain.h", hd, Hd.shape[0]))
        if self.state_names and len(self.state_names) != n:
            raise DimensionError(f"state_names: expected {n} names, got "
                                 f"{len(self.state_names)}")
        for key, value in (("A", As), ("b", bs), ("regions", tuple(regs)), ("E", E), ("C", C),
                           ("domain", dom), ("state_names", tuple(self.state_names))):
            object.__setattr__(self, key, value)
        object.__setattr__(self, "_u_fn", None if E is None else
                           as_input_function("u", self.u, E.shape[1]) if self.u is not None
                           else None)
        self._check_partition()

    def _take_state_space_modes(self) -> None:
        """Modes given as StateSpace models: their ``A``; their common ``B``/``C`` become
        ``E``/``C`` unless given (modes that disagree must say which one to use)."""
        if not any(is_state_space(a) for a in self.A):
            return
        mats = [state_space_matrices(a, f"A[{i}]") if is_state_space(a) else None
                for i, a in enumerate(self.A)]
        object.__setattr__(self, "A", tuple(a if m is None else m.A
                                            for a, m in zip(self.A, mats, strict=True)))
        given = [m for m in mats if m is not None]
        for key, attr in (("E", "B"), ("C", "C")):
            if getattr(self, key) is not None:
                continue
            blocks = [getattr(m, attr) for m in given if getattr(m, attr).size]
            if not blocks:
                continue
            if any(b.shape != blocks[0].shape or np.any(b != blocks[0]) for b in blocks):
                raise ModelError(f"{key}: the StateSpace modes have different {attr} "
                                 f"matrices; a PiecewiseAffineSystem has one {key} for all "
                                 f"regions: pass {key}= explicitly")
            object.__setattr__(self, key, blocks[0])

    def __getstate__(self) -> dict[str, Any]:
        # the input functions are checked first, so that a lambda input is reported by name
        # with the way out instead of pickle's "Can't pickle local object"
        from .lure import _check_picklable

        _check_picklable(self)
        return dict(self.__dict__)

    # -- construction helpers -----------------------------------------------------------
    @classmethod
    def bimodal(cls, A1: ArrayLike, A2: ArrayLike, c: ArrayLike, *, d: float = 0.0,
                b1: ArrayLike | None = None, b2: ArrayLike | None = None,
                E: ArrayLike | None = None, u: InputSignal = None, C: ArrayLike | None = None,
                continuous: bool = True,
                state_names: tuple[str, ...] = ()) -> PiecewiseAffineSystem:
        """Two modes split by a hyperplane: ``A1 x + b1`` on ``cᵀx <= d``, ``A2 x + b2`` on
        ``cᵀx >= d``.

        Parameters
        ----------
        A1, A2 : (n, n) array_like
            State matrices of region 0 (``cᵀx <= d``) and region 1 (``cᵀx >= d``).
        c : (n,) array_like
            Normal of the switching hyperplane (nonzero).
        d : float, optional
            Offset of the hyperplane.
        b1, b2 : (n,) array_like, optional
            Offsets of the two fields (default zeros).
        E, u, C, continuous, state_names
            As in the class.

        Returns
        -------
        PiecewiseAffineSystem

        Raises
        ------
        ModelError
            ``c = 0``, or a discontinuous field declared continuous (for a continuous field
            ``A1 - A2 = g cᵀ`` and ``b1 - b2 = -g d`` for some ``g``).
        """
        c = as_vector("c", c)
        if not np.any(c):
            raise ModelError("c: expected a nonzero normal vector, got zeros")
        n = c.shape[0]
        b1 = np.zeros(n) if b1 is None else b1
        b2 = np.zeros(n) if b2 is None else b2
        regions = ((c[None, :], [d]), (-c[None, :], [-d]))
        return cls(A=(A1, A2), b=(b1, b2), regions=regions, E=E, u=u, C=C,
                   continuous=continuous, state_names=state_names)

    @classmethod
    def conewise(cls, A: Sequence[ArrayLike], H: Sequence[ArrayLike], *, E: ArrayLike | None = None,
                 u: InputSignal = None, C: ArrayLike | None = None, continuous: bool = True,
                 state_names: tuple[str, ...] = ()) -> PiecewiseAffineSystem:
        """Conewise linear system: ``x' = A_i x`` on the cone ``{x : H_i x <= 0}``.

        Parameters
        ----------
        A : sequence of (n, n) array_like
            One matrix per cone.
        H : sequence of (k_i, n) array_like
            Cone ``i`` is ``{x : H_i x <= 0}``.
        E, u, C, continuous, state_names
            As in the class.

        Returns
        -------
        PiecewiseAffineSystem
            Homogeneous of degree one (``is_pwl``) when there is no input.
        """
        regions = tuple((Hi, np.zeros(np.shape(Hi)[0])) for Hi in H)
        return cls(A=A, b=None, regions=regions, E=E, u=u, C=C, continuous=continuous,
                   state_names=state_names)

    # -- queries --------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Dimension ``n`` of the state."""
        return int(self.A[0].shape[0])

    @property
    def n_regions(self) -> int:
        """Number ``N`` of regions."""
        return len(self.A)

    @property
    def is_pwl(self) -> bool:
        """Conic regions and zero offsets (homogeneous of degree one)."""
        return all(not np.any(b) for b in self.b) and all(not np.any(h)
                                                          for _, h in self.regions)

    @property
    def neighbours(self) -> tuple[tuple[int, int, int], ...]:
        """``(i, row, j)``: region ``j`` lies across facet ``row`` of region ``i``."""
        return self._neighbours

    def contains(self, i: int, x: ArrayLike, tol: float = 1e-9) -> bool:
        """Whether a state lies in a region.

        Parameters
        ----------
        i : int
            Region index.
        x : (n,) array_like
            State.
        tol : float, optional
            Relative tolerance on ``H_i x <= h_i`` (to ``1 + |h_i| + |H_i||x|``).

        Returns
        -------
        bool
        """
        H, h = self.regions[i]
        x = np.asarray(x, float)
        return bool(np.all(H @ x - h <= tol * (1.0 + np.abs(h) + np.abs(H) @ np.abs(x))))

    def mode(self, x: ArrayLike, tol: float = 1e-9) -> int:
        """The region of a state.

        Parameters
        ----------
        x : (n,) array_like
            State.
        tol : float, optional
            Relative tolerance (see :meth:`contains`).

        Returns
        -------
        int
            Index of the first region containing ``x`` (``-1`` when none does; on a shared
            facet the lower index).
        """
        for i in range(self.n_regions):
            if self.contains(i, x, tol):
                return i
        return -1

    def field(self, i: int, x: ArrayLike, t: float = 0.0, u: InputSignal = None) -> FloatArray:
        """The vector field of one region.

        Parameters
        ----------
        i : int
            Region index.
        x : (n,) array_like
            State.
        t : float, optional
            Time (for the input).
        u : Exosystem or callable or array_like, optional
            Input overriding the system's default.

        Returns
        -------
        ndarray, shape (n,)
            ``A_i x + b_i + E u(t)``.
        """
        x = np.asarray(x, float)
        f = self.A[i] @ x + self.b[i]
        if self.E is not None:
            uval = self.input_at(t, u)
            if uval is not None:
                f = f + self.E @ uval
        return f

    def input_at(self, t: float, u: InputSignal = None) -> FloatArray | None:
        """The input at one time.

        Parameters
        ----------
        t : float
            Time.
        u : Exosystem or callable or array_like, optional
            Input overriding the system's default.

        Returns
        -------
        ndarray, shape (q,) or None
            ``u(t)``; ``None`` without input.

        Raises
        ------
        ModelError
            ``u`` given for a system without an input matrix ``E``.
        """
        if u is None:
            fn = self._u_fn
        elif self.E is None:
            raise ModelError("u: this system has no input matrix E")
        else:
            fn = as_input_function("u", u, self.E.shape[1])
        return None if fn is None else fn(t)[0]

    # -- partition checks -----------------------------------------------------------------
    def _scale(self) -> float:
        hs = [np.max(np.abs(h), initial=0.0) for _, h in self.regions]
        return max(1.0, *hs)

    def in_domain(self, x: ArrayLike, tol: float = 1e-9) -> bool:
        """Whether a state lies in the ``domain`` (always True without one).

        Parameters
        ----------
        x : (n,) array_like
            State.
        tol : float, optional
            Relative tolerance (see :meth:`contains`).

        Returns
        -------
        bool
        """
        if self.domain is None:
            return True
        return _in_poly(*self.domain, np.asarray(x, float), tol)

    def _check_partition(self) -> None:
        self._check_overlaps()
        facets = tuple(f for i in range(self.n_regions) for f in self._sample_facets(i))
        neigh: set[tuple[int, int, int]] = set()
        eps = 1e-7 * self._scale()
        for fac in facets:
            for p in fac.points:
                out = p + eps * fac.normal
                j = self._find_other(fac.region, out)
                if j < 0:
                    if self.domain is not None and not _in_poly(*self.domain, out, 0.0):
                        continue
                    raise ModelError(
                        f"regions: the regions do not cover the "
                        f"{'domain' if self.domain is not None else 'state space'}: the point "
                        f"{np.array2string(out, precision=6)} just outside facet {fac.row} of "
                        f"region {fac.region} lies in no region. Add the missing region, or "
                        f"pass domain=(H_d, h_d) if the state space is bounded")
                neigh.add((fac.region, fac.row, j))
                if self.continuous:
                    self._check_continuity(fac.region, j, p)
        object.__setattr__(self, "_facets", facets)
        object.__setattr__(self, "_neighbours", tuple(sorted(neigh)))

    def _find_other(self, i: int, x: FloatArray) -> int:
        for j in range(self.n_regions):
            if j != i and self.contains(j, x, 1e-12):
                return j
        return -1

    def _check_continuity(self, i: int, j: int, p: FloatArray) -> None:
        fi = self.A[i] @ p + self.b[i]
        fj = self.A[j] @ p + self.b[j]
        scale = float(np.linalg.norm(fi) + np.linalg.norm(self.A[i], 2) * np.linalg.norm(p)
                      + np.linalg.norm(self.b[i]))
        gap = float(np.linalg.norm(fi - fj))
        if gap > CONTINUITY_RTOL * max(scale, 1e-300):
            raise ModelError(
                f"continuous: the field was declared continuous but regions {i} and {j} "
                f"disagree on their shared facet: at x = {np.array2string(p, precision=6)}, "
                f"|f_{i} - f_{j}| = {gap:.3g} (relative tolerance {CONTINUITY_RTOL:g}). Fix "
                f"the matrices (A_i - A_j must equal g cᵀ across a facet cᵀx = d) or pass "
                f"continuous=False")

    def _check_overlaps(self) -> None:
        for i in range(self.n_regions):
            for j in range(i + 1, self.n_regions):
                H = np.vstack([self.regions[i][0], self.regions[j][0]])
                h = np.concatenate([self.regions[i][1], self.regions[j][1]])
                r, x = _chebyshev(H, h, self._scale())
                if r > 1e-9 * self._scale():   # at least that: the cap is the scale
                    raise ModelError(
                        f"regions: regions {i} and {j} overlap: the ball of radius {r:.3g} "
                        f"around x = {np.array2string(x, precision=6)} lies in both. Regions "
                        f"must have disjoint interiors")

    def _sample_facets(self, i: int) -> list[_Facet]:
        rng = np.random.default_rng(7919 + i)
        H, h = self.regions[i]
        n = self.n_states
        out = []
        for r in range(H.shape[0]):
            norm = np.linalg.norm(H[r])
            if norm == 0.0:
                continue
            normal = H[r] / norm
            others = np.delete(np.arange(H.shape[0]), r)
            center, rad = _facet_center(H, h, r, others, self._scale())
            if center is None or rad <= 1e-9 * self._scale():
                continue  # redundant row or lower-dimensional facet
            pts = [center]
            P = np.eye(n) - np.outer(normal, normal)
            for _ in range(_FACET_SAMPLES - 1):
                d = P @ rng.standard_normal(n)
                if np.linalg.norm(d) == 0.0:
                    continue
                d /= np.linalg.norm(d)
                smax = _ray_length(H[others], h[others], center, d, _BOX * self._scale())
                pts.append(center + rng.uniform(0.0, 0.999) * smax * d)
            out.append(_Facet(i, r, np.array(pts), normal))
        return out


def _in_poly(H: FloatArray, h: FloatArray, x: FloatArray, tol: float) -> bool:
    return bool(np.all(H @ x - h <= tol * (1.0 + np.abs(h) + np.abs(H) @ np.abs(x))))


def _chebyshev(H: FloatArray, h: FloatArray, cap: float) -> tuple[float, FloatArray]:
    """Largest ball (radius, centre) inside ``{Hx <= h}``, the radius capped at ``cap``.

    The centre is free (no bounding box), so an intersection that is thin near the origin but
    opens up far away is still found; a radius equal to ``cap`` means "at least ``cap``"
    (unbounded polyhedra included). ``(-1, 0)`` when the polyhedron is empty.
    """
    from scipy.optimize import linprog

    n = H.shape[1]
    norms = np.linalg.norm(H, axis=1)
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=np.c_[H, norms], b_ub=h,
                  bounds=[(None, None)] * n + [(0.0, cap)], method="highs")
    if res.status != 0:
        return -1.0, np.zeros(n)
    return float(res.x[-1]), res.x[:n]


def _facet_center(H: FloatArray, h: FloatArray, r: int, others: np.ndarray, scale: float
                  ) -> tuple[FloatArray | None, float]:
    """Chebyshev centre of facet ``r`` (within the hyperplane ``H_r x = h_r``)."""
    from scipy.optimize import linprog

    n = H.shape[1]
    box = _BOX * scale
    normal = H[r] / np.linalg.norm(H[r])
    P = np.eye(n) - np.outer(normal, normal)
    Ho = np.vstack([H[others], np.eye(n), -np.eye(n)])
    ho = np.concatenate([h[others], np.full(2 * n, box)])
    norms = np.linalg.norm(Ho @ P, axis=1)  # radius measured within the hyperplane
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=np.c_[Ho, norms], b_ub=ho,
                  A_eq=np.r_[H[r], 0.0][None, :], b_eq=[h[r]],
                  bounds=[(None, None)] * n + [(0.0, box)], method="highs")
    if res.status != 0:
        return None, -1.0
    return res.x[:n], float(res.x[-1])


def _ray_length(H: FloatArray, h: FloatArray, x: FloatArray, d: FloatArray, box: float
                ) -> float:
    """Largest ``s`` with ``H(x + s d) <= h`` and ``|x + s d|_inf <= box``."""
    s = np.inf
    Hd = H @ d
    slack = h - H @ x
    pos = Hd > 1e-14
    if np.any(pos):
        s = min(s, float(np.min(slack[pos] / Hd[pos])))
    for k in range(x.shape[0]):
        if d[k] > 1e-14:
            s = min(s, (box - x[k]) / d[k])
        elif d[k] < -1e-14:
            s = min(s, (-box - x[k]) / d[k])
    return max(0.0, s)

"""Feedback linearization of continuous conewise linear systems (chapter 9).

A system ``x' = A_i x + B u`` on the cones ``C_i`` of a fan is *feedback linearizable* when a
PWL homeomorphism ``z = T(x)`` (``T(x) = T_i x`` on ``C_i``) and a feedback
``u = K_i x + G_i v`` make ``z' = Ā z + B̄ v`` linear and controllable. Three feedback classes:

============  ===================================================================
class         feedback on the interior of ``C_i``
============  ===================================================================
continuous    ``u = K(x) + G v``, ``K`` continuous conewise linear, ``G`` constant
pwl_feedback  ``u = K_i x + G v`` (``K_i`` may jump across facets), ``G`` constant
pwl_gain      ``u = K_i x + G_i v`` with piecewise-constant invertible ``G_i``
============  ===================================================================

Single input (``B = b``), with ``(A_0, b)`` controllable and ``w`` the flat output of mode 0
(``w A_0^k b = 0`` for ``k <= n-2``, ``w A_0^{n-1} b = 1``) and ``γ_i = w A_i^{n-1} b``:

* ``pwl_gain`` iff the **chain** ``w A_i^k = w A_0^k`` holds for ``k = 0..n-2`` in every mode
  and the ``γ_i`` are non-zero with **one sign** (coherent orientation);
* ``pwl_feedback`` iff moreover all ``γ_i`` are equal;
* ``continuous`` iff moreover all ``w A_i^{n-1}`` are equal (the nonlinearity is matched).

Then ``T_i = [w; w A_0; …; w A_0^{n-2}; w A_i^{n-1}]``, ``u = (v − w A_i^{n-1} A_i x)/γ_i``
and ``(Ā, B̄)`` is the Brunovsky chain. With several inputs only the ``continuous`` class is
decided (``im(A_i − A_0) ⊆ im B``, then ``K_i = B⁺(A_0 − A_i)``, ``T = I``, target
``(A_0, B)``); the two other classes are reported unknown.

The tests run in floating point with a relative tolerance, or exactly in rational arithmetic
(:class:`fractions.Fraction` on the exact values of the stored doubles) with ``exact=True``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_matrix, as_vector, check_bool, check_positive
from ..errors import DimensionError, InfeasibleDesignError, ModelError, SlidingError
from ..systems.conewise import ConewiseLinearSystem

__all__ = ["FEEDBACK_CLASSES", "PWLLinearization", "LinearizationResult",
           "pwl_feedback_linearize", "linearize_or_raise", "brunovsky", "input_generator"]

#: The feedback classes, from the most to the least restrictive.
FEEDBACK_CLASSES = ("continuous", "pwl_feedback", "pwl_gain")


def brunovsky(n: int) -> tuple[FloatArray, FloatArray]:
    """The single-input Brunovsky form: the integrator chain of length ``n``.

    Parameters
    ----------
    n : int
        Length of the chain.

    Returns
    -------
    A : (n, n) ndarray
        Ones on the super-diagonal.
    b : (n, 1) ndarray
        The last unit vector.

    Examples
    --------
    >>> A, b = brunovsky(2)
    >>> A.tolist(), b.ravel().tolist()
    ([[0.0, 1.0], [0.0, 0.0]], [0.0, 1.0])
    """
    b = np.zeros((n, 1))
    b[-1, 0] = 1.0
    return np.eye(n, k=1), b


@dataclass(frozen=True, eq=False)
class PWLLinearization:
    """A linearizing transformation and feedback of a conewise linear system.

    Attributes
    ----------
    system
        The system it linearizes.
    feedback_class
        ``"continuous"``, ``"pwl_feedback"`` or ``"pwl_gain"``.
    w
        Flat output (row, single input) or ``None`` (several inputs).
    L
        The common rows ``[w; w A_0; …; w A_0^{n-2}]`` of ``T`` (single input).
    rows
        The last row ``r_i = w A_i^{n-1}`` of ``T_i`` per cone (single input).
    gammas
        ``γ_i = r_i b`` per cone (single input; ones with several inputs).
    T_modes
        ``T_i`` per cone: ``z = T_i x`` on cone ``i``.
    K_modes, G_modes
        The feedback ``u = K_i x + G_i v`` per cone.
    A_target, B_target
        The linear controllable target ``z' = Ā z + B̄ v``.
    forced
        True when built although the requested class's conditions fail (an experiment: its
        closed loop may slide or lose uniqueness, which the simulation then reports).
    """

    system: ConewiseLinearSystem
    feedback_class: str
    w: FloatArray | None
    L: FloatArray
    rows: tuple[FloatArray, ...]
    gammas: FloatArray
    T_modes: tuple[FloatArray, ...]
    K_modes: tuple[FloatArray, ...]
    G_modes: tuple[FloatArray, ...]
    A_target: FloatArray
    B_target: FloatArray
    forced: bool = False

    def T(self, x: ArrayLike) -> FloatArray:
        """The coordinates ``z = T(x)`` (one state or a time-major array of states).

        Parameters
        ----------
        x : (n,) or (k, n) array_like
            State(s).

        Returns
        -------
        ndarray
            ``T_i x`` with ``i`` the cone of each state, same shape as ``x``.
        """
        X = np.atleast_2d(np.asarray(x, float))
        Z = np.array([self.T_modes[self.system.mode(xk)] @ xk for xk in X])
        return Z.reshape(np.shape(x))

    def T_inv(self, z: ArrayLike, tol: float = 1e-9) -> FloatArray:
        """The preimage ``x = T⁻¹(z)``: the first cone ``i`` with ``T_i⁻¹ z ∈ C_i``.

        Parameters
        ----------
        z : (n,) array_like
            Point in the linear coordinates.
        tol : float, optional
            Relative tolerance of the cone test.

        Returns
        -------
        ndarray, shape (n,)

        Raises
        ------
        ModelError
            No cone contains its candidate preimage (``T`` is not onto at ``z``).
        """
        z = as_vector("z", z, self.system.n_states)
        for i, Ti in enumerate(self.T_modes):
            x: FloatArray = np.asarray(np.linalg.solve(Ti, z), float)
            if self.system.contains(i, x, tol):
                return x
        raise ModelError(f"z: {np.array2string(z, precision=6)} has no preimage under T (no "
                         f"cone contains T_i⁻¹ z); T is not a homeomorphism")

    def feedback(self, x: ArrayLike, v: ArrayLike) -> FloatArray:
        """The input ``u = K_i x + G_i v`` at one state.

        Parameters
        ----------
        x : (n,) array_like
            State.
        v : (m,) array_like
            New input.

        Returns
        -------
        ndarray, shape (m,)
        """
        x = as_vector("x", x, self.system.n_states)
        i = self.system.mode(x)
        return self.K_modes[i] @ x + self.G_modes[i] @ np.atleast_1d(np.asarray(v, float))

    def closed_loop(self, v: Any = None, *, outer: ArrayLike | None = None,
                    plant: ConewiseLinearSystem | None = None, check: bool = True) -> Any:
        """The plant under the linearizing feedback, composed by :func:`nscontrol.closed_loop`.

        The new input ``v`` is generated by an exosystem ``ω' = Sω``, ``v = C_v ω`` whose
        state is appended to the plant's (the gains ``G_i`` act on it region by region, so
        the input stays exact and the run uses the exact piecewise flows of
        ``method="switching"``). With ``outer = κ`` the new input is ``v = −κ T(x) + C_v ω``.

        Parameters
        ----------
        v : Exosystem or float, optional
            The new input (``None``: zero; a float: a constant).
        outer : (m, n) or (n,) array_like, optional
            Gain ``κ`` of a linear outer law on the linear coordinates.
        plant : ConewiseLinearSystem, optional
            The plant the law acts on (default: the designed system); same fan and shapes.
        check : bool, optional
            Refuse a loop that is not well posed (default True). On a facet between cones
            ``i`` and ``j`` the normal velocities of the two sides satisfy
            ``cᵀẋ_j = (γ_i/γ_j) cᵀẋ_i``; a negative ratio (a forced construction) means
            attracting sliding or non-unique solutions there. With ``check=False`` the loop is
            built anyway and the simulation raises
            :class:`~nscontrol.errors.SlidingError` when a solution reaches such a facet.

        Returns
        -------
        ClosedLoop
            State ``[x; ω]``; build ``x0`` with :meth:`initial_state`.

        Raises
        ------
        SlidingError
            ``check=True`` and a facet with ``γ_i γ_j < 0`` (the message names it).
        """
        from ..systems.closed_loop import closed_loop
        from ..systems.feedback import PiecewiseStateFeedback
        from ..systems.pwa import PiecewiseAffineSystem

        plant = self.system if plant is None else plant
        self._check_plant(plant)
        if check_bool("check", check):
            self._check_crossings()
        exo = input_generator(v, plant.n_inputs)
        n, q, m = plant.n_states, exo.S.shape[0], plant.n_inputs
        kappa = np.zeros((m, n)) if outer is None else as_matrix("outer", np.atleast_2d(
            np.asarray(outer, float)), rows=m, cols=n)
        A_aug = [np.block([[A, np.zeros((n, q))], [np.zeros((q, n)), exo.S]]) for A in plant.A]
        H_aug = [np.hstack([-E, np.zeros((E.shape[0], q))]) for E in plant.cones]
        B_aug = np.vstack([plant.B, np.zeros((q, m))])
        aug = PiecewiseAffineSystem.conewise(A_aug, H_aug, E=B_aug, continuous=True,
                                             state_names=_names(plant, q))
        gains = [np.hstack([K - G @ kappa @ T, G @ exo.Cu]) for K, G, T in
                 zip(self.K_modes, self.G_modes, self.T_modes, strict=True)]
        law = PiecewiseStateFeedback(gains, discontinuous=self.feedback_class != "continuous")
        return closed_loop(aug, law, input_matrix=B_aug)

    def initial_state(self, x0: ArrayLike, v: Any = None) -> FloatArray:
        """``[x0; ω0]``: the initial state of :meth:`closed_loop` for the input ``v``.

        Parameters
        ----------
        x0 : (n,) array_like
            Plant state.
        v : Exosystem or float, optional
            The same input as given to :meth:`closed_loop`.

        Returns
        -------
        ndarray
        """
        x0 = as_vector("x0", x0, self.system.n_states)
        return np.concatenate([x0, input_generator(v, self.system.n_inputs).w0])

    def _check_crossings(self) -> None:
        for fac in self.system.facets:
            ratio = float(self.gammas[fac.i] / self.gammas[fac.j])
            if ratio < 0:
                raise SlidingError(
                    f"closed_loop: the feedback is not well posed on the facet between cones "
                    f"{fac.i} and {fac.j} (normal {np.array2string(fac.normal, precision=4)}):"
                    f" the normal velocities of the two sides have the ratio γ_{fac.i}/γ_{fac.j}"
                    f" = {ratio:.6g} < 0, so solutions slide along it or branch from it. This "
                    f"forced feedback has no linearizing closed loop; pass check=False to "
                    f"simulate it anyway (the run stops with SlidingError on the facet)")

    def _check_plant(self, plant: ConewiseLinearSystem) -> None:
        s = self.system
        if not isinstance(plant, ConewiseLinearSystem) or plant.n_modes != s.n_modes or \
                plant.n_states != s.n_states or plant.n_inputs != s.n_inputs:
            raise DimensionError(f"plant: expected a ConewiseLinearSystem with {s.n_modes} "
                                 f"cones, {s.n_states} states and {s.n_inputs} input(s) (the "
                                 f"designed system's), got {plant!r:.80}")


@dataclass(frozen=True, eq=False)
class LinearizationResult:
    """The verdicts of the three feedback classes, their reasons and the transformation.

    Attributes
    ----------
    verdict
        Class name → ``True`` (linearizable), ``False`` (not) or ``None`` (not decided: more
        than one input outside the continuous class).
    reasons
        Class name → the failed conditions in words, with the mode, ``k`` and the residual
        (empty for a ``True`` verdict).
    transform
        The :class:`PWLLinearization` of the requested class, or ``None``.
    requested
        The requested class.
    exact
        Whether the tests ran in rational arithmetic.
    chain_residuals
        ``(mode, k, residual)`` of every chain comparison (single input): the residual
        ``‖w A_i^k − w A_0^k‖`` relative to ``‖w A_0^k‖``.
    gammas
        ``γ_i`` per cone (single input, empty otherwise).
    """

    verdict: dict[str, bool | None]
    reasons: dict[str, list[str]]
    transform: PWLLinearization | None
    requested: str
    exact: bool
    chain_residuals: tuple[tuple[int, int, float], ...] = ()
    gammas: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def linearizable(self) -> bool | None:
        """The verdict of the requested class."""
        return self.verdict[self.requested]


def pwl_feedback_linearize(system: ConewiseLinearSystem, feedback_class: str = "pwl_gain", *,
                           tol: float = 1e-9, exact: bool = False,
                           force: bool = False) -> LinearizationResult:
    """Decide feedback linearizability in the three classes and build the transformation.

    Parameters
    ----------
    system : ConewiseLinearSystem
        The (validated, continuous) plant.
    feedback_class : {"pwl_gain", "pwl_feedback", "continuous"}
        The class whose transformation is returned (all three verdicts are always given).
    tol : float, optional
        Relative tolerance of the float tests (a residual ``<= tol`` times its scale counts
        as zero); unused with ``exact=True``.
    exact : bool, optional
        Run the tests in rational arithmetic on the exact values of the stored doubles:
        give data that are exact in binary (integers, halves, …) or whose structure does not
        rest on roundoff — a mode ``A_2 + e cᵀ`` computed in floating point is, exactly, not
        rank-one away from ``A_2`` (the float mode accepts it within ``tol``).
    force : bool, optional
        Build the single-input construction of the requested class even when only the
        orientation or equality of the ``γ_i`` fails (chain intact, ``γ_i ≠ 0``), marked
        ``forced``: to show what goes wrong in closed loop.

    Returns
    -------
    LinearizationResult

    Raises
    ------
    ModelError
        ``feedback_class`` unknown, ``system`` not a :class:`ConewiseLinearSystem`.

    Examples
    --------
    A nonlinearity one integrator below the input: linearizable with a feedback that jumps
    across ``x_1 = 0``, not with a continuous one.

    >>> from nscontrol.systems import ConewiseLinearSystem
    >>> A2 = np.eye(3, k=1)
    >>> A1 = A2 + np.outer([0, 1, 0], [1, 0, 0])
    >>> s = ConewiseLinearSystem.bimodal(A1, A2, [0, 0, 1], [1, 0, 0])
    >>> r = pwl_feedback_linearize(s)
    >>> r.verdict
    {'continuous': False, 'pwl_feedback': True, 'pwl_gain': True}
    >>> r.reasons["continuous"]
    ['unmatched: w A_1^2 ≠ w A_0^2 (the last row of T differs between the cones; residual 0.707)']
    """
    if feedback_class not in FEEDBACK_CLASSES:
        raise ModelError(f"feedback_class: expected one of {FEEDBACK_CLASSES}, got "
                         f"{feedback_class!r}")
    if not isinstance(system, ConewiseLinearSystem):
        raise ModelError(f"system: expected a ConewiseLinearSystem, got "
                         f"{type(system).__name__}")
    tol = check_positive("tol", tol)
    force = check_bool("force", force)
    ar = _Exact() if check_bool("exact", exact) else _Float(tol)
    if system.n_inputs > 1:
        return _multi_input(system, feedback_class, ar)
    return _single_input(system, feedback_class, ar, force)


def linearize_or_raise(system: ConewiseLinearSystem, feedback_class: str = "pwl_gain",
                       **options: Any) -> PWLLinearization:
    """The transformation of :func:`pwl_feedback_linearize`, or an error with the reasons.

    Parameters
    ----------
    system : ConewiseLinearSystem
        The plant.
    feedback_class : str
        As in :func:`pwl_feedback_linearize`.
    **options
        ``tol``, ``exact``, ``force``.

    Returns
    -------
    PWLLinearization

    Raises
    ------
    InfeasibleDesignError
        Not linearizable in the class (``status`` ``"no"`` or ``"unknown"``); the message
        lists the failed conditions.
    """
    res = pwl_feedback_linearize(system, feedback_class, **options)
    if res.transform is None:
        status = "unknown" if res.verdict[feedback_class] is None else "no"
        raise InfeasibleDesignError(f"system: not feedback linearizable in class "
                                    f"{feedback_class!r} ({status}): "
                                    f"{'; '.join(res.reasons[feedback_class])}", status=status)
    return res.transform


# -- arithmetic: one algorithm, two number systems ----------------------------------------------

class _Float:
    """Floating point; a residual counts as zero below ``tol`` times its scale."""

    exact = False

    def __init__(self, tol: float) -> None:
        self.tol = tol

    def array(self, M: FloatArray) -> Any:
        return np.asarray(M, float)

    def to_float(self, M: Any) -> FloatArray:
        return np.asarray(M, float)

    def norm(self, v: Any) -> float:
        return float(np.linalg.norm(v))

    def is_zero(self, residual: Any, scale: float) -> bool:
        return bool(self.norm(residual) <= self.tol * max(scale, 1e-300))

    def rank(self, M: Any) -> int:
        s = np.linalg.svd(M, compute_uv=False)
        return int(np.sum(s > self.tol * s[0])) if s.size and s[0] > 0 else 0

    def solve(self, M: Any, rhs: Any) -> Any:
        return np.linalg.solve(M, rhs)

    def sign(self, x: Any, scale: float) -> int:
        return 0 if abs(float(x)) <= self.tol * max(scale, 1e-300) else int(np.sign(x))


class _Exact:
    """Rational arithmetic (numpy object arrays of Fractions): zero means zero."""

    exact = True
    tol = 0.0

    def array(self, M: FloatArray) -> Any:
        return np.vectorize(Fraction, otypes=[object])(np.asarray(M, float))

    def to_float(self, M: Any) -> FloatArray:
        return np.asarray(M, dtype=object).astype(float)

    def norm(self, v: Any) -> float:
        return float(np.sqrt(float(sum(x * x for x in np.ravel(v)))))

    def is_zero(self, residual: Any, scale: float) -> bool:
        return all(x == 0 for x in np.ravel(residual))

    def rank(self, M: Any) -> int:
        return len(_row_echelon(M)[1])

    def solve(self, M: Any, rhs: Any) -> Any:
        n = M.shape[0]
        R, pivots = _row_echelon(np.hstack([M, np.reshape(rhs, (n, -1))]))
        if len(pivots) < n or pivots[-1] >= n:
            raise np.linalg.LinAlgError("singular matrix")
        return R[:n, n:].reshape(np.shape(rhs))

    def sign(self, x: Any, scale: float) -> int:
        return (x > 0) - (x < 0)


def _row_echelon(M: Any) -> tuple[Any, list[int]]:
    """Reduced row echelon form of a Fraction matrix and its pivot columns."""
    R = np.array(M, dtype=object)
    rows, cols = R.shape
    pivots: list[int] = []
    r = 0
    for c in range(cols):
        p = next((k for k in range(r, rows) if R[k, c] != 0), None)
        if p is None:
            continue
        R[[r, p]] = R[[p, r]]
        R[r] = R[r] / R[r, c]
        for k in range(rows):
            if k != r and R[k, c] != 0:
                R[k] = R[k] - R[k, c] * R[r]
        pivots.append(c)
        r += 1
        if r == rows:
            break
    return R, pivots


# -- single input: the chain, the orientation ------------------------------------------------

def _single_input(system: ConewiseLinearSystem, requested: str, ar: Any, force: bool
                  ) -> LinearizationResult:
    n, N = system.n_states, system.n_modes
    As = [ar.array(A) for A in system.A]
    b = ar.array(system.B[:, 0])
    ctrb = _krylov(As[0], b, n)
    no: dict[str, bool | None] = {c: False for c in FEEDBACK_CLASSES}
    if ar.rank(ctrb) < n:
        why = [f"mode 0 is not controllable: rank [b, A_0 b, …, A_0^{n - 1} b] = "
               f"{ar.rank(ctrb)} < {n} (a linearizable system is controllable in every mode)"]
        return LinearizationResult(no, {c: list(why) for c in FEEDBACK_CLASSES}, None,
                                   requested, ar.exact)
    e_n = ar.array(np.eye(n)[-1])
    w = ar.solve(ctrb.T, e_n)
    chain, residuals, broken = _chain(As, w, n, ar)
    if broken:
        return LinearizationResult(no, {c: list(broken) for c in FEEDBACK_CLASSES}, None,
                                   requested, ar.exact, tuple(residuals))
    rows = [chain[i][n - 1] for i in range(N)]
    gammas = [r @ b for r in rows]
    reasons = _class_reasons(rows, gammas, ar, n)
    verdict: dict[str, bool | None] = {c: not reasons[c] for c in FEEDBACK_CLASSES}
    gam = ar.to_float(np.array(gammas, dtype=object))
    transform = None
    buildable = all(ar.sign(g, ar.norm(r) * ar.norm(b)) != 0
                    for g, r in zip(gammas, rows, strict=True))
    if verdict[requested] or (force and buildable):
        transform = _single_input_transform(system, requested, ar.to_float(w),
                                            [ar.to_float(chain[0][k]) for k in range(n - 1)],
                                            [ar.to_float(r) for r in rows], gam,
                                            forced=not verdict[requested])
    return LinearizationResult(verdict, reasons, transform, requested, ar.exact,
                               tuple(residuals), gam)


def _krylov(A: Any, b: Any, n: int) -> Any:
    cols, v = [b], b
    for _ in range(n - 1):
        v = A @ v
        cols.append(v)
    return np.stack(cols, axis=1)


def _chain(As: list[Any], w: Any, n: int, ar: Any
           ) -> tuple[list[list[Any]], list[tuple[int, int, float]], list[str]]:
    """Krylov rows ``w A_i^k`` (``k = 0..n-1``) and the chain test ``w A_i^k = w A_0^k``
    for ``k <= n-2``: the residuals and, for the first failing ``k`` of each mode, a reason."""
    chain = []
    for A in As:
        r, rows = w, [w]
        for _ in range(n - 1):
            r = r @ A
            rows.append(r)
        chain.append(rows)
    residuals, broken = [], []
    for i in range(1, len(As)):
        for k in range(1, n - 1):
            diff = chain[i][k] - chain[0][k]
            scale = ar.norm(chain[0][k])
            rel = ar.norm(diff) / max(scale, 1e-300)
            residuals.append((i, k, rel))
            if not ar.is_zero(diff, scale):
                broken.append(f"chain broken at k = {k} in mode {i}: w A_{i}^{k} ≠ w A_0^{k} "
                              f"(residual {rel:.3g}); the nonlinearity sits more than one "
                              f"integrator below the input")
                break
    return chain, residuals, broken


def _class_reasons(rows: list[Any], gammas: list[Any], ar: Any, n: int) -> dict[str, list[str]]:
    """The failed conditions of each class once the chain holds (they nest: F0 ⊂ F1 ⊂ F2)."""
    f2: list[str] = []
    scales = [ar.norm(r) for r in rows]
    signs = [ar.sign(g, s) for g, s in zip(gammas, scales, strict=True)]
    for i, s in enumerate(signs):
        if s == 0:
            f2.append(f"sign of γ: γ_{i} = w A_{i}^{n - 1} b = 0 (mode {i} has a lower "
                      f"relative degree; T is singular there)")
    if not f2 and len(set(signs)) > 1:
        i = signs.index(-signs[0])
        f2.append(f"sign of γ: γ_0 = {float(gammas[0]):.6g} and γ_{i} = {float(gammas[i]):.6g} "
                  f"have opposite signs (the pieces of T are not coherently oriented; T is "
                  f"not injective)")
    f1 = list(f2)
    for i in range(1, len(gammas)):
        diff = gammas[i] - gammas[0]
        if not f2 and not ar.is_zero(np.array([diff]), abs(float(gammas[0]))):
            f1.append(f"unequal γ: γ_{i} = {float(gammas[i]):.6g} ≠ γ_0 = "
                      f"{float(gammas[0]):.6g} (a constant input gain G cannot serve both)")
            break
    f0 = list(f1)
    for i in range(1, len(rows)):
        diff = rows[i] - rows[0]
        if not ar.is_zero(diff, scales[0]):
            rel = ar.norm(diff) / max(scales[0], 1e-300)
            f0.append(f"unmatched: w A_{i}^{n - 1} ≠ w A_0^{n - 1} (the last row of T differs "
                      f"between the cones; residual {rel:.3g})")
            break
    return {"continuous": f0, "pwl_feedback": f1, "pwl_gain": f2}


def _single_input_transform(system: ConewiseLinearSystem, cls: str, w: FloatArray,
                            L_rows: list[FloatArray], rows: list[FloatArray],
                            gammas: FloatArray, forced: bool) -> PWLLinearization:
    n = system.n_states
    L = np.array(L_rows).reshape(n - 1, n)
    T = tuple(np.vstack([L, r[None, :]]) for r in rows)
    K = tuple(-(r @ A)[None, :] / g for r, A, g in zip(rows, system.A, gammas, strict=True))
    G = tuple(np.array([[1.0 / g]]) for g in gammas)
    Ab, bb = brunovsky(n)
    return PWLLinearization(system, cls, w, L, tuple(rows), gammas, T, K, G, Ab, bb, forced)


# -- several inputs: the matched (continuous) class only ---------------------------------------

def _multi_input(system: ConewiseLinearSystem, requested: str, ar: Any) -> LinearizationResult:
    n, m = system.n_states, system.n_inputs
    As = [ar.array(A) for A in system.A]
    B = ar.array(system.B)
    unknown = ["not decided for more than one input: only the continuous (matched) class is "
               "characterised"]
    reasons: dict[str, list[str]] = {"pwl_feedback": list(unknown), "pwl_gain": list(unknown)}
    ctrb = np.hstack([_power(As[0], k, n) @ B for k in range(n)])
    f0: list[str] = []
    if ar.rank(ctrb) < n:
        f0.append(f"mode 0 is not controllable: rank [B, A_0 B, …] = {ar.rank(ctrb)} < {n}")
    for i in range(1, len(As)):
        if ar.rank(np.hstack([B, As[i] - As[0]])) > m:
            f0.append(f"unmatched: im(A_{i} − A_0) is not contained in im B (rank "
                      f"[B, A_{i} − A_0] = {ar.rank(np.hstack([B, As[i] - As[0]]))} > {m})")
    reasons["continuous"] = f0
    verdict: dict[str, bool | None] = {"continuous": not f0, "pwl_feedback": None,
                                       "pwl_gain": None}
    if not f0:   # a matched system is linearizable in every class
        verdict = {c: True for c in FEEDBACK_CLASSES}
        reasons = {c: [] for c in FEEDBACK_CLASSES}
    transform = None
    if verdict[requested]:
        Bp = np.linalg.pinv(system.B)
        K = tuple(Bp @ (system.A[0] - A) for A in system.A)
        eye = np.eye(n)
        transform = PWLLinearization(system, requested, None, np.zeros((0, n)), (),
                                     np.ones(system.n_modes), (eye,) * system.n_modes, K,
                                     (np.eye(m),) * system.n_modes, system.A[0].copy(),
                                     system.B.copy())
    return LinearizationResult(verdict, reasons, transform, requested, ar.exact)


def _power(A: Any, k: int, n: int) -> Any:
    P = np.eye(n, dtype=A.dtype) if A.dtype != object else np.vectorize(
        Fraction, otypes=[object])(np.eye(n))
    for _ in range(k):
        P = P @ A
    return P


# -- helpers of the closed loop ---------------------------------------------------------------

def input_generator(v: Any, m: int) -> Any:
    """The new input ``v`` as an exosystem (``ω' = Sω``, ``v = C_v ω``).

    Parameters
    ----------
    v : Exosystem or float or None
        An exosystem, a constant (one input) or ``None`` (zero: a generator of dimension 0).
    m : int
        Number of inputs.

    Returns
    -------
    Exosystem

    Raises
    ------
    DimensionError
        An exosystem with another number of outputs.
    ModelError
        Anything else (a Python function of time is refused: the gains ``G_i`` act on the
        generator's state region by region).
    """
    from ..numerics.lti import Exosystem

    if v is None:
        return Exosystem(np.zeros((0, 0)), np.zeros((m, 0)), np.zeros(0))
    if all(hasattr(v, a) for a in ("S", "Cu", "w0")):
        if np.shape(v.Cu)[0] != m:
            raise DimensionError(f"v: the exosystem gives {np.shape(v.Cu)[0]} input(s), the "
                                 f"plant takes {m}")
        return v
    if np.ndim(v) == 0 and m == 1:
        return Exosystem.constant(float(v))
    raise ModelError(f"v: expected an Exosystem (nscontrol.numerics.lti), a constant or None, "
                     f"got {type(v).__name__}; a new input given as a Python function would "
                     f"need a per-cone input matrix, which the piecewise-affine model lacks")


def _names(plant: ConewiseLinearSystem, q: int) -> tuple[str, ...]:
    if not plant.state_names:
        return ()
    return (*plant.state_names, *(f"omega{k}" for k in range(q)))


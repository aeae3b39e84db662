"""Filippov systems and switched affine systems driven by a sampled (PWM) controller.

* :class:`FilippovSystem`: smooth fields on the sides of switching surfaces ``h_j(x) = 0``; on
  a surface the solution follows Filippov's convex combination (sliding when both sides push
  towards it).
* :class:`SwitchedAffineSystem` with a :class:`PWMController`: modes ``x' = A_σ x + b_σ``; at
  each sampling instant ``t_k = t0 + kT`` the controller reads ``x(t_k)`` and sets the duty
  time ``d_k ∈ [0, T]`` of the "on" mode (DC-DC converters).

Both are integrated by ``simulate(..., method="switching")``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_square,
    as_vector,
    check_integer,
    check_positive,
)
from ..errors import DimensionError, ModelError
from ..numerics.differences import central_difference_gradient, central_difference_jacobian

if TYPE_CHECKING:   # imported where used at run time
    from .pwa import PiecewiseAffineSystem

__all__ = ["FilippovSystem", "SwitchedAffineSystem", "PWMController"]


def _probe_state(n: int) -> FloatArray:
    """A fixed generic state (distinct, non-zero, irrational-looking components)."""
    return 0.1 + 0.37 * np.sqrt(np.arange(1.0, n + 1.0))


def _require_finite(name: str, value: Any, where: str) -> None:
    """Refuse a user callable's value that is not real, numeric and finite."""
    arr = as_float_array(f"{name} (its value {where})", value, finite=False)
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{name}: returned non-finite values "
                         f"{np.array2string(np.atleast_1d(arr), precision=4)} {where}; it must "
                         "be finite wherever it is evaluated (extend it smoothly across the "
                         "surfaces, guard divisions)")


@dataclass(frozen=True, eq=False)
class FilippovSystem:
    """Vector fields on the sides of switching surfaces, with Filippov's convention on them.

    Parameters
    ----------
    n_states : int
        State dimension.
    surfaces : sequence of callables ``h_j(x) -> float``
        The switching surfaces ``h_j(x) = 0``.
    field : callable ``field(t, x, signs) -> (n,) array``
        The smooth field used where ``sign(h_j(x)) = signs[j]`` (``signs`` a tuple of ±1); it
        must be defined (smoothly extended) up to and across the surfaces.
    gradients : sequence of callables ``∇h_j(x)``, optional
        Surface gradients (default: central finite differences).
    jacobian : callable ``jacobian(t, x, signs) -> (n, n)``, optional
        ``∂field/∂x`` for ``sensitivity=True`` (default: central finite differences).
    state_names : tuple of str

    Notes
    -----
    Mode numbers in event tables: ``Σ_j [signs_j > 0] 2^j``; sliding on surface ``j`` adds
    ``(j + 1) 2^J`` (``J`` surfaces). On surface ``j`` with ``σ± = ∇h_jᵀ F±``: crossing when
    ``σ⁻σ⁺ > 0``; attracting sliding when ``σ⁻ > 0 > σ⁺`` with the Filippov field
    ``F_s = (σ⁺F⁻ - σ⁻F⁺)/(σ⁺ - σ⁻)``, left when ``σ⁻`` or ``σ⁺`` reaches zero; repelling
    sliding (``σ⁻ < 0 < σ⁺``) has no unique forward solution and is refused.

    Raises
    ------
    DimensionError
        ``n_states`` not a positive integer, or ``field``/``gradients`` of the wrong shape.
    ModelError
        No surface, or non-callable surfaces/field.

    References
    ----------
    A.F. Filippov, *Differential equations with discontinuous righthand sides*, 1988;
    SICONOS D5.3 chapter 12 (switching control of limit cycles) for the conventions.

    Examples
    --------
    Relay feedback ``x1' = x2``, ``x2' = -sign(x1 + x2)``: sliding on ``x1 + x2 = 0`` from
    ``t = √3 - 1``:

    >>> from nscontrol import simulate
    >>> c = np.array([1.0, 1.0])
    >>> f = FilippovSystem.two_sided(lambda t, x: np.array([x[1], 1.0]),
    ...                              lambda t, x: np.array([x[1], -1.0]),
    ...                              lambda x: float(c @ x), 2, gradient=lambda x: c)
    >>> tr = simulate(f, [1.0, 0.0], (0.0, 2.0))
    >>> [e.kind for e in tr.events], bool(abs(tr.events[0].time - (np.sqrt(3) - 1)) < 1e-10)
    (['sliding_start'], True)
    """

    n_states: int
    surfaces: Sequence[Callable[[FloatArray], float]]
    field: Callable[[float, FloatArray, tuple[int, ...]], FloatArray]
    gradients: Sequence[Callable[[FloatArray], FloatArray]] | None = None
    jacobian: Callable[[float, FloatArray, tuple[int, ...]], FloatArray] | None = None
    state_names: tuple[str, ...] = ()

    default_method = "switching"

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_states", check_integer("n_states", self.n_states, minimum=1,
                                                           error=DimensionError))
        if len(self.surfaces) == 0:
            raise ModelError("surfaces: expected at least one switching surface h_j(x)")
        if not all(callable(h) for h in self.surfaces) or not callable(self.field):
            raise ModelError("surfaces, field: expected callables h_j(x) and field(t, x, signs)")
        if self.gradients is not None and len(self.gradients) != len(self.surfaces):
            raise DimensionError(f"gradients: expected {len(self.surfaces)} gradients (one per "
                                 f"surface), got {len(self.gradients)}")
        probe = as_float_array("field", self.field(0.0, _probe_state(self.n_states),
                                                   (1,) * len(self.surfaces)), finite=False)
        if probe.shape != (self.n_states,):
            raise DimensionError(f"field: expected field(t, x, signs) of shape "
                                 f"({self.n_states},), got {probe.shape}")
        if self.gradients is not None:
            if not all(callable(g) for g in self.gradients):
                raise ModelError("gradients: expected callables grad_j(x) -> (n_states,) array")
            for j in range(len(self.gradients)):
                self.gradient(j, _probe_state(self.n_states))   # shape check
        if self.jacobian is not None and not callable(self.jacobian):
            raise ModelError("jacobian: expected a callable jacobian(t, x, signs) -> (n, n)")
        if self.state_names and len(self.state_names) != self.n_states:
            raise DimensionError(f"state_names: expected {self.n_states} names, got "
                                 f"{len(self.state_names)}")
        self._probe_finite()

    def _probe_finite(self) -> None:
        """Evaluate every user callable once at a generic state and refuse non-finite (or
        complex, or text) values: a NaN field would otherwise pass construction and poison
        the run. A generic point rather than the origin, where a legitimate field (such as
        ``x/|x|``) may be singular; the field is probed on every side (``2^J`` sign
        patterns, the two extreme ones beyond 10 surfaces)."""
        x = _probe_state(self.n_states)
        where = f"at t = 0, x = {np.array2string(x, precision=4)}"
        J = len(self.surfaces)
        for j, h in enumerate(self.surfaces):
            _require_finite(f"surfaces[{j}]", h(x), where)
        sides = (itertools.product((-1, 1), repeat=J) if J <= 10
                 else [(-1,) * J, (1,) * J])
        for signs in sides:
            _require_finite("field", self.field(0.0, x, tuple(signs)),
                            f"{where}, signs = {tuple(signs)}")
            if self.jacobian is not None:
                _require_finite("jacobian", self.jacobian(0.0, x, tuple(signs)),
                                f"{where}, signs = {tuple(signs)}")
        for j, grad in enumerate(self.gradients or ()):
            _require_finite(f"gradients[{j}]", grad(x), where)

    @property
    def n_surfaces(self) -> int:
        """Number ``J`` of switching surfaces."""
        return len(self.surfaces)

    def h(self, x: FloatArray) -> FloatArray:
        """All surface functions at a state.

        Parameters
        ----------
        x : (n,) array_like
            State.

        Returns
        -------
        ndarray, shape (J,)
            ``h_j(x)`` for every surface.
        """
        return np.array([float(h(x)) for h in self.surfaces])

    def gradient(self, j: int, x: FloatArray) -> FloatArray:
        """The gradient of surface ``j``.

        Parameters
        ----------
        j : int
            Surface index.
        x : (n,) array_like
            State.

        Returns
        -------
        ndarray, shape (n,)
            ``∇h_j(x)`` (the user's gradient, or central differences of ``h_j``).

        Raises
        ------
        DimensionError
            The user's gradient does not return ``n_states`` numbers.
        """
        if self.gradients is not None:
            g = np.asarray(self.gradients[j](x), float)
            if g.shape != (self.n_states,):
                if g.size == self.n_states:
                    return g.reshape(self.n_states)
                raise DimensionError(f"gradients[{j}]: expected grad_{j}(x) of shape "
                                     f"({self.n_states},), got shape {g.shape}")
            return g
        return central_difference_gradient(self.surfaces[j], np.asarray(x, float))

    def jac(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        """The Jacobian of the field on one side.

        Parameters
        ----------
        t : float
            Time.
        x : (n,) array_like
            State.
        signs : tuple of ±1
            The side of every surface (selects the smooth field).

        Returns
        -------
        ndarray, shape (n, n)
            ``∂field/∂x`` (the user's ``jacobian``, or central differences).
        """
        if self.jacobian is not None:
            return np.asarray(self.jacobian(t, x, signs), float)
        return central_difference_jacobian(
            lambda xx: np.asarray(self.field(t, xx, signs), float), np.asarray(x, float))

    @classmethod
    def two_sided(cls, f_minus: Callable[[float, FloatArray], FloatArray] | tuple[Any, Any],
                  f_plus: Callable[[float, FloatArray], FloatArray] | tuple[Any, Any],
                  h: Callable[[FloatArray], float] | ArrayLike, n_states: int, *,
                  gradient: Callable[[FloatArray], FloatArray] | None = None,
                  state_names: tuple[str, ...] = ()) -> FilippovSystem:
        """One surface ``h(x) = 0`` with a smooth field on each side.

        Parameters
        ----------
        f_minus, f_plus : callable ``(t, x) -> (n,) array``, or pairs ``(A, b)``
            The fields where ``h(x) < 0`` and ``h(x) > 0``; a pair ``(A, b)`` is the affine
            field ``A x + b`` (give both fields so, with ``h`` a vector).
        h : callable ``x -> float``, or (n,) array_like ``c``
            The switching surface; a vector ``c`` is the hyperplane ``cᵀx = 0`` (fields given
            as pairs).
        n_states : int
            State dimension.
        gradient : callable ``x -> (n,) array``, optional
            ``∇h`` (default: central differences; the data form's is ``c``).
        state_names : tuple of str, optional

        Returns
        -------
        FilippovSystem
            Given as data, the system is :meth:`from_pwa` of the bimodal
            :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` (exact gradient and
            Jacobians); when the two fields differ by a constant (a relay on a linear plant)
            ``method="switching"`` runs it in its compiled loop (``stats["propagation"]`` is
            ``"exact"``).

        Raises
        ------
        ModelError
            Callables mixed with data, or a ``gradient`` given with the data form.
        DimensionError
            Data of the wrong shape.

        Examples
        --------
        The relay ``x1' = x2``, ``x2' = -sign(x1 + x2)`` as data:

        >>> A = [[0.0, 1.0], [0.0, 0.0]]
        >>> f = FilippovSystem.two_sided((A, [0.0, 1.0]), (A, [0.0, -1.0]), [1.0, 1.0], 2)
        >>> from nscontrol import simulate
        >>> simulate(f, [1.0, 0.0], (0.0, 2.0)).stats["propagation"]
        'exact'
        """
        if callable(f_minus) and callable(f_plus) and callable(h):
            return cls(n_states, (h,), _TwoSided(f_minus, f_plus),
                       gradients=None if gradient is None else (gradient,),
                       state_names=state_names)
        if callable(f_minus) or callable(f_plus) or callable(h):
            raise ModelError("f_minus, f_plus, h: expected three callables, or the data form "
                             "(A, b) pairs and a normal vector c; got "
                             f"{', '.join(type(v).__name__ for v in (f_minus, f_plus, h))}")
        if gradient is not None:
            raise ModelError("gradient: the data form's gradient is the normal c itself; "
                             "leave gradient out")
        return cls.from_pwa(_bimodal_of_data(f_minus, f_plus, h, n_states, state_names))

    @classmethod
    def from_pwa(cls, pwa: PiecewiseAffineSystem) -> FilippovSystem:
        """The Filippov form of a bimodal piecewise-affine system, for discontinuous fields with
        sliding.

        Parameters
        ----------
        pwa : PiecewiseAffineSystem
            Two regions split by one hyperplane (as built by ``PiecewiseAffineSystem.bimodal``);
            region 0 ``cᵀx <= d`` becomes the side ``h = cᵀx - d < 0``.

        Returns
        -------
        FilippovSystem
            One surface ``h(x) = cᵀx - d`` with the exact gradient ``c`` and Jacobians ``A_i``.

        Raises
        ------
        ModelError
            ``pwa`` is not bimodal.
        """
        if pwa.n_regions != 2 or any(H.shape[0] != 1 for H, _ in pwa.regions):
            raise ModelError("pwa: from_pwa handles bimodal systems (two half-spaces); got "
                             f"{pwa.n_regions} regions")
        (H0, h0), _ = pwa.regions
        c, d = H0[0].copy(), float(h0[0])  # region 0: cᵀx <= d is the side h = cᵀx - d < 0

        def field(t: float, x: FloatArray, s: tuple[int, ...]) -> FloatArray:
            return pwa.field(1 if s[0] > 0 else 0, x, t)
        field.pwa = pwa   # type: ignore[attr-defined]  # the switching method's compiled path reads it

        def jac(t: float, x: FloatArray, s: tuple[int, ...]) -> FloatArray:
            return pwa.A[1 if s[0] > 0 else 0]

        return cls(pwa.n_states, (lambda x: float(c @ x) - d,), field,
                   gradients=(lambda x: c,), jacobian=jac, state_names=pwa.state_names)


def _bimodal_of_data(f_minus: Any, f_plus: Any, c: Any, n_states: int,
                     state_names: tuple[str, ...]) -> PiecewiseAffineSystem:
    """The bimodal PWA of :meth:`FilippovSystem.two_sided`'s data form: ``A⁻x + b⁻`` on
    ``cᵀx <= 0``, ``A⁺x + b⁺`` on ``cᵀx >= 0``."""
    from .pwa import PiecewiseAffineSystem

    n = check_integer("n_states", n_states, minimum=1, error=DimensionError)
    pairs = []
    for name, pair in (("f_minus", f_minus), ("f_plus", f_plus)):
        try:
            A, b = pair
        except (TypeError, ValueError):
            raise DimensionError(f"{name}: expected a callable (t, x) -> (n,) array or a pair "
                                 f"(A, b) of the affine field A x + b") from None
        pairs.append((as_square(f"{name}[0] (A)", A, n), as_vector(f"{name}[1] (b)", b, n)))
    (Am, bm), (Ap, bp) = pairs
    c = as_vector("h", c, n)
    if not np.any(c):
        raise ModelError("h: expected a nonzero normal vector c of the surface cᵀx = 0, got "
                         "zeros")
    return PiecewiseAffineSystem.bimodal(Am, Ap, c, b1=bm, b2=bp,
                                         continuous=False, state_names=state_names)


class _TwoSided:
    """``field(t, x, signs)`` of :meth:`FilippovSystem.two_sided` (picklable when the two
    fields are)."""

    def __init__(self, f_minus: Callable[[float, FloatArray], FloatArray],
                 f_plus: Callable[[float, FloatArray], FloatArray]) -> None:
        self.f_minus, self.f_plus = f_minus, f_plus

    def __call__(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return self.f_plus(t, x) if signs[0] > 0 else self.f_minus(t, x)


@dataclass(frozen=True, eq=False)
class PWMController:
    """A sampled pulse-width modulator: duty time ``d_k = duty(t_k, x(t_k))`` clipped to
    ``[0, period]``.

    Parameters
    ----------
    period : float
        Sampling (and PWM) period ``T``; the sampling instants are ``t_k = t0 + kT``.
    duty : callable ``duty(t_k, x_k) -> float``
        Time spent in ``on_mode`` during ``[t_k, t_k + T)``, computed from the sampled state.
    on_mode, off_mode : int
        Distinct mode indices of the switched system.
    pattern : {"centered", "leading", "trailing"}
        ``centered``: on for ``d/2``, off, on for the last ``d/2`` (ch10); ``leading``: on
        first; ``trailing``: on last.

    Raises
    ------
    ModelError
        ``period`` not finite and positive, ``duty`` not callable, ``on_mode == off_mode``, or
        an unknown ``pattern``.

    Examples
    --------
    >>> pwm = PWMController(0.5, lambda t, x: 0.125, pattern="leading")
    >>> pwm.schedule(0.0, np.zeros(2))
    (0.125, [(0.125, 1), (0.375, 0)])
    """

    period: float
    duty: Callable[[float, FloatArray], float]
    on_mode: int = 1
    off_mode: int = 0
    pattern: Literal["centered", "leading", "trailing"] = "centered"

    def __post_init__(self) -> None:
        object.__setattr__(self, "period", check_positive("period", self.period))
        if not callable(self.duty):
            raise ModelError("duty: expected a callable duty(t_k, x_k) -> float")
        for name in ("on_mode", "off_mode"):
            object.__setattr__(self, name, check_integer(name, getattr(self, name), minimum=0))
        if self.on_mode == self.off_mode:
            raise ModelError(f"on_mode, off_mode: expected two different modes, got both "
                             f"{self.on_mode}")
        if self.pattern not in ("centered", "leading", "trailing"):
            raise ModelError(f"pattern: expected 'centered', 'leading' or 'trailing', got "
                             f"{self.pattern!r}")

    def offsets(self, d: float) -> list[tuple[float, int]]:
        """The switching offsets of one period for a duty ``d``.

        Parameters
        ----------
        d : float
            Duty time in ``[0, T]``.

        Returns
        -------
        list of (offset, mode)
            Start of each nonempty piece within the period (``0 <= offset < T``, increasing)
            and its mode. The period's instants are ``t_k + offset``, computed from the exact
            ``t_k = t0 + kT`` so that they do not drift over long runs.
        """
        T = self.period
        on, off = self.on_mode, self.off_mode
        if self.pattern == "centered":
            starts = [(0.0, on), (d / 2, off), (T - d / 2, on)]
        elif self.pattern == "leading":
            starts = [(0.0, on), (d, off)]
        else:
            starts = [(0.0, off), (T - d, on)]
        ends = [o for o, _ in starts[1:]] + [T]
        return [(o, m) for (o, m), e in zip(starts, ends, strict=True) if e > o]

    def duty_at(self, t_k: float, x_k: FloatArray) -> float:
        """The duty time of the period starting at ``t_k``.

        Parameters
        ----------
        t_k : float
            Sampling instant.
        x_k : (n,) ndarray
            Sampled state ``x(t_k)``.

        Returns
        -------
        float
            ``duty(t_k, x_k)`` clipped to ``[0, T]``.

        Raises
        ------
        ModelError
            The duty function returned a non-number, NaN or an infinity.
        """
        try:
            raw = float(self.duty(t_k, x_k))
        except (TypeError, ValueError) as exc:
            raise ModelError(f"duty: expected duty(t_k, x_k) to return a number, at t_k = "
                             f"{t_k:.12g} it failed with {exc}") from None
        if not np.isfinite(raw):
            raise ModelError(f"duty: expected a finite duty time, got {raw!r} at t_k = "
                             f"{t_k:.12g} (x_k = {np.array2string(np.asarray(x_k), precision=6)});"
                             f" check the duty law for a division by zero or a NaN state")
        return float(np.clip(raw, 0.0, self.period))

    def schedule(self, t_k: float, x_k: FloatArray) -> tuple[float, list[tuple[float, int]]]:
        """The duty and the pieces of the period starting at ``t_k``.

        Parameters
        ----------
        t_k : float
            Sampling instant.
        x_k : (n,) ndarray
            Sampled state ``x(t_k)``.

        Returns
        -------
        d_k : float
            Duty time, clipped to ``[0, T]``.
        pieces : list of (duration, mode)
            The nonempty pieces of the period in order (durations add up to ``T``).

        Raises
        ------
        ModelError
            A non-finite duty (see :meth:`duty_at`).
        """
        d = self.duty_at(t_k, x_k)
        offs = self.offsets(d)
        ends = [o for o, _ in offs[1:]] + [self.period]
        return d, [(e - o, m) for (o, m), e in zip(offs, ends, strict=True)]


@dataclass(frozen=True, eq=False)
class SwitchedAffineSystem:
    """Modes ``x' = A_σ x + b_σ`` selected by a controller.

    Parameters
    ----------
    modes : sequence of (A, b)
        One affine field per mode (at least two).
    controller : PWMController
        Sampled controller setting the mode; required by ``simulate`` (it is part of the
        model, not a simulation option).
    C : (p, n) array_like, optional
        Output ``y = C x`` (recorded as a signal).
    state_names : tuple of str

    Raises
    ------
    DimensionError
        Inconsistent shapes.
    ModelError
        Fewer than two modes, or a controller that is not a ``PWMController`` or names a mode
        that does not exist.

    Notes
    -----
    Each mode is affine, so it is propagated exactly by the flow of the augmented matrix
    ``[[A_σ, b_σ], [0, 0]]`` (:meth:`flow`, a shared :class:`~nscontrol.numerics.lti.LTIFlow`).

    Examples
    --------
    A buck converter (normalised) with a constant duty 0.6 of the period 0.25:

    >>> from nscontrol import simulate
    >>> A = np.array([[0.0, 1.0], [-1.0, -0.5]])
    >>> buck = SwitchedAffineSystem(((A, [0.0, 0.0]), (A, [0.0, 1.0])),
    ...                             PWMController(0.25, lambda t, x: 0.15))
    >>> tr = simulate(buck, [0.0, 0.0], (0.0, 1.0))
    >>> tr.event_times("switch")[:2].round(12).tolist()
    [0.075, 0.175]
    """

    modes: Sequence[tuple[Any, Any]]
    controller: PWMController | None = None
    C: Any = None
    state_names: tuple[str, ...] = ()

    default_method = "switching"

    def __post_init__(self) -> None:
        if len(self.modes) < 2:
            raise ModelError(f"modes: expected at least two modes (A, b), got "
                             f"{len(self.modes)}")
        mats = []
        n = None
        for i, mode in enumerate(self.modes):
            try:
                A, b = mode
            except (TypeError, ValueError):
                raise DimensionError(f"modes[{i}]: expected a pair (A, b)") from None
            A = as_square(f"modes[{i}].A", A, n)
            n = A.shape[0]
            mats.append((A, as_vector(f"modes[{i}].b", b, n)))
        object.__setattr__(self, "modes", tuple(mats))
        if self.controller is not None:
            if not isinstance(self.controller, PWMController):
                raise ModelError(f"controller: expected a PWMController, got "
                                 f"{type(self.controller).__name__}")
            for name in ("on_mode", "off_mode"):
                k = getattr(self.controller, name)
                if not 0 <= k < len(mats):
                    raise ModelError(f"controller.{name}: expected a mode index in "
                                     f"[0, {len(mats)}), got {k}")
        if self.C is not None:
            object.__setattr__(self, "C", as_matrix("C", self.C, cols=n))
        if self.state_names and len(self.state_names) != n:
            raise DimensionError(f"state_names: expected {n} names, got "
                                 f"{len(self.state_names)}")

    @property
    def n_states(self) -> int:
        """Dimension ``n`` of the state."""
        return int(self.modes[0][0].shape[0])

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return len(self.modes)

    def field(self, mode: int, x: FloatArray) -> FloatArray:
        """The vector field of one mode.

        Parameters
        ----------
        mode : int
            Mode index.
        x : (n,) array_like
            State.

        Returns
        -------
        ndarray, shape (n,)
            ``A_mode x + b_mode``.
        """
        A, b = self.modes[mode]
        return A @ np.asarray(x, float) + b

    def flow(self, mode: int) -> Any:
        """The exact flow of one mode on the augmented state ``[x; 1]``.

        Parameters
        ----------
        mode : int
            Mode index.

        Returns
        -------
        LTIFlow
            ``LTIFlow.shared([[A, b], [0, 0]])`` (decomposition reused across runs).
        """
        from ..numerics.lti import LTIFlow

        A, b = self.modes[mode]
        n = A.shape[0]
        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n] = A, b
        return LTIFlow.shared(M)

    def propagate(self, mode: int, x: ArrayLike, t: ArrayLike) -> FloatArray:
        """Exact solution of one mode.

        Parameters
        ----------
        mode : int
            Mode index.
        x : (n,) array_like
            State at time 0.
        t : float or array_like
            Time(s) after which the state is wanted.

        Returns
        -------
        ndarray
            ``x(t)``: ``(n,)`` for a scalar ``t``, ``(len(t), n)`` otherwise (from
            :meth:`flow`).
        """
        n = self.n_states
        xi = np.r_[as_vector("x", x, n), 1.0]
        out = self.flow(mode).propagate(xi, t)
        return out[..., :n]

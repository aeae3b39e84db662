"""Controllers and observers: what they read, what they return, how they reset at jumps.

A controller or an observer is a dynamical block with an internal state ``xc`` (possibly
empty) that reads a :class:`Measurement` of the plant and returns its output — the plant
input ``u`` for a controller, the estimate ``x̂`` for an observer:

* **continuous-time** (``period is None``): ``xc' = update(t, xc, m)``, output
  ``output(t, xc, m)`` at every instant (part of the flow);
* **sampled** (``period = T > 0``): at ``t_k = t0 + kT`` the block reads ``m``, returns
  ``output(t_k, xc_k, m)`` held constant on ``[t_k, t_{k+1})`` (zero-order hold) and moves to
  ``xc_{k+1} = update(t_k, xc_k, m)``;
* at a plant jump (an impact, a mode switch) ``xc⁺ = reset(t, xc⁻, jump)`` with the jump's
  data (:class:`Jump`).

Any object with these attributes is a block (:class:`Controller`, :class:`Observer` are
protocols). Linear and affine blocks — :class:`StateFeedback`, :class:`LinearController`,
:class:`LinearObserver` — also expose their matrices, so that
:func:`nscontrol.closed_loop` can stack them with a linear plant into one model that the
integrators keep exact (event-driven flows by matrix exponentials) or compiled (Moreau–Jean,
implicit Euler).

Compiled blocks: a block may also offer ``compiled()``, returning a :class:`CompiledBlock`
(numba-jitted ``output``/``update``/``reset`` functions and a parameter array). When every
block of a loop has one, the integrator's compiled loop calls them at every step instead of
the Python methods (implicit Euler on a Lur'e plant, Moreau–Jean on a Lagrangian plant);
blocks without it run in Python, unchanged. See :func:`compiled_form`.

Conventions: a controller's output ``u`` enters the plant through the plant's input matrix
(``actuation`` of a Lagrangian system, ``B`` of a Lur'e system, or the ``input_matrix`` given
to :func:`~nscontrol.closed_loop`); state feedback is ``u = K x + k`` (the sign in ``K``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_square,
    as_vector,
    check_bool,
    check_positive,
)
from ..errors import DimensionError, ModelError

__all__ = ["Measurement", "Jump", "Controller", "Observer", "StaticLaw", "StateFeedback",
           "PiecewiseStateFeedback", "LinearController", "LinearObserver", "PiecewiseObserver",
           "CompiledBlock", "compiled_form"]


@dataclass(frozen=True)
class Measurement:
    """What a controller or an observer reads at time ``t``.

    Attributes
    ----------
    t
        Time.
    y
        The plant's measured output ``y = C x`` (the closed loop's ``output_matrix``;
        the whole state when none is declared).
    x
        The plant's state. State feedback reads it; an observer should not (it is what the
        observer estimates), but nothing stops a test from comparing.
    xhat
        The observer's estimate, when the loop has an observer (read by output feedback).
    lam
        Contact multipliers: ``λ̂``, the last step's contact impulses divided by ``h``
        (Moreau–Jean), ``None`` for methods that do not provide them.
    active
        Indices of the contacts in the last step's active set (Moreau–Jean), else ``None``.
    w
        The exogenous input (reference, disturbance) at ``t``, when the loop has one.
    """

    t: float
    y: FloatArray
    x: FloatArray
    xhat: FloatArray | None = None
    lam: FloatArray | None = None
    active: np.ndarray | None = None
    w: FloatArray | None = None


@dataclass(frozen=True)
class Jump:
    """A plant jump as a block's :meth:`~Controller.reset` sees it.

    Attributes
    ----------
    t
        Time of the jump.
    x_minus, x_plus
        Plant states just before and after.
    indices
        The contacts or guards involved.
    impulse
        Contact impulses of an impact (``None`` for other jumps).
    """

    t: float
    x_minus: FloatArray
    x_plus: FloatArray
    indices: np.ndarray
    impulse: FloatArray | None = None


@runtime_checkable
class Controller(Protocol):
    """A feedback law with internal state; its output is the plant input ``u``.

    Attributes
    ----------
    n_states : int
        Size of the internal state (0 for a static law).
    period : float or None
        ``None``: continuous-time; ``T > 0``: sampled with a zero-order hold.
    n_outputs : int
        Size of ``u``.
    """

    # read-only members: plain attributes, frozen dataclass fields and properties all fit
    @property
    def n_states(self) -> int: ...

    @property
    def period(self) -> float | None: ...

    @property
    def n_outputs(self) -> int: ...

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """The block's output at ``t``."""
        ...

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """``xc'`` (continuous) or ``xc`` at the next sampling instant (sampled)."""
        ...

    def reset(self, t: float, xc: FloatArray, jump: Jump) -> FloatArray:
        """The internal state after a plant jump."""
        ...


@runtime_checkable
class Observer(Controller, Protocol):
    """A :class:`Controller` whose output is an estimate ``x̂`` of (part of) the plant state.

    Attributes
    ----------
    estimates : ndarray, shape (n_outputs, n_plant)
        ``S``: the observer estimates ``S x`` (the identity when it estimates the whole
        state); the loop's ``error`` signal is ``S x - x̂``.
    """

    @property
    def estimates(self) -> FloatArray: ...


@dataclass(frozen=True, eq=False)
class CompiledBlock:
    """The compiled form of a controller or an observer, called by the integrators' compiled
    loops in place of the block's Python methods.

    The three functions are compiled by ``numba.njit`` with their signature declared,
    ``@njit(BLOCK_SIGNATURE, cache=True)`` for ``output``/``update`` and
    ``@njit(RESET_SIGNATURE, cache=True)`` for ``reset`` (both importable from
    ``nscontrol.systems.feedback``): the compiled loops then receive them as first-class
    functions, and stay compiled once for every block. They take plain arrays (``float64``,
    one-dimensional, contiguous)::

        output(t, xb, y, x, xhat, lam, params) -> out      (the block's output)
        update(t, xb, y, x, xhat, lam, params) -> xb_next  (xb' or the next sample's xb)
        reset(t, xb, x_minus, x_plus, impulse, params) -> xb_after_jump

    ``y``, ``x``, ``xhat``, ``lam`` are the fields of :class:`Measurement`, with an empty
    array for ``None`` (no observer, no contact multipliers); ``impulse`` is empty when the
    jump has none. They must compute what the Python methods compute (the tests of a block
    compare the two paths).

    Attributes
    ----------
    output, update : numba dispatcher
        The block's output and state update.
    params : ndarray of float64, shape (p,)
        Everything the functions read besides their arguments (gains, reference, ...).
    reset : numba dispatcher, optional
        The state after a plant jump; ``None``: unchanged (the shared identity kernel).
    """

    output: Any
    update: Any
    params: FloatArray
    reset: Any = None

    def __post_init__(self) -> None:
        from ._feedback_kernels import BLOCK_SIGNATURE, RESET_SIGNATURE, keep_state

        if self.reset is None:
            object.__setattr__(self, "reset", keep_state)
        for name, sig, sig_name in (("output", BLOCK_SIGNATURE, "BLOCK_SIGNATURE"),
                                    ("update", BLOCK_SIGNATURE, "BLOCK_SIGNATURE"),
                                    ("reset", RESET_SIGNATURE, "RESET_SIGNATURE")):
            if not _has_signature(getattr(self, name), sig):
                raise ModelError(f"{name}: a CompiledBlock needs a function compiled by "
                                 f"numba.njit({sig_name}) (from "
                                 f"nscontrol.systems.feedback), the signature declared, got "
                                 f"{getattr(self, name)!r}")
        # strings are not parsed and NaN is refused; +-inf may stand for "no bound"
        params = as_float_array("params", self.params, finite=False).reshape(-1)
        if np.isnan(params).any():
            raise ModelError(f"params: expected numbers (+-inf allowed for a missing bound), "
                             f"got NaN at index {np.flatnonzero(np.isnan(params)).tolist()}; "
                             f"the kernels would compute NaN outputs from it")
        object.__setattr__(self, "params", np.ascontiguousarray(params))


def _has_signature(fn: Any, sig: Any) -> bool:
    """``fn`` is a numba dispatcher compiled for ``sig`` only (declared, so that the compiled
    loops receive it as a first-class function of that type and stay cached)."""
    import warnings

    from numba import typeof, types
    from numba.core.errors import NumbaExperimentalFeatureWarning

    if not hasattr(fn, "py_func"):
        return False
    # numba's typing of a dispatcher costs ~0.1 ms, and a block makes its compiled form at
    # every run: the answer is kept per dispatcher and the overloads it has
    key = (fn, sig, tuple(getattr(fn, "overloads", ())))
    known = _SIGNATURE_CHECKED.get(key)
    if known is None:
        with warnings.catch_warnings():   # numba flags its first-class functions experimental
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            known = bool(typeof((fn,)) == types.UniTuple(types.FunctionType(sig), 1))
        _SIGNATURE_CHECKED[key] = known
    return known


_SIGNATURE_CHECKED: dict[tuple[Any, ...], bool] = {}


def __getattr__(name: str) -> Any:
    """``BLOCK_SIGNATURE`` and ``RESET_SIGNATURE`` load numba only when asked for."""
    if name in ("BLOCK_SIGNATURE", "RESET_SIGNATURE"):
        from . import _feedback_kernels

        return getattr(_feedback_kernels, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def compiled_form(block: Any) -> CompiledBlock | None:
    """The block's compiled form (its ``compiled()``), or ``None`` when it has none (no
    method, or the method returns ``None`` for this configuration).

    Parameters
    ----------
    block : Controller or Observer or None
        The block (``None`` gives ``None``).

    Returns
    -------
    CompiledBlock or None

    Raises
    ------
    ModelError
        ``compiled()`` returned something other than a :class:`CompiledBlock`.

    Examples
    --------
    >>> form = compiled_form(StateFeedback([[-2.0, -3.0]]))
    >>> out = form.output(0.0, np.zeros(0), np.zeros(1), np.array([1.0, 1.0]), np.zeros(0),
    ...                   np.zeros(0), form.params)
    >>> out.tolist()
    [-5.0]
    """
    make = getattr(block, "compiled", None)
    if block is None or make is None:
        return None
    form = make()
    if form is not None and not isinstance(form, CompiledBlock):
        raise ModelError(f"compiled: {type(block).__name__}.compiled() must return a "
                         f"CompiledBlock or None, got {type(form).__name__}")
    return form


class _Block:
    """Defaults shared by the ready-made blocks: no reset, continuous-time."""

    period: float | None = None

    def reset(self, t: float, xc: FloatArray, jump: Jump) -> FloatArray:
        """The internal state after a plant jump: unchanged.

        Parameters
        ----------
        t : float
            Time of the jump.
        xc : ndarray
            The block's internal state.
        jump : Jump
            The plant's jump.
        """
        return xc


class StaticLaw:
    """Base of a feedback law without internal state (``n_states = 0``): a subclass gives
    ``n_outputs``, ``period`` (``None``: continuous-time) and ``output``; ``update`` and
    ``reset`` leave the empty state as it is.

    Examples
    --------
    >>> class Saturated(StaticLaw):
    ...     n_outputs, period = 1, None
    ...     def output(self, t, xc, m):
    ...         return np.clip(-m.x[:1], -1.0, 1.0)
    >>> isinstance(Saturated(), Controller)
    True
    """

    n_states: int = 0

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """No internal state: the empty state, unchanged.

        Parameters
        ----------
        t : float
            Time.
        xc : ndarray
            The (empty) internal state.
        m : Measurement
            Unused.
        """
        return xc

    def reset(self, t: float, xc: FloatArray, jump: Jump) -> FloatArray:
        """No internal state: the empty state, unchanged by a plant jump.

        Parameters
        ----------
        t : float
            Time of the jump.
        xc : ndarray
            The (empty) internal state.
        jump : Jump
            Unused.
        """
        return xc


@dataclass(frozen=True, eq=False)
class StateFeedback(StaticLaw):
    """Static state feedback ``u = K x + k`` (continuous-time, or sampled with ``period``).

    Parameters
    ----------
    K : array_like (m, n)
        Gain on the plant state (or on the estimate, with ``on="estimate"``).
    k : array_like (m,), optional
        Constant offset (default zero).
    on : {"state", "estimate"}
        What the law reads: the plant state, or the observer's estimate (output feedback).
    period : float, optional
        Sampling period (zero-order hold); ``None`` for continuous-time feedback.

    Examples
    --------
    >>> fb = StateFeedback([[-2.0, -3.0]])
    >>> fb.output(0.0, np.zeros(0), Measurement(0.0, y=np.zeros(1), x=np.array([1.0, 1.0])))
    array([-5.])
    """

    K: Any
    k: Any = None
    on: str = "state"
    period: float | None = None
    n_states: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        K = as_matrix("K", self.K)
        object.__setattr__(self, "K", K)
        k = np.zeros(K.shape[0]) if self.k is None else as_vector("k", self.k, K.shape[0])
        object.__setattr__(self, "k", k)
        if self.on not in ("state", "estimate"):
            raise ModelError(f"on: expected 'state' or 'estimate', got {self.on!r}")
        if self.period is not None:
            object.__setattr__(self, "period", check_positive("period", self.period))

    @property
    def n_outputs(self) -> int:
        return int(self.K.shape[0])

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        x = m.x if self.on == "state" else m.xhat
        if x is None:
            raise ModelError("StateFeedback(on='estimate'): the loop has no observer; pass "
                             "observer= to closed_loop, or use on='state'")
        return self.K @ x + self.k

    def compiled(self) -> CompiledBlock:
        """The compiled form (:class:`CompiledBlock`): ``u = K x + k`` (or on ``x̂``)."""
        from ._feedback_kernels import affine_output, static_update

        m, n = self.K.shape
        head = [float(m), float(n), 1.0 if self.on == "estimate" else 0.0]
        return CompiledBlock(affine_output, static_update,
                             np.concatenate([head, self.K.ravel(), self.k]))


@dataclass(frozen=True, eq=False)
class PiecewiseStateFeedback(StaticLaw):
    """Region-wise affine state feedback ``u = K_i x + k_i`` for a piecewise-affine plant
    (``i``: the plant's region), continuous-time.

    Parameters
    ----------
    K : sequence of array_like (m, n)
        One gain per region of the plant (the plant's region order).
    k : sequence of array_like (m,), optional
        One offset per region (default zeros).
    on : {"state", "estimate"}
        Read the plant state (region of ``x``) or the observer's estimate (region of ``x̂``:
        ``u = K_j x̂ + k_j``, output feedback).
    discontinuous : bool, optional
        The law may jump across the plant's facets (default False: the stacked loop of a
        continuous plant is checked continuous). With True the loop is a discontinuous
        piecewise-affine model; the switching integrator checks every crossing and raises
        :class:`~nscontrol.errors.SlidingError` where the loop would slide.
    """

    # The fields hold the validated arrays; __init__ accepts sequences of array_like.
    K: tuple[FloatArray, ...]
    k: tuple[FloatArray, ...] = None  # type: ignore[assignment]  # None -> zeros at init
    on: str = "state"
    discontinuous: bool = False
    n_states: int = field(default=0, init=False)
    period: float | None = field(default=None, init=False)   # runs in continuous time

    if TYPE_CHECKING:
        def __init__(self, K: Sequence[ArrayLike], k: Sequence[ArrayLike] | None = None,
                     on: str = "state", discontinuous: bool = False) -> None: ...

    def __post_init__(self) -> None:
        Ks = tuple(as_matrix(f"K[{i}]", Ki) for i, Ki in enumerate(self.K))
        if not Ks:
            raise ModelError("K: expected one gain per region, got none")
        if any(Ki.shape != Ks[0].shape for Ki in Ks):
            raise DimensionError(f"K: every region's gain must have the same shape, got "
                                 f"{[Ki.shape for Ki in Ks]}")
        ks = (tuple(np.zeros(Ks[0].shape[0]) for _ in Ks) if self.k is None else
              tuple(as_vector(f"k[{i}]", ki, Ks[0].shape[0]) for i, ki in enumerate(self.k)))
        if len(ks) != len(Ks):
            raise DimensionError(f"k: expected {len(Ks)} offsets (one per region), got "
                                 f"{len(ks)}")
        object.__setattr__(self, "K", Ks)
        object.__setattr__(self, "k", ks)
        object.__setattr__(self, "discontinuous", check_bool("discontinuous",
                                                             self.discontinuous))
        if self.on not in ("state", "estimate"):
            raise ModelError(f"on: expected 'state' or 'estimate', got {self.on!r}")

    @property
    def n_outputs(self) -> int:
        return int(self.K[0].shape[0])

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        raise ModelError("PiecewiseStateFeedback: its region is the plant's; it runs only "
                         "stacked into a PiecewiseAffineSystem by closed_loop")


@dataclass(frozen=True, eq=False)
class LinearController(_Block):
    """A linear dynamic controller reading the measured output ``y``.

    Its equations::

        continuous:  xc' = A xc + B y,          u = C xc + D y
        sampled:     xc_{k+1} = A xc_k + B y_k,  u_k = C xc_k + D y_k   (period T)

    Parameters
    ----------
    A, B, C, D : array_like
        Shapes ``(r, r)``, ``(r, p)``, ``(m, r)``, ``(m, p)``.
    period : float, optional
        Sampling period; ``None`` for continuous-time.
    """

    A: Any
    B: Any
    C: Any
    D: Any
    period: float | None = None
    n_states: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        A = as_square("A", self.A)
        r = A.shape[0]
        B = as_matrix("B", self.B, rows=r)
        C = as_matrix("C", self.C, cols=r)
        D = as_matrix("D", self.D, rows=C.shape[0], cols=B.shape[1])
        for name, value in (("A", A), ("B", B), ("C", C), ("D", D)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "n_states", r)
        if self.period is not None:
            object.__setattr__(self, "period", check_positive("period", self.period))

    @property
    def n_outputs(self) -> int:
        return int(self.C.shape[0])

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        return self.C @ xc + self.D @ m.y

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        return self.A @ xc + self.B @ m.y

    def compiled(self) -> CompiledBlock:
        """The compiled form (:class:`CompiledBlock`) of ``u = C xc + D y``,
        ``A xc + B y``."""
        from ._feedback_kernels import linear_output, linear_update

        r, p, m = self.A.shape[0], self.B.shape[1], self.C.shape[0]
        return CompiledBlock(linear_output, linear_update, np.concatenate(
            [[float(r), float(p), float(m)], self.A.ravel(), self.B.ravel(), self.C.ravel(),
             self.D.ravel()]))


@dataclass(frozen=True, eq=False)
class LinearObserver(_Block):
    """A linear observer, optionally hybrid (resets at plant jumps) or of Lur'e type::

        xo' = F xo + L y + B u + G ŵ,      x̂ = E xo,
        ẑ = H xo + K y + D ŵ (+ the plant's shift g(t)),   ŵ ∈ -φ(ẑ)   (with a law)
        at a plant jump:  xo⁺ = J_o xo⁻ + J_y y⁻                     (with a jump)

    ``y`` is the measured vector the closed loop feeds it (its ``output_matrix`` times the
    plant state: the plant's output, and the known inputs when the observer needs them).

    Parameters
    ----------
    F : array_like (r, r)
    L : array_like (r, p)
        Output injection gain.
    B : array_like (r, m), optional
        How the plant's known input ``u`` enters the observer (default: it does not).
    E : array_like (n_est, r), optional
        Estimate map (default: identity, ``x̂ = xo``).
    estimates : array_like (n_est, n_plant), optional
        ``S``: the plant coordinates estimated (default identity); ``error = S x - x̂``.
    jump : (array_like (r, r), array_like (r, p)), optional
        ``(J_o, J_y)``: the observer's reset at a plant jump.
    law : SetValuedLaw, optional
        The observer's copy of the plant's set-valued law (Lur'e observers); with it
        ``G, H, K`` (and ``D``) are required.
    G, H, K, D : array_like, optional
        The Lur'e observer's matrices (shapes ``(r, mw)``, ``(mw, r)``, ``(mw, p)``,
        ``(mw, mw)``).
    names : sequence of str, optional
        Names of the observer states.
    """

    F: Any
    L: Any
    B: Any = None
    E: Any = None
    estimates: Any = None
    jump: tuple[Any, Any] | None = None
    law: Any = None
    G: Any = None
    H: Any = None
    K: Any = None
    D: Any = None
    names: Sequence[str] = ()
    n_states: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        F = as_matrix("F", self.F)
        r = F.shape[0]
        L = as_matrix("L", self.L, rows=r)
        set_(self, "F", F)
        set_(self, "L", L)
        set_(self, "n_states", r)
        set_(self, "E", np.eye(r) if self.E is None else as_matrix("E", self.E, cols=r))
        if self.B is not None:
            set_(self, "B", as_matrix("B", self.B, rows=r))
        if self.estimates is not None:
            set_(self, "estimates", as_matrix("estimates", self.estimates,
                                              rows=self.E.shape[0]))
        if self.jump is not None:
            Jo, Jy = self.jump
            set_(self, "jump", (as_matrix("jump[0]", Jo, rows=r, cols=r),
                                as_matrix("jump[1]", Jy, rows=r, cols=L.shape[1])))
        if self.law is not None:
            self._check_lure(r, L.shape[1])
        elif any(getattr(self, k) is not None for k in ("G", "H", "K", "D")):
            raise ModelError("law: G, H, K, D describe a Lur'e observer's set-valued part; "
                             "pass the law too (law=plant.law)")

    def _check_lure(self, r: int, p: int) -> None:
        for name in ("G", "H", "K"):
            if getattr(self, name) is None:
                raise ModelError(f"{name}: a Lur'e observer (law given) needs G, H and K")
        G = as_matrix("G", self.G, rows=r)
        mw = G.shape[1]
        object.__setattr__(self, "G", G)
        object.__setattr__(self, "H", as_matrix("H", self.H, rows=mw, cols=r))
        object.__setattr__(self, "K", as_matrix("K", self.K, rows=mw, cols=p))
        D = np.zeros((mw, mw)) if self.D is None else as_matrix("D", self.D, rows=mw, cols=mw)
        object.__setattr__(self, "D", D)

    @property
    def n_outputs(self) -> int:
        return int(self.E.shape[0])

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        return self.E @ xc

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        if self.law is not None:
            raise ModelError("LinearObserver with a law: its multiplier is solved with the "
                             "plant's; it runs only stacked into a LureSystem by closed_loop")
        out = self.F @ xc + self.L @ m.y
        if self.B is not None:
            raise ModelError("LinearObserver with B: the known input is stacked by "
                             "closed_loop; it runs only stacked into the plant's model")
        return out

    def compiled(self) -> CompiledBlock | None:
        """The compiled form (:class:`CompiledBlock`) of ``x̂ = E xo``, ``F xo + L y``;
        ``None`` with a law, a known input ``B`` or a jump (those run stacked)."""
        from ._feedback_kernels import linear_output, linear_update

        if self.law is not None or self.B is not None or self.jump is not None:
            return None
        r, p, m = self.n_states, self.L.shape[1], self.E.shape[0]
        zero = np.zeros((m, p))
        return CompiledBlock(linear_output, linear_update, np.concatenate(
            [[float(r), float(p), float(m)], self.F.ravel(), self.L.ravel(), self.E.ravel(),
             zero.ravel()]))

    def reset(self, t: float, xc: FloatArray, jump: Jump) -> FloatArray:
        if self.jump is None:
            return xc
        raise ModelError("LinearObserver with a jump: it runs stacked into a "
                         "LinearHybridSystem by closed_loop (the jump reads y⁻)")


@dataclass(frozen=True, eq=False)
class PiecewiseObserver(_Block):
    """A copy of a piecewise-affine plant with output injection (the region is the estimate's)::

        x̂' = A_j x̂ + b_j + B u + E w(t) + L (y - C x̂),    j: the region of x̂

    The modes are the plant's own: :func:`~nscontrol.closed_loop` stacks plant and observer
    into one :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` on the product of their
    regions.

    Parameters
    ----------
    L : array_like (n, p)
        Output injection gain.
    C : array_like (p, n)
        The measured output ``y = C x``.
    """

    L: Any
    C: Any
    n_states: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        L = as_matrix("L", self.L)
        C = as_matrix("C", self.C, rows=L.shape[1], cols=L.shape[0])
        object.__setattr__(self, "L", L)
        object.__setattr__(self, "C", C)
        object.__setattr__(self, "n_states", L.shape[0])

    @property
    def n_outputs(self) -> int:
        return self.n_states

    @property
    def estimates(self) -> FloatArray:
        return np.eye(self.n_states)

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        return xc

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        raise ModelError("PiecewiseObserver: its modes are the plant's; it runs only stacked "
                         "into a PiecewiseAffineSystem by closed_loop")

"""Lur'e systems with a maximal monotone set-valued feedback: :class:`LureSystem`.

::

    x' = A x + G w + B u(t)
    z  = H x + D w (+ g(t))
    w  ∈ -φ(z)
    y  = C x

``φ`` is any maximal monotone law of :mod:`nscontrol.laws` (relay, Coulomb friction, normal
cones / complementarity, products of these). A plant and its observer (or controller) in closed
loop are *one* ``LureSystem``: stack the states and combine the laws with ``Product``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_matrix, as_square, as_vector
from ..errors import DimensionError, ModelError
from ..numerics.statespace import is_state_space, state_space_matrices, state_space_names
from .protocols import InputSignal

if TYPE_CHECKING:   # imported where used at run time
    from ..laws.base import SetValuedLaw

__all__ = ["LureSystem"]


class _ConstantInput:
    """A constant signal as a vectorised function ``t -> (len(t), size)`` (picklable)."""

    def __init__(self, value: FloatArray) -> None:
        self.value = value

    def __call__(self, t: Any) -> FloatArray:
        return np.broadcast_to(self.value, (np.size(t), self.value.shape[0])).copy()


class _SampledInput:
    """A function of time (or an Exosystem's ``u``) vectorised to ``t -> (len(t), size)``.

    A module-level class rather than a closure, so that systems holding it can be pickled
    (process pools, Dask) whenever the user's function can; pickling a lambda or a local
    function raises :class:`~nscontrol.errors.ModelError` naming the input and the way out.
    """

    def __init__(self, name: str, fn: Callable[[Any], Any], size: int) -> None:
        self.name, self.fn, self.size = name, fn, size

    def __call__(self, t: Any) -> FloatArray:
        fn, size = self.fn, self.size
        t = np.atleast_1d(np.asarray(t, dtype=float))
        try:
            out = np.asarray(fn(t), dtype=float)
            if out.shape == (t.size, size):
                return out
            if out.shape == (size, t.size) and size != t.size:
                return out.T.copy()
            if size == 1 and out.shape == (t.size,):
                return out.reshape(-1, 1)
        except (TypeError, ValueError):
            pass
        return np.array([np.atleast_1d(np.asarray(fn(float(s)), dtype=float)).ravel()
                         for s in t]).reshape(t.size, size)

    def __getstate__(self) -> dict[str, Any]:
        import pickle

        try:
            pickle.dumps(self.fn)
        except (pickle.PicklingError, AttributeError, TypeError) as exc:
            raise ModelError(
                f"{self.name}: the input {self.name}(t) = {self.fn!r} cannot be pickled ({exc}), "
                f"so this system cannot be sent to another process (process pools, Dask). Pass "
                f"an Exosystem, a constant, or a function defined at module level instead of a "
                f"lambda or a local function") from None
        return dict(self.__dict__)


def _check_picklable(system: Any) -> None:
    """Raise the clear :class:`ModelError` of an input function that cannot be pickled."""
    for key in ("_u_fn", "_g_fn"):
        fn = getattr(system, key, None)
        if isinstance(fn, _SampledInput):
            fn.__getstate__()


def as_input_function(name: str, value: InputSignal,
                      size: int) -> Callable[[Any], FloatArray] | None:
    """Normalise an input signal to a vectorised ``t -> (len(t), size)`` function.

    Accepts ``None``, an :class:`~nscontrol.numerics.lti.Exosystem` (anything with a ``u``
    method), a callable ``t -> vector``, or a constant vector. The result is picklable when
    the given function is.
    """
    if value is None:
        return None
    if hasattr(value, "u") and callable(value.u):
        fn = value.u
    elif callable(value):
        fn = value
    else:
        return _ConstantInput(as_vector(name, value, size))
    probe = np.atleast_1d(np.asarray(fn(0.0), dtype=float)).ravel()
    if probe.shape[0] != size:
        raise DimensionError(f"{name}: expected {name}(t) to have length {size}, got "
                             f"length {probe.shape[0]}")
    return _SampledInput(name, fn, size)


@dataclass(frozen=True, eq=False)
class LureSystem:
    """A linear system in feedback with a maximal monotone set-valued law.

    Parameters
    ----------
    A : (n, n) array_like or StateSpace
        State matrix; or a python-control ``StateSpace`` with inputs ``[w; u]`` and outputs
        ``[z; y]`` (``B_ss = [G, B]``, ``C_ss = [H; C]``, ``D_ss = [[D, 0], [0, 0]]``), which
        gives ``G``, ``H``, ``B``, ``C``, ``D`` at once: ``LureSystem(ss, law)``. With only
        the ``m`` outputs ``z``, ``C`` is what ``C=`` says (default the whole state).
    G : (n, m) array_like
        The multiplier's input channel: how ``w`` enters the state equation (``B`` in much
        of the Lur'e literature).
    H : (m, n) array_like
        The multiplier's output channel: the state's output that feeds the law (``C`` in
        much of the Lur'e literature).
    law : SetValuedLaw
        The maximal monotone map ``φ`` of dimension ``m`` (``w ∈ -φ(z)``).
    B : (n, q) array_like, optional
        Input matrix of the external input ``u(t)``; required with ``u``.
    C : (p, n) array_like, optional
        Measured output ``y = C x`` (default: the whole state).
    D : (m, m) array_like, optional
        Feedthrough of ``w`` into ``z``; ``D + Dᵀ`` must be positive semidefinite.
    u : Exosystem or callable or array_like, optional
        External input ``u(t)`` (an ``Exosystem``, a function of time, or a constant).
    g : callable or array_like, optional
        Known shift of the law's argument, ``z = H x + D w + g(t)``.
    state_names : tuple of str, optional
        Names of the state components.

    Raises
    ------
    DimensionError
        Shapes disagree (the message names the matrix and the expected shape).
    ModelError
        ``D + Dᵀ`` is not positive semidefinite, or ``law`` is not monotone (the message gives
        the loop-transformed system to build instead:
        ``lt = law.loop_transformation()``,
        ``LureSystem(lt.transform_A(A, G, H), G, H, lt.monotone_part, ...)``).

    Notes
    -----
    With ``D + Dᵀ ⪰ 0`` the map ``w ↦ -φ(Hx + Dw)`` is again maximal monotone and the
    implicit Euler step is a uniquely solvable monotone inclusion whenever the step matrix
    ``D_h = h H (I - hθA)^{-1} G + D`` is positive definite, or block triangular (a plant and
    its observer) with positive definite diagonal blocks (checked by the integrator).

    A system whose inputs are an Exosystem, constants or module-level functions can be
    pickled (process pools, Dask); pickling one with a lambda input raises ``ModelError``.

    References
    ----------
    SICONOS D5.3, chapter 8; B. Brogliato, W.P.M.H. Heemels, "Observer design for Lur'e
    systems with multivalued mappings: a passivity approach", IEEE TAC 54(8), 2009.

    Examples
    --------
    Siconos' relay example ``x1' = x2``, ``x2' = w``, ``w ∈ -Sign(x1 + x2)`` reaches the sliding
    surface at ``√3 - 1`` and stays on it (``z`` exactly zero):

    >>> from nscontrol import simulate
    >>> from nscontrol.laws.relay import Relay
    >>> lure = LureSystem([[0, 1], [0, 0]], [[0], [1]], [[1, 1]], Relay(1.0))
    >>> lure.n_states, lure.n_multipliers, lure.has_input
    (2, 1, False)
    >>> tr = simulate(lure, [1.0, 0.0], (0.0, 2.0), h=1e-3)
    >>> k = int(np.argmax(tr.signal("z")[:, 0] == 0.0))
    >>> bool(abs(tr.t[k] - (np.sqrt(3) - 1)) <= 1e-3), bool(np.all(tr.signal("z")[k:] == 0.0))
    (True, True)
    """

    A: FloatArray
    G: FloatArray = None  # type: ignore[assignment]  # None: from a StateSpace A
    H: FloatArray = None  # type: ignore[assignment]
    law: SetValuedLaw = None  # type: ignore[assignment]
    B: FloatArray | None = None
    C: FloatArray = None  # type: ignore[assignment]  # None -> identity at init
    D: FloatArray = None  # type: ignore[assignment]  # None -> zeros at init
    u: InputSignal = None
    g: InputSignal = None
    state_names: tuple[str, ...] = ()
    # u and g as vectorised functions of time (set by __post_init__)
    _u_fn: Callable[[ArrayLike], FloatArray] | None = field(default=None, init=False, repr=False)
    _g_fn: Callable[[ArrayLike], FloatArray] | None = field(default=None, init=False, repr=False)

    default_method = "implicit_euler"

    if TYPE_CHECKING:
        # What the constructor accepts (the dataclass fields hold the validated arrays).
        def __init__(self, A: ArrayLike, G: ArrayLike | None = None,
                     H: ArrayLike | None = None, law: SetValuedLaw | None = None,
                     B: ArrayLike | None = None, C: ArrayLike | None = None,
                     D: ArrayLike | None = None, u: InputSignal = None,
                     g: InputSignal = None,
                     state_names: Sequence[str] = ()) -> None: ...

    def __post_init__(self) -> None:
        if is_state_space(self.A):
            self._split_state_space()
        self._require_channels()
        A = as_square("A", self.A)
        n = A.shape[0]
        G = as_matrix("G", self.G, rows=n)
        m = G.shape[1]
        H = as_matrix("H", self.H, rows=m, cols=n)
        law_dim = getattr(self.law, "dim", None)
        if law_dim is None:
            raise ModelError(f"law: expected a SetValuedLaw from nscontrol.laws, got "
                             f"{type(self.law).__name__}")
        if int(law_dim) != m:
            raise DimensionError(f"law: expected a law of dimension {m} (G has {m} columns), "
                                 f"got dimension {law_dim}")
        self._require_monotone()
        D = np.zeros((m, m)) if self.D is None else as_square("D", self.D, m)
        lam = float(np.linalg.eigvalsh(D + D.T)[0]) if m else 0.0
        if lam < -1e-12 * max(1.0, float(np.max(np.abs(D)))):
            raise ModelError(f"D: expected D + D^T positive semidefinite (so that "
                             f"w ∈ -φ(Hx + Dw) stays monotone), got smallest eigenvalue "
                             f"{lam:.3g}; move the indefinite part of D into the law or A")
        C = np.eye(n) if self.C is None else as_matrix("C", self.C, cols=n)
        B = None
        if self.B is not None:
            B = as_matrix("B", self.B, rows=n)
        if self.u is not None and B is None:
            raise ModelError("u: an input u(t) was given but B is None; pass B (n, q)")
        u_fn = None if B is None else as_input_function("u", self.u, B.shape[1])
        g_fn = as_input_function("g", self.g, m)
        if self.state_names and len(self.state_names) != n:
            raise DimensionError(f"state_names: expected {n} names, got "
                                 f"{len(self.state_names)}")
        for key, value in (("A", A), ("G", G), ("H", H), ("B", B), ("C", C), ("D", D),
                           ("state_names", tuple(self.state_names))):
            object.__setattr__(self, key, value)
        object.__setattr__(self, "_u_fn", u_fn)
        object.__setattr__(self, "_g_fn", g_fn)

    def __getstate__(self) -> dict[str, Any]:
        # the input functions are checked first, so that a lambda input is reported by name
        # with the way out instead of pickle's "Can't pickle local object"
        from .lure import _check_picklable

        _check_picklable(self)
        return dict(self.__dict__)

    def _require_channels(self) -> None:
        """Name the multiplier's channels when ``G`` or ``H`` is missing (the letters differ
        across the literature)."""
        missing = [k for k in ("G", "H") if getattr(self, k) is None]
        if missing:
            raise ModelError(
                f"{', '.join(missing)}: missing; LureSystem needs the multiplier's channels: "
                f"G (n, m), its input channel (x' = A x + G w + B u), and H (m, n), its output "
                f"channel (z = H x + D w feeds the law, w ∈ -φ(z)). Much of the Lur'e "
                f"literature calls them B and C (x' = A x + B w, z = C x); here B is the "
                f"external input's matrix and C the measured output's. A python-control "
                f"StateSpace with inputs [w; u] and outputs [z; y] gives all of them: "
                f"LureSystem(ss, law)")
        if self.law is None:
            raise ModelError("law: missing; pass the maximal monotone law φ of dimension m "
                             "(e.g. nscontrol.laws.Relay(1.0)), w ∈ -φ(z)")

    def _split_state_space(self) -> None:
        """``LureSystem(ss, law)``: inputs ``[w; u]``, outputs ``[z; y]`` of a StateSpace."""
        A, Bs, Cs, Ds = state_space_matrices(self.A, "A")
        if not self.state_names:
            object.__setattr__(self, "state_names", state_space_names(self.A))
        law = self.law
        if law is None and getattr(self.G, "dim", None) is not None:
            law, given = self.G, [k for k in ("H",) if getattr(self, k) is not None]
        else:
            given = [k for k in ("G", "H") if getattr(self, k) is not None]
        if given:
            raise ModelError(f"{', '.join(given)}: a StateSpace already holds the channels "
                             f"(inputs [w; u], outputs [z; y]); pass LureSystem(ss, law) "
                             f"without them")
        m = getattr(law, "dim", None)
        if m is None:
            raise ModelError(f"law: expected a SetValuedLaw from nscontrol.laws, got "
                             f"{type(law).__name__}")
        m = int(m)
        if Bs.shape[1] < m or Cs.shape[0] < m:
            raise DimensionError(f"A: expected a StateSpace with at least {m} inputs (w) and "
                                 f"{m} outputs (z) for a law of dimension {m}, got "
                                 f"{Bs.shape[1]} inputs and {Cs.shape[0]} outputs")
        if np.any(Ds[m:, :]) or np.any(Ds[:m, m:]):
            raise ModelError("A: the StateSpace's feedthrough is only allowed from w to z "
                             "(D[:m, :m]); the measured outputs y = C x and the law's argument "
                             "take no u directly (use the shift g(t) for a known additive term)")
        if self.B is not None or self.C is not None and Cs.shape[0] > m:
            raise ModelError("B, C: a StateSpace already holds the input matrix (its inputs "
                             "after the first m) and the measured output (its outputs after "
                             "the first m); pass them there")
        B = Bs[:, m:] if Bs.shape[1] > m else None
        if B is None and self.u is not None:
            raise ModelError(f"u: the StateSpace has {Bs.shape[1]} inputs, all taken by the "
                             f"law's multipliers w (m = {m}), so there is no input for u; add "
                             f"the u columns after the first {m}, or drop u")
        # a single-output model (only z) measures what C= says, else the whole state as usual
        C = Cs[m:] if Cs.shape[0] > m else self.C
        D = Ds[:m, :m] if np.any(Ds[:m, :m]) else self.D
        for key, value in (("A", A), ("G", Bs[:, :m]), ("H", Cs[:m]), ("law", law), ("B", B),
                           ("C", C), ("D", D)):
            object.__setattr__(self, key, value)

    def _require_monotone(self) -> None:
        from ..laws.base import require_monotone

        try:
            require_monotone(self.law, who="LureSystem")
        except ModelError:
            if getattr(self.law, "monotone", True):
                raise
            raise ModelError(
                f"law: LureSystem requires a maximal monotone law, got the non-monotone "
                f"{self.law!r}. Way out (loop transformation, ch08 §2.6): "
                f"lt = law.loop_transformation(); LureSystem(lt.transform_A(A, G, H), G, H, "
                f"lt.monotone_part, B=B, C=C, u=u, g=g) -- the slope moves into A; valid with "
                f"D = 0 (a feedthrough D changes under the transformation too)") from None

    # -- sizes and signals ---------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Dimension ``n`` of the state ``x``."""
        return int(self.A.shape[0])

    @property
    def n_multipliers(self) -> int:
        """Dimension ``m`` of the multiplier ``w`` (and of the law's argument ``z``)."""
        return int(self.G.shape[1])

    @property
    def n_inputs(self) -> int:
        """Dimension ``q`` of the external input ``u`` (0 without ``B``)."""
        return 0 if self.B is None else int(self.B.shape[1])

    def input_at(self, t: ArrayLike) -> FloatArray:
        """The external input sampled at given times.

        Parameters
        ----------
        t : float or array_like
            Time or times.

        Returns
        -------
        ndarray, shape (len(t), q)
            ``u(t)`` row by row (zeros when the system has no input).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if self._u_fn is None:
            return np.zeros((t.size, self.n_inputs))
        return self._u_fn(t)

    def shift_at(self, t: ArrayLike) -> FloatArray:
        """The known shift ``g`` of the law's argument sampled at given times.

        Parameters
        ----------
        t : float or array_like
            Time or times.

        Returns
        -------
        ndarray, shape (len(t), m)
            ``g(t)`` row by row (zeros when the system has no shift).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if self._g_fn is None:
            return np.zeros((t.size, self.n_multipliers))
        return self._g_fn(t)

    @property
    def has_input(self) -> bool:
        """Whether an external input ``u(t)`` was given."""
        return self._u_fn is not None

    @property
    def has_shift(self) -> bool:
        """Whether a shift ``g(t)`` of the law's argument was given."""
        return self._g_fn is not None

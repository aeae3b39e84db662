"""One composition for every closed loop: ``closed_loop(plant, controller, observer, exosystem)``.

The result is a system every integrator accepts (:func:`nscontrol.simulate` lowers it for the
method at hand) and records the loop's named signals:

* ``"xhat"`` — the observer's estimate, ``"error"`` — ``S x - x̂`` (with an observer);
* ``"u"`` — the controller's output (with a controller);
* the plant's own signals (``"gap"``, ``"impulse"``, ``"z"``, ``"w"``, ``"y"`` ...).

How a loop is run, by what its parts are:

=========================================  ===============================================
parts                                      what the integrator sees
=========================================  ===============================================
linear blocks (:class:`StateFeedback`,     ONE stacked model of the plant's family: a
:class:`LinearController`,                 :class:`LinearHybridSystem` (exact event-driven
:class:`LinearObserver`) around a          flow, compiled event loop when the jumps are
LinearHybridSystem / ImpactingBodies,      matrices), a :class:`LureSystem` (implicit
LureSystem or PiecewiseAffineSystem        Euler's compiled paths, the observer's law
                                           solved with the plant's), a
                                           :class:`PiecewiseAffineSystem`
static state feedback on a linear          the plant's own model with the feedback folded
LagrangianSystem                           into its linear forces (exact event-driven
                                           flow, compiled Moreau–Jean)
any :class:`Controller` / :class:`Observer`  Moreau–Jean on the plant, the blocks stepped at
(Python, sampled or continuous, with       the start of every step (zero-order hold), fed
state) around a LagrangianSystem           the contact multipliers ``λ̂`` and reset at impacts
the same around a LureSystem               implicit Euler on the plant (its set-valued law
                                           solved every step), the blocks stepped at the
                                           start of every step (zero-order hold)
=========================================  ===============================================

Any other combination is refused with a :class:`~nscontrol.errors.ModelError` that says what
would run.

The state of a stacked loop is ``[x; xo; xc]`` (plant, observer, controller); for a loop of
Python blocks the integrator's state is the plant's and the blocks' states are the signals
``"xo"`` and ``"xc"``. :meth:`ClosedLoop.initial_state` builds the right ``x0`` either way.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_matrix,
    as_vector,
    check_bool,
    check_positive,
)
from ..errors import DimensionError, ModelError
from ..systems.feedback import (
    Controller,
    LinearController,
    LinearObserver,
    Observer,
    PiecewiseObserver,
    PiecewiseStateFeedback,
    StateFeedback,
)
from ..systems.protocols import Exogenous, SimulableSystem
from ._block_runner import BlockRunner, CompiledBlocks
from ._block_runner import output_matrix as _output_matrix
from .driver import Integrator, Lowered
from .trajectory import Trajectory

__all__ = ["closed_loop", "ClosedLoop"]


def closed_loop(plant: SimulableSystem, controller: Controller | None = None,
                observer: Observer | None = None, exosystem: Exogenous | None = None, *,
                input_matrix: ArrayLike | None = None,
                output_matrix: ArrayLike | None = None, compiled: bool = True) -> ClosedLoop:
    """Compose a plant with a controller and/or an observer (and an exogenous input).

    Parameters
    ----------
    plant
        A model of :mod:`nscontrol.systems`.
    controller : Controller, optional
        Its output is the plant input ``u`` (see :mod:`nscontrol.systems.feedback`).
    observer : Observer, optional
        Reads the measured output; its estimate feeds ``StateFeedback(on="estimate")``.
    exosystem : Exosystem, optional
        Exogenous input of the plant (its reference or disturbance), for plants that take it
        as an input (Lagrangian systems, impacting bodies).
    input_matrix : array_like (n, m), optional
        How ``u`` enters ``x'`` when the plant does not say (``B`` of a Lur'e system and the
        ``actuation`` of a mechanical system are used by default).
    output_matrix : array_like (p, n), optional
        The measured output ``y = C x`` (default: the plant's ``C``, its ``"y"`` output, or
        the whole state).
    compiled : bool
        Run blocks that offer a compiled form (``compiled()``, see
        :class:`~nscontrol.systems.feedback.CompiledBlock`) in the integrator's compiled loop
        when every block of the loop has one (default); ``False`` runs their Python methods
        (to compare the two, or to debug a block).

    Returns
    -------
    ClosedLoop

    Raises
    ------
    ModelError
        A block that is neither a controller nor an observer; a combination no integrator
        runs (the message says which would).

    Examples
    --------
    A mass on a spring against a wall, with a PD law folded into the model (so the flow
    stays exact between impacts):

    >>> import nscontrol as nsc
    >>> from nscontrol.systems.lagrangian import LagrangianSystem
    >>> from nscontrol.systems.feedback import StateFeedback
    >>> mass = LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0],
    ...                         restitution=0.5, constant_force=[-1.0])
    >>> loop = nsc.closed_loop(mass, StateFeedback([[-4.0, -1.0]], k=[5.0]))
    >>> tr = nsc.simulate(loop, [0.2, 0.0], (0.0, 40.0))
    >>> bool(abs(tr.x[-1, 0] - 1.0) < 1e-6)   # equilibrium 5 - 1 - 4 q = 0; decay e^(-t/2)
    True
    """
    for name, block in (("controller", controller), ("observer", observer)):
        if block is not None and not all(hasattr(block, a) for a in
                                         ("n_states", "output", "update", "reset")):
            raise ModelError(f"{name}: expected a block with n_states, output(t, xc, m), "
                             f"update(t, xc, m) and reset(t, xc, jump) (see "
                             f"nscontrol.systems.feedback), got {type(block).__name__}")
    if observer is not None and isinstance(observer, StateFeedback | LinearController):
        raise ModelError("observer: a StateFeedback/LinearController outputs an input, not an "
                         "estimate; pass it as controller=")
    for name, block in (("controller", controller), ("observer", observer)):
        period = getattr(block, "period", None)
        if block is not None and period is not None:   # a sampled block's own period
            check_positive(f"{name}.period", period,
                           hint="a block's period is None (continuous-time) or its sampling "
                                "period T > 0")
    compiled = check_bool("compiled", compiled)
    return ClosedLoop(plant, controller, observer, exosystem, input_matrix, output_matrix,
                      compiled)


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """A plant with its controller, observer and exogenous input (see :func:`closed_loop`)."""

    plant: Any
    controller: Any = None
    observer: Any = None
    exosystem: Any = None
    input_matrix: Any = None
    output_matrix: Any = None
    compiled: bool = True
    _stacked: Any = field(default=None, init=False, repr=False)
    _maps: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict, init=False,
                                                            repr=False)

    def __post_init__(self) -> None:
        stacked = _stack(self)
        model, maps = stacked if stacked is not None else (None, {})
        object.__setattr__(self, "_stacked", model)
        object.__setattr__(self, "_maps", maps)

    # -- what the loop is -------------------------------------------------------------------
    @property
    def stacked(self) -> Any:
        """The one model the loop is (plant, observer and controller stacked), or ``None``
        when its blocks run as Python code beside the plant."""
        return self._stacked

    @property
    def default_method(self) -> str:
        from ..systems.lure import LureSystem
        from ..systems.sliding_mode import SlidingModePlant

        if self._stacked is not None:
            return str(self._stacked.default_method)
        if isinstance(self.plant, SlidingModePlant):
            return "sampled_zoh"
        return "implicit_euler" if isinstance(self.plant, LureSystem) else "moreau_jean"

    @property
    def n_states(self) -> int:
        """Length of the ``x0`` :func:`simulate` takes: the stacked state, or the plant's."""
        if self._stacked is not None:
            return int(self._stacked.n_states)
        return int(self.plant.n_states)

    @property
    def state_names(self) -> tuple[str, ...]:
        system = self._stacked if self._stacked is not None else self.plant
        return tuple(getattr(system, "state_names", ()))

    def initial_state(self, plant: Any, observer: Any = None, controller: Any = None
                      ) -> FloatArray:
        """``x0`` for :func:`simulate`: the plant's initial state and the blocks' (zeros by
        default), stacked when the loop is one model.

        Raises
        ------
        DimensionError
            A part of the wrong length.
        """
        xp = as_vector("plant", plant, int(self._plant_model().n_states))
        parts = [xp]
        for name, block, value in (("observer", self.observer, observer),
                                   ("controller", self.controller, controller)):
            if block is None:
                continue
            parts.append(np.zeros(block.n_states) if value is None else
                         as_vector(name, value, block.n_states))
        if self._stacked is None:
            if any(p.size for p in parts[1:]):
                raise ModelError("initial_state: this loop runs its blocks in Python; give "
                                 "their initial states to the blocks themselves (x0 is the "
                                 "plant's)")
            return xp
        return np.concatenate(parts)

    def _plant_model(self) -> Any:
        """The plant as the stacked model sees it (an exosystem appended for mechanics)."""
        from ..systems.impacting_bodies import ImpactingBodies

        if isinstance(self.plant, ImpactingBodies) and self._needs_hybrid():
            return self.plant.hybrid(self.exosystem)
        return self.plant

    def _needs_hybrid(self) -> bool:
        return self.observer is not None or isinstance(self.controller, LinearController)

    # -- what an integrator gets ---------------------------------------------------------------
    def lower(self, method: type[Integrator], x0: Any) -> Lowered:
        """The system ``method`` integrates, its initial state, options and signals."""
        if self._stacked is not None:
            if not method.supports(self._stacked):
                raise ModelError(f"{method.name}: this loop is one "
                                 f"{type(self._stacked).__name__}, which {method.name} does "
                                 f"not integrate; use method={self._stacked.default_method!r}")
            options = {"u": self.exosystem} if self.exosystem is not None else {}
            return Lowered(self._stacked, x0, options, _signals_of_stack(self))
        return _lower_python_blocks(self, method, x0)


# -- stacking linear blocks -------------------------------------------------------------------
def _stack(loop: ClosedLoop) -> Any:
    """The loop as one model of the plant's family, or ``None`` (blocks run in Python)."""
    from ..systems.hybrid import LinearHybridSystem
    from ..systems.impacting_bodies import ImpactingBodies
    from ..systems.lagrangian import LagrangianSystem
    from ..systems.lure import LureSystem
    from ..systems.pwa import PiecewiseAffineSystem
    from ..systems.sliding_mode import SlidingModePlant

    plant, ctrl, obs = loop.plant, loop.controller, loop.observer
    linear_blocks = (_is_linear_block(ctrl, "controller") and
                     _is_linear_block(obs, "observer"))
    if isinstance(plant, PiecewiseAffineSystem):
        return _stack_pwa(loop) if linear_blocks else _refuse(loop)
    if isinstance(plant, LureSystem):
        return _stack_lure(loop) if linear_blocks else None   # Python blocks: implicit Euler
    if isinstance(plant, LinearHybridSystem) or (
            isinstance(plant, ImpactingBodies) and loop._needs_hybrid()):
        return _stack_hybrid(loop) if linear_blocks else _refuse(loop)
    if isinstance(plant, LagrangianSystem) and obs is None and \
            isinstance(ctrl, StateFeedback) and ctrl.on == "state" and \
            ctrl.period is None and plant.is_linear:
        return _fold_state_feedback(plant, ctrl, loop.input_matrix)
    if isinstance(plant, LagrangianSystem | ImpactingBodies | SlidingModePlant):
        return None             # Python blocks beside the plant (or the loop itself: sampled_zoh)
    raise ModelError(f"plant: closed_loop composes LagrangianSystem, ImpactingBodies, "
                     f"LinearHybridSystem, LureSystem, PiecewiseAffineSystem and "
                     f"SlidingModePlant plants, got "
                     f"{type(plant).__name__}")


def _is_linear_block(block: Any, role: str) -> bool:
    if block is None:
        return True
    if role == "controller" and isinstance(block, StateFeedback | PiecewiseStateFeedback |
                                           LinearController):
        return block.period is None
    return role == "observer" and isinstance(block, LinearObserver | PiecewiseObserver)


def _refuse(loop: ClosedLoop) -> Any:
    raise ModelError(f"closed_loop: a {type(loop.plant).__name__} plant runs with blocks given "
                     f"as matrices (StateFeedback, PiecewiseStateFeedback, continuous "
                     f"LinearController, LinearObserver), stacked into one model; blocks "
                     f"written as Python code (or sampled) run around LagrangianSystem and "
                     f"ImpactingBodies plants with method='moreau_jean' and around "
                     f"LureSystem plants with method='implicit_euler'")


def _input_matrix(loop: ClosedLoop, default: Any, n: int) -> FloatArray:
    B = loop.input_matrix if loop.input_matrix is not None else default
    if B is None:
        raise ModelError(f"input_matrix: the plant does not say how u enters x'; pass "
                         f"closed_loop(..., input_matrix=B) with B of shape ({n}, m)")
    return as_matrix("input_matrix", B, rows=n)


@dataclass(frozen=True)
class _Interconnection:
    """``z = [x; xo; xc]``: the flow's linear part and the maps of the loop's signals."""

    A: FloatArray        # z' = A z (+ the plant's own affine and set-valued terms)
    U: FloatArray        # u = U z + u0 (the controller's output; (0, N) without one)
    u0: FloatArray
    Xhat: FloatArray     # x̂ = Xhat z
    Err: FloatArray      # error = Err z
    Cy: FloatArray       # y = Cy x (plant coordinates)
    n: int
    r: int
    c: int


def _interconnect(loop: ClosedLoop, A: FloatArray, B: FloatArray | None, Cy: FloatArray,
                  Bknown: FloatArray | None = None) -> _Interconnection:
    """The stacked linear flow of plant ``x' = A x + B u``, observer and controller.

    ``Bknown`` maps the plant state to a known input the observer reads through its ``B``
    (an exosystem embedded in the plant state).
    """
    ctrl, obs = loop.controller, loop.observer
    n = A.shape[0]
    r = 0 if obs is None else obs.n_states
    c = 0 if ctrl is None else ctrl.n_states
    N = n + r + c
    Px = np.hstack([np.eye(n), np.zeros((n, r + c))])
    Po = np.hstack([np.zeros((r, n)), np.eye(r), np.zeros((r, c))])
    Pc = np.hstack([np.zeros((c, n + r)), np.eye(c)])
    Xhat = obs.E @ Po if obs is not None else np.zeros((0, N))
    U, u0 = _controller_maps(ctrl, Px, Xhat, Pc, Cy)
    Z = np.zeros((N, N))
    Z[:n] = A @ Px
    if U.shape[0]:
        if B is None:   # a controller drives the plant through its input matrix
            raise ModelError("input_matrix: the plant declares no input matrix for the "
                             "controller's output; pass input_matrix= to closed_loop")
        Z[:n] += B @ U
    if obs is not None:
        flow = obs.F @ Po + obs.L @ Cy @ Px
        if obs.B is not None:
            known = (Bknown @ Px) if Bknown is not None else np.zeros((obs.B.shape[1], N))
            if U.shape[0]:
                if U.shape[0] != obs.B.shape[1]:
                    raise DimensionError(f"observer: its B reads {obs.B.shape[1]} input(s), "
                                         f"the controller outputs {U.shape[0]}")
                known = known + U
            flow = flow + obs.B @ known
        Z[n:n + r] = flow
    if isinstance(ctrl, LinearController):
        Z[n + r:] = ctrl.A @ Pc + ctrl.B @ Cy @ Px
    S = obs.estimates if obs is not None and obs.estimates is not None else \
        (np.eye(n)[: Xhat.shape[0]] if obs is not None else np.zeros((0, n)))
    if obs is not None and S.shape != (Xhat.shape[0], n):
        raise DimensionError(f"observer: estimates must have shape ({Xhat.shape[0]}, {n}), "
                             f"got {S.shape}")
    Err = S @ Px - Xhat if obs is not None else np.zeros((0, N))
    return _Interconnection(Z, U, u0, Xhat, Err, Cy, n, r, c)


def _controller_maps(ctrl: Any, Px: FloatArray, Xhat: FloatArray, Pc: FloatArray,
                     Cy: FloatArray) -> tuple[FloatArray, FloatArray]:
    N = Px.shape[1]
    if ctrl is None:
        return np.zeros((0, N)), np.zeros(0)
    if isinstance(ctrl, LinearController):
        return ctrl.C @ Pc + ctrl.D @ Cy @ Px, np.zeros(ctrl.n_outputs)
    if isinstance(ctrl, StateFeedback):
        if ctrl.on == "estimate":
            if Xhat.shape[0] == 0:
                raise ModelError("controller: StateFeedback(on='estimate') needs an observer")
            if ctrl.K.shape[1] != Xhat.shape[0]:
                raise DimensionError(f"controller: K has {ctrl.K.shape[1]} columns, the "
                                     f"estimate {Xhat.shape[0]} entries")
            return ctrl.K @ Xhat, ctrl.k
        if ctrl.K.shape[1] != Px.shape[0]:
            raise DimensionError(f"controller: K has {ctrl.K.shape[1]} columns, the plant "
                                 f"{Px.shape[0]} states")
        return ctrl.K @ Px, ctrl.k
    raise ModelError(f"controller: {type(ctrl).__name__} is stacked only into a "
                     f"PiecewiseAffineSystem")


def _stack_hybrid(loop: ClosedLoop) -> Any:
    from ..systems.hybrid import LinearHybridSystem

    p = loop._plant_model()
    n = p.n_states
    if loop.controller is not None and getattr(loop.controller, "k", None) is not None \
            and np.any(loop.controller.k):
        raise ModelError("controller: a constant offset k on a LinearHybridSystem plant needs a "
                         "constant state; append it to the plant (x' = 0, x = 1) and put k "
                         "into K")
    B = _input_matrix(loop, None, n) if loop.controller is not None else None
    Cy = _output_matrix(loop, p.outputs.get("y"), n)
    net = _interconnect(loop, p.A, B, Cy, p.outputs.get("u"))
    N = net.A.shape[0]
    G = np.hstack([p.G, np.zeros((p.G.shape[0], N - n))])
    jump = _stacked_jump(p, loop.observer, net)
    outputs = {k: np.hstack([v, np.zeros((v.shape[0], N - n))]) for k, v in p.outputs.items()}
    if loop.observer is not None:
        outputs.update({"xhat": net.Xhat, "error": net.Err})
    return LinearHybridSystem(net.A, G, p.g0, jump, state_names=_names(loop, p),
                              outputs=outputs), _maps(loop, net)


def _stacked_jump(p: Any, obs: Any, net: _Interconnection) -> Any:
    """The plant's jump, the observer's reset ``xo⁺ = J_o xo + J_y y⁻``, the controller's
    state kept: as matrices when the plant's are (the compiled event loop)."""
    n, r, c = net.n, net.r, net.c
    N = n + r + c

    def block(Jp: FloatArray) -> FloatArray:
        J = np.eye(N)
        J[:n, :n] = Jp
        if obs is not None and obs.jump is not None:
            Jo, Jy = obs.jump
            J[n:n + r, :n] = Jy @ net.Cy
            J[n:n + r, n:n + r] = Jo
        return J

    if p.jump_matrices is not None:
        return np.stack([block(Jp) for Jp in p.jump_matrices])

    def jump(t: float, z: FloatArray, indices: np.ndarray) -> FloatArray:
        out = block(np.eye(n)) @ z
        out[:n] = p.apply_jump(t, z[:n], indices)
        return out
    return jump


def _stack_lure(loop: ClosedLoop) -> Any:
    from ..laws.set_valued import Product
    from ..systems.lure import LureSystem

    p, obs = loop.plant, loop.observer
    n = p.n_states
    if loop.controller is not None and np.any(getattr(loop.controller, "k", 0.0)):
        raise ModelError("controller: a constant offset k on a Lur'e plant enters as an input; "
                         "put it into the plant's u(t)")
    B = _input_matrix(loop, p.B, n) if loop.controller is not None else None
    Cy = _output_matrix(loop, p.C, n)
    net = _interconnect(loop, p.A, B, Cy)
    r, c = net.r, net.c
    mw = p.G.shape[1]
    pad = np.zeros
    if obs is not None and obs.law is not None:
        G = np.block([[p.G, pad((n, obs.G.shape[1]))], [pad((r, mw)), obs.G],
                      [pad((c, mw + obs.G.shape[1]))]])
        H = np.block([[p.H, pad((mw, r + c))],
                      [obs.K @ Cy, obs.H, pad((obs.H.shape[0], c))]])
        D = np.block([[p.D, pad((mw, obs.D.shape[0]))], [pad((obs.D.shape[0], mw)), obs.D]])
        law = Product(p.law, obs.law)
        g = _stacked_shift(p, 2) if p.has_shift else None
    else:
        G = np.vstack([p.G, pad((r + c, mw))])
        H = np.hstack([p.H, pad((mw, r + c))])
        D, law = p.D, p.law
        g = p.g
    Bu = u = None
    if getattr(p, "B", None) is not None:
        from ..numerics.lti import Exosystem

        Bo = obs.B if obs is not None and obs.B is not None else pad((r, p.B.shape[1]))
        Bu = np.vstack([p.B, Bo, pad((c, p.B.shape[1]))])
        # an exosystem input is passed as such: implicit Euler integrates its exact step mean
        u = (p.u if isinstance(p.u, Exosystem) else p.input_at if p.has_input else None)
    C = net.Err if obs is not None else np.hstack([p.C, pad((p.C.shape[0], r + c))])
    return LureSystem(net.A, G, H, law, B=Bu, C=C, D=D, u=u, g=g,
                      state_names=_names(loop, p)), _maps(loop, net)


def _stacked_shift(p: Any, copies: int) -> Callable[[Any], FloatArray]:
    def g(t: Any) -> FloatArray:
        s = p.shift_at(t)
        return np.hstack([s] * copies)
    return g


def _stack_pwa(loop: ClosedLoop) -> Any:
    p, ctrl, obs = loop.plant, loop.controller, loop.observer
    if obs is not None and not isinstance(obs, PiecewiseObserver):
        raise ModelError("observer: a PWA plant takes a PiecewiseObserver (a copy of the plant "
                         "with output injection)")
    if ctrl is None and obs is None:
        return p, {}
    n, N = p.n_states, len(p.A)
    B = _input_matrix(loop, None, n) if ctrl is not None else np.zeros((n, 1))
    Ks, ks, on = _pwa_gains(ctrl, N, B, n)
    if obs is None:
        if on == "estimate":
            raise ModelError("controller: feedback on the estimate needs an observer")
        maps = {"u": (ctrl.K, ctrl.k)} if isinstance(ctrl, StateFeedback) else {}
        # a law declared discontinuous makes the loop discontinuous whatever the plant
        jumps = isinstance(ctrl, PiecewiseStateFeedback) and ctrl.discontinuous
        return replace(p, A=tuple(A + B @ K for A, K in zip(p.A, Ks, strict=True)),
                       b=tuple(b + B @ k for b, k in zip(p.b, ks, strict=True)),
                       continuous=p.continuous and not jumps), maps
    return _stack_pwa_observer(p, obs, B, Ks, ks, on)


def _pwa_gains(ctrl: Any, N: int, B: FloatArray, n: int
               ) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...], str]:
    """Per-region gains of the controller (zeros without one) and what they read."""
    if ctrl is None:
        return (np.zeros((1, n)),) * N, (np.zeros(1),) * N, "state"
    if isinstance(ctrl, PiecewiseStateFeedback):
        if len(ctrl.K) != N:
            raise DimensionError(f"controller: {len(ctrl.K)} region gains for a plant with "
                                 f"{N} regions")
        Ks, ks, on = tuple(ctrl.K), tuple(ctrl.k), ctrl.on
    elif isinstance(ctrl, StateFeedback):
        Ks, ks, on = (ctrl.K,) * N, (ctrl.k,) * N, ctrl.on
    else:
        raise ModelError("controller: a PWA plant takes StateFeedback or "
                         "PiecewiseStateFeedback")
    for i, Ki in enumerate(Ks):
        if Ki.shape != (B.shape[1], n):
            raise DimensionError(f"controller: K[{i}] must have shape ({B.shape[1]}, {n}), "
                                 f"got {Ki.shape}")
    return Ks, ks, on


def _stack_pwa_observer(p: Any, obs: PiecewiseObserver, B: FloatArray,
                        Ks: tuple[FloatArray, ...], ks: tuple[FloatArray, ...], on: str) -> Any:
    """Plant and observer on the product of their regions: in region ``(i, j)`` (plant in
    ``i``, estimate in ``j``) the feedback acts by the region of what it reads::

        x'  = A_i x + b_i + B u + E w,           u = K_r (x or x̂) + k_r
        x̂' = A_j x̂ + b_j + B u + E w + L C (x - x̂)
    """
    from ..systems.pwa import PiecewiseAffineSystem

    n, N = p.n_states, len(p.A)
    if obs.n_states != n or obs.C.shape[1] != n:
        raise DimensionError(f"observer: L must have {n} rows and C {n} columns (the plant's "
                             f"states), got L {obs.L.shape}, C {obs.C.shape}")
    LC = obs.L @ obs.C
    zero = np.zeros((n, n))
    As, bs, regions = [], [], []
    for i in range(N):
        Hi, hi = p.regions[i]
        for j in range(N):
            Hj, hj = p.regions[j]
            r = j if on == "estimate" else i
            BK = B @ Ks[r]
            Kx, Kh = (zero, BK) if on == "estimate" else (BK, zero)
            As.append(np.block([[p.A[i] + Kx, Kh], [LC + Kx, p.A[j] + Kh - LC]]))
            bs.append(np.concatenate([p.b[i] + B @ ks[r], p.b[j] + B @ ks[r]]))
            regions.append((np.block([[Hi, np.zeros_like(Hi)], [np.zeros_like(Hj), Hj]]),
                            np.concatenate([hi, hj])))
    E = None if p.E is None else np.vstack([p.E, p.E])
    stacked = PiecewiseAffineSystem(A=tuple(As), b=tuple(bs), regions=tuple(regions), E=E,
                                    u=p.u, C=np.hstack([np.eye(n), zero]), continuous=True)
    eye = np.eye(n)
    return stacked, {"xhat": (np.hstack([zero, eye]), np.zeros(n)),
                     "error": (np.hstack([eye, -eye]), np.zeros(n))}


def _fold_state_feedback(plant: Any, ctrl: StateFeedback, input_matrix: Any) -> Any:
    """``u = K [q; v] + k`` on a linear Lagrangian plant is a linear force: fold it into the
    model (stiffness ``- S K_q``, damping ``- S K_v``, constant force ``+ S k``) so the flow
    stays exact event-driven and compiled in Moreau–Jean."""
    n = plant.n_dof
    S = (np.eye(n) if plant.actuation is None else plant.actuation) if input_matrix is None \
        else as_matrix("input_matrix", input_matrix, rows=n)
    if ctrl.K.shape != (S.shape[1], 2 * n):
        raise DimensionError(f"controller: K must have shape ({S.shape[1]}, {2 * n}) (inputs "
                             f"x [q; v]), got {ctrl.K.shape}")
    Kq, Kv = ctrl.K[:, :n], ctrl.K[:, n:]
    zero = np.zeros((n, n))
    K = (plant.stiffness if plant.stiffness is not None else zero) - S @ Kq
    D = (plant.damping if plant.damping is not None else zero) - S @ Kv
    f0 = (plant.constant_force if plant.constant_force is not None else np.zeros(n)) \
        + S @ ctrl.k
    return (replace(plant, stiffness=K, damping=D, constant_force=f0),
            {"u": (ctrl.K, ctrl.k)})


def _names(loop: ClosedLoop, p: Any) -> tuple[str, ...]:
    names = tuple(getattr(p, "state_names", ()))
    if not names:
        return ()
    obs, ctrl = loop.observer, loop.controller
    if obs is not None:
        names += tuple(obs.names) if obs.names else tuple(f"xo{i + 1}"
                                                          for i in range(obs.n_states))
    if ctrl is not None:
        names += tuple(f"xc{i + 1}" for i in range(ctrl.n_states))
    return names


def _maps(loop: ClosedLoop, net: _Interconnection) -> dict[str, tuple[FloatArray, FloatArray]]:
    """The loop's signals as affine maps of the stacked state."""
    maps = {}
    if loop.controller is not None:
        maps["u"] = (net.U, net.u0)
    if loop.observer is not None:
        zero = np.zeros(net.Xhat.shape[0])
        maps.update({"xhat": (net.Xhat, zero), "error": (net.Err, zero)})
    return maps


def _signals_of_stack(loop: ClosedLoop) -> Callable[[Trajectory], Trajectory]:
    """Adds the loop's signals (``u``, ``xhat``, ``error``) computed from the stacked state;
    a plant input already named ``u`` (an exosystem's) is kept as ``u_exo``."""
    from ..systems.lagrangian import LagrangianSystem

    def finish(traj: Trajectory) -> Trajectory:
        signals = dict(traj.signals)
        if "u" in loop._maps and "u" in signals:
            signals["u_exo"] = signals.pop("u")
        for name, (M, offset) in loop._maps.items():
            if name not in signals:
                signals[name] = traj.x @ M.T + offset
        if isinstance(loop.plant, LagrangianSystem) and "energy" in signals:
            signals["energy"] = loop.plant.energy(traj.x)  # the plant's, not the folded model's
        return replace(traj, signals=signals)
    return finish


# -- Python blocks beside a mechanical plant (Moreau–Jean) -----------------------------------
def _lower_python_blocks(loop: ClosedLoop, method: type[Integrator], x0: Any) -> Lowered:
    from ..systems.lure import LureSystem
    from ..systems.sliding_mode import SlidingModePlant

    if isinstance(loop.plant, LureSystem):
        return _lower_python_blocks_lure(loop, method, x0)
    if isinstance(loop.plant, SlidingModePlant):
        raise ModelError(f"{method.name}: a {type(loop.plant).__name__} plant runs with its "
                         f"sampled controller by method='sampled_zoh'")
    if method.name != "moreau_jean":
        raise ModelError(f"{method.name}: this loop's blocks run as Python code stepped with "
                         f"the plant; use method='moreau_jean' (or give the blocks as "
                         f"matrices: StateFeedback, LinearController, LinearObserver)")
    runner = BlockRunner(loop)
    options: dict[str, Any] = {"controller": runner.step, "listeners": [runner.on_jump]}
    if loop.exosystem is not None:
        options["u"] = loop.exosystem
    compiled = CompiledBlocks.of(runner)
    if compiled is not None:       # used when the plant has a compiled model too
        options["compiled_blocks"] = compiled
    return Lowered(loop.plant, x0, options, runner.finish)


def _lower_python_blocks_lure(loop: ClosedLoop, method: type[Integrator], x0: Any
                              ) -> Lowered:
    """Python blocks around a Lur'e plant: implicit Euler with ``controller=`` (ZOH)."""
    if method.name != "implicit_euler":
        raise ModelError(f"{method.name}: this loop's blocks run as Python code stepped with "
                         f"a LureSystem plant; use method='implicit_euler'")
    if loop.exosystem is not None:
        raise ModelError("exosystem: a Lur'e plant with Python blocks takes its reference "
                         "through the blocks themselves (the plant's input is the controller's "
                         "output)")
    runner = BlockRunner(loop)
    options: dict[str, Any] = {"controller": runner.step_state}
    compiled = CompiledBlocks.of(runner)
    if compiled is not None:
        options["compiled_blocks"] = compiled
    return Lowered(loop.plant, x0, options, runner.finish)

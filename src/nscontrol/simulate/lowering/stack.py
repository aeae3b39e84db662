"""Linear blocks around a linear plant, stacked exactly into ONE model of the plant's family.

A :class:`~nscontrol.systems.closed_loop.ClosedLoop` of composition ``"stacked"`` —
:class:`StateFeedback`, :class:`PiecewiseStateFeedback`, continuous :class:`LinearController`,
:class:`LinearObserver`, :class:`PiecewiseObserver` around a :class:`LinearHybridSystem`
(:class:`ImpactingBodies` through its hybrid form), a :class:`LureSystem` or a
:class:`PiecewiseAffineSystem` — becomes one model of ``z = [x; xo; xc]`` (plant, observer,
controller): exact event-driven flows and the compiled event loop (jumps as matrices),
implicit Euler's compiled paths with the observer's law solved with the plant's, the PWA
flows. The loop's signals ``u``, ``xhat``, ``error`` are affine maps of ``z``, added to the
trajectory by :meth:`StackLinearBlocks.invert`.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..._validation import FloatArray
from ...errors import DimensionError, ModelError
from ...systems.closed_loop import ClosedLoop
from ...systems.feedback import LinearController, StateFeedback
from .._block_runner import output_matrix
from ._signals import Maps, add_loop_signals, input_matrix
from .base import Lowered, Lowering, merge_options

if TYPE_CHECKING:
    from ..trajectory import Trajectory

__all__ = ["StackLinearBlocks", "stacked_model"]

#: The loop's signals as affine maps ``name -> (M, offset)`` of the stacked state.

#: One stacking per loop (a loop is immutable): loop -> (stacked model, maps).
_STACKS: weakref.WeakKeyDictionary[ClosedLoop, tuple[Any, Maps]] = \
    weakref.WeakKeyDictionary()


class StackLinearBlocks(Lowering):
    """A ``"stacked"`` closed loop as the one model it is (see the module docstring)."""

    name = "stack linear blocks"

    def accepts(self, system: Any, method: Any) -> bool:
        return isinstance(system, ClosedLoop) and system.composition == "stacked"

    def apply(self, system: Any, method: Any, x0: Any, options: Mapping[str, Any]
              ) -> Lowered:
        model, maps = _stacked(system)
        own = {"u": system.exosystem} if system.exosystem is not None else {}
        return Lowered(model, x0, merge_options(options, own), (system, maps))

    def invert(self, traj: Trajectory, lowered: Lowered) -> Trajectory:
        loop, maps = lowered.data
        return add_loop_signals(traj, maps, loop.plant)


def stacked_model(loop: ClosedLoop) -> Any:
    """The one model a closed loop is (plant, observer and controller stacked), or ``None``
    when it is not stacked (its blocks run beside the plant, or feedback folded into it).

    Parameters
    ----------
    loop : ClosedLoop
        From :func:`nscontrol.closed_loop`.

    Returns
    -------
    LinearHybridSystem, LureSystem, PiecewiseAffineSystem or None

    Raises
    ------
    ModelError, DimensionError
        Blocks and plant that do not fit together (the message names the part).
    """
    if loop.composition == "folded":
        from .fold import folded_plant

        return folded_plant(loop)[0]
    if loop.composition != "stacked":
        return None
    return _stacked(loop)[0]


def _stacked(loop: ClosedLoop) -> tuple[Any, Maps]:
    if loop not in _STACKS:
        _STACKS[loop] = _stack(loop)
    return _STACKS[loop]


def _stack(loop: ClosedLoop) -> tuple[Any, Maps]:
    from ...systems.lure import LureSystem
    from ...systems.pwa import PiecewiseAffineSystem

    if isinstance(loop.plant, PiecewiseAffineSystem):
        from ._pwa_stack import stack_pwa

        return stack_pwa(loop)
    if isinstance(loop.plant, LureSystem):
        return _stack_lure(loop)
    return _stack_hybrid(loop)


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
        Z[n:n + r] = _observer_flow(obs, Po, Px, Cy, U, Bknown, N)
    if isinstance(ctrl, LinearController):
        Z[n + r:] = ctrl.A @ Pc + ctrl.B @ Cy @ Px
    S = obs.estimates if obs is not None and obs.estimates is not None else \
        (np.eye(n)[: Xhat.shape[0]] if obs is not None else np.zeros((0, n)))
    if obs is not None and S.shape != (Xhat.shape[0], n):
        raise DimensionError(f"observer: estimates must have shape ({Xhat.shape[0]}, {n}), "
                             f"got {S.shape}")
    Err = S @ Px - Xhat if obs is not None else np.zeros((0, N))
    return _Interconnection(Z, U, u0, Xhat, Err, Cy, n, r, c)


def _observer_flow(obs: Any, Po: FloatArray, Px: FloatArray, Cy: FloatArray, U: FloatArray,
                   Bknown: FloatArray | None, N: int) -> FloatArray:
    """``xo' = F xo + L y + B (known input)``, as rows of the stacked flow."""
    flow = obs.F @ Po + obs.L @ Cy @ Px
    if obs.B is not None:
        known = (Bknown @ Px) if Bknown is not None else np.zeros((obs.B.shape[1], N))
        if U.shape[0]:
            if U.shape[0] != obs.B.shape[1]:
                raise DimensionError(f"observer: its B reads {obs.B.shape[1]} input(s), "
                                     f"the controller outputs {U.shape[0]}")
            known = known + U
        flow = flow + obs.B @ known
    return flow


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


def _stack_hybrid(loop: ClosedLoop) -> tuple[Any, Maps]:
    from ...systems.hybrid import LinearHybridSystem

    p = loop.plant_model
    n = p.n_states
    if loop.controller is not None and getattr(loop.controller, "k", None) is not None \
            and np.any(loop.controller.k):
        raise ModelError("controller: a constant offset k on a LinearHybridSystem plant needs a "
                         "constant state; append it to the plant (x' = 0, x = 1) and put k "
                         "into K")
    B = input_matrix(loop, None, n) if loop.controller is not None else None
    Cy = output_matrix(loop, p.outputs.get("y"), n)
    net = _interconnect(loop, p.A, B, Cy, p.outputs.get("u"))
    N = net.A.shape[0]
    G = np.hstack([p.G, np.zeros((p.G.shape[0], N - n))])
    jump = _stacked_jump(p, loop.observer, net)
    outputs = {k: np.hstack([v, np.zeros((v.shape[0], N - n))]) for k, v in p.outputs.items()}
    if loop.observer is not None:
        outputs.update({"xhat": net.Xhat, "error": net.Err})
    return LinearHybridSystem(net.A, G, p.g0, jump, state_names=loop.state_names,
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


def _stack_lure(loop: ClosedLoop) -> tuple[Any, Maps]:
    from ...systems.lure import LureSystem

    p = loop.plant
    n = p.n_states
    if loop.controller is not None and np.any(getattr(loop.controller, "k", 0.0)):
        raise ModelError("controller: a constant offset k on a Lur'e plant enters as an input; "
                         "put it into the plant's u(t)")
    B = input_matrix(loop, p.B, n) if loop.controller is not None else None
    Cy = output_matrix(loop, p.C, n)
    net = _interconnect(loop, p.A, B, Cy)
    G, H, D, law, g = _lure_constraints(p, loop.observer, net)
    Bu = u = None
    if getattr(p, "B", None) is not None:
        from ...numerics.lti import Exosystem

        obs, r, c = loop.observer, net.r, net.c
        Bo = obs.B if obs is not None and obs.B is not None else np.zeros((r, p.B.shape[1]))
        Bu = np.vstack([p.B, Bo, np.zeros((c, p.B.shape[1]))])
        # an exosystem input is passed as such: implicit Euler integrates its exact step mean
        u = (p.u if isinstance(p.u, Exosystem) else p.input_at if p.has_input else None)
    C = net.Err if loop.observer is not None else \
        np.hstack([p.C, np.zeros((p.C.shape[0], net.r + net.c))])
    maps = _maps(loop, net)
    if loop.observer is not None:   # the stacked output is the error: y is the plant's Cy x
        maps["y"] = (np.hstack([Cy, np.zeros((Cy.shape[0], net.r + net.c))]),
                     np.zeros(Cy.shape[0]))
    return LureSystem(net.A, G, H, law, B=Bu, C=C, D=D, u=u, g=g,
                      state_names=loop.state_names), maps


def _lure_constraints(p: Any, obs: Any, net: _Interconnection) -> tuple[Any, ...]:
    """``G, H, D, law, g`` of the stacked Lur'e system: the plant's, and the observer's
    set-valued law beside it when it has one (solved together, one inclusion a step)."""
    from ...laws.set_valued import Product

    n, r, c = net.n, net.r, net.c
    mw = p.G.shape[1]
    pad = np.zeros
    if obs is not None and obs.law is not None:
        G = np.block([[p.G, pad((n, obs.G.shape[1]))], [pad((r, mw)), obs.G],
                      [pad((c, mw + obs.G.shape[1]))]])
        H = np.block([[p.H, pad((mw, r + c))],
                      [obs.K @ net.Cy, obs.H, pad((obs.H.shape[0], c))]])
        D = np.block([[p.D, pad((mw, obs.D.shape[0]))], [pad((obs.D.shape[0], mw)), obs.D]])
        return G, H, D, Product(p.law, obs.law), (_stacked_shift(p, 2) if p.has_shift
                                                  else None)
    return (np.vstack([p.G, pad((r + c, mw))]), np.hstack([p.H, pad((mw, r + c))]), p.D,
            p.law, p.g)


def _stacked_shift(p: Any, copies: int) -> Callable[[Any], FloatArray]:
    def g(t: Any) -> FloatArray:
        s = p.shift_at(t)
        return np.hstack([s] * copies)
    return g


def _maps(loop: ClosedLoop, net: _Interconnection) -> Maps:
    """The loop's signals as affine maps of the stacked state."""
    maps = {}
    if loop.controller is not None:
        maps["u"] = (net.U, net.u0)
    if loop.observer is not None:
        zero = np.zeros(net.Xhat.shape[0])
        maps.update({"xhat": (net.Xhat, zero), "error": (net.Err, zero)})
    return maps

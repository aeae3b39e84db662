"""The stack of a piecewise-affine plant with state feedback and a :class:`PiecewiseObserver`
(part of the ``stack linear blocks`` lowering, :mod:`.stack`)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import DimensionError, ModelError
from ...systems.closed_loop import ClosedLoop
from ...systems.feedback import PiecewiseObserver, PiecewiseStateFeedback, StateFeedback
from ._signals import Maps, input_matrix

__all__ = ["stack_pwa"]


def stack_pwa(loop: ClosedLoop) -> tuple[Any, Maps]:
    """The loop of a :class:`PiecewiseAffineSystem` plant as one such system, and the maps
    of its signals."""
    p, ctrl, obs = loop.plant, loop.controller, loop.observer
    if obs is not None and not isinstance(obs, PiecewiseObserver):
        raise ModelError("observer: a PWA plant takes a PiecewiseObserver (a copy of the plant "
                         "with output injection)")
    if ctrl is None and obs is None:
        return p, {}
    n, N = p.n_states, len(p.A)
    B = input_matrix(loop, None, n) if ctrl is not None else np.zeros((n, 1))
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
    return _stack_pwa_observer(loop, obs, B, Ks, ks, on)


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


def _stack_pwa_observer(loop: ClosedLoop, obs: PiecewiseObserver, B: FloatArray,
                        Ks: tuple[FloatArray, ...], ks: tuple[FloatArray, ...], on: str
                        ) -> tuple[Any, Maps]:
    """Plant and observer on the product of their regions: in region ``(i, j)`` (plant in
    ``i``, estimate in ``j``) the feedback acts by the region of what it reads::

        x'  = A_i x + b_i + B u + E w,           u = K_r (x or x̂) + k_r
        x̂' = A_j x̂ + b_j + B u + E w + L C (x - x̂)
    """
    from ...systems.pwa import PiecewiseAffineSystem

    p = loop.plant
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
                                    u=p.u, C=np.hstack([np.eye(n), zero]), continuous=True,
                                    state_names=loop.state_names)
    eye = np.eye(n)
    return stacked, {"xhat": (np.hstack([zero, eye]), np.zeros(n)),
                     "error": (np.hstack([eye, -eye]), np.zeros(n))}

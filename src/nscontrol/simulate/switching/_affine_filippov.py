"""Filippov systems with affine sides in the compiled loop of the PWA path.

A :meth:`~nscontrol.systems.switched.FilippovSystem.from_pwa` system whose two fields differ by
a constant, ``F± = A x + b±`` (a relay or a sign feedback on a linear plant), with no input and
``δ = cᵀ(b⁺ - b⁻) ≠ 0``, has an affine Filippov field on its surface ``cᵀx = d``: with
``σ± = cᵀF±`` and ``σ⁺ - σ⁻ = δ`` constant, ``F_s = F⁻ - (σ⁻/δ)(b⁺ - b⁻)``. It runs as a PWA
with three modes in the compiled loop of :mod:`._pwa_kernels`: the two sides (regions
``cᵀx <= d``, ``cᵀx >= d``) and the sliding mode, whose flow is ``F_s`` (its matrix built from
values of the one Filippov combination, :func:`._filippov_kernels.filippov_field`) and whose
guards are the exits ``σ⁻ >= 0`` (to the side ``h < 0``) and ``σ⁺ <= 0`` (to ``h > 0``). As a
region it is the surface (two opposite facets) cut by the exits, so the loop's own choice of
the next region — the one whose flow enters it — makes the Filippov decision at a hit: a
crossing when the far side's field enters the far side, sliding when it points back and the
exits hold, a tangential exit to the side whose field then leaves the surface. Pieces, the
samples of a sliding motion and its exits are exact (matrix exponentials, the certified
guard search), on the surface to rounding with no projection.

The loop hands back every event it does not settle (a grazing, no mode whose flow enters, a
tangent ``nᵀF⁻``): the Python stepper of :mod:`._filippov` settles it and runs the rest of the
span, so this path changes the speed, not the semantics. Event kinds and mode numbers are
those of :mod:`._filippov` (a sliding mode numbered after the side it was entered from).
"""

from __future__ import annotations

import types
import weakref
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ._filippov import FilippovStepper, _Fields, _mode_code, start_mode
from ._pwa import CompiledPiecesStepper, _Modes

#: Mode indices of the compiled loop: the side ``h < 0``, the side ``h > 0``, sliding.
MINUS, PLUS, SLIDING = 0, 1, 2


def affine_sides(system: Any) -> Any:
    """The bimodal PWA behind a ``FilippovSystem.from_pwa`` system whose sliding field is
    affine (equal state matrices, no input, ``cᵀ(b⁺ - b⁻) ≠ 0``); ``None`` otherwise."""
    pwa = getattr(system.field, "pwa", None)
    if pwa is None or pwa.domain is not None or (pwa.E is not None and pwa.u is not None):
        return None
    A0, A1 = (np.asarray(a, float) for a in pwa.A)
    c = np.asarray(pwa.regions[0][0][0], float)
    if not np.array_equal(A0, A1):
        return None
    if float(c @ (np.asarray(pwa.b[1], float) - np.asarray(pwa.b[0], float))) == 0.0:
        return None
    return pwa


def _sliding_aug(aug: FloatArray, c: FloatArray, n: int) -> FloatArray:
    """The sliding mode's augmented matrix: ``F_s`` of the sides' flows ``aug[0]``,
    ``aug[1]`` is affine in ``ξ = [x; 1]``, so its columns are differences of its values at
    ``ξ = e_m`` and ``e_m + e_k`` (rounding ``eps |F_s(e_m)|`` in each)."""
    from ._filippov_kernels import filippov_field

    m = aug.shape[1]
    out = np.zeros((m, m))

    def at(xi: FloatArray) -> FloatArray:
        return filippov_field(aug[MINUS, :n] @ xi, aug[PLUS, :n] @ xi, c)

    base = np.zeros(m)
    base[-1] = 1.0
    out[:n, -1] = f0 = at(base)
    for k in range(m - 1):
        base[k] = 1.0
        out[:n, k] = at(base) - f0
        base[k] = 0.0
    return out


def _modes(pwa: Any) -> _Modes:
    """The three modes of a PWA of :func:`affine_sides` (kept per model object)."""
    known = _MODES_OF.get(pwa)
    if known is not None:
        return known
    n = pwa.n_states
    H0, h0 = pwa.regions[0]
    c, d = np.asarray(H0[0], float), float(h0[0])   # from_pwa's surface: h = cᵀx - d
    A, (b0, b1) = np.asarray(pwa.A[0], float), (np.asarray(b, float) for b in pwa.b)
    # sliding: the exits σ⁻ >= 0, σ⁺ <= 0 first (guard row = facet row), then cᵀx = d
    H = np.vstack([-(c @ A), c @ A, c, -c])
    h = np.array([c @ b0, -(c @ b1), d, -d])
    lowered = types.SimpleNamespace(n_states=n, n_regions=3, A=(A, A, A), b=(b0, b1, b0),
                                    regions=((c[None, :], [d]), (-c[None, :], [-d]), (H, h)),
                                    domain=None)
    modes = _Modes(lowered, np.zeros((0, 0)), np.zeros((n, 0)))
    modes.aug[SLIDING] = _sliding_aug(modes.aug, c, n)
    G, g0 = modes.guards[SLIDING]
    modes.guards[SLIDING] = (G[:2], g0[:2])   # the surface itself is no guard: F_s keeps it
    _MODES_OF[pwa] = modes
    return modes


_MODES_OF: weakref.WeakKeyDictionary[Any, _Modes] = weakref.WeakKeyDictionary()


class AffineFilippovStepper(CompiledPiecesStepper):
    """A Filippov run of an :func:`affine_sides` system in the compiled loop, handing the
    rest of the span to :class:`._filippov.FilippovStepper` at an event the loop does not
    settle (or from the start, for a start in second-order sliding)."""

    def __init__(self, system: Any, x0: FloatArray, run: Any, pwa: Any) -> None:
        x, signs, sliding, second = start_mode(_Fields(system), run, run.t0, x0.copy())
        self.arrival = signs[0]          # the side a sliding motion was entered from
        i = SLIDING if sliding >= 0 else (MINUS if signs[0] < 0 else PLUS)
        super().__init__(system, run, _modes(pwa), np.concatenate([x, [1.0]]), i,
                         first_sample=False)   # start_mode recorded it
        self.python: FilippovStepper | None = None
        if second >= 0:
            self.python = FilippovStepper.resume(system, run, run.t0, x, (signs, -1))
            self.python.second = second

    def label(self, row: int, i: int, j: int) -> tuple[str, int, int, int]:
        """The Filippov event of the settled transition from mode ``i`` to ``j``."""
        if j == SLIDING:
            self.arrival = -1 if i == MINUS else 1
            return "sliding_start", 0, i, _mode_code((self.arrival,), 0)
        if i == SLIDING:
            return "sliding_exit", 0, _mode_code((self.arrival,), 0), j
        return "crossing", 0, i, j

    def _mode(self, i: int) -> tuple[tuple[int, ...], int]:
        """``(signs, sliding)`` of :mod:`._filippov` for the compiled mode ``i``."""
        if i == SLIDING:
            return (self.arrival,), 0
        return (-1 if i == MINUS else 1,), -1

    def _to_python(self, t: float, i: int) -> FilippovStepper:
        self.python = FilippovStepper.resume(self.system, self.run, t,
                                             self.xi[:self.modes.n].copy(), self._mode(i))
        return self.python

    def handoff(self, t: float, i: int, hits: list[int]) -> None:
        """The Python stepper settles the event (a surface hit, or an exit: guard row 0 is
        ``σ⁻ = 0``, row 1 ``σ⁺ = 0``) and runs the rest of the span."""
        python = self._to_python(t, i)
        if i == SLIDING:
            python.settle("exit", -1 if hits[0] == 0 else 1)
        else:
            python.settle("surface", 0)

    def inadmissible(self, t: float, i: int, index: int, user: bool) -> None:
        """A piece would start beyond a guard of mode ``i``: the Python stepper goes on."""
        self._to_python(t, i)

    def piece(self) -> float:
        if self.python is None:
            return super().piece()
        self.t = self.python.piece()
        self.done = self.python.done
        return self.t

    def state(self) -> FloatArray:
        return self.xi[:self.modes.n] if self.python is None else self.python.x

    def extra(self) -> dict[str, Any]:
        if self.python is not None:
            return {**self.python.extra(), "segments": self.segments,
                    "propagation": "exact, then dop853"}
        signs, sliding = self._mode(self.i)
        return {"pieces": self.segments, "segments": self.segments,
                "final_mode": _mode_code(signs, sliding), "propagation": "exact"}

"""The step loops of Moreau–Jean's paths, behind one interface (the run of
:func:`nscontrol.simulate.moreau_jean.integrate` drives whichever it gets).

A runner takes a chunk of steps: ``runner(state, fext, times)`` returns ``(done, code, q_out,
v_out, p_out)`` (``code`` 0, the LCP's status, ``MODEL_ERROR`` or ``SINGULAR`` with the
message in ``state.failure``) and leaves the state after the last step done in ``state``.
Every step is a compiled kernel of :mod:`nscontrol.simulate.moreau_jean._step_kernels`: the O(n)
pairwise loop, the dense loop, or (any ``M(q)``, force or gap) ``mj_step`` called once a step
with the user's callables evaluated in Python (:mod:`._python_runner`); the compiled-model
loop runs the same ``mj_step`` (:mod:`._compiled`).

With the Python blocks of a closed loop (``state.inline``) every runner but the compiled
model's takes its chunk one step at a time (:meth:`Runner.stepped`): the blocks' input is
evaluated before each step, their reset (``state.after_step``) after a step with an impact.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ..trajectory import ChunkProgress, Recorder
from ._options import MoreauJeanOptions

LCP_STATUS = {1: "ray termination (no solution)", 2: "iteration limit",
              3: "numerical failure"}

#: ``(t_end, x_minus, x_plus, p, p_before)`` after a step: the blocks' reset at an impact
AfterStep = Callable[[float, FloatArray, FloatArray, FloatArray, FloatArray], None]


@dataclass(slots=True)
class RunState:
    """What the run carries from chunk to chunk."""

    q: FloatArray
    v: FloatArray
    #: the impulses of the last step done
    p_prev: FloatArray
    #: steps done
    k: int = 0
    #: the active set of the last step done (what the blocks read as ``active``)
    active_prev: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: the blocks' input ``S u(t, q, v, p_prev, active_prev)``, evaluated before each step
    inline: Callable[..., FloatArray] | None = None
    #: called after each step of a stepped chunk (the blocks' reset at an impact)
    after_step: AfterStep | None = None
    #: the rows of the chunk under way
    progress: ChunkProgress | None = None
    #: the message of a step stopped with ``MODEL_ERROR`` or ``SINGULAR``
    failure: str = ""
    #: ``(t, q, v, p)`` of the last step done
    last: tuple[float, FloatArray, FloatArray, FloatArray] | None = None
    #: the run's first time while its first sample is held back (recorded with the first
    #: chunk: :func:`~._recording.record_chunk`), then ``None``
    first: float | None = None


class StepFailure(Exception):
    """A step stopped by the model (``MODEL_ERROR``) or a singular ``M̂`` (``SINGULAR``)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code, self.message = code, message


class Runner:
    """The interface of a path's step loop (and its defaults)."""

    path = ""

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> None:
        self.system, self.opts, self.S = system, opts, S
        #: the active set of the last step :meth:`step` took
        self.active_prev = np.zeros(0, dtype=np.int64)

    def for_step(self, h: float) -> Runner:
        """The runner of the shortened last step."""
        raise NotImplementedError   # pragma: no cover - every runner defines it

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        return self.stepped(state, fext, times)

    def python_steps(self, state: RunState) -> bool:
        """Whether a chunk steps in Python (:meth:`stepped`, which counts the rows written
        in ``state.progress``), rather than in one compiled call."""
        return True

    def step(self, t: float, q: FloatArray, v: FloatArray, fext: FloatArray,
             outs: tuple[FloatArray, FloatArray, FloatArray], k: int) -> int:
        """One step from ``(q, v)`` at ``t`` into row ``k`` of ``outs`` (``q``, ``v`` left
        unchanged); returns the LCP's status (a :class:`StepFailure` for the model's)."""
        raise NotImplementedError   # pragma: no cover - every stepped runner defines it

    def stepped(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        """The chunk one :meth:`step` at a time, the blocks' input (``state.inline``) added
        before each and ``state.after_step`` called after each."""
        outs = _outputs(self.system, times.size)
        q_out, v_out, p_out = outs
        if state.progress is not None:   # the rows a failed step leaves behind are kept
            state.progress.rows = outs
        q, v, p, inline = state.q, state.v, state.p_prev, state.inline
        for k in range(times.size):
            t = float(times[k])
            try:
                f_k = fext[min(k, fext.shape[0] - 1)]
                if inline is not None:
                    f_k = f_k + inline(t, q, v, p, state.active_prev)
                code = self.step(t, q, v, f_k, outs, k)
            except StepFailure as failure:
                code, state.failure = failure.code, failure.message
            if code:
                state.q, state.v = q, v
                return k, code, q_out, v_out, p_out
            state.active_prev = self.active_prev
            if state.progress is not None:
                state.progress.done = k + 1
            if state.after_step is not None:
                state.after_step(t + self.opts.h, np.concatenate([q, v]),
                                 np.concatenate([q_out[k], v_out[k]]), p_out[k], p)
            q, v, p = q_out[k], v_out[k], p_out[k]
        state.q, state.v = q.copy(), v.copy()
        return times.size, 0, q_out, v_out, p_out

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        raise NotImplementedError   # pragma: no cover - every runner defines it

    def observers(self, listeners: Sequence[Callable[..., None]]
                  ) -> Sequence[Callable[..., None]]:
        """The listeners the run calls after each chunk."""
        return listeners

    def signals(self, q: FloatArray, v: FloatArray, p: FloatArray, rec: Recorder
                ) -> dict[str, FloatArray] | None:
        """The chunk's signals when this runner computes them (``None``: the run does)."""
        return None

    def failure(self, code: int, t: float, state: RunState) -> str:
        """The message of a run stopped by ``code`` at ``t`` (may raise instead)."""
        from ._step_kernels import MODEL_ERROR, SINGULAR

        if code in (MODEL_ERROR, SINGULAR):
            return state.failure
        return (f"moreau_jean: the LCP of step {state.k} (t = {t:.6g}) failed: "
                f"{LCP_STATUS.get(code, code)}; try a smaller h, or check the constraints "
                "for redundancy")

    def stats(self) -> dict[str, Any]:
        return {}


#: Per system, what the runners compute from it and the step alone (the path, the step
#: matrices): a system is frozen, its matrices do not change; the kernels only read them.
_SETUPS: weakref.WeakKeyDictionary[Any, dict[tuple, Any]] = weakref.WeakKeyDictionary()


def kept(system: Any, key: tuple, build: Callable[[], Any]) -> Any:
    """``build()``, computed once per ``system`` and ``key`` (a study of many steps keeps
    the latest few of each system)."""
    per_system = _SETUPS.get(system)
    if per_system is None:
        per_system = _SETUPS[system] = {}
    value = per_system.pop(key, None)
    if value is None:
        if len(per_system) >= 8:
            per_system.pop(next(iter(per_system)))
        value = build()
    per_system[key] = value   # the latest used last: evicted last
    return value


def _outputs(system: Any, chunk: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    n, m = system.n_dof, system.n_contacts
    return np.empty((chunk, n)), np.empty((chunk, n)), np.zeros((chunk, m))


class _KernelRunner(Runner):
    """A path whose steps are one compiled loop (:meth:`_kernel`): a chunk is one call, or
    one call a step under Python blocks."""

    def python_steps(self, state: RunState) -> bool:
        return state.inline is not None

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        if state.inline is not None:   # the blocks' input before each step
            return self.stepped(state, fext, times)
        q_out, v_out, p_out = _outputs(self.system, times.size)
        done, code = self._kernel(state.q, state.v, fext, q_out, v_out, p_out)
        return done, code, q_out, v_out, p_out

    def step(self, t: float, q: FloatArray, v: FloatArray, fext: FloatArray,
             outs: tuple[FloatArray, FloatArray, FloatArray], k: int) -> int:
        self.active_prev = self.active_set(q, v)
        _, code = self._kernel(q.copy(), v.copy(), fext[None, :],
                               *(out[k:k + 1] for out in outs))
        return int(code)

    def _kernel(self, q: FloatArray, v: FloatArray, fext: FloatArray, q_out: FloatArray,
                v_out: FloatArray, p_out: FloatArray) -> tuple[int, int]:
        """The compiled loop over the rows of ``q_out``, in place on ``q``, ``v``."""
        raise NotImplementedError   # pragma: no cover - every compiled path defines it


class PairwiseRunner(_KernelRunner):
    """Diagonal ``M̂``, contacts between neighbours: the O(n) compiled loop."""

    path = "tridiagonal"

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None,
                 pairs: tuple[np.ndarray, ...]) -> None:
        super().__init__(system, opts, S)
        self.kdiag, self.ddiag, self.minv, self.pairs = kept(
            system, ("tridiagonal", opts.h, opts.theta),
            lambda: self._matrices(system, opts.h, opts.theta, pairs))

    @staticmethod
    def _matrices(system: Any, h: float, th: float, pairs: tuple[np.ndarray, ...]
                  ) -> tuple[FloatArray, FloatArray, FloatArray, tuple[np.ndarray, ...]]:
        n = system.n_dof
        kdiag = np.zeros(n) if system.stiffness is None else np.diag(system.stiffness).copy()
        ddiag = np.zeros(n) if system.damping is None else np.diag(system.damping).copy()
        minv = 1.0 / (system.mass_diagonal + h * th * ddiag + (h * th) ** 2 * kdiag)
        return kdiag, ddiag, minv, tuple(np.ascontiguousarray(p) for p in pairs)

    def for_step(self, h: float) -> Runner:
        return PairwiseRunner(self.system, self.opts.with_step(h), self.S, self.pairs)

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The kernel's active set at ``(q, v)`` (by the kernel's own function)."""
        from ._step_kernels import pairwise_active_set

        o, (ia, ib, ca, cb) = self.opts, self.pairs
        act = np.empty(self.system.n_contacts, np.int64)
        na = pairwise_active_set(q, v, ia, ib, ca, cb, self.system.gap_offset, o.gamma, o.h,
                                 o.activation, act)
        return act[:na]

    def _kernel(self, q: FloatArray, v: FloatArray, fext: FloatArray, q_out: FloatArray,
                v_out: FloatArray, p_out: FloatArray) -> tuple[int, int]:
        """The compiled loop over the rows of ``q_out``, in place on ``q``, ``v``."""
        from ._step_kernels import mj_pairwise_kernel

        s, o, (ia, ib, ca, cb) = self.system, self.opts, self.pairs
        done, code = mj_pairwise_kernel(q, v, self.minv, self.kdiag, self.ddiag,
                                        s.constant_force, np.ascontiguousarray(fext),
                                        ia, ib, ca, cb, s.gap_offset, s.restitution, o.h, o.theta,
                                        o.gamma, o.activation, q_out, v_out, p_out)
        return done, code


class DenseRunner(_KernelRunner):
    """Constant ``M``, linear forces, affine gaps: the dense compiled loop."""

    path = "dense"

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> None:
        super().__init__(system, opts, S)
        self.K, self.D, self.minv, self.G, self.minv_gt, self.W = kept(
            system, ("dense", opts.h, opts.theta),
            lambda: self._matrices(system, opts.h, opts.theta))

    @staticmethod
    def _matrices(system: Any, h: float, th: float) -> tuple[FloatArray, ...]:
        n = system.n_dof
        K = np.zeros((n, n)) if system.stiffness is None else system.stiffness
        D = np.zeros((n, n)) if system.damping is None else system.damping
        minv = np.linalg.inv(system.mass_matrix() + h * th * D + (h * th) ** 2 * K)
        G = np.ascontiguousarray(system.dense_gap_matrix())
        minv_gt = np.ascontiguousarray(minv @ G.T)
        return K, D, minv, G, minv_gt, np.ascontiguousarray(G @ minv_gt)

    def for_step(self, h: float) -> Runner:
        return DenseRunner(self.system, self.opts.with_step(h), self.S)

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The kernel's active set at ``(q, v)`` (by the kernel's own functions)."""
        from ._step_kernels import active_set, affine_gaps

        o, m = self.opts, self.system.n_contacts
        act = np.empty(m, np.int64)
        gq = affine_gaps(self.G, self.system.gap_offset, q, np.empty(m))
        na = active_set(self.G, gq, v, o.gamma, o.h, o.activation, np.empty(m), act)
        return act[:na]

    def _kernel(self, q: FloatArray, v: FloatArray, fext: FloatArray, q_out: FloatArray,
                v_out: FloatArray, p_out: FloatArray) -> tuple[int, int]:
        """The compiled loop over the rows of ``q_out``, in place on ``q``, ``v``."""
        from ._step_kernels import mj_dense_kernel

        s, o = self.system, self.opts
        done, code = mj_dense_kernel(q, v, self.minv, self.K, self.D,
                                     s.constant_force, np.ascontiguousarray(fext), self.G,
                                     s.gap_offset, s.restitution, self.minv_gt, self.W, o.h,
                                     o.theta, o.gamma, o.activation, q_out, v_out, p_out)
        return done, code


def singular_message(rcond: float, t: float, forces: str) -> str:
    """The refusal of an iteration matrix ``M̂`` singular to working precision:
    ``rcond < n ε``, ``rcond = 1 / (scale ‖M̂⁻¹‖₁)`` with ``scale`` the 1-norm of the terms
    summed into ``M̂`` (cancellation between ``M`` and ``h²θ² ∂f/∂q`` is measured against
    the terms, not against the result: a 1 x 1 ``M̂`` is never ill-conditioned by itself)."""
    what = ("M(q) - hθ ∂f/∂v - h²θ² ∂f/∂q" if forces == "implicit" else "M(q)")
    return (f"moreau_jean: the iteration matrix {what} is singular at t = {t:.6g} "
            f"(reciprocal condition number {rcond:.3g}); a negative stiffness of size "
            "M/(hθ)² does this: try a smaller h")

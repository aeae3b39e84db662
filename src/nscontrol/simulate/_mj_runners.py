"""The step loops of Moreau–Jean's paths, behind one interface (the run of
:func:`nscontrol.simulate.moreau_jean.integrate` drives whichever it gets).

A runner takes a chunk of steps: ``runner(state, fext, times)`` returns ``(done, code, q_out,
v_out, p_out)`` (``code`` 0, the LCP's status, ``MODEL_ERROR`` or ``SINGULAR`` with the
message in ``state.failure``) and leaves the state after the last step done in ``state``.
Every step is a compiled kernel of :mod:`._moreau_jean_kernels`: the O(n) pairwise loop, the
dense loop, or (any ``M(q)``, force or gap) :func:`~._moreau_jean_kernels.mj_step` called once a
step with the user's callables evaluated here; the compiled-model loop runs the same
``mj_step`` (:mod:`._mj_compiled`).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import ModelError
from ._mj_options import MoreauJeanOptions
from .trajectory import ChunkProgress, Recorder

LCP_STATUS = {1: "ray termination (no solution)", 2: "iteration limit",
              3: "numerical failure"}


@dataclass
class RunState:
    """What the run carries from chunk to chunk."""

    q: FloatArray
    v: FloatArray
    #: the impulses of the last step done
    p_prev: FloatArray
    #: which of ``lam_hat``, ``active`` the controller reads
    reads: frozenset[str] = frozenset()
    #: steps done
    k: int = 0
    #: the active set of the last step done (given to a controller reading ``active``)
    active_prev: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: a controller as a force evaluated inside the Python step loop
    inline: Callable[..., FloatArray] | None = None
    #: the rows of the chunk under way
    progress: ChunkProgress | None = None
    #: the message of a step stopped with ``MODEL_ERROR`` or ``SINGULAR``
    failure: str = ""
    #: ``(t, q, v, p)`` of the last step done
    last: tuple[float, FloatArray, FloatArray, FloatArray] | None = None


class StepFailure(Exception):
    """A step stopped by the model (``MODEL_ERROR``) or a singular ``M̂`` (``SINGULAR``)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code, self.message = code, message


class Runner:
    """The interface of a path's step loop (and its defaults)."""

    path = ""
    #: whether the run's ``controller`` is evaluated outside the runner (False: the compiled
    #: loop runs the blocks it stands for)
    takes_controller = True

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> None:
        self.system, self.opts, self.S = system, opts, S

    def for_step(self, h: float) -> Runner:
        """The runner of the shortened last step."""
        return choose_runner(self.system, self.opts.with_step(h), self.S)

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        raise NotImplementedError   # pragma: no cover - every runner defines it

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
        from ._moreau_jean_kernels import MODEL_ERROR, SINGULAR

        if code in (MODEL_ERROR, SINGULAR):
            return state.failure
        return (f"moreau_jean: the LCP of step {state.k} (t = {t:.6g}) failed: "
                f"{LCP_STATUS.get(code, code)}; try a smaller h, or check the constraints "
                "for redundancy")

    def stats(self) -> dict[str, Any]:
        return {}


def choose_runner(system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> Runner:
    """The fastest correct step loop for this system (see the module docstring of
    :mod:`nscontrol.simulate.moreau_jean`)."""
    path = kept(system, ("path", opts.forces), lambda: _path(system, opts.forces))
    if path == "tridiagonal":
        return PairwiseRunner(system, opts, S, system.pairwise_contacts())
    return DenseRunner(system, opts, S) if path == "dense" else PythonRunner(system, opts, S)


def _path(system: Any, forces: str) -> str:
    """The path of :func:`choose_runner` (the system's structure alone decides it)."""
    if system.is_linear and forces == "implicit":
        K = system.stiffness
        D = system.damping
        diag = system.mass_diagonal
        offdiag = [X for X in (K, D) if X is not None and np.count_nonzero(X - np.diag(np.diag(X)))]
        pairs = system.pairwise_contacts()
        if diag is not None and not offdiag and pairs is not None and _neighbour_only(pairs):
            return "tridiagonal"
        return "dense"
    return "python"


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


def _neighbour_only(pairs: tuple[np.ndarray, ...]) -> bool:
    """Contacts share coordinates only with their neighbours: the Delassus matrix is
    tridiagonal."""
    ia, ib, _, _ = pairs
    owner: dict[int, list[int]] = {}
    for j, (a, b) in enumerate(zip(ia, ib, strict=True)):
        for d in (a, b):
            if d >= 0:
                owner.setdefault(int(d), []).append(j)
    return all(max(js) - min(js) <= 1 for js in owner.values())


def _outputs(system: Any, chunk: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    n, m = system.n_dof, system.n_contacts
    return np.empty((chunk, n)), np.empty((chunk, n)), np.zeros((chunk, m))


class PairwiseRunner(Runner):
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

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The kernel's active set at ``(q, v)`` (by the kernel's own function)."""
        from ._moreau_jean_kernels import pairwise_active_set

        o, (ia, ib, ca, cb) = self.opts, self.pairs
        act = np.empty(self.system.n_contacts, np.int64)
        na = pairwise_active_set(q, v, ia, ib, ca, cb, self.system.gap_offset, o.gamma, o.h,
                                 o.activation, act)
        return act[:na]

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        from ._moreau_jean_kernels import mj_pairwise_kernel

        s, o, (ia, ib, ca, cb) = self.system, self.opts, self.pairs
        q_out, v_out, p_out = _outputs(s, times.size)
        done, code = mj_pairwise_kernel(state.q, state.v, self.minv, self.kdiag, self.ddiag,
                                        s.constant_force, np.ascontiguousarray(fext),
                                        ia, ib, ca, cb, s.gap_offset, s.restitution, o.h, o.theta,
                                        o.gamma, o.activation, q_out, v_out, p_out)
        return done, code, q_out, v_out, p_out


class DenseRunner(Runner):
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
        from ._moreau_jean_kernels import active_set, affine_gaps

        o, m = self.opts, self.system.n_contacts
        act = np.empty(m, np.int64)
        gq = affine_gaps(self.G, self.system.gap_offset, q, np.empty(m))
        na = active_set(self.G, gq, v, o.gamma, o.h, o.activation, np.empty(m), act)
        return act[:na]

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        from ._moreau_jean_kernels import mj_dense_kernel

        s, o = self.system, self.opts
        q_out, v_out, p_out = _outputs(s, times.size)
        done, code = mj_dense_kernel(state.q, state.v, self.minv, self.K, self.D,
                                     s.constant_force, np.ascontiguousarray(fext), self.G,
                                     s.gap_offset, s.restitution, self.minv_gt, self.W, o.h,
                                     o.theta, o.gamma, o.activation, q_out, v_out, p_out)
        return done, code, q_out, v_out, p_out


class PythonRunner(Runner):
    """``M(q)`` or nonlinear forces/gaps: the user's callables evaluated in Python at every
    step, the step itself by the compiled :func:`~._moreau_jean_kernels.mj_step` (the one
    of the compiled-model loop)."""

    path = "python"

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> None:
        super().__init__(system, opts, S)
        n, m = system.n_dof, system.n_contacts
        self.analytic = system.force is None or system.force_jacobian is not None
        self.zeros = np.zeros((n, n))  # the Jacobians of explicit forces
        self.minv, self.dv, self.un = np.empty((n, n)), np.empty(n), np.empty(m)
        self.act = np.empty(m, np.int64)
        self.mgt = np.empty((n, m))
        self.active_prev = np.zeros(0, dtype=np.int64)
        # affine gaps (possibly scipy.sparse): one dense matrix for the whole run
        self.G = (None if system.gap_matrix is None
                  else np.ascontiguousarray(system.dense_gap_matrix(), dtype=float))

    def for_step(self, h: float) -> Runner:
        return PythonRunner(self.system, self.opts.with_step(h), self.S)

    def gap_jacobian(self, q: FloatArray) -> np.ndarray:
        if self.G is not None:
            return self.G
        s = self.system
        G = np.ascontiguousarray(s.gap_jacobian(q), dtype=float)
        if G.shape != (s.n_contacts, s.n_dof):
            raise StepFailure(_model_error(), f"jacobian: expected shape "
                              f"({s.n_contacts}, {s.n_dof}) at q = {q!r}, got {G.shape}")
        return G

    def gaps(self, q: FloatArray) -> np.ndarray:
        s = self.system
        g = np.ascontiguousarray(s.gaps(q), dtype=float)
        if g.shape != (s.n_contacts,):
            raise StepFailure(_model_error(), f"gap: expected {s.n_contacts} value(s) at "
                              f"q = {q!r}, got shape {g.shape}")
        return g

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        """The contacts predicted to close, ``g + γ h G v <= activation`` (the step's
        own test, :func:`~._moreau_jean_kernels.active_set`)."""
        from ._moreau_jean_kernels import active_set

        o = self.opts
        na = active_set(self.gap_jacobian(q), self.gaps(q), v, o.gamma, o.h, o.activation,
                        self.un, self.act)
        return self.act[:na].copy()

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        q, v = state.q, state.v
        q_out, v_out, p_out = _outputs(self.system, times.size)
        if state.progress is not None:   # the rows a failed step leaves behind are kept
            state.progress.rows = (q_out, v_out, p_out)
        inline = state.inline
        for k in range(times.size):
            t = float(times[k])
            try:
                f_k = fext[min(k, fext.shape[0] - 1)]
                if inline is not None:
                    f_k = f_k + inline(t, q, v, p_out[k - 1] if k else state.p_prev,
                                       self.active_prev if k else state.active_prev)
                code = self._step(t, q, v, f_k, p_out, q_out, v_out, k)
            except StepFailure as failure:
                code, state.failure = failure.code, failure.message
            if code:
                state.q, state.v = q, v
                return k, code, q_out, v_out, p_out
            q, v = q_out[k], v_out[k]
            if state.progress is not None:
                state.progress.done = k + 1
        state.q, state.v = q.copy(), v.copy()
        if inline is not None:
            state.active_prev = self.active_prev
        return times.size, 0, q_out, v_out, p_out

    def _step(self, t: float, q: FloatArray, v: FloatArray, fext: FloatArray,
              p_out: FloatArray, q_out: FloatArray, v_out: FloatArray, k: int) -> int:
        """One step from ``(q, v)`` at ``t`` into row ``k``; returns the LCP's status."""
        from ._moreau_jean_kernels import MODEL_ERROR, SINGULAR, mj_step, positive_definite

        s, o = self.system, self.opts
        h, th = o.h, o.theta
        qm = q + th * h * v if o.mass_at == "predicted" and not s.constant_mass else q
        M = np.ascontiguousarray(s.mass_matrix(qm))
        if not s.constant_mass and not positive_definite(M):  # M(q) must stay definite
            raise StepFailure(MODEL_ERROR, f"mass: M(q) is not positive definite at "
                              f"t = {t:.6g}, q = {qm!r}; the model is only valid where the "
                              "mass matrix is")
        if o.forces == "implicit":
            tm = t + th * h  # the θ-weighted time (module docstring)
            f = _checked_force(s, tm, q, v)
            Jq, Jv = self._jacobians(tm, q, v)
        else:
            f, Jq, Jv = _checked_force(s, t, q, v), self.zeros, self.zeros
        code, rcond, na = mj_step(M, f, Jq, Jv, np.ascontiguousarray(fext, dtype=float),
                                  self.gap_jacobian(q), self.gaps(q), q, v, s.restitution, h,
                                  th, o.gamma, o.activation, self.minv, self.dv, self.un,
                                  self.act, self.mgt, p_out, q_out, v_out, k)
        if code == SINGULAR:
            raise StepFailure(SINGULAR, singular_message(rcond, t, o.forces))
        self.active_prev = self.act[:na].copy()
        return int(code)

    def _jacobians(self, t: float, q: FloatArray, v: FloatArray
                   ) -> tuple[FloatArray, FloatArray]:
        """``∂f/∂q, ∂f/∂v`` at ``(t, q, v)``, finite (a ``StepFailure`` otherwise)."""
        try:
            Jq, Jv, _ = self.system.force_jacobians(t, q, v)
        except ModelError as err:
            raise StepFailure(_model_error(), str(err)) from None
        if not self.analytic and not (np.isfinite(Jq).all() and np.isfinite(Jv).all()):
            raise StepFailure(_model_error(),
                              f"force: its central differences are not finite at t = "
                              f"{t:.6g}, q = {q!r}, v = {v!r}; give force_jacobian or "
                              "keep the force finite near the motion")
        return np.ascontiguousarray(Jq, dtype=float), np.ascontiguousarray(Jv, dtype=float)

    def stats(self) -> dict[str, Any]:
        return {"forces": self.opts.forces,
                "force_jacobian": "analytic" if self.analytic else "central differences"}


def _checked_force(system: Any, t: float, q: FloatArray, v: FloatArray) -> FloatArray:
    f = np.asarray(system.forces(t, q, v), float)
    if f.shape != (system.n_dof,) or not np.isfinite(f).all():
        raise StepFailure(_model_error(),
                          f"force: expected a finite vector of length {system.n_dof} at "
                          f"t = {t:.6g}, got {f!r} (q = {q!r}, v = {v!r})")
    return np.ascontiguousarray(f)


def _model_error() -> int:
    from ._moreau_jean_kernels import MODEL_ERROR

    return int(MODEL_ERROR)


def singular_message(rcond: float, t: float, forces: str) -> str:
    """The refusal of an iteration matrix ``M̂`` singular to working precision:
    ``rcond < n ε``, ``rcond = 1 / (scale ‖M̂⁻¹‖₁)`` with ``scale`` the 1-norm of the terms
    summed into ``M̂`` (cancellation between ``M`` and ``h²θ² ∂f/∂q`` is measured against
    the terms, not against the result: a 1 x 1 ``M̂`` is never ill-conditioned by itself)."""
    what = ("M(q) - hθ ∂f/∂v - h²θ² ∂f/∂q" if forces == "implicit" else "M(q)")
    return (f"moreau_jean: the iteration matrix {what} is singular at t = {t:.6g} "
            f"(reciprocal condition number {rcond:.3g}); a negative stiffness of size "
            "M/(hθ)² does this: try a smaller h")

"""The Python path of Moreau–Jean: ``M(q)``, a ``force`` callable or nonlinear gaps evaluated
in Python at every step, the step itself by the compiled
:func:`~nscontrol.simulate.moreau_jean._step_kernels.mj_step` (the compiled-model loop's own).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError
from ._options import MoreauJeanOptions
from ._runners import Runner, StepFailure, singular_message

__all__ = ["PythonRunner"]


class PythonRunner(Runner):
    """``M(q)`` or nonlinear forces/gaps: the user's callables evaluated in Python at every
    step, the step itself by the compiled ``mj_step`` (the compiled-model loop's own)."""

    path = "python"

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> None:
        from ._step_kernels import step_workspace

        super().__init__(system, opts, S)
        n, m = system.n_dof, system.n_contacts
        self.analytic = system.force is None or system.force_jacobian is not None
        self.zeros = np.zeros((n, n))  # the Jacobians of explicit forces
        self.minv, self.dv, self.un = np.empty((n, n)), np.empty(n), np.empty(m)
        self.act = np.empty(m, np.int64)
        self.mgt, self.L = np.empty((n, m)), np.empty((n, n))
        self.work = step_workspace(n, m)
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
        own test, :func:`~._step_kernels.active_set`)."""
        from ._step_kernels import active_set

        o = self.opts
        na = active_set(self.gap_jacobian(q), self.gaps(q), v, o.gamma, o.h, o.activation,
                        self.un, self.act)
        return self.act[:na].copy()

    def step(self, t: float, q: FloatArray, v: FloatArray, fext: FloatArray,
             outs: tuple[FloatArray, FloatArray, FloatArray], k: int) -> int:
        """One step from ``(q, v)`` at ``t`` into row ``k``; returns the LCP's status."""
        from ._step_kernels import MODEL_ERROR, SINGULAR, mj_step, positive_definite

        s, o = self.system, self.opts
        h, th = o.h, o.theta
        qm = q + th * h * v if o.mass_at == "predicted" and not s.constant_mass else q
        M = np.ascontiguousarray(s.mass_matrix(qm))
        if not s.constant_mass and not positive_definite(M, self.L):  # M(q) must stay definite
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
                                  th, o.gamma, o.activation, self.minv, -1.0, self.dv,
                                  self.un, self.act, self.mgt, self.work, outs[2], outs[0],
                                  outs[1], k)
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
    from ._step_kernels import MODEL_ERROR

    return int(MODEL_ERROR)

"""Moreau–Jean on a Lagrangian system with a compiled model (``system.compiled``): the
runner of the compiled loop :func:`~nscontrol.simulate.moreau_jean._model_kernels.mj_model_steps`,
whose step is the Python path's (:func:`~nscontrol.simulate.moreau_jean._step_kernels.mj_step`),
optionally with the compiled blocks of a closed loop (``CompiledBlocks.of`` the loop's block
runner). The run of :func:`nscontrol.simulate.moreau_jean.integrate` drives it as any other
runner.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ..trajectory import Recorder
from ._options import MoreauJeanOptions
from ._runners import Runner, RunState, singular_message


class ModelRunner(Runner):
    """The compiled model's loop; with ``blocks`` the loop steps and resets them itself,
    other listeners observe after each chunk."""

    path = "compiled_model"

    def __init__(self, system: Any, opts: MoreauJeanOptions, S: FloatArray | None,
                 model: Any, blocks: Any) -> None:
        super().__init__(system, opts, S)
        n = system.n_dof
        self.cm, self.blocks = model, blocks
        self.model = model.entries      # typed once per process, not at every chunk
        zero = np.zeros((n, n))
        self.K = zero if system.stiffness is None else np.ascontiguousarray(system.stiffness)
        self.D = zero if system.damping is None else np.ascontiguousarray(system.damping)
        self.Su = np.ascontiguousarray(S if S is not None else np.zeros((n, 0)))
        self.block_args = (True, blocks.Cy, *_with_resets(blocks)) if blocks is not None \
            else _no_blocks(system, self.Su.shape[1])
        self.info = np.zeros(2)
        #: what the system's structure makes constant over a run (the kernel's docstring)
        self.structure = (bool(system.constant_mass), system.force is not None,
                          system.gap_matrix is not None)

    def for_step(self, h: float) -> Runner:
        runner = ModelRunner.__new__(ModelRunner)
        runner.__dict__.update(self.__dict__, opts=self.opts.with_step(h))
        return runner

    def observers(self, listeners: Sequence[Callable[..., None]]
                  ) -> Sequence[Callable[..., None]]:
        """The listeners other than the compiled blocks' own (reset inside the loop)."""
        runner = getattr(self.blocks, "runner", None)
        return [fn for fn in listeners
                if runner is None or getattr(fn, "__self__", None) is not runner]

    def python_steps(self, state: RunState) -> bool:
        return False

    def __call__(self, state: RunState, fext: FloatArray, times: FloatArray) -> tuple:
        from ...systems._feedback_kernels import calling_blocks
        from ._model_kernels import mj_model_steps

        s, o, size = self.system, self.opts, times.size
        n, m = s.n_dof, s.n_contacts
        q_out, v_out, p_out = np.empty((size, n)), np.empty((size, n)), np.zeros((size, m))
        XO, XC, U = self.blocks.log_arrays(size) if self.blocks is not None else \
            (np.empty((size, 0)), np.empty((size, 0)), np.empty((size, self.Su.shape[1])))
        with calling_blocks():      # a block's error raised from the call
            done, code = mj_model_steps(  # type: ignore[call-arg]  # numba's stub
                self.model, self.cm.params, self.K, self.D, s.constant_force, self.Su,
                s.restitution, o.h, o.theta, o.gamma, o.activation, o.mass_at == "predicted",
                self.structure, times, state.q, state.v, state.p_prev.copy(),
                np.ascontiguousarray(fext), *self.block_args, XO, XC, U, q_out, v_out, p_out,
                self.info)
        if self.blocks is not None:
            self.blocks.log(times[:done], XO[:done], XC[:done], U[:done])
        if done:
            state.q, state.v = q_out[done - 1].copy(), v_out[done - 1].copy()
        return done, code, q_out, v_out, p_out

    def active_set(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        raise NotImplementedError   # pragma: no cover - the blocks read no active set

    def failure(self, code: int, t: float, state: RunState) -> str:
        """A block's failure is raised (the run context attaches the steps so far)."""
        from ._model_kernels import BLOCKS, MODEL_ERROR, SINGULAR

        if code >= BLOCKS:
            self.blocks.raise_status(int(code - BLOCKS), t)
        if code == MODEL_ERROR:
            state.failure = (f"model: at t = {t:.6g} the compiled model gave a mass matrix "
                             f"that is not positive definite or a non-finite force (q = "
                             f"{state.q!r})")
        elif code == SINGULAR:
            state.failure = singular_message(float(self.info[1]), t, "implicit")
        return super().failure(code, t, state)

    def signals(self, q: FloatArray, v: FloatArray, p: FloatArray, rec: Recorder
                ) -> dict[str, FloatArray]:
        """``impulse``, ``gap`` and ``energy`` of a chunk by the compiled model, without a
        Python call per step unless the model's potential has no compiled form."""
        from numba.core.errors import NumbaExperimentalFeatureWarning

        with warnings.catch_warnings():   # numba's first-class functions: "experimental"
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            return _signals_of_rows(self.system, self.cm, q, v, p, rec)

    def stats(self) -> dict[str, Any]:
        return {"forces": "implicit", "force_jacobian": "compiled"}


def _signals_of_rows(system: Any, cm: Any, q: Any, v: Any, p: Any, rec: Recorder
                     ) -> dict[str, Any]:
    from ._model_kernels import gap_rows, kinetic_energy_rows, potential_rows

    out: dict[str, Any] = {}
    if rec.wants("impulse"):
        out["impulse"] = p
    if rec.wants("gap"):
        out["gap"] = gap_rows((cm.entries[3],), cm.params, q, system.n_contacts)
    if rec.wants("energy"):
        energy = kinetic_energy_rows((cm.entries[0],), cm.params, q, v) - q @ system.constant_force
        if system.stiffness is not None:
            energy = energy + 0.5 * np.einsum("...i,ij,...j->...", q, system.stiffness, q)
        if system.potential is not None:
            if cm.potential is not None:
                energy = energy + potential_rows(((cm.potential,),), cm.params, q)
            else:
                energy = energy + np.array([system.potential(qi) for qi in q])
        out["energy"] = energy
    return out


def _no_blocks(system: Any, n_inputs: int) -> tuple[Any, ...]:
    """The kernel's block arguments of a loop without blocks (never called)."""
    from ...systems._feedback_kernels import (
        compiled_entries,
        empty_output,
        keep_state,
        static_update,
    )

    n, m = system.n_dof, system.n_contacts
    e0 = np.zeros(0)
    fns, rs = compiled_entries(empty_output, static_update), compiled_entries(keep_state)
    return (False, np.zeros((0, 2 * n)), False, fns, rs, e0, -1.0, e0, e0, False,
            fns, rs, e0, -1.0, e0, np.zeros(n_inputs), e0, np.zeros(2 * n), e0,
            np.zeros(m), np.full(3, np.nan))


def _with_resets(blocks: Any) -> tuple[Any, ...]:
    """The blocks' kernel arguments with the reset functions after each block's
    ``(output, update)``: ``has_obs, obs_fns, obs_reset, obs_params, ...``."""
    state = blocks.kernel_state()
    (has_o, o_fns, o_par, o_per, xo, xhat, has_c, c_fns, c_par, c_per, xc, u, *rest) = state
    _, o_reset, _, _, _, c_reset, _, _ = blocks.resets()
    return (has_o, o_fns, o_reset, o_par, o_per, xo, xhat, has_c, c_fns, c_reset, c_par,
            c_per, xc, u, *rest)

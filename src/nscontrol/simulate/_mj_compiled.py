"""Moreau–Jean on a Lagrangian system with a compiled model (``system.compiled``): the
driver of the compiled loop :func:`~nscontrol.simulate._mj_compiled_kernels.mj_model_steps`
(chunks of steps, recording, errors), called by :func:`nscontrol.simulate.moreau_jean.
integrate`, whose Python path it replaces step for step.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from .._progress import TimeProgress
from ..errors import ModelError, SolverError
from .trajectory import Recorder, Trajectory

_CHUNK = 20_000


def integrate_compiled(system: Any, setup: Any, x0: Any, t_span: tuple[float, float],
                       n_full: int, h_last: float, u: Any, blocks: Any, rec: Recorder,
                       activation: float, progress: Any, listeners: Any = (),
                       model: Any = None) -> Trajectory:
    """The run of :func:`~nscontrol.simulate.moreau_jean.integrate` on the compiled path.
    The compiled loop resets the blocks itself; other listeners observe after each chunk
    (as on the Python path without a controller)."""
    from numba.core.errors import NumbaExperimentalFeatureWarning

    from . import _mj_compiled_kernels as kern
    from .moreau_jean import (
        _LCP_STATUS,
        _chunk_force,
        _end_at_input_failure,
        _record_chunk,
        _signals,
    )

    n, m = system.n_dof, system.n_contacts
    t0, tf = t_span
    h = setup.h
    n_steps = n_full + (1 if h_last > 1e-9 * h else 0)
    cm = system.compiled if model is None else model
    model = ((cm.mass,), (cm.force,), (cm.force_jacobian,), (cm.gaps,), (cm.gap_jacobian,))
    zero = np.zeros((n, n))
    K = zero if system.stiffness is None else np.ascontiguousarray(system.stiffness)
    D = zero if system.damping is None else np.ascontiguousarray(system.damping)
    S = np.ascontiguousarray(setup.Sinput if setup.Sinput is not None else np.zeros((n, 0)))
    state: dict[str, Any] = {"q": x0[:n].copy(), "v": x0[n:].copy(), "p_prev": np.zeros(m),
                             "k": 0, "t0": t0, "h": h, "reads": set()}
    p_prev = np.zeros(m)
    if blocks is not None:
        block_args = (True, blocks.Cy, *_with_resets(blocks))
    else:
        from ..systems._feedback_kernels import empty_output, keep_state, static_update

        e0 = np.zeros(0)
        fns, rs = (empty_output, static_update), (keep_state,)
        block_args = (False, np.zeros((0, 2 * n)), False, fns, rs, e0, -1.0, e0, e0, False,
                      fns, rs, e0, -1.0, e0, np.zeros(S.shape[1]), e0, np.zeros(2 * n), e0,
                      np.zeros(m), np.full(3, np.nan))
    runner = getattr(blocks, "runner", None)
    observers = [fn for fn in listeners if getattr(fn, "__self__", None) is not runner
                 or runner is None]
    info = np.zeros(2)
    status, message, code = 0, None, 0
    with TimeProgress(t0, tf, desc="moreau_jean", enable=progress) as bar:
        while state["k"] < n_steps:
            k = state["k"]
            if k == n_full:
                times, step = np.array([t0 + h * k]), h_last
            else:
                times, step = t0 + h * np.arange(k, min(n_full, k + _CHUNK)), h
            fext, failed = _chunk_force(setup, u, None, times, state)
            if failed is not None:          # run the steps before u's first failing time
                if fext.shape[0] == 0:
                    _end_at_input_failure(failed, rec, system)
                times = times[:fext.shape[0]]
            fext = np.ascontiguousarray(fext)
            q_pre, v_pre = state["q"].copy(), state["v"].copy()
            size = times.size
            q_out, v_out, p_out = np.empty((size, n)), np.empty((size, n)), np.zeros((size, m))
            XO, XC, U = blocks.log_arrays(size) if blocks is not None else \
                (np.empty((size, 0)), np.empty((size, 0)), np.empty((size, S.shape[1])))
            with warnings.catch_warnings():   # numba's first-class functions: "experimental"
                warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
                done, code = kern.mj_model_steps(  # type: ignore[call-arg]  # numba's stub
                    model, cm.params, K, D, system.constant_force, S, system.restitution,
                    step, setup.theta, setup.gamma, activation, setup.mass_at == "predicted",
                    times, q_pre, v_pre, p_prev, fext, *block_args, XO, XC, U, q_out, v_out,
                    p_out, info)
            if blocks is not None:
                blocks.log(times[:done], XO[:done], XC[:done], U[:done])
            if done:
                _record_chunk(rec, system, times[:done] + step, q_out[:done], v_out[:done],
                              p_out[:done], state, q_pre, v_pre, observers, step,
                              _signals_compiled(system, cm, q_out[:done], v_out[:done],
                                                p_out[:done], rec))
                state["q"], state["v"] = q_out[done - 1].copy(), v_out[done - 1].copy()
                state["last"] = (times[done - 1] + step, q_out[done - 1], v_out[done - 1],
                                 p_out[done - 1])
            state["k"] = k + done
            bar.update(t0 + h * state["k"])
            if failed is not None and done == times.size:   # the steps before it all ran
                _end_at_input_failure(failed, rec, system)
            if code == 0:
                continue
            t_fail = float(times[done])
            if code >= kern.BLOCKS:   # the run context attaches the steps so far
                blocks.raise_status(int(code - kern.BLOCKS), t_fail)
            if code == kern.MODEL_ERROR:
                message = (f"model: at t = {t_fail:.6g} the compiled model gave a mass matrix "
                           f"that is not positive definite or a non-finite force (q = "
                           f"{state['q']!r})")
                raise ModelError(message, trajectory=rec.finish(
                    status=-1, message=message, method="moreau_jean",
                    state_names=system.state_names))
            status = -1
            if code == kern.SINGULAR:
                message = (f"moreau_jean: the iteration matrix M(q) - hθ ∂f/∂v - h²θ² ∂f/∂q "
                           f"is singular at t = {t_fail:.6g} (reciprocal condition number "
                           f"{info[1]:.3g}); try a smaller h")
            else:
                message = (f"moreau_jean: the LCP of step {state['k']} (t = {t_fail:.6g}) "
                           f"failed: {_LCP_STATUS.get(int(code), code)}; try a smaller h, or "
                           "check the constraints for redundancy")
            break
    if "last" in state and rec.last_time < state["last"][0]:  # always keep the final state
        t_last, q_l, v_l, p_l = state["last"]
        sig = _signals(system, q_l[None], v_l[None], p_l[None], rec)
        rec.sample(t_last, np.concatenate([q_l, v_l]), force=True,
                   **{key: val[0] for key, val in sig.items()})
    stats = {"steps": int(state["k"]), "path": "compiled_model", "h": h,
             "theta": setup.theta, "forces": "implicit", "force_jacobian": "compiled"}
    traj = rec.finish(status=status, message=message, method="moreau_jean", stats=stats,
                      state_names=system.state_names)
    if "gap" in traj.signals and traj.signals["gap"].size:
        traj.stats["max_penetration"] = float(max(0.0, -np.min(traj.signals["gap"])))
    if status < 0:
        raise SolverError(str(message), status=_LCP_STATUS.get(int(code),
                                                               "singular iteration matrix"),
                          trajectory=traj)
    return traj


def _signals_compiled(system: Any, cm: Any, q: Any, v: Any, p: Any, rec: Recorder
                      ) -> dict[str, Any]:
    """``impulse``, ``gap`` and ``energy`` of a chunk with the compiled model (the Python
    path's :func:`~nscontrol.simulate.moreau_jean._signals`, without a Python call per
    step unless the model's potential has no compiled form)."""
    from numba.core.errors import NumbaExperimentalFeatureWarning

    with warnings.catch_warnings():   # numba's first-class functions: "experimental"
        warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
        return _signals_of_rows(system, cm, q, v, p, rec)


def _signals_of_rows(system: Any, cm: Any, q: Any, v: Any, p: Any, rec: Recorder
                     ) -> dict[str, Any]:
    from ._mj_compiled_kernels import gap_rows, kinetic_energy_rows, potential_rows

    out: dict[str, Any] = {}
    if rec.wants("impulse"):
        out["impulse"] = p
    if rec.wants("gap"):
        out["gap"] = gap_rows(((cm.gaps,),), cm.params, q, system.n_contacts)
    if rec.wants("energy"):
        energy = kinetic_energy_rows(((cm.mass,),), cm.params, q, v) - q @ system.constant_force
        if system.stiffness is not None:
            energy = energy + 0.5 * np.einsum("...i,ij,...j->...", q, system.stiffness, q)
        if system.potential is not None:
            if cm.potential is not None:
                energy = energy + potential_rows(((cm.potential,),), cm.params, q)
            else:
                energy = energy + np.array([system.potential(qi) for qi in q])
        out["energy"] = energy
    return out


def _with_resets(blocks: Any) -> tuple[Any, ...]:
    """The blocks' kernel arguments with the reset functions after each block's
    ``(output, update)``: ``has_obs, obs_fns, obs_reset, obs_params, ...``."""
    state = blocks.kernel_state()
    (has_o, o_fns, o_par, o_per, xo, xhat, has_c, c_fns, c_par, c_per, xc, u, *rest) = state
    _, o_reset, _, _, _, c_reset, _, _ = blocks.resets()
    return (has_o, o_fns, o_reset, o_par, o_per, xo, xhat, has_c, c_fns, c_reset, c_par,
            c_per, xc, u, *rest)

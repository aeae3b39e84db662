"""The Python blocks of a closed loop, stepped beside the plant's integrator.

:class:`BlockRunner` steps a loop's controller and observer at the start of every plant step
(zero-order hold over the step) and keeps their states and outputs for the loop's signals;
:class:`CompiledBlocks` holds the blocks' compiled forms and the state the compiled loops
carry between chunks of steps.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from .._validation import FloatArray, as_float_array, as_matrix, as_vector
from ..errors import DimensionError, ModelError
from ..systems.feedback import Jump, Measurement
from .trajectory import Trajectory

__all__ = ["BlockRunner", "CompiledBlocks", "output_matrix"]


def output_matrix(loop: Any, default: Any, n: int) -> FloatArray:
    """The loop's output matrix ``C`` (``y = C x``): given, the plant's own, or ``I``."""
    C = loop.output_matrix if loop.output_matrix is not None else default
    return np.eye(n) if C is None else as_matrix("output_matrix", C, cols=n)


class BlockRunner:
    """Steps the blocks at the start of every plant step (zero-order hold over the step).

    Continuous-time blocks advance their state by explicit Euler with the plant's step; a
    sampled block updates at its own instants ``t0 + kT`` (the first step start at or after
    each), so ``T`` should be a multiple of ``h``.
    """

    def __init__(self, loop: Any) -> None:
        from ..systems.impacting_bodies import ImpactingBodies
        from ..systems.sliding_mode import SlidingModePlant

        self.loop = loop
        p = loop.plant
        self.n = int(p.n_states)
        self.Cy = output_matrix(loop, None, self.n)
        self.perm = p.lagrangian_permutation() if isinstance(p, ImpactingBodies) else None
        self.obs, self.ctrl = loop.observer, loop.controller
        if hasattr(p, "law"):          # a LureSystem: u enters through its B
            self.Cy = output_matrix(loop, p.C, self.n)
            self.n_inputs = int(p.n_inputs)
        elif isinstance(p, SlidingModePlant):    # sampled_zoh: u enters through its B
            self.n_inputs = int(p.B.shape[1])
        else:
            mech = p.lagrangian() if isinstance(p, ImpactingBodies) else p
            self.n_inputs = mech.n_dof if mech.actuation is None else mech.actuation.shape[1]
            self.n_lam = int(mech.n_contacts)      # the size of λ̂ (compiled blocks)
        self.xo = np.zeros(0 if self.obs is None else self.obs.n_states)
        self.xc = np.zeros(0 if self.ctrl is None else self.ctrl.n_states)
        for name, block in (("observer", self.obs), ("controller", self.ctrl)):
            x_init = getattr(block, "x0", None)
            if block is not None and x_init is not None:
                setattr(self, "xo" if name == "observer" else "xc",
                        as_vector(f"{name}.x0", x_init, block.n_states))
        from . import _block_kernels as bk  # numba loads with the first closed loop
        # the sampled blocks' schedules, laid out as the compiled loops' ``sched`` (its
        # ``t_prev`` slot unused here): one rule, ``take_sample``, for both paths
        self.sched = np.full(bk.SCHED_SIZE, np.nan)
        self.slot = {"observer": bk.SLOT_OBSERVER, "controller": bk.SLOT_CONTROLLER}
        self.take_sample = bk.take_sample
        # a continuous block's last Measurement, a sampled block's held output ("<role>_out")
        self.held: dict[str, Any] = {}
        self.t_prev: float | None = None
        self.log: list[tuple[float, FloatArray, FloatArray, FloatArray | None]] = []
        # what a compiled loop logged instead: (times, xo, xc, u) arrays per chunk
        self.chunks: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = []

    def step(self, t: float, q: FloatArray, v: FloatArray, lam_hat: Any = None,
             active: Any = None) -> FloatArray:
        x = np.concatenate([q, v])
        if self.perm is not None:      # the plant's own state order for the blocks
            back = np.empty_like(x)
            back[self.perm] = x
            x = back
        return self.step_state(t, x, lam_hat, active)

    def step_state(self, t: float, x: FloatArray, lam_hat: Any = None,
                   active: Any = None) -> FloatArray:
        """The blocks at the start of a step of a plant in state ``x``; returns ``u``."""
        h = 0.0 if self.t_prev is None else t - self.t_prev
        self.t_prev = t
        w = None if self.loop.exosystem is None else np.atleast_1d(
            self.loop.exosystem.u(np.array([t]))[0])
        m = Measurement(t, y=self.Cy @ x, x=x, lam=None if lam_hat is None else
                        np.asarray(lam_hat, float), active=active, w=w)
        xhat = None
        if self.obs is not None:
            self.xo, xhat = self._advance("observer", self.obs, self.xo, t, h, m)
            m = Measurement(m.t, m.y, m.x, xhat, m.lam, m.active, m.w)   # replace() is slow
        u = np.zeros(self.n_inputs)      # an observer alone leaves the plant unforced
        if self.ctrl is not None:
            self.xc, u = self._advance("controller", self.ctrl, self.xc, t, h, m)
        self.log.append((t, self.xo.copy(), self.xc.copy(), u.copy()))
        return u

    def _advance(self, role: str, block: Any, xb: FloatArray, t: float, h: float,
                 m: Measurement) -> tuple[FloatArray, FloatArray]:
        period = block.period
        if period is None:           # continuous: explicit Euler over the previous step
            if h > 0.0 and role in self.held:
                xb = xb + h * _finite(role, block.update(t - h, xb, self.held[role]),
                                      xb.size, t)
            self.held[role] = m
            return xb, _finite(role, block.output(t, xb, m), None, t)
        if self.take_sample(self.sched, self.slot[role], float(t), float(period)):
            out = _finite(role, block.output(t, xb, m), None, t)
            xb = _finite(role, block.update(t, xb, m), xb.size, t)
            self.held[role + "_out"] = out
        return xb, self.held[role + "_out"]

    def on_jump(self, t: float, x_minus: FloatArray, x_plus: FloatArray, indices: Any,
                impulse: Any) -> None:
        jump = Jump(t, np.asarray(x_minus), np.asarray(x_plus), np.asarray(indices), impulse)
        if self.obs is not None:
            self.xo = _finite("observer", self.obs.reset(t, self.xo, jump), self.xo.size, t)
        if self.ctrl is not None:
            self.xc = _finite("controller", self.ctrl.reset(t, self.xc, jump), self.xc.size,
                              t)

    def finish(self, traj: Trajectory) -> Trajectory:
        """The blocks' states and outputs as signals, held over each step (ZOH)."""
        if not self.log and not self.chunks:
            return traj
        if self.chunks:
            columns = [np.concatenate([c[i] for c in self.chunks]) for i in range(4)]
        else:
            columns = [np.array([row[i] for row in self.log]) for i in range(4)]
        times = columns[0]
        # sample k (end of step k) shows what acted over step k: the value logged at its start
        # (a sample that rounding puts just past the next step start, t0 + k h + h vs
        # t0 + (k + 1) h, still shows step k: compare a millionth of a step earlier)
        eps = 1e-6 * float(np.min(np.diff(times))) if times.size > 1 else 0.0
        idx = np.clip(np.searchsorted(times, traj.t - eps, side="left") - 1, 0,
                      len(times) - 1)
        signals = dict(traj.signals)
        for name, col in (("xo", 1), ("xc", 2), ("u", 3)):
            rows = columns[col]
            if rows.ndim == 2 and rows.shape[1]:
                signals[name] = rows[idx]
        if self.obs is not None:
            E = getattr(self.obs, "E", None)
            xo = signals["xo"]
            signals["xhat"] = xo @ E.T if E is not None else xo
        return replace(traj, signals=signals)


class CompiledBlocks:
    """The compiled forms of a loop's blocks and the state the compiled loops carry between
    chunks of steps (the Python runner's ``xo``, ``xc``, held outputs and sampling
    instants, as arrays). The integrator calls :meth:`kernel_state`, :meth:`log_arrays`,
    :meth:`log` and :meth:`raise_status`."""

    def __init__(self, runner: BlockRunner, obs: Any, ctrl: Any) -> None:
        from ..systems._feedback_kernels import empty_output, keep_state, static_update

        self.runner = runner
        self.Cy = np.ascontiguousarray(runner.Cy, dtype=float)
        n, p = int(runner.n), self.Cy.shape[0]
        empty = np.zeros(0)
        n_lam = int(getattr(runner, "n_lam", 0))

        def parts(block: Any, form: Any, xb: FloatArray, n_out: int) -> tuple[Any, ...]:
            if form is None:
                return (False, empty_output, static_update, keep_state, empty, -1.0,
                        np.zeros(0), np.zeros(0))
            period = -1.0 if block.period is None else float(block.period)
            return (True, form.output, form.update, form.reset, form.params, period,
                    np.array(xb, dtype=float), np.zeros(n_out))
        o = parts(runner.obs, obs, runner.xo, 0 if runner.obs is None else
                  int(runner.obs.n_outputs))
        c = parts(runner.ctrl, ctrl, runner.xc, int(runner.n_inputs))
        self.obs_parts, self.ctrl_parts = o, c
        self.prev = (np.zeros(p), np.zeros(n), np.zeros(o[7].size), np.zeros(n_lam))
        from . import _block_kernels as bk

        self.sched = np.full(bk.SCHED_SIZE, np.nan)
        if not c[0]:
            self.ctrl_parts = c[:7] + (np.zeros(int(runner.n_inputs)),)

    @classmethod
    def of(cls, runner: BlockRunner) -> CompiledBlocks | None:
        """The compiled blocks of the runner's loop, or ``None`` if a block has no compiled
        form (or the loop has an exosystem, which the compiled loops do not read)."""
        from ..systems.feedback import compiled_form

        if runner.loop.exosystem is not None or not runner.loop.compiled:
            return None
        obs, ctrl = compiled_form(runner.obs), compiled_form(runner.ctrl)
        if (runner.obs is not None and obs is None) or (runner.ctrl is not None and
                                                        ctrl is None):
            return None
        return cls(runner, obs, ctrl)

    def kernel_state(self) -> tuple[Any, ...]:
        """``has_obs, obs_out, obs_upd, obs_params, obs_period, xo, xhat, has_ctrl, ...,
        u, prev_y, prev_x, prev_xhat, prev_lam, sched`` for
        :func:`~nscontrol.simulate._block_kernels.step_blocks`."""
        o, c = self.obs_parts, self.ctrl_parts
        return (o[0], (o[1], o[2]), o[4], o[5], o[6], o[7], c[0], (c[1], c[2]), c[4], c[5],
                c[6], c[7], *self.prev, self.sched)

    def resets(self) -> tuple[Any, ...]:
        """``has_obs, obs_reset, obs_params, xo, has_ctrl, ctrl_reset, ctrl_params, xc`` for
        :func:`~nscontrol.simulate._block_kernels.reset_blocks`."""
        o, c = self.obs_parts, self.ctrl_parts
        return (o[0], (o[3],), o[4], o[6], c[0], (c[3],), c[4], c[6])

    def log_arrays(self, k: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Empty logs for ``k`` steps: the blocks' states and ``u`` at each step start."""
        return (np.empty((k, self.obs_parts[6].size)), np.empty((k, self.ctrl_parts[6].size)),
                np.empty((k, self.ctrl_parts[7].size)))

    def log(self, times: FloatArray, xo: FloatArray, xc: FloatArray, u: FloatArray) -> None:
        """Keep a chunk's log for the loop's signals; the runner's states follow."""
        if times.size:
            self.runner.chunks.append((np.array(times), xo.copy(), xc.copy(), u.copy()))
        self.runner.xo, self.runner.xc = self.obs_parts[6].copy(), self.ctrl_parts[6].copy()

    def raise_status(self, status: int, t: float) -> None:
        """The error the Python path raises for a block's failure at ``t``."""
        from . import _block_kernels as bk

        role = "observer" if status in (bk.STATUS_OBSERVER_SIZE,
                                        bk.STATUS_OBSERVER_NONFINITE,
                                        bk.STATUS_OBSERVER_OUTPUT_SIZE) else "controller"
        if status in (bk.STATUS_OBSERVER_SIZE, bk.STATUS_CONTROLLER_SIZE):
            raise DimensionError(f"{role}: update returned a state of the wrong length (at "
                                 f"t = {t:.6g})")
        if status == bk.STATUS_CONTROLLER_OUTPUT_SIZE:
            raise ModelError(f"controller: expected a finite input of length "
                             f"{self.ctrl_parts[7].size} at t = {t:.6g}")
        if status == bk.STATUS_OBSERVER_OUTPUT_SIZE:
            raise DimensionError(f"observer: output returned an estimate of the wrong length, "
                                 f"expected {self.obs_parts[7].size} (at t = {t:.6g})")
        raise ModelError(f"{role}: returned a non-finite value at t = {t:.6g}")


def _all_finite(a: FloatArray) -> bool:
    """``np.isfinite(a).all()``, without numpy's reduction overhead for the few entries a
    block returns at every step."""
    if a.size <= 8:
        return all(map(math.isfinite, a.tolist()))
    return bool(np.isfinite(a).all())


def _finite(role: str, value: Any, size: int | None, t: float) -> FloatArray:
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":   # the usual case, fast
        out = value.astype(float, copy=False).reshape(-1)
    else:        # numpy would parse a string '1.0': refuse anything that is not numeric
        try:
            out = as_float_array(role, value, finite=False).reshape(-1)
        except ModelError as err:
            raise ModelError(f"{err} (returned by the block at t = {t:.6g}); its output and "
                             f"update must return numeric arrays") from None
    if size is not None and out.size != size:
        raise DimensionError(f"{role}: update or reset returned {out.size} values, its state "
                             f"has {size} (at t = {t:.6g})")
    if not _all_finite(out):
        raise ModelError(f"{role}: returned a non-finite value at t = {t:.6g}: {out!r}")
    return out

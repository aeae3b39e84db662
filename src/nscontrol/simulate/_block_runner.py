"""The Python blocks of a closed loop, stepped beside the plant's integrator.

:class:`BlockRunner` steps a loop's controller and observer at the start of every plant step
(zero-order hold over the step) and keeps their states and outputs for the loop's signals;
:class:`CompiledBlocks` holds the blocks' compiled forms and the state the compiled loops
carry between chunks of steps.
"""

from __future__ import annotations

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
    each), so ``T`` should be a multiple of ``h``. The stepping is the compiled loops' own
    (:func:`~nscontrol.simulate._block_kernels.step_blocks` and ``reset_blocks``, run as
    Python); this class gives it the blocks' methods in the compiled forms' signature.
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
        self.n_lam = 0                  # the size of λ̂
        if hasattr(p, "law"):          # a LureSystem: u enters through its B
            self.Cy = output_matrix(loop, p.C, self.n)
            self.n_inputs = int(p.n_inputs)
        elif isinstance(p, SlidingModePlant):    # sampled_zoh: u enters through its B
            self.n_inputs = int(p.B.shape[1])
        else:
            mech = p.lagrangian() if isinstance(p, ImpactingBodies) else p
            self.n_inputs = mech.n_dof if mech.actuation is None else mech.actuation.shape[1]
            self.n_lam = int(mech.n_contacts)
        self.xo = np.zeros(0 if self.obs is None else self.obs.n_states)
        self.xc = np.zeros(0 if self.ctrl is None else self.ctrl.n_states)
        for name, block in (("observer", self.obs), ("controller", self.ctrl)):
            x_init = getattr(block, "x0", None)
            if block is not None and x_init is not None:
                setattr(self, "xo" if name == "observer" else "xc",   # stepped in place
                        np.array(as_vector(f"{name}.x0", x_init, block.n_states)))
        self.log: list[tuple[float, FloatArray, FloatArray, FloatArray | None]] = []
        # what a compiled loop logged instead: (times, xo, xc, u) arrays per chunk
        self.chunks: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = []
        self._kernel_arguments()

    def _kernel_arguments(self) -> None:
        """The stepper's arguments for the Python blocks: their methods adapted to the
        compiled forms' signature, the held outputs, the last step's measurement, the
        sampling schedule (see :mod:`._block_kernels`)."""
        from ._block_kernels import SCHED_SIZE, python_form  # numba: with the first loop

        self._step, self._reset = python_form("step_blocks"), python_form("reset_blocks")
        self.sched = np.full(SCHED_SIZE, np.nan)
        self.xhat = np.zeros(0 if self.obs is None else _n_outputs(self.obs))
        self.u = np.zeros(self.n_inputs)    # an observer alone leaves the plant unforced
        self.prev = (np.zeros(self.Cy.shape[0]), np.zeros(self.n), np.zeros(self.xhat.size),
                     np.zeros(self.n_lam))
        # what the arrays do not carry (lam given, active, w), this step's and the last's
        self.now: tuple[bool, Any, Any] = (False, None, None)
        self.before = self.now
        self.jump: Jump | None = None
        self.last: Any = None           # the value a block returned last (for its error)
        self._cached: tuple[Any, ...] = (None, None, None, None)
        self.blocks: list[tuple[bool, tuple[Any, Any, Any], float]] = []
        for role, block in (("observer", self.obs), ("controller", self.ctrl)):
            period = -1.0 if block is None or getattr(block, "period", None) is None \
                else float(block.period)
            self.blocks.append((block is not None, self._adapted(role, block), period))

    def _adapted(self, role: str, block: Any) -> tuple[Any, Any, Any]:
        """``output``, ``update`` and ``reset`` of a Python block with the compiled forms'
        arguments (``params`` unused); their values are numeric arrays or an error."""
        def output(t: float, xb: FloatArray, y: FloatArray, x: FloatArray, xhat: FloatArray,
                   lam: FloatArray, params: Any) -> FloatArray:
            self.last = _numeric(role, block.output(t, xb, self._measure(t, y, x, xhat, lam)),
                                 t)
            return self.last

        def update(t: float, xb: FloatArray, y: FloatArray, x: FloatArray, xhat: FloatArray,
                   lam: FloatArray, params: Any) -> FloatArray:
            self.last = _numeric(role, block.update(t, xb, self._measure(t, y, x, xhat, lam)),
                                 t)
            return self.last

        def reset(t: float, xb: FloatArray, x_minus: Any, x_plus: Any, impulse: Any,
                  params: Any) -> FloatArray:
            self.last = _numeric(role, block.reset(t, xb, self.jump), t)
            return self.last
        return output, update, reset

    def _measure(self, t: float, y: FloatArray, x: FloatArray, xhat: FloatArray,
                 lam: FloatArray) -> Measurement:
        """The :class:`Measurement` of the stepper's arrays (built once for a block's
        output and update at the same instant)."""
        cached = self._cached
        if cached[0] is y and cached[1] is xhat and cached[2] == t:
            return cached[3]
        given, active, w = self.before if y is self.prev[0] else self.now
        m = Measurement(t, y, x, xhat.copy() if xhat.size else None, lam if given else None,
                        active, w)
        self._cached = (y, xhat, t, m)
        return m

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
        t = float(t)
        w = None if self.loop.exosystem is None else np.atleast_1d(
            self.loop.exosystem.u(np.array([t]))[0])
        lam = _EMPTY if lam_hat is None else np.asarray(lam_hat, dtype=float).reshape(-1)
        if lam.size != self.prev[3].size:
            self.prev = (*self.prev[:3], np.zeros(lam.size))
        self.before, self.now = self.now, (lam_hat is not None, active, w)
        (has_o, o_fns, o_per), (has_c, c_fns, c_per) = self.blocks
        # the stepper moves the states in place: on copies, so that a state read before
        # the step (a caller's, a block's own argument) keeps its value
        self.xo, self.xc = self.xo.copy(), self.xc.copy()
        status = self._step(t, x, self.Cy @ x, lam, has_o, o_fns, None, o_per, self.xo,
                            self.xhat, has_c, c_fns, None, c_per, self.xc, self.u, *self.prev,
                            self.sched)
        if status:
            raise block_error(status, t, self.sizes(), value=self.last)
        self.log.append((t, self.xo.copy(), self.xc.copy(), self.u.copy()))
        return self.u.copy()           # the integrator's own: the held buffer moves on

    def on_jump(self, t: float, x_minus: FloatArray, x_plus: FloatArray, indices: Any,
                impulse: Any) -> None:
        self.jump = Jump(t, np.asarray(x_minus), np.asarray(x_plus), np.asarray(indices),
                         impulse)
        (has_o, o_fns, _), (has_c, c_fns, _) = self.blocks
        self.xo, self.xc = self.xo.copy(), self.xc.copy()      # as in step_state
        status = self._reset(t, x_minus, x_plus, impulse, has_o, o_fns[2:], None, self.xo,
                             has_c, c_fns[2:], None, self.xc)
        if status:
            raise block_error(status, t, self.sizes(), "reset", self.last)

    @property
    def held(self) -> dict[str, FloatArray]:
        """The outputs held since the blocks' last samples (``<role>_out``)."""
        return {"observer_out": self.xhat, "controller_out": self.u}

    def sizes(self) -> tuple[int, int, int, int]:
        """The observer's state and estimate, the controller's state and ``u``: lengths."""
        return self.xo.size, self.xhat.size, self.xc.size, self.u.size

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
    """The compiled forms of a loop's blocks, stepped on the runner's own state (its ``xo``,
    ``xc``, held outputs, last measurement and sampling schedule, which the compiled loops
    carry between chunks of steps). The integrator calls :meth:`kernel_state`,
    :meth:`resets`, :meth:`log_arrays`, :meth:`log` and :meth:`raise_status`."""

    def __init__(self, runner: BlockRunner, obs: Any, ctrl: Any) -> None:
        from ..systems._feedback_kernels import (
            compiled_entries,
            empty_output,
            keep_state,
            static_update,
        )

        self.runner = runner
        self.Cy = np.ascontiguousarray(runner.Cy, dtype=float)

        def parts(form: Any, period: float) -> tuple[Any, ...]:
            if form is None:
                return (False, empty_output, static_update, keep_state, _EMPTY, -1.0)
            return (True, form.output, form.update, form.reset, form.params, period)
        (_, _, o_period), (_, _, c_period) = runner.blocks
        self._obs, self._ctrl = parts(obs, o_period), parts(ctrl, c_period)
        # the kernels' first-class functions, typed once (not at every call of a loop)
        self._fns = (compiled_entries(*self._obs[1:3]), compiled_entries(*self._ctrl[1:3]),
                     compiled_entries(self._obs[3]), compiled_entries(self._ctrl[3]))

    @property
    def obs_parts(self) -> tuple[Any, ...]:
        """``has, output, update, reset, params, period, xo, xhat`` of the observer."""
        return (*self._obs, self.runner.xo, self.runner.xhat)

    @property
    def ctrl_parts(self) -> tuple[Any, ...]:
        """``has, output, update, reset, params, period, xc, u`` of the controller."""
        return (*self._ctrl, self.runner.xc, self.runner.u)

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
        """``has_obs, obs_fns, obs_params, obs_period, xo, xhat, has_ctrl, ..., u, prev_y,
        prev_x, prev_xhat, prev_lam, sched`` for
        :func:`~nscontrol.simulate._block_kernels.step_blocks`."""
        r, o, c = self.runner, self.obs_parts, self.ctrl_parts
        return (o[0], self._fns[0], o[4], o[5], o[6], o[7], c[0], self._fns[1], c[4], c[5],
                c[6], c[7], *r.prev, r.sched)

    def resets(self) -> tuple[Any, ...]:
        """``has_obs, obs_reset, obs_params, xo, has_ctrl, ctrl_reset, ctrl_params, xc`` for
        :func:`~nscontrol.simulate._block_kernels.reset_blocks`."""
        o, c = self.obs_parts, self.ctrl_parts
        return (o[0], self._fns[2], o[4], o[6], c[0], self._fns[3], c[4], c[6])

    def log_arrays(self, k: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Empty logs for ``k`` steps: the blocks' states and ``u`` at each step start."""
        r = self.runner
        return np.empty((k, r.xo.size)), np.empty((k, r.xc.size)), np.empty((k, r.u.size))

    def log(self, times: FloatArray, xo: FloatArray, xc: FloatArray, u: FloatArray) -> None:
        """Keep a chunk's log for the loop's signals."""
        if times.size:
            self.runner.chunks.append((np.array(times), xo.copy(), xc.copy(), u.copy()))

    def raise_status(self, status: int, t: float) -> None:
        """The error the Python path raises for a block's failure at ``t``."""
        raise block_error(status, t, self.runner.sizes())


_EMPTY = np.zeros(0)


def block_error(status: int, t: float, sizes: tuple[int, int, int, int],
                what: str = "update", value: Any = None) -> Exception:
    """The error for a status of the block stepper (``STATUS_*`` of
    :mod:`._block_kernels`) at ``t``: one message per status for the compiled and the Python
    blocks. ``sizes``: the observer's state and estimate, the controller's state and
    ``u``; ``what``: the method that returned the state; ``value``: what the block returned
    last, when known (a Python block's)."""
    from ._block_kernels import (
        STATUS_CONTROLLER_OUTPUT_SIZE,
        STATUS_CONTROLLER_SIZE,
        STATUS_OBSERVER_NONFINITE,
        STATUS_OBSERVER_OUTPUT_SIZE,
        STATUS_OBSERVER_SIZE,
    )

    n_xo, n_xhat, n_xc, n_u = sizes
    role = "observer" if status in (STATUS_OBSERVER_SIZE, STATUS_OBSERVER_NONFINITE,
                                    STATUS_OBSERVER_OUTPUT_SIZE) else "controller"
    got = "" if value is None else f": it returned {np.size(value)} values"
    if status in (STATUS_OBSERVER_SIZE, STATUS_CONTROLLER_SIZE):
        n = n_xo if role == "observer" else n_xc
        has = "" if value is None else f", its state has {n}"
        return DimensionError(f"{role}: {what} returned a state of the wrong length (at "
                              f"t = {t:.6g}){got}{has}")
    if status == STATUS_CONTROLLER_OUTPUT_SIZE:
        return ModelError(f"controller: expected a finite input of length {n_u} at "
                          f"t = {t:.6g}{'' if value is None else f', got {value!r}'}")
    if status == STATUS_OBSERVER_OUTPUT_SIZE:
        return DimensionError(f"observer: output returned an estimate of the wrong length, "
                              f"expected {n_xhat} (at t = {t:.6g}){got}")
    shown = value is not None and not np.all(np.isfinite(value))
    return ModelError(f"{role}: returned a non-finite value at t = {t:.6g}"
                      f"{f': {value!r}' if shown else ''}")


def _n_outputs(block: Any) -> int:
    """The length of an observer's estimate (its ``n_outputs``)."""
    n = getattr(block, "n_outputs", None)
    if n is None:
        raise ModelError(f"observer: expected n_outputs, the length of its estimate x̂ (see "
                         f"nscontrol.systems.feedback.Observer), got a "
                         f"{type(block).__name__} without it")
    return int(n)


def _numeric(role: str, value: Any, t: float) -> FloatArray:
    """A block's value as a flat float array; anything that is not numeric is refused
    (numpy would parse a string '1.0')."""
    if type(value) is np.ndarray and value.dtype.char == "d" and value.ndim == 1:
        return value                    # the usual case, fast
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        return value.astype(float).reshape(-1)
    try:
        return as_float_array(role, value, finite=False).reshape(-1)
    except ModelError as err:
        raise ModelError(f"{err} (returned by the block at t = {t:.6g}); its output and "
                         f"update must return numeric arrays") from None

"""A chunk of steps by the solver path planned for the run: the compiled closed form, the
compiled per-step LCP, the Python inclusion solver, and a closed loop's blocks (compiled in
the closed form's loop, or the Python runner held over each step).

Each path writes its steps into ``X``, ``Z``, ``W`` (state, law argument, multiplier after
each step). A path that fails puts the verified steps before the failure in
:attr:`Steps.progress` (an error of the user's, ``KeyboardInterrupt``) or on the
:class:`~nscontrol.errors.SolverError` it raises (``err.partial``), so that the run keeps
them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError, SolverError
from ..trajectory import ChunkProgress, evaluable_prefix
from ._inclusion import solve_inclusion_python
from ._plan import Setup

__all__ = ["LCP_TOL", "Steps"]

#: Acceptance of a per-step LCP solution (natural residual, relative to ``1 + max|q|``).
LCP_TOL = 1e-10
_RESIDUAL_FAILURE = 3  # NUMERICAL_FAILURE of the LCP kernels: residual check failed
_LEMKE_STATUS = {1: "ray_termination", 2: "max_iter", 3: "residual"}

Rows = tuple[FloatArray, FloatArray, FloatArray]


def _exosystem_mean(exo: Any, h: float) -> FloatArray:
    """``Ψ/h`` with ``Ψ = ∫_0^h e^{Sτ} dτ``: the mean of ``ω`` over a step is ``(Ψ/h) ω(t_k)``
    (top-right block of the exponential of ``[[S, I], [0, 0]] h``)."""
    from scipy.linalg import expm

    S = np.atleast_2d(np.asarray(exo.S, float))
    r = S.shape[0]
    M = np.zeros((2 * r, 2 * r))
    M[:r, :r], M[:r, r:] = S, np.eye(r)
    return expm(M * h)[:r, r:] / h


def _with_partial(err: SolverError, rows: Rows, k: int) -> SolverError:
    """``err`` carrying the first ``k`` verified steps of ``rows`` (``err.partial``)."""
    err.partial = tuple(r[:k] for r in rows)  # type: ignore[attr-defined]  # added at raise
    return err


class Steps:
    """Runs chunks of steps with the solver chosen once for the whole run."""

    def __init__(self, system: Any, setup: Setup) -> None:
        mats = setup.mats
        self.system, self.m, self.plan = system, mats, setup.plan
        self.worst = 0.0   # largest accepted per-step residual (LCP / Python paths)
        self.progress = ChunkProgress()   # the chunk in progress (see Recorder.chunk)
        u = system.u
        self.exo = None
        if system.has_input and all(hasattr(u, a) for a in ("S", "Cu", "w0", "w")):
            self.exo = u
            self.mean = _exosystem_mean(u, mats.h).T @ np.atleast_2d(np.asarray(u.Cu, float)).T
        self.input_mode = ("exact_mean" if self.exo is not None else
                           "samples" if system.has_input else "none")
        if setup.spec is not None:   # the closed form's law data
            self.spec, self.curve, self.ucol = setup.spec, setup.curve, setup.ucol

    def _buffers(self, k: int) -> Rows:
        n, mm = self.system.n_states, self.system.n_multipliers
        return np.empty((k, n)), np.empty((k, mm)), np.empty((k, mm))

    def _shifts(self, times: FloatArray) -> FloatArray:
        """``g(t_{k+1})`` of each step over ``times``."""
        sys_ = self.system
        return np.ascontiguousarray(sys_.shift_at(times[1:]), dtype=float) if sys_.has_shift \
            else np.zeros((times.size - 1, sys_.n_multipliers))

    def _inputs(self, times: FloatArray) -> FloatArray:
        sys_, th = self.system, self.m.theta
        if self.exo is not None:   # exact mean of the input over each step
            ubar = np.atleast_2d(self.exo.w(times[:-1])).reshape(times.size - 1, -1) @ self.mean
        elif sys_.has_input:
            U = sys_.input_at(times)
            ubar = (1.0 - th) * U[:-1] + th * U[1:]
        else:
            ubar = np.zeros((times.size - 1, max(sys_.n_inputs, 0)))
        return np.ascontiguousarray(ubar)

    # -- the plant's own input ---------------------------------------------------------------
    def run(self, x: FloatArray, times: FloatArray) -> Rows:
        """The steps over ``times`` with the system's input (its samples are taken first;
        an input that raises keeps the steps before its first failing time)."""
        try:
            ubar, gnext = self._inputs(times), self._shifts(times)
        except Exception:
            self._run_until_input_fails(x, times)
            raise
        rows = self.solve(x, times, ubar, gnext)
        self.progress.rows, self.progress.done = rows, times.size - 1   # kept if interrupted
        return rows

    def _run_until_input_fails(self, x: FloatArray, times: FloatArray) -> None:
        """The steps of a chunk whose input cannot be evaluated over it whole (``u``
        raised): those before the first time it fails at (found by bisection on prefixes of
        ``times``) are run into :attr:`progress`, kept when the caller's error goes on
        (``times[:k]`` gives the inputs of the ``k - 1`` steps it spans)."""
        ok = evaluable_prefix(lambda k: self._inputs(times[:k]), times.size)
        if ok >= 2:
            self.progress.rows = self.run(x, times[:ok])
            self.progress.done = ok - 1

    def solve(self, x: FloatArray, times: FloatArray, ubar: FloatArray, gnext: FloatArray,
              out: Rows | None = None) -> Rows:
        """The steps over ``times`` with the input means ``ubar`` and shifts ``gnext``, by the
        planned solver, into ``out`` (new buffers by default)."""
        rows = self._buffers(times.size - 1) if out is None else out
        if self.plan.solver == "closed_form":
            from ._lure_kernels import triangular_steps

            m, plan, (kind, p1, p2) = self.m, self.plan, self.spec
            triangular_steps(m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, plan.order,
                             plan.structure != "diagonal", kind, p1, p2, self.curve,
                             self.system.H, self.ucol, x, ubar, gnext, *rows)
        elif self.plan.solver == "lcp":
            self._lcp(x, times, ubar, gnext, rows)
        else:
            self._python(x, ubar, gnext, rows, track=out is None)
        return rows

    def _lcp(self, x: FloatArray, times: FloatArray, ubar: FloatArray, gnext: FloatArray,
             rows: Rows) -> None:
        """The compiled per-step LCP (Lemke, each solution verified)."""
        from ._lure_lcp_kernels import lcp_steps

        m, plan = self.m, self.plan
        if plan.lcp is None:   # the plan sets the LCP data whenever it chooses "lcp"
            raise ModelError("law: the LCP step was planned without its LCP data")
        done, status, res = lcp_steps(  # type: ignore[call-arg]  # numba's stub: 1 tuple
            m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, *plan.lcp, x, ubar, gnext, *rows,
            LCP_TOL)
        if status == 0:
            self.worst = max(self.worst, float(res))
            return
        name = _LEMKE_STATUS.get(int(status), str(status))
        why = (f"Lemke stopped with status {name!r}" if status != _RESIDUAL_FAILURE
               else f"its natural residual {res:.3g} is above {LCP_TOL:g}")
        raise _with_partial(SolverError(
            f"implicit_euler: the one-step LCP at t = {times[done + 1]:.6g} has no verified "
            f"solution: {why}; the step matrix may be badly conditioned (reduce h)",
            status=name), rows, done)

    def _python(self, x: FloatArray, ubar: FloatArray, gnext: FloatArray, rows: Rows, *,
                track: bool) -> None:
        """One inclusion per step in Python, block by block in dependency order (``track``:
        count the finished steps in :attr:`progress`; not when the caller owns it)."""
        m, plan, H = self.m, self.plan, self.system.H
        X, Z, W = rows
        mm = self.system.n_multipliers
        for j in range(ubar.shape[0]):
            q = m.Phi @ x + m.Gam @ ubar[j]
            a = H @ q + gnext[j]
            w = np.zeros(mm)
            z = np.empty(mm)
            try:
                for blk in plan.blocks:   # in dependency order: earlier blocks are solved
                    ag = a[blk.idx] + plan.D[blk.idx] @ w   # w of this and later blocks is 0
                    zg, wg, res = solve_inclusion_python(blk.law, ag, blk.D)
                    w[blk.idx], z[blk.idx] = wg, zg
                    self.worst = max(self.worst, res)
            except SolverError as exc:
                raise _with_partial(exc, rows, j) from None
            x = q + m.Gh @ w
            X[j], Z[j], W[j] = x, z, w
            if track:
                self.progress.rows, self.progress.done = rows, j + 1

    # -- a closed loop's blocks --------------------------------------------------------------
    def run_with_runner(self, x: FloatArray, times: FloatArray, runner: Any) -> Rows:
        """Steps over ``times`` one at a time, the input the loop's blocks give at each step
        start (``runner.step_state``, which checks it) held over the step (zero-order
        hold)."""
        rows = X, Z, W = self._buffers(times.size - 1)
        self.progress.rows = rows
        gnext = self._shifts(times)
        for j in range(times.size - 1):
            u = runner.step_state(float(times[j]), x.copy())
            try:
                self.solve(x, times[j:j + 2], u[None, :], gnext[j:j + 1],
                           (X[j:j + 1], Z[j:j + 1], W[j:j + 1]))
            except SolverError as exc:
                raise _with_partial(exc, rows, j) from None
            x = X[j]
            self.progress.rows, self.progress.done = rows, j + 1
        return rows

    def run_with_blocks(self, x: FloatArray, times: FloatArray, blocks: Any) -> Rows:
        """Steps over ``times`` in one compiled loop with the compiled blocks of a closed loop
        (``blocks``, a :class:`~nscontrol.simulate._block_runner.CompiledBlocks`): the same
        operations, in the same order, as :meth:`run_with_runner` with the blocks' Python
        methods."""
        from ...systems._feedback_kernels import calling_blocks
        from ._lure_kernels import controlled_steps

        k = times.size - 1
        rows = self._buffers(k)
        gnext = self._shifts(times)
        XO, XC, U = blocks.log_arrays(k)
        m, plan, (kind, p1, p2) = self.m, self.plan, self.spec
        with calling_blocks():      # a block's error raised from the call
            done, status = controlled_steps(  # type: ignore[call-arg]  # numba's stub: 1 tuple
                m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, plan.order,
                plan.structure != "diagonal", kind, p1, p2, self.curve, self.system.H,
                self.ucol, blocks.Cy, times, np.ascontiguousarray(x, dtype=float), gnext,
                *rows, *blocks.kernel_state(), XO, XC, U)
            # kept before a block's own error is raised: the steps before it stay recorded
            blocks.log(times[:done], XO[:done], XC[:done], U[:done])
            self.progress.rows, self.progress.done = rows, int(done)
        if status != 0:
            blocks.raise_status(int(status), float(times[done]))
        return rows

"""One Moreau–Jean run as a stepper of :func:`nscontrol.simulate.loop.drive`: whichever
runner steps (:mod:`._runners`, :mod:`._python_runner`, :mod:`._compiled`), :class:`Run`
advances it a chunk of steps at a time, records the chunk into the record ``drive`` holds
and calls the listeners; ``drive`` freezes the trajectory."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any, NoReturn

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError
from ..loop import END, Recording, Stop
from ..trajectory import Recorder, evaluable_prefix
from ._options import Feedback, MoreauJeanOptions, input_matrix
from ._paths import choose_runner
from ._recording import jump_listener, record_chunk, record_finished, sample_initial, signals_of
from ._runners import LCP_STATUS, DenseRunner, Runner, RunState

__all__ = ["Run"]

#: Floats per chunk of the compiled loop (bounds memory for large systems).
_CHUNK_FLOATS = 2_000_000


class Grid:
    """Whole steps of ``h`` from ``t0``, then one shorter step so that the run ends exactly
    at ``tf`` (read at every chunk: computed once; a plain class, built at every run)."""

    __slots__ = ("t0", "tf", "h", "n_full", "h_last", "n_steps")

    def __init__(self, t0: float, tf: float, h: float) -> None:
        self.t0, self.tf, self.h = t0, tf, h
        #: whole steps of ``h``
        self.n_full = math.floor((tf - t0) / h + 1e-9)
        #: the shortened last step's length
        self.h_last = (tf - t0) - self.n_full * h
        #: steps in all
        self.n_steps = self.n_full + (1 if self.h_last > 1e-9 * h else 0)


class Run:
    """One run over a chunk loop (a :class:`~nscontrol.simulate.loop.Stepper`): whichever
    runner steps, this records, calls the listeners and ends the run on a failure."""

    def __init__(self, system: Any, x0: FloatArray, t_span: tuple[float, float],
                 opts: MoreauJeanOptions, feedback: Feedback) -> None:
        n, m = system.n_dof, system.n_contacts
        self.system, self.opts, self.fb = system, opts, feedback
        self.grid = Grid(t_span[0], t_span[1], opts.h)
        self.recording = Recording(
            system.n_states, every=opts.record_every, signals=opts.signals,
            offered=("impulse", "gap", "energy"), state_names=system.state_names,
            capacity=Recorder.capacity_for(self.grid.n_steps + 2, opts.record_every))
        self.x0 = x0
        self.S = input_matrix(system, opts.u is not None or feedback.blocks is not None)
        self.runner = first_runner(system, opts, feedback, self.S)
        self.path = self.runner.path
        self.state = RunState(q=x0[:n].copy(), v=x0[n:].copy(), p_prev=np.zeros(m))
        if feedback.blocks is not None and self.path != "compiled_model":
            # the Python blocks: their input before each step, their reset (and the other
            # listeners, in their order) after a step with an impact
            assert self.S is not None   # blocks always set the input matrix
            self.state.inline = blocks_input(feedback.blocks, self.S, opts.h)
            self.state.after_step = jump_listener(system, feedback.listeners)

    def start(self, rec: Recorder) -> None:
        """Keep the run's record; the initial state is held back, to be recorded with the
        first chunk (one evaluation of the signals and one write for both), or by
        :meth:`settle` if the run ends before."""
        self.rec = rec
        self.state.first = self.grid.t0

    def advance(self) -> float | Stop:
        """Run and record the next chunk; the time reached, or the run's :class:`Stop`."""
        g, st = self.grid, self.state
        if st.k >= g.n_steps:
            return END
        code, t_fail = self._chunk()
        if code:
            return Stop(-1, self._failure(code, t_fail),
                        LCP_STATUS.get(code, "singular iteration matrix"))
        return g.t0 + g.h * st.k

    def _chunk(self) -> tuple[int, float]:
        """Run and record the next chunk; returns the stopping code and time (0 and the
        chunk's end when every step ran)."""
        g, st, system = self.grid, self.state, self.system
        k = st.k
        if k == g.n_full:  # the shortened last step
            self.runner = self.runner.for_step(g.h_last)
            times, step = np.array([g.t0 + g.h * k]), g.h_last
        else:
            chunk = max(1, min(g.n_full - k, 20_000,
                               _CHUNK_FLOATS // max(1, 2 * system.n_dof + system.n_contacts)))
            times, step = np.arange(k, k + chunk, dtype=np.float64), g.h
            times *= g.h        # t0 + k h, in place (a run's fixed cost: no temporaries)
            times += g.t0
        fext, failed = _chunk_force(self, times)
        if failed is not None:          # run the steps before u's first failing time
            if fext.shape[0] == 0:
                self._end_at_input_failure(failed)
            times = times[:fext.shape[0]]
        q_pre, v_pre = st.q.copy(), st.v.copy()
        observers = () if st.after_step is not None else self.runner.observers(
            self.fb.listeners)
        if self.runner.python_steps(st):   # a failing step keeps the steps before it
            with self.rec.chunk(partial(record_finished, rec=self.rec, system=system,
                                        times=times, state=st, q_pre=q_pre, v_pre=v_pre,
                                        listeners=observers, h=step)) as st.progress:
                done, code, q_out, v_out, p_out = self.runner(st, fext, times)
        else:                               # one compiled call: done or not
            done, code, q_out, v_out, p_out = self.runner(st, fext, times)
        if code and self.runner.path == "tridiagonal":
            # a singular Delassus matrix (redundant contacts): the tridiagonal solve has
            # no pivot; Lemke handles positive semi-definite W. Redo from the failed step.
            self.runner = DenseRunner(system, self.runner.opts, self.S)
            self.path, code = "tridiagonal+dense", 0
        if done:
            q_out, v_out, p_out = q_out[:done], v_out[:done], p_out[:done]
            record_chunk(self.rec, system, times[:done] + step, q_out, v_out, p_out, st,
                         q_pre, v_pre, observers, step, self.runner.signals)
            st.last = (times[done - 1] + step, q_out[-1], v_out[-1], p_out[-1])
        st.k = k + done
        if failed is not None and done == times.size:   # the steps before it all ran
            self._end_at_input_failure(failed)
        return code, float(times[done]) if code else float(times[-1] + step)

    def _failure(self, code: int, t_fail: float) -> str:
        """The message of a run stopped by ``code``; a model error is raised here."""
        from ._step_kernels import MODEL_ERROR

        message = self.runner.failure(code, t_fail, self.state)
        if code == MODEL_ERROR:
            raise ModelError(message)   # drive attaches the steps before it
        return message

    def _end_at_input_failure(self, failed: Exception) -> NoReturn:
        """Raise the error of an input that failed, once the steps before it are recorded
        (drive attaches them to it)."""
        raise failed

    def settle(self) -> None:
        """Record the initial state if no chunk did, and the last state when
        ``record_every`` dropped it."""
        rec, system, st = self.rec, self.system, self.state
        if st.first is not None:
            sample_initial(rec, system, st.first, self.x0)
            st.first = None
        if st.last is not None and rec.last_time < st.last[0]:
            t_last, q_l, v_l, p_l = st.last
            sig = signals_of(system, q_l[None], v_l[None], p_l[None], rec)
            rec.sample(t_last, np.concatenate([q_l, v_l]), force=True,
                       **{key: val[0] for key, val in sig.items()})

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics."""
        stats = {"steps": int(self.state.k), "path": self.path, "h": self.opts.h,
                 "theta": self.opts.theta, **self.runner.stats()}
        return _with_penetration(stats, self.rec)


def _with_penetration(stats: dict[str, Any], rec: Recorder) -> dict[str, Any]:
    """``stats`` with ``max_penetration``, the deepest recorded gap below 0, when the gaps
    are recorded."""
    lowest = rec.signal_min("gap")
    if lowest is not None:
        stats["max_penetration"] = max(0.0, -lowest)
    return stats


def first_runner(system: Any, opts: MoreauJeanOptions, feedback: Feedback,
                 S: FloatArray | None) -> Runner:
    """The compiled model's loop (with the compiled form of a closed loop's blocks) when it
    applies, else the fastest step loop for the system."""
    compiled = None if feedback.blocks is None else compiled_form_of(feedback.blocks)
    model = system.compiled
    if model is None and compiled is not None:   # a linear plant under compiled blocks
        from ...systems.lagrangian import affine_compiled_model

        model = affine_compiled_model(system)
    if model is not None and opts.forces == "implicit" and (
            feedback.blocks is None or compiled is not None):
        from ._compiled import ModelRunner

        return ModelRunner(system, opts, S, model, compiled)
    return choose_runner(system, opts, S)


def compiled_form_of(blocks: Any) -> Any:
    """The compiled form of the blocks (``CompiledBlocks.of``), or ``None``: also for
    impacting bodies, whose Lagrangian form permutes the state the blocks read (their
    Python form puts it back, the compiled one would not)."""
    from .._block_runner import CompiledBlocks

    return None if blocks.perm is not None else CompiledBlocks.of(blocks)


def blocks_input(blocks: Any, S: FloatArray, h: float) -> Callable[..., FloatArray]:
    """The blocks as a force ``S u`` evaluated before each step: they read the state, the
    last step's impulses over ``h`` (``λ̂``) and its active set; a bad output raises the
    blocks' own error (the steps before it are kept)."""
    def force(t: float, q: FloatArray, v: FloatArray, p_prev: FloatArray,
              active_prev: np.ndarray) -> FloatArray:
        return S @ blocks.step(t, q, v, p_prev / h, active_prev.copy())

    return force


# -- the input ---------------------------------------------------------------------------
def _external_force(run: Run, times: FloatArray) -> FloatArray:
    """Rows ``S u(t_k)`` for the steps of a chunk (a single zero row without input)."""
    S, u = run.S, run.opts.u
    if S is None or u is None:
        return np.zeros((1, run.system.n_dof))
    vals = u.u(times) if hasattr(u, "u") else np.array([np.atleast_1d(u(t)) for t in times])
    return np.asarray(vals, float).reshape(times.shape[0], -1) @ S.T


def _chunk_force(run: Run, times: FloatArray) -> tuple[FloatArray, Exception | None]:
    """:func:`_external_force` over a chunk, or, when it raises, over the chunk's longest
    prefix that evaluates (empty when none does), with the error to raise once those steps
    are recorded."""
    try:
        return _external_force(run, times), None
    except Exception as err:  # noqa: BLE001 - handed back to the caller, who re-raises it
        k = evaluable_prefix(lambda j: _external_force(run, times[:j]), times.size)
        return (_external_force(run, times[:k]) if k
                else np.zeros((0, run.system.n_dof))), err


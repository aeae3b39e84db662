"""Moreau–Jean with Coulomb friction at the contacts, and the position projection.

The step of :mod:`nscontrol.simulate.moreau_jean` (θ-method on the linear forces, Newton's
law at velocity level on the contacts predicted to close), with the contact impulse
``r_j = (P_N, P_T)`` of each active contact in Coulomb's cone (De Saxcé's form, one frictional
contact problem a step, :func:`~nscontrol.numerics.friction_contact.solve_friction_contact`):

    M̂ (v_free - v_k) = h f̃_k,   H = [G; T] (per contact: normal row, tangent rows),
    u = W r + H_A v_free + (e u_N,k, 0),   W = H_A M̂⁻¹ H_Aᵀ,   v_{k+1} = v_free + M̂⁻¹ H_Aᵀ r.

With ``θ = ½`` the discrete energy balance is exact: ``E_{k+1} - E_k = r · (u_k + u_{k+1})/2``
(with ``u = H v``), split into the normal and the friction work, both recorded.

Every step is the one compiled step of :mod:`._frictional_kernels`, whatever ``M̂`` (diagonal
or not), the step's length (the shortened last step has its own constants) and the
projection. Its sweeps start from the previous step's impulses (``warm_start``); a run that
starts loaded starts from the frictionless impulses (one LCP). A step whose sweeps do not
reach the tolerance within :data:`MAX_SWEEPS` gets its impulses from the checked solver
(:func:`~nscontrol.numerics.friction_contact.solve_friction_contact`, from the last step's
impulses) and is then taken by the compiled step with them as given: the step itself is
written once.

``projection=True`` adds a position correction after each step: ``q`` is replaced by its
projection on ``{g(q) >= 0}`` in the kinetic metric, ``min ½ (q' - q)ᵀ M (q' - q)``, i.e.
``q' = q + M⁻¹ Gᵀ λ`` with ``0 <= λ ⟂ G M⁻¹ Gᵀ λ + g(q) >= 0`` (one LCP by
:func:`~nscontrol.numerics.lcp.solve_lcp`). The lift raises the potential energy by ``ΔV``;
the velocity keeps its direction (the impulse law's outcome) and gives that energy back,
``v' = v sqrt(1 - ΔV / T)`` with ``T = ½ vᵀ M v`` (``v' = 0`` when ``T <= ΔV``), so the
projection adds no energy: without this, the lifts add ``m g`` times the penetration at every
landing and later impacts drift by a step per bounce.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from scipy import sparse

from ..._validation import FloatArray
from ...errors import ModelError, SolverError
from ..loop import END, Recording, Stop, drive
from ..trajectory import Recorder, Trajectory
from ._options import Feedback, input_matrix
from ._recording import record_impacts
from ._run import _CHUNK_FLOATS, Grid, _chunk_force, _with_penetration, blocks_input

if TYPE_CHECKING:
    from ._frictional_kernels import FrictionalStep
    from ._options import MoreauJeanOptions

#: Budget of sweeps of one step's contact problem (then the checked solver takes the step).
MAX_SWEEPS = 1000
#: Signals this path records (those of plain Moreau–Jean, and the contact's).
OFFERED = ("impulse", "gap", "energy", "friction_impulse", "contact_state", "friction_work",
           "normal_work", "projection_energy", "residual")


class _Contacts:
    """``H``, ``M̂⁻¹``, the compiled step of one step length and the Delassus matrices of the
    active sets met so far (for the cold start and the checked fallback)."""

    def __init__(self, system: Any, h: float, opts: MoreauJeanOptions) -> None:
        m, theta = system.n_contacts, opts.theta
        self.d = system.friction_dim
        self.dim = 1 + self.d
        self.r_size = m * self.dim
        self.mu = np.zeros(m) if system.friction is None else np.asarray(system.friction)
        G = sparse.csr_matrix(system.gap_matrix, dtype=np.float64)
        if self.d:
            T = sparse.csr_matrix(system.tangent_matrix, dtype=np.float64)
            perm = np.empty(m * self.dim, np.int64)
            for j in range(m):
                perm[j * self.dim] = j
                perm[j * self.dim + 1: (j + 1) * self.dim] = m + j * self.d + np.arange(self.d)
            self.H = sparse.csr_matrix(sparse.vstack([G, T]).tocsr()[perm])
        else:
            self.H = G
        self.G = G
        K = None if system.stiffness is None else np.asarray(system.stiffness)
        D = None if system.damping is None else np.asarray(system.damping)
        M = system.mass_matrix()
        Mhat = M + (0 if D is None else h * theta * D) \
            + (0 if K is None else (h * theta) ** 2 * K)
        diag = np.diag(Mhat)
        self.diagonal = bool(np.array_equal(Mhat, np.diag(diag)))
        self.minv: Any = sparse.diags(1.0 / diag) if self.diagonal else np.linalg.inv(Mhat)
        mdiag = np.diag(M)
        self.mass_inv: Any = (sparse.diags(1.0 / mdiag) if np.array_equal(M, np.diag(mdiag))
                              else np.linalg.inv(M))
        self.cache: dict[bytes, tuple[Any, np.ndarray]] = {}
        self.step = self._step(system, h, opts, K, D)

    def _step(self, system: Any, h: float, opts: MoreauJeanOptions, K: Any, D: Any
              ) -> FrictionalStep:
        """The compiled step's constants (:class:`FrictionalStep`)."""
        from ...numerics import _friction_kernels as fk
        from ._frictional_kernels import FrictionalStep

        n, H = system.n_dof, self.H
        if self.diagonal:   # B = H M̂⁻¹ keeps H's pattern; h M̂⁻¹ entry by entry
            B = sparse.csr_matrix(H.multiply(self.minv.diagonal()[None, :]))
            hminv = sparse.diags(h * self.minv.diagonal())
        else:
            B, hminv = H @ self.minv, h * self.minv
        W = sparse.csr_matrix(H @ self.minv @ H.T)
        W.sort_indices()
        blocks = fk.diagonal_blocks(W.indptr.astype(np.int64), W.indices.astype(np.int64),
                                    W.data, system.n_contacts, self.dim)
        return FrictionalStep(
            *_csr(H), *_csr(B), *_csr(hminv), *_csr(K, n), *_csr(D, n),
            np.ascontiguousarray(system.constant_force, dtype=float),
            np.ascontiguousarray(system.gap_offset, dtype=float),
            np.ascontiguousarray(system.restitution, dtype=float),
            np.ascontiguousarray(self.mu, dtype=float), blocks, _inverses(blocks, self.dim),
            self.dim, h, opts.theta, opts.gamma, opts.activation)

    def delassus(self, active: np.ndarray) -> tuple[Any, np.ndarray]:
        """``(W_A as sorted CSR, its rows)`` for the active set ``A`` (cached)."""
        key = active.tobytes()
        hit = self.cache.get(key)
        if hit is None:
            rows = (active[:, None] * self.dim + np.arange(self.dim)).ravel()
            HA = self.H[rows]
            MinvHt = self.minv @ HA.T
            MinvHt = sparse.csr_matrix(MinvHt) if self.diagonal else np.asarray(MinvHt)
            W = sparse.csr_matrix(HA @ MinvHt)
            W.sum_duplicates()
            W.sort_indices()
            if len(self.cache) > 64:
                self.cache.clear()
            hit = (W, rows)
            self.cache[key] = hit
        return hit


def _csr(A: Any, n: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of ``A`` as int64, int64, float64 (``n`` empty rows for
    ``None``)."""
    if A is None:
        return np.zeros(n + 1, np.int64), np.zeros(0, np.int64), np.zeros(0)
    A = sparse.csr_matrix(A, dtype=np.float64)
    A.sort_indices()
    return A.indptr.astype(np.int64), A.indices.astype(np.int64), A.data.astype(np.float64)


def _inverses(blocks: np.ndarray, dim: int) -> np.ndarray:
    """The inverses of the spatial blocks ``W_ii`` the local solver's stick test uses; a NaN
    in place of one that is singular or ill-conditioned (slip then decides)."""
    inverses = np.zeros_like(blocks)
    if dim != 3:
        return inverses
    for j in range(blocks.shape[0]):
        try:
            inverses[j] = np.linalg.inv(blocks[j])
        except np.linalg.LinAlgError:
            inverses[j, 0, 0] = np.nan
        if not np.all(np.isfinite(inverses[j])) or np.linalg.cond(
                blocks[j]) > 1.0 / (1e3 * float(np.finfo(float).eps)):
            inverses[j] = 0.0
            inverses[j, 0, 0] = np.nan
    return inverses


def integrate_frictional(system: Any, x0: FloatArray, t0: float, tf: float,
                         opts: MoreauJeanOptions, *, warm_start: bool = True,
                         feedback: Feedback | None = None) -> Trajectory:
    """The frictional run (``opts`` checked by :func:`moreau_jean.integrate`) through
    :func:`~nscontrol.simulate.loop.drive`; ``warm_start=False`` starts every step's sweeps
    from zero impulses instead of the previous step's (to measure what the warm start saves).
    ``feedback``: a closed loop's Python blocks (stepped before each step) and the jump
    listeners (called after each step with an impact).
    """
    if not system.is_linear:
        raise ModelError("friction: Moreau-Jean with friction or projection needs a constant "
                         "mass, linear forces (f0, K, D) and affine gaps; linearise the model "
                         "about its working configuration")
    run = FrictionalRun(system, x0, (t0, tf), opts, warm_start,
                        Feedback() if feedback is None else feedback)
    return drive(run, (t0, tf), desc="moreau_jean", progress=opts.progress)


class FrictionalRun:
    """One frictional run as a stepper of :func:`~nscontrol.simulate.loop.drive`: each
    :meth:`advance` runs and records a chunk of compiled steps (:mod:`._frictional_kernels`),
    projects a step that penetrates, and takes a step whose sweeps did not converge with the
    checked solver.

    Under a closed loop's Python blocks a chunk is one step: the blocks run before it (on
    the loop's integer tick schedule, the step starts ``t0 + k h``), reading the state, the
    last step's normal impulses over ``h`` and its active set, as in plain Moreau–Jean; the
    listeners (the blocks' reset among them) are called after a step with an impact, so
    before the next step's blocks."""

    def __init__(self, system: Any, x0: FloatArray, t_span: tuple[float, float],
                 opts: MoreauJeanOptions, warm_start: bool, feedback: Feedback) -> None:
        self.system, self.opts, self.warm = system, opts, warm_start
        self.grid = Grid(t_span[0], t_span[1], opts.h)
        self.steps: dict[float, _Contacts] = {}
        c = self.contacts(opts.h)
        m, n = system.n_contacts, system.n_dof
        self.recording = Recording(
            system.n_states, every=opts.record_every, signals=opts.signals, offered=OFFERED,
            state_names=system.state_names,
            capacity=Recorder.capacity_for(self.grid.n_steps + 2, opts.record_every))
        self.x0 = x0
        self.q, self.v = x0[:n].copy(), x0[n:].copy()
        self.r, self.work, self.states = np.zeros(m * c.dim), np.zeros(2), np.zeros(m, np.int64)
        blocks, self.listeners = feedback.blocks, feedback.listeners
        # the input matrix, read by _chunk_force and the blocks' input
        self.S = input_matrix(system, opts.u is not None or blocks is not None)
        self.inline = None if blocks is None or self.S is None else blocks_input(
            blocks, self.S, opts.h)   # (blocks always set S)
        #: the blocks' force of step ``k`` (a step taken again keeps it), the active set of
        #: the last step taken (what the blocks read)
        self.held: tuple[int, FloatArray] | None = None
        self.active_prev = np.zeros(0, np.int64)
        self.proj = {"energy": 0.0, "lift_energy": 0.0, "before": 0.0, "count": 0}
        self.k, self.sweeps, self.fallback_steps, self.max_residual = 0, 0, 0, 0.0
        self.redo = False   # the next step's sweeps failed: take it with the checked solver

    def start(self, rec: Recorder) -> None:
        """Record the initial state and its signals into the run's record."""
        system, x0, c = self.system, self.x0, self.contacts(self.opts.h)
        m, n = system.n_contacts, system.n_dof
        self.rec = rec
        rec.extend(np.array([self.grid.t0]), x0[None], **_rows(
            system, c, x0[None, :n], x0[None, n:], np.zeros((1, m * c.dim)),
            np.zeros((1, m)), np.zeros((1, 2)), np.zeros(1), np.zeros(1), rec))

    def contacts(self, h: float) -> _Contacts:
        """The contact data and compiled step of the step length ``h`` (built once)."""
        c = self.steps.get(h)
        if c is None:
            c = self.steps[h] = _Contacts(self.system, h, self.opts)
        return c

    def advance(self) -> float | Stop:
        """Run and record the next chunk of steps; the time reached, or the run's stop."""
        g = self.grid
        if self.k >= g.n_steps:
            return END
        try:
            self._chunk()
        except SolverError as err:
            return Stop(-1, f"moreau_jean: the contact problem of step {self.k} "
                            f"(t = {g.t0 + g.h * self.k:.6g}) failed: {err}", "contact")
        return g.t0 + g.h * self.k

    def _chunk(self) -> None:
        """Run and record the steps from step ``k``: compiled, and the checked solver for a
        step whose sweeps did not converge."""
        from ._frictional_kernels import NOT_CONVERGED, PENETRATED

        g, k, system = self.grid, self.k, self.system
        step = g.h if k < g.n_full else g.h_last
        c = self.contacts(step)
        size = 1 if self.inline is not None else max(
            1, min(g.n_full - k, 20_000, _CHUNK_FLOATS // (2 * system.n_dof + 2 * c.r_size)))
        times: FloatArray = g.t0 + g.h * np.arange(k, k + size, dtype=np.float64)
        # u(t) of the chunk; when it raises, the steps before its first failing time
        fext, failed = _chunk_force(cast(Any, self), times)   # reads system, S, opts.u
        if failed is not None:
            if fext.shape[0] == 0:
                raise failed
            times = times[:fext.shape[0]]
        if self.inline is not None:
            fext, active = self._with_blocks(c, float(times[0]), fext[:1])
        pre = (self.q.copy(), self.v.copy(), self.r.copy(), self.proj["energy"])
        if self.redo:
            out, done, code = self._checked_step(c, fext[:1])
        else:
            if self.warm and not np.any(self.r):
                self._cold_start(c, fext[0])
            out, done, code = self._compiled(c, times.shape[0], fext, given=False)
        if code == NOT_CONVERGED:   # r was spoiled by the sweeps: the last step's
            self.redo = True
            self.r = out[2][done - 1].copy() if done else pre[2]
        if code == PENETRATED:
            try:
                self._project(c, out, done - 1)
            except SolverError:
                self._keep(c, out, times[:done - 1] + step, pre, step)   # the steps before
                raise
        self._keep(c, out, times[:done] + step, pre, step)
        if self.inline is not None and done:
            self.active_prev = active
        if failed is not None and done == times.shape[0]:
            raise failed

    def _with_blocks(self, c: _Contacts, t: float, fext: FloatArray
                     ) -> tuple[FloatArray, np.ndarray]:
        """The input force of step ``k`` with the blocks' (run once per step: a step taken
        again by the checked solver keeps it) and the step's active set."""
        k, dim, inline = self.k, c.dim, self.inline
        assert inline is not None   # called under blocks only
        if self.held is None or self.held[0] != k:
            self.held = (k, inline(t, self.q, self.v, self.r[0::dim],
                                   self.active_prev))
        fe = fext + self.held[1]
        return fe, self._problem(c, fe[0])[0]

    def _keep(self, c: _Contacts, out: tuple[np.ndarray, ...], times: FloatArray,
              pre: tuple[Any, ...], step: float) -> None:
        """Record the chunk's first ``len(times)`` steps (taken from ``pre``: ``q, v, r``
        and the projection energy before them) and count them."""
        done = times.shape[0]
        if not done:
            return
        proj = np.full(done, pre[3])
        proj[-1] = self.proj["energy"]
        _record(self.rec, self.system, c, times, out[0][:done], out[1][:done], out[2][:done],
                out[3][:done], out[4][:done], out[5][:done], proj, pre[0], pre[1], pre[2],
                step, self.listeners)
        self.k += done

    def _compiled(self, c: _Contacts, size: int, fext: FloatArray, given: bool
                  ) -> tuple[tuple[np.ndarray, ...], int, int]:
        """Up to ``size`` compiled steps under the input forces ``fext`` (a row per step, or
        one row for all): ``(outputs, steps done, code)``."""
        from ._frictional_kernels import NOT_CONVERGED, frictional_mj_kernel

        n, m = self.system.n_dof, self.system.n_contacts
        out = (np.empty((size, n)), np.empty((size, n)), np.empty((size, c.r_size)),
               np.empty((size, m), np.int64), np.empty((size, 2)), np.empty(size),
               np.empty(size, np.int64))
        done, code = frictional_mj_kernel(
            c.step, self.q, self.v, np.ascontiguousarray(fext), self.r, self.work, self.states,
            self.warm, given, self.opts.projection, self.opts.contact_tol, MAX_SWEEPS, *out)
        self.sweeps += int(out[6][:done + (code == NOT_CONVERGED)].sum())
        if done:
            self.max_residual = max(self.max_residual, float(out[5][:done].max()))
        return out, int(done), int(code)

    def _problem(self, c: _Contacts, fe: FloatArray) -> tuple[np.ndarray, FloatArray]:
        """The active contacts of the next step (input force ``fe``) and their free local
        velocities."""
        from ._frictional_kernels import step_problem

        m = self.system.n_contacts
        active, qfree = np.zeros(m, np.bool_), np.zeros(c.r_size)
        step_problem(c.step, self.q, self.v, np.ascontiguousarray(fe), qfree, active)
        return np.flatnonzero(active), qfree

    def _cold_start(self, c: _Contacts, fe: FloatArray) -> None:
        """Without previous impulses, start a loaded set of contacts from the impulses of
        the problem without friction (one LCP; from zero a stack needs O(n²) sweeps)."""
        from ...numerics.friction_contact import frictionless_impulses

        active, qfree = self._problem(c, fe)
        if active.size:
            W, rows = c.delassus(active)
            self.r[rows] = frictionless_impulses(W, qfree[rows], c.dim)

    def _checked_step(self, c: _Contacts, fext: FloatArray
                      ) -> tuple[tuple[np.ndarray, ...], int, int]:
        """The step whose sweeps did not converge: its impulses by the checked solver
        (from the last step's), then the compiled step with them as given."""
        from ...numerics.friction_contact import solve_friction_contact

        active, qfree = self._problem(c, fext[0])
        r = np.zeros_like(self.r)
        self.states[:] = 0
        if active.size:
            W, rows = c.delassus(active)
            r0 = self.r[rows] if np.any(self.r[rows]) else None
            res = solve_friction_contact(W, qfree[rows], np.ascontiguousarray(c.mu[active]),
                                         dim=c.dim, tol=self.opts.contact_tol, r0=r0)
            self.sweeps += res.iterations if res.method == "nsgs" else 0
            r[rows] = res.r
            self.states[active] = res.states
        self.r, self.redo = r, False
        self.fallback_steps += 1
        return self._compiled(c, 1, fext, given=True)

    def _project(self, c: _Contacts, out: tuple[np.ndarray, ...], k: int) -> None:
        """Project step ``k`` of the chunk ``out`` (in place) and the state."""
        q, v = _project(self.system, c, out[0][k], out[1][k], self.system.gaps(out[0][k]),
                        self.proj)
        out[0][k], out[1][k] = q, v
        self.q[:], self.v[:] = q, v

    def settle(self) -> None:
        """Nothing held back: each chunk is recorded whole, its last step included."""

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics."""
        system, opts, proj = self.system, self.opts, self.proj
        return _with_penetration({
            "steps": self.k, "path": "frictional" if system.friction_dim else "projection",
            "h": opts.h, "theta": opts.theta, "friction_dim": system.friction_dim,
            "warm_start": self.warm, "contact_sweeps": self.sweeps,
            "contact_fallback_steps": self.fallback_steps,
            "max_contact_residual": self.max_residual, "projection": bool(opts.projection),
            "projections": proj["count"], "projection_energy": proj["energy"],
            "projection_lift_energy": proj["lift_energy"],
            "max_penetration_before_projection": proj["before"]}, self.rec)


def _project(system: Any, c: _Contacts, q: FloatArray, v: FloatArray, gap: FloatArray,
             proj: dict[str, Any]) -> tuple[FloatArray, FloatArray]:
    """``q`` projected on ``{G q + g0 >= 0}`` in the metric of ``M`` (one LCP per round;
    a contact opened by none of the rounds' corrections is never touched), and ``v`` scaled
    to give back the potential energy the lift cost (the module docstring)."""
    from ...numerics.lcp import solve_lcp

    proj["before"] = max(proj["before"], float(-np.min(gap)))
    proj["count"] += 1
    e0 = float(system.energy(np.concatenate([q, v])))
    chosen = np.flatnonzero(gap <= 0.0)
    for _ in range(10):
        GC = c.G[chosen]
        MinvGt = c.mass_inv @ GC.T
        MinvGt = sparse.csr_matrix(MinvGt) if sparse.issparse(MinvGt) else np.asarray(MinvGt)
        W = GC @ MinvGt
        res = solve_lcp(W.toarray() if sparse.issparse(W) and chosen.size <= 64 else W,
                        gap[chosen])
        if not res.success:
            raise SolverError(f"projection: the LCP failed ({res.status})", status=res.status)
        q = q + np.asarray(MinvGt @ res.z).ravel()
        gap = system.gaps(q)
        more = np.setdiff1d(np.flatnonzero(gap < 0.0), chosen)
        if more.size == 0:
            break
        chosen = np.union1d(chosen, more)
    lift = float(system.energy(np.concatenate([q, v]))) - e0    # ΔV: v is unchanged so far
    diag = system.mass_diagonal
    kinetic = 0.5 * float(v @ (diag * v if diag is not None else system.mass_matrix(q) @ v))
    if lift > 0.0 and kinetic > 0.0:
        v = v * np.sqrt(max(0.0, 1.0 - lift / kinetic))
    proj["lift_energy"] += lift
    proj["energy"] += float(system.energy(np.concatenate([q, v]))) - e0
    return q, v


def _record(rec: Recorder, system: Any, c: _Contacts, times: FloatArray, q: FloatArray,
            v: FloatArray, r: FloatArray, states: np.ndarray, work: FloatArray,
            residual: FloatArray, proj_energy: FloatArray, q_pre: FloatArray,
            v_pre: FloatArray, r_pre: FloatArray, h: float,
            listeners: Sequence[Callable[..., None]]) -> None:
    """Write a chunk of steps, and an ``"impact"`` event for every contact whose normal
    impulse becomes positive while it approaches (its time where the gap extrapolated from
    the step's start reaches zero, as plain Moreau–Jean; the jump listeners called for it)."""
    rec.extend(times, (q, v), **_rows(system, c, q, v, r, states, work, residual,
                                      proj_energy, rec))
    record_impacts(rec, system, times, q, v, r[:, 0::c.dim], r_pre[0::c.dim], q_pre, v_pre,
                   listeners, h)


def _rows(system: Any, c: _Contacts, q: FloatArray, v: FloatArray, r: FloatArray,
          states: np.ndarray, work: FloatArray, residual: FloatArray, proj_energy: FloatArray,
          rec: Recorder) -> dict[str, Any]:
    """The signals of a block of steps (only those the recorder keeps are computed)."""
    dim, k = c.dim, q.shape[0]
    rows: dict[str, Any] = {}
    if rec.wants("impulse"):
        rows["impulse"] = r[:, 0::dim]
    if rec.wants("gap"):
        rows["gap"] = np.asarray(c.G @ q.T).T + system.gap_offset
    if rec.wants("energy"):
        rows["energy"] = system.energy(np.hstack([q, v]))
    if c.d and rec.wants("friction_impulse"):
        rows["friction_impulse"] = r.reshape(k, -1, dim)[:, :, 1:].reshape(k, -1)
    rows.update(contact_state=np.asarray(states, float), normal_work=work[:, 0],
                friction_work=work[:, 1], residual=residual,
                projection_energy=proj_energy)
    return rows

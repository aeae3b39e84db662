"""Moreau–Jean with Coulomb friction at the contacts, and the position projection.

The step of :mod:`nscontrol.simulate.moreau_jean` (θ-method on the linear forces, Newton's
law at velocity level on the contacts predicted to close), with the contact impulse
``r_j = (P_N, P_T)`` of each active contact in Coulomb's cone (De Saxcé's form, one frictional
contact problem a step, :func:`~nscontrol.numerics.friction_contact.solve_friction_contact`):

    M̂ (v_free - v_k) = h f̃_k,   H = [G; T] (per contact: normal row, tangent rows),
    u = W r + H_A v_free + (e u_N,k, 0),   W = H_A M̂⁻¹ H_Aᵀ,   v_{k+1} = v_free + M̂⁻¹ H_Aᵀ r.

With ``θ = ½`` the discrete energy balance is exact: ``E_{k+1} - E_k = r · (u_k + u_{k+1})/2``
(with ``u = H v``), split into the normal and the friction work, both recorded.

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

from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import sparse

from ..._progress import TimeProgress
from ..._validation import FloatArray
from ...errors import ModelError, SolverError
from ..trajectory import Recorder, Trajectory

if TYPE_CHECKING:
    from ._options import MoreauJeanOptions

#: Signals this path records (those of plain Moreau–Jean, and the contact's).
OFFERED = ("impulse", "gap", "energy", "friction_impulse", "contact_state", "friction_work",
           "normal_work", "projection_energy", "residual")


class _Contacts:
    """``H``, ``M̂⁻¹`` and the Delassus matrices of the active sets met so far."""

    def __init__(self, system: Any, h: float, theta: float) -> None:
        m = system.n_contacts
        self.d = system.friction_dim
        self.dim = 1 + self.d
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
        self.K = None if system.stiffness is None else np.asarray(system.stiffness)
        self.D = None if system.damping is None else np.asarray(system.damping)
        M = system.mass_matrix()
        Mhat = M + (0 if self.D is None else h * theta * self.D) \
            + (0 if self.K is None else (h * theta) ** 2 * self.K)
        diag = np.diag(Mhat)
        self.diagonal = bool(np.array_equal(Mhat, np.diag(diag)))
        self.minv: Any = sparse.diags(1.0 / diag) if self.diagonal else np.linalg.inv(Mhat)
        mdiag = np.diag(M)
        self.mass_inv: Any = (sparse.diags(1.0 / mdiag) if np.array_equal(M, np.diag(mdiag))
                              else np.linalg.inv(M))
        self.cache: dict[bytes, tuple[Any, Any, np.ndarray, Any]] = {}

    def rows(self, active: np.ndarray) -> np.ndarray:
        return (active[:, None] * self.dim + np.arange(self.dim)).ravel()

    def delassus(self, active: np.ndarray) -> tuple[Any, Any, np.ndarray, Any]:
        """``(W_A as sorted CSR, M̂⁻¹ H_Aᵀ, rows, H_A)`` for the active set ``A`` (cached)."""
        key = active.tobytes()
        hit = self.cache.get(key)
        if hit is None:
            rows = self.rows(active)
            HA = self.H[rows]
            MinvHt = self.minv @ HA.T
            MinvHt = sparse.csr_matrix(MinvHt) if self.diagonal else np.asarray(MinvHt)
            W = sparse.csr_matrix(HA @ MinvHt)
            W.sum_duplicates()
            W.sort_indices()
            if len(self.cache) > 64:
                self.cache.clear()
            hit = (W, MinvHt, rows, HA)
            self.cache[key] = hit
        return hit


def integrate_frictional(system: Any, x0: FloatArray, t0: float, tf: float,
                         opts: MoreauJeanOptions) -> Trajectory:
    """The frictional step loop (``opts`` checked by :func:`moreau_jean.integrate`).

    A compiled loop (:mod:`._frictional_kernels`) when ``M̂`` is diagonal and no
    projection is asked; a step whose NSGS does not converge there, and every step otherwise,
    is taken here in Python with the checked solver.
    """
    if not system.is_linear:
        raise ModelError("friction: Moreau-Jean with friction or projection needs a constant "
                         "mass, linear forces (f0, K, D) and affine gaps; linearise the model "
                         "about its working configuration")
    h = opts.h
    n_full = int(np.floor((tf - t0) / h + 1e-9))
    h_last = (tf - t0) - n_full * h
    n_steps = n_full + (1 if h_last > 1e-9 * h else 0)
    rec = Recorder(system.n_states, every=opts.record_every, signals=opts.signals,
                   offered=OFFERED, capacity=Recorder.capacity_for(n_steps + 2,
                                                                   opts.record_every))
    run = _Run(system, opts)
    rec.extend(np.array([t0]), x0[None], **_rows(
        system, run.c, x0[None, :system.n_dof], x0[None, system.n_dof:], run.r[None],
        np.zeros((1, system.n_contacts)), np.zeros((1, 2)), np.zeros(1), 0.0, rec))
    state = (x0[:system.n_dof].copy(), x0[system.n_dof:].copy())
    k, status, message = 0, 0, None
    with TimeProgress(t0, tf, desc="moreau_jean", enable=opts.progress) as bar:
        while k < n_steps:
            try:
                k, state = _chunk(run, rec, state, k, t0, n_full, h_last)
            except SolverError as err:
                status, message = -1, (f"moreau_jean: the contact problem of step {k} "
                                       f"(t = {t0 + h * k:.6g}) failed: {err}")
                break
            bar.update(t0 + h * k)
    return _finish(run, rec, k, status, message)


def _chunk(run: _Run, rec: Recorder, state: tuple[FloatArray, FloatArray], k: int,
           t0: float, n_full: int, h_last: float) -> tuple[int, tuple[FloatArray, FloatArray]]:
    """Run and record the steps from step ``k``: a compiled chunk, or one Python step when
    the compiled loop does not apply or its NSGS did not converge."""
    q, v = state
    h = run.h
    step = h if k < n_full else h_last
    compiled = run.compiled and step == h
    size = max(1, min(n_full - k, 2000)) if compiled else 1
    times: FloatArray = t0 + h * np.arange(k, k + size, dtype=np.float64)
    q_pre, v_pre, r_pre = q.copy(), v.copy(), run.r.copy()
    done = 0
    if compiled:
        out, done = run.kernel_chunk(q, v, times)
    if not done:   # the Python step: one step, the checked solver
        out = run.python_step(q, v, times[0], step)
        done = 1
    q_out, v_out = out[0][:done], out[1][:done]
    _record(rec, run.system, run.c, times[:done] + step, q_out, v_out, out[2][:done],
            out[3][:done], out[4][:done], out[5][:done], run.proj["energy"], q_pre, v_pre,
            r_pre, step)
    return k + done, (q_out[-1].copy(), v_out[-1].copy())


def _finish(run: _Run, rec: Recorder, k: int, status: int, message: str | None
            ) -> Trajectory:
    """The trajectory with the run's stats (a ``SolverError`` carrying it on a failure)."""
    system = run.system
    traj = rec.finish(status=status, message=message, method="moreau_jean", stats={
        "steps": k, "path": ("frictional" if system.friction_dim else "projection")
        + ("+compiled" if run.compiled else ""),
        "h": run.h, "theta": run.theta, "friction_dim": system.friction_dim,
        "contact_sweeps": run.sweeps, "contact_python_steps": run.python_steps,
        "max_contact_residual": run.max_residual, "projection": bool(run.projection),
        "projections": run.proj["count"], "projection_energy": run.proj["energy"],
        "projection_lift_energy": run.proj["lift_energy"],
        "max_penetration_before_projection": run.proj["before"]},
        state_names=system.state_names)
    if "gap" in traj.signals and traj.signals["gap"].size:
        traj.stats["max_penetration"] = float(max(0.0, -np.min(traj.signals["gap"])))
    if status < 0:
        raise SolverError(str(message), status="contact", trajectory=traj)
    return traj


class _Run:
    """The state carried between steps (previous impulses, cumulative work) and the two
    step implementations."""

    def __init__(self, system: Any, opts: MoreauJeanOptions) -> None:
        h, theta, u, projection = opts.h, opts.theta, opts.u, opts.projection
        self.system, self.h, self.theta, self.gamma = system, h, theta, opts.gamma
        self.activation, self.tol, self.projection = opts.activation, opts.contact_tol, projection
        self.c = _Contacts(system, h, theta)
        self.steps: dict[float, _Contacts] = {h: self.c}
        m, n = system.n_contacts, system.n_dof
        self.r = np.zeros(m * self.c.dim)
        self.work = np.zeros(2)
        self.u = u
        self.S = None if u is None else (np.eye(n) if system.actuation is None
                                         else np.asarray(system.actuation, float))
        self.proj = {"energy": 0.0, "lift_energy": 0.0, "before": 0.0, "count": 0}
        self.sweeps, self.python_steps, self.max_residual = 0, 0, 0.0
        diag_forces = all(X is None or np.array_equal(X, np.diag(np.diag(X)))
                          for X in (self.c.K, self.c.D))
        self.compiled = self.c.diagonal and diag_forces and not projection
        if self.compiled:
            self._prepare_kernel()

    def _prepare_kernel(self) -> None:
        from ...numerics import _friction_kernels as fk

        c, s = self.c, self.system
        H = c.H
        self.csr = (H.indptr.astype(np.int64), H.indices.astype(np.int64),
                    H.data.astype(np.float64))
        self.minv_diag = np.asarray(c.minv.diagonal(), float)
        n = s.n_dof
        self.kdiag = np.zeros(n) if c.K is None else np.diag(c.K).copy()
        self.ddiag = np.zeros(n) if c.D is None else np.diag(c.D).copy()
        W = sparse.csr_matrix(H @ c.minv @ H.T)
        W.sort_indices()
        m, dim = s.n_contacts, c.dim
        self.blocks = fk.diagonal_blocks(W.indptr.astype(np.int64), W.indices.astype(np.int64),
                                         W.data, m, dim)
        self.inverses = np.zeros_like(self.blocks)
        for j in range(m):
            if dim == 3:
                try:
                    self.inverses[j] = np.linalg.inv(self.blocks[j])
                except np.linalg.LinAlgError:
                    self.inverses[j, 0, 0] = np.nan   # no stick impulse: slip decides
                if not np.all(np.isfinite(self.inverses[j])) or np.linalg.cond(
                        self.blocks[j]) > 1.0 / (1e3 * float(np.finfo(float).eps)):
                    self.inverses[j] = 0.0
                    self.inverses[j, 0, 0] = np.nan

    def force_rows(self, times: FloatArray) -> FloatArray:
        """``S u(t_k)`` per step (one zero row without input)."""
        n = self.system.n_dof
        if self.S is None:
            return np.zeros((1, n))
        u = self.u
        vals = u.u(times) if hasattr(u, "u") else np.array([np.atleast_1d(u(t)) for t in times])
        return np.asarray(vals, float).reshape(times.shape[0], -1) @ self.S.T

    def kernel_chunk(self, q: FloatArray, v: FloatArray, times: FloatArray
                     ) -> tuple[tuple[np.ndarray, ...], int]:
        from ._frictional_kernels import frictional_mj_kernel

        s, c = self.system, self.c
        size, n, m, dim = times.shape[0], s.n_dof, s.n_contacts, c.dim
        if not np.any(self.r) and self._closing(q, v).any():
            self.r = self._frictionless_guess(q, v)   # a cold start of a loaded set
        out = (np.empty((size, n)), np.empty((size, n)), np.empty((size, m * dim)),
               np.empty((size, m), np.int64), np.empty((size, 2)), np.empty(size),
               np.empty(size, np.int64))
        done, _ = frictional_mj_kernel(
            q, v, self.minv_diag, self.kdiag, self.ddiag, s.constant_force,
            np.ascontiguousarray(self.force_rows(times)), *self.csr, s.gap_offset,
            s.restitution, np.ascontiguousarray(c.mu), self.blocks, self.inverses, dim,
            self.h, self.theta, self.gamma, self.activation, self.tol, 1000, self.r,
            self.work, *out)
        self.sweeps += int(out[6][:done].sum())
        if done:
            self.max_residual = max(self.max_residual, float(out[5][:done].max()))
        return out, done

    def _closing(self, q: FloatArray, v: FloatArray) -> np.ndarray:
        s = self.system
        un = np.asarray(self.c.G @ v).ravel()
        return s.gaps(q) + self.gamma * self.h * un <= self.activation

    def _frictionless_guess(self, q: FloatArray, v: FloatArray) -> FloatArray:
        """Impulses of the first step without friction (one LCP): NSGS's start when no
        previous impulse exists (a loaded stack would need O(n²) sweeps from zero)."""
        from ...numerics.friction_contact import frictionless_impulses

        c, s = self.c, self.system
        active = np.flatnonzero(self._closing(q, v))
        W, _, rows, HA = c.delassus(active)
        f = s.constant_force - (0 if c.K is None else c.K @ (q + self.h * self.theta * v)) \
            - (0 if c.D is None else c.D @ v)
        v_free = v + self.h * np.asarray(c.minv @ f).ravel()
        qloc = np.asarray(HA @ v_free).ravel()
        qloc[0::c.dim] += s.restitution[active] * np.asarray(c.G[active] @ v).ravel()
        r = np.zeros_like(self.r)
        r[rows] = frictionless_impulses(W, qloc, c.dim)
        return r

    def python_step(self, q: FloatArray, v: FloatArray, t: float, step: float
                    ) -> tuple[np.ndarray, ...]:
        """One step in Python (any ``M̂``, projection, a short last step)."""
        from ...numerics import _friction_kernels as fk
        from ...numerics.friction_contact import solve_friction_contact

        s = self.system
        c = self.steps.get(step)
        if c is None:
            c = self.steps[step] = _Contacts(s, step, self.theta)
        m, dim = s.n_contacts, c.dim
        f = s.constant_force.copy()
        if c.K is not None:
            f -= c.K @ (q + step * self.theta * v)
        if c.D is not None:
            f -= c.D @ v
        f += self.force_rows(np.array([t]))[0]
        v_free = v + step * np.asarray(c.minv @ f).ravel()
        un = np.asarray(c.G @ v).ravel()
        active = np.flatnonzero(s.gaps(q) + self.gamma * step * un <= self.activation)
        r_full = np.zeros(m * dim)
        states = np.zeros(m, np.int64)
        residual = 0.0
        v_new = v_free
        if active.size:
            W, MinvHt, rows, HA = c.delassus(active)
            qloc = np.asarray(HA @ v_free).ravel()
            qloc[0::dim] += s.restitution[active] * un[active]
            mu = np.ascontiguousarray(c.mu[active])
            r0 = self.r[rows].copy() if np.any(self.r[rows]) else None
            res = _solve(fk, W, qloc, mu, dim, self.tol, r0, solve_friction_contact)
            self.sweeps += res.iterations if res.method == "nsgs" else 0
            residual = res.residual
            self.max_residual = max(self.max_residual, residual)
            r_full[rows] = res.r
            states[active] = res.states
            v_new = v_free + np.asarray(MinvHt @ res.r).ravel()
        self.python_steps += 1
        q_new = q + step * ((1 - self.theta) * v + self.theta * v_new)
        # θ = ½: E_{k+1} - E_k = r · (H v_k + H v_{k+1}) / 2, normal and tangent parts
        prod = r_full * (0.5 * np.asarray(c.H @ (v + v_new)).ravel())
        self.work[0] += prod[0::dim].sum()
        self.work[1] += prod.sum() - prod[0::dim].sum()
        gap_new = s.gaps(q_new)
        if self.projection and np.min(gap_new, initial=0.0) < 0.0:
            q_new, v_new = _project(s, c, q_new, v_new, gap_new, self.proj)
        self.r = r_full
        return (q_new[None], v_new[None], r_full[None], states[None], self.work[None].copy(),
                np.array([residual]))


def _solve(fk: Any, W: Any, q: FloatArray, mu: FloatArray, dim: int, tol: float,
           r0: FloatArray | None, fallback: Any) -> Any:
    """NSGS from the previous step's impulses (compiled, no re-validation); the checked
    solver (planar LCP, or NSGS from the frictionless guess) when it does not converge."""
    from ...numerics.friction_contact import FrictionContactResult

    if r0 is not None:
        r = r0.copy()
        u = np.empty_like(q)
        states = np.zeros(mu.shape[0], np.int64)
        code, sweeps, err = fk.nsgs_kernel(W.indptr, W.indices, W.data, q, mu, dim, r, u,
                                           states, tol, 1000)
        if code == 0:
            return FrictionContactResult(r, u, states, float(err), int(sweeps), "nsgs",
                                         "solved")
    return fallback(W, q, mu, dim=dim, tol=tol)


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
            residual: FloatArray, proj_energy: float, q_pre: FloatArray, v_pre: FloatArray,
            r_pre: FloatArray, h: float) -> None:
    """Write a chunk of steps, and an ``"impact"`` event for every contact whose normal
    impulse becomes positive while it approaches (its time where the gap extrapolated from
    the step's start reaches zero, as plain Moreau–Jean)."""
    rec.extend(times, (q, v), **_rows(system, c, q, v, r, states, work, residual,
                                      proj_energy, rec))
    dim = c.dim
    pn = r[:, 0::dim]
    prev = np.vstack([r_pre[None, 0::dim], pn[:-1]])
    for k in np.flatnonzero(((pn > 0.0) & (prev == 0.0)).any(axis=1)):
        qb = q_pre if k == 0 else q[k - 1]
        vb = v_pre if k == 0 else v[k - 1]
        un = np.asarray(c.G @ vb).ravel()
        gap = system.gaps(qb)
        for j in np.flatnonzero((pn[k] > 0.0) & (prev[k] == 0.0) & (un < 0.0)):
            tau = float(np.clip(gap[j] / -un[j], 0.0, h))
            rec.event(times[k] - h + tau, "impact", int(j), np.concatenate([qb, vb]),
                      np.concatenate([q[k], v[k]]))


def _rows(system: Any, c: _Contacts, q: FloatArray, v: FloatArray, r: FloatArray,
          states: np.ndarray, work: FloatArray, residual: FloatArray, proj_energy: float,
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
                projection_energy=np.full(k, proj_energy))
    return rows

"""Implicit Euler / θ-method time-stepping for Lur'e systems (``method="implicit_euler"``).

Integrates :class:`~nscontrol.systems.lure.LureSystem` (``x' = Ax + Gw + Bu``,
``z = Hx + Dw + g``, ``w ∈ -φ(z)``). The smooth part is a θ-method, the multiplier is always
implicit, so every step is the one-step inclusion

::

    x_{k+1} = Φ x_k + Γ ū_k + G_h w,        ū_k = (1-θ) u(t_k) + θ u(t_{k+1})
    z_{k+1} = a_k + D_h w,   w ∈ -φ(z_{k+1}),   a_k = H(Φ x_k + Γ ū_k) + g(t_{k+1})

with ``W = I - hθA``, ``Φ = W⁻¹(I + h(1-θ)A)``, ``Γ = hW⁻¹B``, ``G_h = hW⁻¹G``,
``D_h = H G_h + D``. It is solved exactly at every step:

* componentwise laws (relay, Coulomb, normal cones of intervals, complementarity and their
  products) with a diagonal ``D_h``: closed-form resolvent ``z = (I + D_h φ)⁻¹(a)`` in a
  compiled loop;
* laws with a complementarity form (``law.complementarity_form()``: relay, friction, normal
  cones, products) and a full ``D_h``: one LCP per step by the shared Lemke kernel of
  :mod:`nscontrol.numerics._lcp_kernels`, in the same compiled loop;
* any other monotone law (curved graphs): its own resolvent when ``D_h`` is diagonal, else
  forward–backward splitting on ``0 ∈ D_h⁻¹(z - a) + φ(z)``, in Python.

Because the multiplier is implicit, a sliding motion is reached in finitely many steps and then
held with ``z`` exactly zero (no chattering).

Options
-------
h : float
    Step (the span is cut into ``N = ceil((tf - t0)/h)`` equal steps).
theta : float in [1/2, 1]
    θ of the smooth part (1: backward Euler, 1/2: trapezoidal).
record_every : int
    Keep every k-th step (the final state is always kept).
signals : iterable of str, optional
    Subset of ``("z", "w", "y")`` to record.
progress : bool, optional
    Progress bar on stderr (default: shown after 2 s).
on_failure : {"raise", "return"}
    On a failed step raise :class:`~nscontrol.errors.SolverError` (with the partial
    trajectory) or return it with ``status = -1``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._progress import TimeProgress
from .._validation import FloatArray, as_vector, check_in_interval, check_positive
from ..errors import InadmissibleStateError, ModelError, SolverError
from .trajectory import Recorder, Trajectory

__all__ = ["integrate", "StepMatrices", "step_matrices", "componentwise_spec", "lcp_step_data"]

_CHUNK = 1 << 16
_OPTIONS = {"h", "theta", "record_every", "signals", "progress", "on_failure"}


class StepMatrices:
    """The constant matrices of one θ-method step (see the module docstring)."""

    def __init__(self, system: Any, h: float, theta: float) -> None:
        A, G, H = system.A, system.G, system.H
        n = A.shape[0]
        W = np.eye(n) - h * theta * A
        cond = np.linalg.cond(W)
        if not np.isfinite(cond) or cond > 1e14:
            raise ModelError(f"h: I - h·θ·A is singular for h = {h:g}, θ = {theta:g} "
                             f"(condition number {cond:.3g}); change the step h")
        B = system.B if system.B is not None else np.zeros((n, 0))
        self.Phi = np.linalg.solve(W, np.eye(n) + h * (1.0 - theta) * A)
        self.Gam = np.linalg.solve(W, h * B)
        self.Gh = np.linalg.solve(W, h * G)
        self.HPhi = H @ self.Phi
        self.HGam = H @ self.Gam
        self.Dh = H @ self.Gh + system.D
        self.h, self.theta = h, theta


def step_matrices(system: Any, h: float, theta: float = 1.0) -> StepMatrices:
    """The step matrices ``Φ, Γ, G_h, D_h`` of the θ-method for ``system`` and step ``h``."""
    return StepMatrices(system, h, theta)


def componentwise_spec(law: Any) -> tuple[np.ndarray, FloatArray, FloatArray] | None:
    """``(kind, p1, p2)`` arrays when ``law`` acts componentwise with a known resolvent.

    ``kind[i] = 0``: ``c Sign`` with ``c = p1[i]`` (relay, Coulomb); ``kind[i] = 1``: normal
    cone of ``[p1[i], p2[i]]`` (complementarity: ``[0, inf)``). ``None`` for other laws.
    """
    from ..laws.normal_cone import NormalConeBox
    from ..laws.product import Product
    from ..laws.relay import Relay

    if isinstance(law, Product):
        parts = [componentwise_spec(p) for p in law.parts]
        if any(p is None for p in parts):
            return None
        return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))  # type: ignore
    m = int(law.dim)
    if isinstance(law, Relay):  # Coulomb is a Relay of bound mu·N
        return np.zeros(m, np.int64), _per_component(law.bound, m), np.zeros(m)
    if isinstance(law, NormalConeBox):
        return (np.ones(m, np.int64), _per_component(law.lower, m),
                _per_component(law.upper, m))
    return None


def _per_component(value: Any, m: int) -> FloatArray:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, float), (m,)), dtype=float)


def lcp_step_data(law: Any, Dh: FloatArray) -> tuple[FloatArray, ...] | None:
    """The per-step LCP ``0 <= ξ ⟂ Mξ + Qa·a + q0 >= 0``, ``w = Tξ + s`` of the inclusion
    ``w ∈ -φ(a + D_h w)``, from the law's complementarity form (``None`` when it has none).

    With the form ``w = w0 + Eξ``, ``η = Nz z + Nξ ξ + r``: ``M = Nz D_h E + Nξ``, ``Qa = Nz``,
    ``q0 = Nz D_h w0 + r``, ``T = E``, ``s = w0``; ``M`` is monotone when ``D_h`` is.
    """
    try:
        form = law.complementarity_form()
    except ModelError:
        return None
    M = form.Nz @ Dh @ form.E + form.Nxi
    q0 = form.Nz @ Dh @ form.w0 + form.r
    return (np.ascontiguousarray(M), np.ascontiguousarray(form.Nz), q0,
            np.ascontiguousarray(form.E), np.asarray(form.w0, float).copy())


def _is_diagonal(M: FloatArray) -> bool:
    off = M - np.diag(np.diag(M))
    return bool(np.max(np.abs(off), initial=0.0) <= 1e-14 * max(1.0, np.max(np.abs(M))))


def _check_step_matrix(Dh: FloatArray, h: float) -> None:
    sym = 0.5 * (Dh + Dh.T)
    lam = float(np.linalg.eigvalsh(sym)[0])
    if lam <= 0.0:
        raise ModelError(
            f"h: the one-step matrix D_h = h·H(I - hθA)⁻¹G + D is not positive definite for "
            f"h = {h:g} (smallest eigenvalue of its symmetric part {lam:.3g}); the one-step "
            f"inclusion may have no or several solutions. Check the sign of H·G (it must be "
            f"positive, relative degree one) or add a positive feedthrough D")


def _initial_multiplier(system: Any, x0: FloatArray, t0: float) -> tuple[FloatArray, FloatArray]:
    """``(z0, w0)`` at the initial time (the minimal-norm selection when ``D = 0``)."""
    a = system.H @ x0 + system.shift_at(t0)[0]
    m = a.shape[0]
    if not np.any(system.D):
        try:
            return a, -np.asarray(system.law.select(a), float).reshape(m)
        except InadmissibleStateError:  # outside the law's domain: the first step projects
            return a, np.full(m, np.nan)
    return _solve_inclusion_python(system.law, a, system.D)


def _solve_inclusion_python(law: Any, a: FloatArray, Dh: FloatArray
                            ) -> tuple[FloatArray, FloatArray]:
    """Solve ``w ∈ -φ(a + D_h w)`` for a general monotone law (outside the compiled loops):
    the shared :func:`nscontrol.laws.inclusion.solve_inclusion` (closed form or LCP), and for
    curved laws with a full ``D_h`` forward–backward splitting."""
    from ..laws.inclusion import solve_inclusion

    if _is_diagonal(Dh) or lcp_step_data(law, Dh) is not None:
        sol = solve_inclusion(law, Dh, a)
        return sol.z, sol.w
    # forward-backward on 0 ∈ D_h⁻¹(z - a) + φ(z): strongly monotone + Lipschitz (ch08 §3.1)
    Dinv = np.linalg.inv(Dh)
    mu = float(np.linalg.eigvalsh(0.5 * (Dinv + Dinv.T))[0])
    gamma = mu / float(np.linalg.norm(Dinv, 2)) ** 2
    z = a.copy()
    for _ in range(100_000):
        z_new = np.asarray(law.resolvent(z - gamma * (Dinv @ (z - a)), gamma=gamma), float)
        if np.linalg.norm(z_new - z) <= 1e-13 * max(1.0, np.linalg.norm(z)):
            return z_new, Dinv @ (z_new - a)
        z = z_new
    raise SolverError("implicit_euler: forward-backward iteration for the one-step inclusion "
                      "did not converge in 100000 iterations; the step matrix is badly "
                      "conditioned (reduce h)", status="max_iter")


def _check_options(options: dict[str, Any]) -> None:
    unknown = set(options) - _OPTIONS
    if unknown:
        raise ModelError(f"implicit_euler: unknown option(s) {sorted(unknown)}; accepted: "
                         f"{sorted(_OPTIONS)}")


def integrate(system: Any, x0: Any, t_span: tuple[float, float], **options: Any) -> Trajectory:
    """Integrate a :class:`~nscontrol.systems.lure.LureSystem` by the θ-method.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system (a plant with its observer is one stacked system).
    x0 : array_like, shape (n,)
        Initial state.
    t_span : (float, float)
        Start and end times.
    **options
        ``h`` (required), ``theta`` (default 1), ``record_every``, ``signals``, ``progress``,
        ``on_failure`` -- see the module docstring.

    Returns
    -------
    Trajectory
        States at the step times and signals ``z`` (law argument), ``w`` (multiplier) and
        ``y = C x``; ``stats`` has ``steps``, ``h``, ``theta``, ``solver``.

    Raises
    ------
    ModelError
        Not a LureSystem, bad options, ``I - hθA`` singular, or ``D_h`` not positive definite.
    SolverError
        A one-step problem failed; ``err.trajectory`` holds the steps before it.
    """
    from ..systems.lure import LureSystem

    _check_options(options)
    if not isinstance(system, LureSystem):
        raise ModelError(f"implicit_euler: expected a LureSystem, got {type(system).__name__}; "
                         f"for PWA/Filippov/switched systems use method='switching'")
    if "h" not in options:
        raise ModelError("h: implicit_euler needs a step, e.g. simulate(sys, x0, t_span, "
                         "method='implicit_euler', h=1e-3)")
    h_req = check_positive("h", options["h"])
    theta = check_in_interval("theta", options.get("theta", 1.0), 0.5, 1.0)
    on_failure = options.get("on_failure", "raise")
    if on_failure not in ("raise", "return"):
        raise ModelError(f"on_failure: expected 'raise' or 'return', got {on_failure!r}")
    n = system.n_states
    x0 = as_vector("x0", x0, n)
    t0, tf = t_span
    n_steps = max(1, math.ceil((tf - t0) / h_req - 1e-9))
    h = (tf - t0) / n_steps
    mats = StepMatrices(system, h, theta)
    _check_step_matrix(mats.Dh, h)
    spec = componentwise_spec(system.law)
    lcp_data = None
    if spec is not None and _is_diagonal(mats.Dh):
        solver = "closed_form"
    else:
        lcp_data = lcp_step_data(system.law, mats.Dh)
        solver = "python" if lcp_data is None else "lcp"

    rec = Recorder(n, every=int(options.get("record_every", 1)), signals=options.get("signals"))
    z0, w0 = _initial_multiplier(system, x0, t0)
    rec.sample(t0, x0, force=True, z=z0, w=w0, y=system.C @ x0)
    stepper = _Stepper(system, mats, spec, solver, lcp_data)
    x = x0
    done = 0
    status, message = 0, None
    with TimeProgress(t0, tf, desc="implicit_euler", enable=options.get("progress")) as bar:
        while done < n_steps:
            k1 = min(n_steps, done + _CHUNK)
            times = t0 + h * np.arange(done, k1 + 1)
            try:
                X, Z, W = stepper.run(x, times)
            except SolverError as exc:
                X, Z, W = exc.partial  # type: ignore[attr-defined]
                _record_block(rec, system, times[1:1 + X.shape[0]], X, Z, W, last=True)
                traj = rec.finish(status=-1, message=str(exc), method="implicit_euler",
                                  stats=_stats(done + X.shape[0], h, theta, solver),
                                  state_names=system.state_names)
                if on_failure == "return":
                    return traj
                raise SolverError(str(exc), status=exc.status, trajectory=traj) from None
            _record_block(rec, system, times[1:], X, Z, W, last=k1 == n_steps)
            x = X[-1]
            done = k1
            bar.update(times[-1])
    return rec.finish(status=status, message=message, method="implicit_euler",
                      stats=_stats(n_steps, h, theta, solver), state_names=system.state_names)


def _stats(steps: int, h: float, theta: float, solver: str) -> dict[str, Any]:
    return {"steps": int(steps), "h": float(h), "theta": float(theta), "solver": solver}


def _record_block(rec: Recorder, system: Any, t: FloatArray, X: FloatArray, Z: FloatArray,
                  W: FloatArray, *, last: bool) -> None:
    if X.shape[0] == 0:
        return
    sig = {}
    if rec.wants("z"):
        sig["z"] = Z
    if rec.wants("w"):
        sig["w"] = W
    if rec.wants("y"):
        sig["y"] = X @ system.C.T
    if last and X.shape[0] > 1:
        rec.extend(t[:-1], X[:-1], **{k: v[:-1] for k, v in sig.items()})
        rec.sample(t[-1], X[-1], force=True, **{k: v[-1] for k, v in sig.items()})
    elif last:
        rec.sample(t[-1], X[-1], force=True, **{k: v[-1] for k, v in sig.items()})
    else:
        rec.extend(t, X, **sig)


class _Stepper:
    """Runs blocks of steps with the solver chosen once for the whole run."""

    def __init__(self, system: Any, mats: StepMatrices, spec: Any, solver: str,
                 lcp_data: Any) -> None:
        self.system, self.m, self.spec, self.solver = system, mats, spec, solver
        self.enc = lcp_data

    def _inputs(self, times: FloatArray) -> tuple[FloatArray, FloatArray]:
        sys_, th = self.system, self.m.theta
        if sys_.has_input:
            U = sys_.input_at(times)
            ubar = (1.0 - th) * U[:-1] + th * U[1:]
        else:
            ubar = np.zeros((times.size - 1, max(sys_.n_inputs, 0)))
        gnext = sys_.shift_at(times[1:]) if sys_.has_shift else \
            np.zeros((times.size - 1, sys_.n_multipliers))
        return np.ascontiguousarray(ubar), np.ascontiguousarray(gnext)

    def run(self, x: FloatArray, times: FloatArray) -> tuple[FloatArray, ...]:
        ubar, gnext = self._inputs(times)
        k = times.size - 1
        n, mm = self.system.n_states, self.system.n_multipliers
        X, Z, W = np.empty((k, n)), np.empty((k, mm)), np.empty((k, mm))
        m = self.m
        if self.solver == "closed_form":
            from ._lure_kernels import diagonal_steps

            kind, p1, p2 = self.spec
            diagonal_steps(m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, np.ascontiguousarray(
                np.diag(m.Dh)), kind, p1, p2, x, ubar, gnext, X, Z, W)
            return X, Z, W
        if self.solver == "lcp":
            from ._lure_lcp_kernels import lcp_steps

            M, Qa, q0, T, s = self.enc
            done, status = lcp_steps(m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, m.Dh, M, Qa, q0, T, s,
                                     x, ubar, gnext, X, Z, W, 50 * (M.shape[0] + 1))
            if status != 0:
                err = SolverError(f"implicit_euler: the LCP of step {done} (t = "
                                  f"{times[done + 1]:.6g}) failed with Lemke status {status}",
                                  status=str(status))
                err.partial = (X[:done], Z[:done], W[:done])  # type: ignore[attr-defined]
                raise err
            return X, Z, W
        law = self.system.law
        for j in range(k):
            q = m.Phi @ x + m.Gam @ ubar[j]
            a = self.system.H @ q + gnext[j]
            try:
                z, w = _solve_inclusion_python(law, a, m.Dh)
            except SolverError as exc:
                exc.partial = (X[:j], Z[:j], W[:j])  # type: ignore[attr-defined]
                raise
            x = q + m.Gh @ w
            X[j], Z[j], W[j] = x, z, w
        return X, Z, W

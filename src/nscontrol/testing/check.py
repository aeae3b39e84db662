"""``check_system(obj)``: prove numerically that a law or a system keeps nscontrol's contracts.

A user who writes their own set-valued law (a subclass of
:class:`~nscontrol.laws.base.SetValuedLaw`), impact law or system can run it through the same
checks the built-in ones pass (``tests/test_check_system.py``), in the spirit of
scikit-learn's ``check_estimator``. Each check measures a number and compares it with a
threshold; the first failure raises :class:`~nscontrol.errors.ModelError` naming the property,
the number, the threshold and the point where it failed, and success returns a
:class:`CheckReport` listing what was measured.

What is checked
---------------
*Set-valued laws* (``SetValuedLaw``):

1. ``dim`` is a positive integer, ``monotone`` and ``componentwise`` are bools;
2. ``resolvent`` refuses a point of the wrong length with ``DimensionError``;
3. the resolvent lands in the graph: for random ``x`` and step weights ``gamma`` (a vector for
   componentwise laws; ``gamma sigma_tan < 1`` for non-monotone ones), ``z = resolvent(x,
   gamma)`` and ``v = (x - z) / gamma`` satisfy ``graph_residual(z, v) <= tol``;
4. ``select(z)`` is in the graph at those points;
5. monotonicity (for a law that declares ``monotone``): ``(z1 - z2)·(v1 - v2) >= -tol`` on
   random pairs of graph points; a non-monotone law is checked through its
   ``loop_transformation().monotone_part`` instead;
6. the complementarity form, when the law offers one: its shapes, and for random diagonal
   positive steps ``z = M w + q`` the LCP solution (Lemke) recovered through the form lies in
   the graph and equals the closed-form solution ``z = (I + M phi)^{-1} q`` (unique for a
   monotone law).

*Impact laws* (``NewtonImpactLaw``): on random masses, contact gradients and pre-impact
velocities, impulses are nonnegative and complementary to ``W^T v+ + e W^T v-``, momentum
changes by exactly ``W P``, and kinetic energy does not grow (one coefficient for all
contacts).

*Systems* (anything with ``n_states`` and ``default_method``: ``LagrangianSystem``,
``ImpactingBodies``, ``LureSystem``, ``PiecewiseAffineSystem``, ``FilippovSystem``,
``SwitchedAffineSystem``, ``LinearHybridSystem``, closed loops built by designs):

1. ``n_states`` is a positive integer and ``default_method`` one of ``simulate``'s methods;
   ``state_names``, when given, has ``n_states`` entries;
2. ``simulate`` (and ``check_state``, when defined) refuse an ``x0`` of length
   ``n_states + 1`` with ``DimensionError``;
3. a short run of ``simulate(obj, x0, t_span)`` with the default method returns a
   ``Trajectory`` of that method whose ``t`` is nondecreasing from ``t0`` to ``tf`` (or to a
   terminal event), ``x`` has shape ``(len(t), n_states)`` and starts at ``x0``, every signal
   has ``len(t)`` rows, every value is finite and every event lies in the span, in time order;
4. with Coulomb friction (``friction_dim > 0``), the run's friction impulses lie in the cone
   and oppose the slip velocity (maximal dissipation), to the contact solver's tolerance.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray, as_vector, check_integer, check_positive
from ..errors import DimensionError, ModelError, NscontrolError

__all__ = ["check_system", "CheckReport", "CheckItem"]

#: Time-stepping methods need a step; ``check_system`` uses ``(tf - t0) / STEPS``.
STEPS = 100


@dataclass(frozen=True)
class CheckItem:
    """One measured property: ``value <= threshold`` (or a yes/no fact with ``value`` a bool).

    Attributes
    ----------
    name
        The property, in words.
    value, threshold
        The measured number and its bound (``None`` for yes/no facts).
    passed
        Whether the property holds.
    detail
        Where it was measured, or why it failed.
    """

    name: str
    value: Any
    threshold: Any
    passed: bool
    detail: str = ""

    def __str__(self) -> str:
        mark = "pass" if self.passed else "FAIL"
        if self.threshold is None:
            return f"[{mark}] {self.name}" + (f" ({self.detail})" if self.detail else "")
        return (f"[{mark}] {self.name}: {_fmt(self.value)} <= {_fmt(self.threshold)}"
                + (f" ({self.detail})" if self.detail else ""))


@dataclass(frozen=True)
class CheckReport:
    """What :func:`check_system` measured on an object that passed every check.

    Attributes
    ----------
    subject
        ``repr`` of the checked object (shortened).
    kind
        ``"set-valued law"``, ``"impact law"`` or ``"system"``.
    items
        The checks, in the order they ran.
    """

    subject: str
    kind: str
    items: tuple[CheckItem, ...] = field(default_factory=tuple)

    @property
    def passed(self) -> bool:
        """True when every check passed (always, for a returned report)."""
        return all(i.passed for i in self.items)

    def __str__(self) -> str:
        return "\n".join([f"check_system({self.subject}): {self.kind}, {len(self.items)} "
                          "checks"] + [f"  {i}" for i in self.items])


class _Checker:
    """Collects the items and raises at the first failure."""

    def __init__(self, subject: str, kind: str) -> None:
        self.subject, self.kind = subject, kind
        self.items: list[CheckItem] = []

    def record(self, name: str, value: Any, threshold: Any, passed: bool,
               detail: str = "") -> None:
        item = CheckItem(name, value, threshold, bool(passed), detail)
        self.items.append(item)
        if not item.passed:
            err = ModelError(f"check_system({self.subject}): {self.kind} fails '{name}': "
                             + (f"{_fmt(value)} > {_fmt(threshold)}" if threshold is not None
                                else "no") + (f"; {detail}" if detail else ""))
            err.report = self.report()  # type: ignore[attr-defined]  # the checks so far, added at raise
            raise err

    def bound(self, name: str, value: float, threshold: float, detail: str = "") -> None:
        self.record(name, float(value), float(threshold), bool(value <= threshold), detail)

    def fact(self, name: str, passed: bool | np.bool_, detail: str = "") -> None:
        self.record(name, bool(passed), None, bool(passed), detail)

    def report(self) -> CheckReport:
        return CheckReport(self.subject, self.kind, tuple(self.items))


def check_system(obj: Any, *, x0: Any = None, t_span: tuple[float, float] = (0.0, 0.05),
                 options: Mapping[str, Any] | None = None, n_points: int = 50,
                 tol: float = 1e-12, seed: int = 0) -> CheckReport:
    """Check numerically that a law or a system keeps nscontrol's contracts.

    Parameters
    ----------
    obj
        A :class:`~nscontrol.laws.base.SetValuedLaw`, a
        :class:`~nscontrol.laws.impact.NewtonImpactLaw`, or a system (an object with
        ``n_states`` and ``default_method``).
    x0 : array_like, optional
        Systems only: the initial state of the short run. Default: the first of a few
        candidates (``linspace(1, 2, n)``, ``0.5``, zeros, seeded random states) that the
        system accepts as admissible.
    t_span : (float, float)
        Systems only: the span of the short run.
    options : mapping, optional
        Systems only: options for ``simulate`` (default ``progress=False`` and, for the
        time-stepping methods ``moreau_jean`` and ``implicit_euler``, ``h = (tf - t0) / 100``).
    n_points : int
        Laws: random points (and pairs) per property.
    tol : float
        Laws: threshold of the graph residuals, of the monotonicity defect and of the
        agreement of the complementarity form with the resolvent (absolute; points are drawn
        in ``[-10, 10]``).
    seed : int
        Seed of the random points and states.

    Returns
    -------
    CheckReport
        Every check that ran, all passed.

    Raises
    ------
    ModelError
        A property fails (the message names it, with the numbers and the point; ``err.report``
        holds the checks so far), or ``obj`` is neither a law nor a system, or no admissible
        initial state was found.
    DimensionError, InadmissibleStateError
        A given ``x0`` of the wrong length, or not admissible for the system.

    Notes
    -----
    The checks are the module docstring's numbered lists. They sample, so passing them is
    evidence, not proof; failing them is a counterexample, with the point that shows it.

    Examples
    --------
    >>> from nscontrol.laws.relay import Relay
    >>> report = check_system(Relay([1.0, 2.0]))
    >>> report.kind, report.passed
    ('set-valued law', True)
    >>> from nscontrol.laws.base import SetValuedLaw
    >>> class Sloppy(Relay):               # a resolvent that ignores the law
    ...     def _resolvent(self, x, gamma):
    ...         return x
    >>> check_system(Sloppy(1.0))         # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: check_system(Sloppy(...)): set-valued law fails 'resolvent ...
    """
    from ..laws.base import SetValuedLaw
    from ..laws.impact import NewtonImpactLaw

    n_points = check_integer("n_points", n_points, minimum=2)
    tol = check_positive("tol", tol)
    rng = np.random.default_rng(check_integer("seed", seed, minimum=0))
    subject = _short_repr(obj)
    if isinstance(obj, SetValuedLaw):
        chk = _Checker(subject, "set-valued law")
        _check_law(chk, obj, rng, n_points, tol)
    elif isinstance(obj, NewtonImpactLaw):
        chk = _Checker(subject, "impact law")
        _check_impact_law(chk, obj, rng, n_points)
    elif hasattr(obj, "n_states") and hasattr(obj, "default_method"):
        chk = _Checker(subject, "system")
        _check_system(chk, obj, x0, t_span, dict(options or {}), rng)
    else:
        raise ModelError(f"obj: expected a SetValuedLaw, a NewtonImpactLaw or a system (an "
                         f"object with n_states and default_method), got "
                         f"{type(obj).__name__}")
    return chk.report()


# ----------------------------------------------------------------------------- laws


def _gamma(law: Any, rng: np.random.Generator) -> FloatArray:
    g = rng.uniform(0.05, 20.0, law.dim) if law.componentwise else np.full(law.dim, 1.3)
    sigma = np.asarray(getattr(law, "sigma_tan", np.zeros(law.dim)), dtype=float)
    if not law.monotone and np.any(sigma > 0.0):     # unique resolvent needs gamma sigma < 1
        g = np.minimum(g, 0.9 / np.maximum(sigma, 1e-300))
        if not law.componentwise:
            g = np.full(law.dim, float(g.min()))
    return g


def _point(law: Any, rng: np.random.Generator) -> FloatArray:
    x = rng.uniform(-10.0, 10.0, law.dim)
    x[rng.random(law.dim) < 0.3] *= 1e-3            # also reach the flat parts of graphs
    return x


def _graph_points(chk: _Checker, law: Any, rng: np.random.Generator, n: int, tol: float,
                  label: str) -> list[tuple[FloatArray, FloatArray]]:
    """Graph points from the resolvent, checking that they are in the graph."""
    points, worst, where = [], 0.0, ""
    for _ in range(n):
        x, g = _point(law, rng), _gamma(law, rng)
        z = np.asarray(law.resolvent(x, g), dtype=float)
        if z.shape != (law.dim,) or not np.all(np.isfinite(z)):
            chk.fact(f"{label}resolvent returns a finite point of length dim", False,
                     f"resolvent(x={_vec(x)}, gamma={_vec(g)}) = {z!r}")
        v = (x - z) / g
        res = float(law.graph_residual(z, v))
        if not res <= worst:
            worst, where = res, f"x = {_vec(x)}, gamma = {_vec(g)}, z = {_vec(z)}"
        points.append((z, v))
    chk.bound(f"{label}resolvent lands in the graph (max graph_residual over {n} points)",
              worst, tol, f"worst at {where}")
    return points


def _check_law(chk: _Checker, law: Any, rng: np.random.Generator, n: int, tol: float,
               label: str = "") -> None:
    dim = getattr(law, "dim", None)
    chk.fact(f"{label}dim is a positive integer", isinstance(dim, int | np.integer)
             and not isinstance(dim, bool) and dim >= 1, f"dim = {dim!r}")
    if not isinstance(dim, int | np.integer):   # fact() has raised already; narrows dim
        return
    for flag in ("monotone", "componentwise"):
        value = getattr(law, flag, None)
        chk.fact(f"{label}{flag} is a bool", isinstance(value, bool | np.bool_),
                 f"{flag} = {value!r}")
    try:
        law.resolvent(np.zeros(dim + 1), 1.0)
        refused = False
    except DimensionError:
        refused = True
    chk.fact(f"{label}resolvent refuses a point of length dim + 1 with DimensionError", refused)

    points = _graph_points(chk, law, rng, n, tol, label)
    worst, where = 0.0, ""
    for z, _ in points:
        try:
            s = np.asarray(law.select(z), dtype=float)
        except NscontrolError as exc:
            chk.fact(f"{label}select is defined at resolvent points", False,
                     f"select(z={_vec(z)}) raised {type(exc).__name__}: {exc}")
        res = float(law.graph_residual(z, s))
        if not res <= worst:
            worst, where = res, f"z = {_vec(z)}, select(z) = {_vec(s)}"
    chk.bound(f"{label}select(z) lies in the graph (max graph_residual)", worst, tol,
              f"worst at {where}")

    if law.monotone:
        worst, where = 0.0, ""
        for (z1, v1), (z2, v2) in zip(points[::2], points[1::2], strict=False):
            defect = -float((z1 - z2) @ (v1 - v2))
            if not defect <= worst:
                worst, where = defect, (f"(z1, v1) = ({_vec(z1)}, {_vec(v1)}), (z2, v2) = "
                                        f"({_vec(z2)}, {_vec(v2)})")
        chk.bound(f"{label}monotone: max of -(z1 - z2)·(v1 - v2) over {len(points) // 2} "
                  "pairs", worst, tol, f"worst at {where}")
    else:
        part = law.loop_transformation().monotone_part
        chk.fact(f"{label}non-monotone: its loop transformation has a monotone part",
                 bool(part.monotone), f"monotone_part = {part!r}")
        _check_law(chk, part, rng, n, tol, label=f"{label}loop-transformed part: ")
        return
    _check_complementarity(chk, law, rng, max(3, n // 5), tol, label)


def _check_complementarity(chk: _Checker, law: Any, rng: np.random.Generator, n: int,
                           tol: float, label: str) -> None:
    from ..numerics.lcp import solve_lcp

    try:
        form = law.complementarity_form()
    except ModelError:
        chk.fact(f"{label}complementarity form: none offered (a curved graph)", True)
        return
    m, k = law.dim, form.n_complementarity
    shapes = {"w0": (m,), "E": (m, k), "Nz": (k, m), "Nxi": (k, k), "r": (k,)}
    bad = [f"{a} {np.shape(getattr(form, a))} (expected {s})" for a, s in shapes.items()
           if np.shape(getattr(form, a)) != s]
    chk.fact(f"{label}complementarity form has consistent shapes", not bad, "; ".join(bad))
    worst_graph, worst_agree, where = 0.0, 0.0, ""
    for _ in range(n):
        d = rng.uniform(0.1, 5.0, m) if law.componentwise else np.full(m, rng.uniform(0.1, 5))
        M, q = np.diag(d), rng.uniform(-10.0, 10.0, m)
        if k == 0:
            w = form.w0.copy()
            z = M @ w + q
        else:
            A, b = form.lcp(M, q)
            res = solve_lcp(A, b, method="lemke")
            if not res.success:
                chk.fact(f"{label}complementarity form: the LCP of a diagonal positive step is "
                         "solved (Lemke)", False,
                         f"M = diag({_vec(d)}), q = {_vec(q)}: {res.message}")
            z, w = form.recover(res.z, M, q)
        g_res = float(law.graph_residual(z, -w))
        z_closed = law.resolvent(q, d)
        agree = float(np.max(np.abs(z - z_closed))) / (1.0 + float(np.max(np.abs(q))))
        if not g_res <= worst_graph:
            worst_graph = g_res
        if not agree <= worst_agree:
            worst_agree, where = agree, f"M = diag({_vec(d)}), q = {_vec(q)}"
    chk.bound(f"{label}complementarity form: its solutions lie in the graph (max "
              "graph_residual(z, -w))", worst_graph, 1e3 * tol)
    chk.bound(f"{label}complementarity form agrees with the resolvent (max |z_lcp - z_closed| "
              "/ (1 + |q|))", worst_agree, 1e3 * tol, f"worst at {where}")


def _check_impact_law(chk: _Checker, law: Any, rng: np.random.Generator, n: int) -> None:
    worst = {"complementarity": 0.0, "momentum": 0.0, "energy gain": 0.0, "impulse sign": 0.0}
    for _ in range(max(5, n // 5)):
        ndof = int(rng.integers(2, 6))
        k = int(law.e.size) if law.e.size > 1 else int(rng.integers(1, ndof))
        masses = rng.uniform(0.5, 3.0, ndof)
        W = rng.standard_normal((ndof, k))
        v_minus = rng.standard_normal(ndof)
        try:
            out = law.apply(np.diag(masses), W, v_minus)
        except NscontrolError as exc:
            chk.fact("apply solves random impacts", False, f"{type(exc).__name__}: {exc}")
        e = law.coefficients(k)
        scale = 1.0 + float(np.max(np.abs(v_minus)))
        slack = W.T @ out.v_plus + e * (W.T @ v_minus)
        worst["impulse sign"] = max(worst["impulse sign"], float(-out.impulse.min()) / scale,
                                    float(-slack.min()) / scale)
        worst["complementarity"] = max(worst["complementarity"],
                                       float(np.abs(out.impulse * slack).max()) / scale**2)
        worst["momentum"] = max(worst["momentum"], float(np.abs(
            masses * (out.v_plus - v_minus) - W @ out.impulse).max()) / scale)
        if np.ptp(e) == 0.0:
            gain = 0.5 * float(masses @ (out.v_plus**2 - v_minus**2))
            worst["energy gain"] = max(worst["energy gain"], gain / scale**2)
    chk.bound("impulses and post-impact slacks are nonnegative (relative)",
              worst["impulse sign"], 1e-10)
    chk.bound("impulse ⟂ W^T v+ + e W^T v- (relative)", worst["complementarity"], 1e-10)
    chk.bound("momentum changes by W P (relative)", worst["momentum"], 1e-10)
    chk.bound("kinetic energy does not grow (relative gain)", worst["energy gain"], 1e-10)


# ----------------------------------------------------------------------------- systems


def _check_system(chk: _Checker, system: Any, x0: Any, t_span: tuple[float, float],
                  options: dict[str, Any], rng: np.random.Generator) -> None:
    from ..simulate import METHODS, Trajectory, simulate

    n = system.n_states
    chk.fact("n_states is a positive integer", isinstance(n, int | np.integer)
             and not isinstance(n, bool) and n >= 1, f"n_states = {n!r}")
    method = system.default_method
    chk.fact("default_method is one of simulate's methods", method in METHODS,
             f"default_method = {method!r}, methods {sorted(METHODS)}")
    names = tuple(getattr(system, "state_names", ()) or ())
    chk.fact("state_names is empty or has n_states names", len(names) in (0, n),
             f"{len(names)} names for {n} states")
    t0, tf = float(t_span[0]), float(t_span[1])
    if method in ("moreau_jean", "implicit_euler"):
        options.setdefault("h", (tf - t0) / STEPS)
    options.setdefault("progress", False)

    wrong = np.zeros(n + 1)
    if hasattr(system, "check_state"):
        chk.fact("check_state refuses an x0 of length n_states + 1 with DimensionError",
                 *_raises(DimensionError, lambda: system.check_state(wrong)))
    chk.fact("simulate refuses an x0 of length n_states + 1 with DimensionError",
             *_raises(DimensionError, lambda: simulate(system, wrong, (t0, tf), **options)))

    start = _initial_state(system, x0, n, rng)
    try:
        traj = simulate(system, start, (t0, tf), **options)
    except NscontrolError as exc:
        chk.fact(f"a short simulate() run ({method}) completes", False,
                 f"x0 = {_vec(start)}, t_span = {(t0, tf)}: {type(exc).__name__}: {exc}")
    chk.fact("simulate returns a Trajectory", isinstance(traj, Trajectory),
             f"got {type(traj).__name__}")
    chk.fact("the trajectory names the method that made it", traj.method == method,
             f"method = {traj.method!r}, default_method = {method!r}")
    t, x = traj.t, traj.x
    chk.fact("t is a nonempty 1-d array", t.ndim == 1 and t.size >= 1, f"shape {t.shape}")
    chk.fact("x has shape (len(t), n_states)", x.shape == (t.size, n),
             f"x.shape = {x.shape}, len(t) = {t.size}, n_states = {n}")
    chk.bound("t starts at t0 (|t[0] - t0|)", abs(t[0] - t0), 1e-12 * (1.0 + abs(t0)))
    end = tf if traj.status == 0 else float(t[-1])
    chk.fact("the run succeeded and t ends at tf (or at a terminal event)",
             traj.success and abs(t[-1] - end) <= 1e-9 * (1.0 + abs(tf)) and t[-1] <= tf
             + 1e-9 * (1.0 + abs(tf)), f"status {traj.status}, t[-1] = {t[-1]!r}, tf = {tf}")
    steps = np.diff(t)
    chk.bound("t is nondecreasing (max backward step)", float(max(0.0, -steps.min(initial=0.0))),
              0.0)
    chk.fact("t and x are finite", bool(np.all(np.isfinite(t)) and np.all(np.isfinite(x))))
    scale = 1.0 + float(np.max(np.abs(start)))
    chk.bound("x starts at x0 (max |x[0] - x0| / (1 + |x0|))",
              float(np.max(np.abs(x[0] - start))) / scale, 1e-12)
    bad = [f"{k}: {np.shape(v)}" for k, v in traj.signals.items() if np.shape(v)[:1] != (t.size,)]
    chk.fact("every signal has len(t) rows", not bad, "; ".join(bad))
    nonfinite = [k for k, v in traj.signals.items()
                 if np.asarray(v).dtype.kind in "fc" and not np.all(np.isfinite(v))]
    chk.fact("every signal is finite", not nonfinite, f"non-finite: {nonfinite}")
    times = traj.event_times()
    outside = times[(times < t0 - 1e-12) | (times > t[-1] + 1e-12)]
    chk.fact("every event lies in the span, in time order",
             outside.size == 0 and bool(np.all(np.diff(times) >= 0.0)),
             f"{times.size} events, outside: {outside.tolist()[:5]}")
    if getattr(system, "friction_dim", 0):
        _check_friction(chk, system, traj)


def _check_friction(chk: _Checker, system: Any, traj: Any) -> None:
    """Coulomb's law on the recorded impulses: in the cone, and maximal dissipation (the
    friction impulse opposes the slip velocity at the step's end, ``P_T · u_T <= 0``), to
    the contact solver's tolerance ``max_contact_residual`` (relative)."""
    d, n = system.friction_dim, system.n_dof
    pn = traj.signals["impulse"][1:]
    pt = traj.signals["friction_impulse"][1:].reshape(pn.shape[0], -1, d)
    tol = 10.0 * max(float(traj.stats.get("max_contact_residual", 0.0)), 1e-15)
    scale = 1.0 + float(np.max(np.abs(pn), initial=0.0))
    excess = np.linalg.norm(pt, axis=2) - system.friction * pn
    chk.bound("friction impulses lie in the Coulomb cone (|P_T| - mu P_N, relative)",
              float(np.max(excess, initial=0.0)) / scale, tol)
    ut = np.asarray(system.tangent_matrix @ traj.x[1:, n:].T).T.reshape(pn.shape[0], -1, d)
    vscale = 1.0 + float(np.max(np.abs(traj.x[:, n:]), initial=0.0))
    power = np.einsum("kjd,kjd->kj", pt, ut)
    chk.bound("friction impulses oppose the slip (max P_T · u_T, relative)",
              float(np.max(power, initial=0.0)) / (scale * vscale), tol)


def _initial_state(system: Any, x0: Any, n: int, rng: np.random.Generator) -> FloatArray:
    """``x0`` (validated), or the first admissible candidate state."""
    if x0 is not None:
        x0 = as_vector("x0", x0, n)
        if hasattr(system, "check_state"):
            system.check_state(x0)
        return x0
    candidates = [np.linspace(1.0, 2.0, n), np.full(n, 0.5), np.zeros(n)]
    candidates += [rng.uniform(0.1, 1.0, n) for _ in range(3)]
    candidates += [rng.standard_normal(n) for _ in range(3)]
    check = getattr(system, "check_state", None)
    domain = getattr(system, "domain", None)
    for cand in candidates:
        try:
            if check is not None:
                check(cand)
            if domain is not None and not np.all(domain[0] @ cand <= domain[1]):
                continue
        except NscontrolError:
            continue
        return cand
    raise ModelError(f"x0: check_system found no admissible initial state for "
                     f"{_short_repr(system)} among {len(candidates)} candidates; pass x0=")


# ----------------------------------------------------------------------------- helpers


def _raises(error: type[Exception], fn: Callable[[], Any]) -> tuple[bool, str]:
    """Whether ``fn()`` raises ``error``, and what happened otherwise."""
    try:
        fn()
    except error:
        return True, ""
    except Exception as exc:  # noqa: BLE001 - any other outcome is the failure being checked
        return False, f"it raised {type(exc).__name__}: {exc}"
    return False, "it raised nothing"


def _short_repr(obj: Any, limit: int = 80) -> str:
    try:
        text = repr(obj)
    except Exception:  # noqa: BLE001 - a broken __repr__ must not hide the real check
        text = type(obj).__name__
    if not text.startswith(type(obj).__name__) or len(text) > limit:
        text = f"{type(obj).__name__}(...)"       # a default or an inherited repr
    return text


def _vec(a: Any) -> str:
    return np.array2string(np.asarray(a, dtype=float), precision=4, threshold=8,
                           separator=", ")


def _fmt(value: Any) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)

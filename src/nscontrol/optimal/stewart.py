r"""Finite elements with switch detection (FESD) for piecewise-smooth systems in Stewart's
form: several switching functions, nonlinear switching functions and nonlinear fields.

**The model.** One or several *layers* :class:`StewartSystem`, their fields summed::

    x' = Σ_l Σ_i θ^l_i f^l_i(x, u),
    g^l(x) = -S^l c^l(x) = λ^l + μ^l 1,     0 <= θ^l ⟂ λ^l >= 0,     Σ_i θ^l_i = 1.

Layer ``l`` has switching functions ``c^l(x) ∈ R^m`` and one field per row of its sign matrix
``S^l ∈ {-1, 1}^{n_f × m}``: field ``i`` rules the region ``R_i = {x : S_i,j c_j(x) > 0 for
every j}`` (by default every one of the ``2^m`` sign vectors). At an ``x`` inside ``R_i``
the indicator ``g_i = -Σ_j |c_j|`` is the least entry of ``g``, so ``λ_i = g_i - min g`` is
zero exactly on the regions whose closures hold ``x`` and ``θ`` selects among their fields:
Filippov's convex combinations on the surfaces.

**Transcription.** ``[0, T]`` is cut into ``N`` control stages (one input each), each into
``N_fe`` finite elements of lengths ``h_k``. Implicit Euler on each element, the algebraic
variables ``θ_k, λ_k, μ_k`` at its end::

    x_{k+1} = x_k + h_k Σ_l F^l(x_{k+1}, u_s) θ^l_k,     g^l(x_{k+1}) = λ^l_k + μ^l_k 1.

(One element's rows and stage cost are CasADi functions mapped over the K elements, not K
copies written out in Python: the NLP is declared several times faster.)

With ``switch_detection`` the lengths are unknowns (``Σ h_k = T``, and per stage ``T / N``
with ``equidistant_control_grid``; each within ``element_bounds`` times ``h̄ = T / (N N_fe)``)
and the **cross complementarity** ``θ^l_{k,i} λ^l_{k-1,i} = 0`` (with ``λ`` at ``x0`` before
the first element) forbids an element to leave a region whose field was active at its
start: a switch happens only at an element boundary, which the solver moves onto the
switching instant. **Step equilibration** (``equilibration = ρ > 0``) adds
``ρ Σ_k (h_k - h̄)²`` (``equilibration_form="mean"``) or ``ρ Σ (h_k - h_{k-1})²`` over the
consecutive elements of each stage (``"delta"``) to the objective: without it the lengths of
the elements that hold no switch are not determined by the problem (any split of an element
with no switch is optimal), which leaves IPOPT a degenerate direction. Only these heuristic
penalties are offered (they bias the optimum by their own size; the plan reports the cost
without them, :attr:`FesdPlan.cost`, and with them, :attr:`FesdPlan.objective`).

The complementarity pairs (``θ ⟂ λ`` and the cross pairs) go through the Scholtes homotopy
and polish of :mod:`.homotopy`; :attr:`FesdPlan.residual` is their largest
``|min(a, b)|``.

Fields and switching functions are Python callables ``f(x, u)`` and ``c(x)`` traced once
with CasADi's ``SX`` symbols: CasADi expressions (``casadi.sin``...), or numpy-friendly code
(``A @ x``, ``x[0] ** 2``, ``np.sin(x[0])`` on a scalar entry) returning a vector or a list.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_vector,
    check_bool,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import DimensionError, ModelError
from ._casadi import require_casadi
from .contact import Relaxation, _bound, _vector_with_nan
from .homotopy import residual, solve_homotopy, stage_stats

__all__ = ["StewartSystem", "FesdProblem", "FesdPlan", "HeldInput"]


@dataclass(frozen=True, eq=False)
class StewartSystem:
    """One layer of a piecewise-smooth system in Stewart's form (the module docstring).

    Parameters
    ----------
    fields : sequence of callable
        ``f_i(x, u)``, one per region (a vector of the state's size).
    switching : callable or sequence of callable
        ``c(x)`` returning the ``m`` switching functions, or one callable ``c_j(x)`` per
        switching function (each a scalar).
    signs : array_like (n_f, m), optional
        Row ``i``: the signs (``±1``) of ``c(x)`` in field ``i``'s region. Default: every
        sign vector, in the order of ``itertools.product((-1, 1), repeat=m)`` (then
        ``len(fields)`` must be ``2^m``).

    Raises
    ------
    ModelError
        A field or switching function that is not callable, signs other than ``±1``, two
        regions with the same signs.
    DimensionError
        Signs whose shape disagrees with the fields (checked here) or with the switching
        functions (checked when a :class:`FesdProblem` traces them).
    """

    fields: Sequence[Callable[..., Any]]
    switching: Callable[..., Any] | Sequence[Callable[..., Any]]
    signs: Any = None

    def __post_init__(self) -> None:
        fields = tuple(self.fields) if isinstance(self.fields, Sequence) else None
        if not fields:
            raise ModelError("fields: expected a non-empty sequence of callables f(x, u), "
                             f"got {type(self.fields).__name__}")
        for i, f in enumerate(fields):
            if not callable(f):
                raise ModelError(f"fields: entry {i} is a {type(f).__name__}, not a callable "
                                 "f(x, u); pass one function per region")
        object.__setattr__(self, "fields", fields)
        if not callable(self.switching):
            parts = tuple(self.switching) if isinstance(self.switching, Sequence) else ()
            if not parts or not all(callable(c) for c in parts):
                raise ModelError("switching: expected a callable c(x) or a sequence of "
                                 f"callables c_j(x), got {type(self.switching).__name__}")
            object.__setattr__(self, "switching", parts)
        if self.signs is None:
            m = int(np.log2(len(fields)))
            if 2 ** m != len(fields):
                raise DimensionError(f"signs: not given, so every sign vector of m switching "
                                     f"functions is a region (2^m fields), but there are "
                                     f"{len(fields)} fields; give the sign matrix")
            S = np.array(list(itertools.product((-1.0, 1.0), repeat=m)), float).reshape(-1, m)
        else:
            S = as_matrix("signs", self.signs, rows=len(fields))
            if not np.all(np.abs(S) == 1.0):
                raise ModelError("signs: entries must be -1 or 1 (the sign of c_j in the "
                                 "region)")
            if len({tuple(r) for r in S}) != S.shape[0]:
                raise ModelError("signs: two rows are equal (two fields on one region); "
                                 "merge them or give distinct sign vectors")
        object.__setattr__(self, "signs", S)

    @property
    def m(self) -> int:
        """Number of switching functions."""
        return int(self.signs.shape[1])


def _column(name: str, value: Any, size: int) -> Any:
    """A traced value as an ``SX`` column of ``size`` entries, or a DimensionError."""
    ca = require_casadi()
    if isinstance(value, (ca.SX, ca.DM)):
        out = ca.SX(value)
    else:
        arr = np.asarray(value, dtype=object).reshape(-1) if not np.isscalar(value) \
            else np.array([value], dtype=object)
        out = ca.vertcat(*[ca.SX(v) for v in arr.tolist()]) if arr.size else ca.SX(0, 1)
    if out.shape[1] != 1 and out.shape[0] == 1:
        out = out.T
    if out.numel() != size or out.shape[1] != 1:
        raise DimensionError(f"{name}: returned shape {out.shape}, expected {size} values")
    return out


def _trace(name: str, fn: Callable[..., Any], args: tuple[Any, ...], size: int) -> Any:
    """``fn`` called on CasADi symbols, as an ``SX`` column. A numpy function of a symbol
    (``np.sin(x[0])``) gives CasADi's symbol, what tracing wants: CasADi's notice that it
    may change that default is silenced here."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="\ncasadi: a numpy function",
                                    category=FutureWarning)
            value = fn(*args)
    except (TypeError, ValueError, IndexError, AttributeError) as exc:
        raise ModelError(f"{name}: calling it on CasADi symbols failed ({exc}); write it with "
                         "casadi functions or numpy operators on the entries") from exc
    return _column(name, value, size)


class _Traced:
    """The CasADi functions of the problem's layers, cost and guess."""

    def __init__(self, layers: tuple[StewartSystem, ...], n: int, p: int,
                 stage_cost: Callable[..., Any] | None,
                 terminal_cost: Callable[..., Any] | None) -> None:
        ca = require_casadi()
        x, u = ca.SX.sym("x", n), ca.SX.sym("u", p)
        fields, switching, self.sizes = [], [], []
        for li, layer in enumerate(layers):
            where = f"layer {li}: " if len(layers) > 1 else ""
            cols = [_trace(f"fields ({where}field {i})", f, (x, u), n)
                    for i, f in enumerate(layer.fields)]
            if callable(layer.switching):
                c = _trace(f"switching ({where.strip()})".replace(" ()", ""), layer.switching,
                           (x,), layer.m)
            else:
                if len(layer.switching) != layer.m:
                    raise DimensionError(f"signs: {where}{layer.m} columns but "
                                         f"{len(layer.switching)} switching functions")
                c = ca.vertcat(*[_trace(f"switching ({where}function {j})", cj, (x,), 1)
                                 for j, cj in enumerate(layer.switching)])
            fields.append(ca.horzcat(*cols))
            switching.append(-ca.mtimes(ca.DM(layer.signs), c))
            self.sizes.append(len(cols))
        self.rows = np.cumsum([0, *self.sizes])
        # the field Σ_l F^l θ^l of one element (and its derivative in u, for the guess's
        # inputs) and the layers' g stacked: the transcription's one declaration of each
        th = ca.SX.sym("th", int(self.rows[-1]))
        f = sum(ca.mtimes(Fl, th[self.rows[i]:self.rows[i + 1]])
                for i, Fl in enumerate(fields))
        self.field = ca.Function("field", [x, u, th], [f, ca.jacobian(f, u)])
        self.g = ca.Function("g", [x], [ca.vertcat(*switching)])
        L = ca.sumsqr(u) if stage_cost is None else _trace("stage_cost", stage_cost, (x, u), 1)
        self.L = ca.Function("L", [x, u], [L])
        Lt = ca.SX(0) if terminal_cost is None else _trace("terminal_cost", terminal_cost,
                                                           (x,), 1)
        self.Lt = ca.Function("Lt", [x], [Lt])


@dataclass(frozen=True)
class HeldInput:
    """An input held constant on each interval ``[t_s, t_{s+1})`` of a non-uniform grid
    (the last value after it): the planned input of a :class:`FesdPlan`, for
    ``simulate(..., u=...)``.

    Parameters
    ----------
    t : ndarray, shape (N + 1,)
        Interval boundaries.
    values : ndarray, shape (N, p)
        One input per interval.
    """

    t: FloatArray
    values: FloatArray

    def __call__(self, t: float) -> FloatArray:
        k = int(np.searchsorted(self.t, float(t), side="right")) - 1
        return self.values[min(max(k, 0), self.values.shape[0] - 1)].copy()


@dataclass(frozen=True)
class FesdPlan:
    """A planned motion of a :class:`FesdProblem` on its finite elements.

    Attributes
    ----------
    t : ndarray, shape (K + 1,)
        Element boundaries (``K = N N_fe``).
    x : ndarray, shape (K + 1, n)
        States at the boundaries.
    u : ndarray, shape (N, p)
        Input of each control stage.
    t_stages : ndarray, shape (N + 1,)
        Stage boundaries.
    theta : ndarray, shape (K, n_θ)
        The fields' weights on each element (the layers' rows stacked).
    cost : float
        ``Σ_k h_k L(x_{k+1}, u_k) + L_T(x_K)``.
    objective : float
        ``cost`` plus the step equilibration penalty.
    residual : float
        Largest ``|min(a, b)|`` over the complementarity pairs (cross ones included).
    stats : dict
        ``stages``, ``solve_time``, ``iterations``, ``polished``, ``switch_detection``.
    """

    t: FloatArray
    x: FloatArray
    u: FloatArray
    t_stages: FloatArray
    theta: FloatArray
    cost: float
    objective: float
    residual: float
    stats: dict[str, Any] = field(default_factory=dict)

    def input(self) -> HeldInput:
        """The planned inputs as ``simulate``'s ``u=`` (held over each stage)."""
        return HeldInput(self.t_stages, self.u)

    def crossings(self, c: Callable[[FloatArray], float]) -> FloatArray:
        """Where the scalar ``c(x)`` changes sign along the plan (linear between
        boundaries; a boundary where ``c`` is exactly 0 counts once).

        Parameters
        ----------
        c : callable
            ``c(x)`` on a numpy state.

        Returns
        -------
        ndarray
        """
        check_type("c", c, Callable)  # type: ignore[arg-type]
        psi = np.array([float(c(xk)) for xk in self.x])
        return _sign_changes(self.t, psi)


def _sign_changes(t: FloatArray, psi: FloatArray) -> FloatArray:
    k = np.flatnonzero(np.sign(psi[:-1]) * np.sign(psi[1:]) < 0)
    out = t[k] + (t[k + 1] - t[k]) * psi[k] / (psi[k] - psi[k + 1])
    zero = np.flatnonzero((psi == 0.0)[1:-1]) + 1
    return np.sort(np.concatenate([out, t[zero]]))


def _x_bound(name: str, value: Any, n: int) -> FloatArray | None:
    if value is None:
        return None
    arr = as_float_array(name, np.broadcast_to(np.asarray(value, float), (n,))
                         if np.ndim(value) == 0 else value, finite=False).reshape(-1)
    if arr.shape != (n,):
        raise DimensionError(f"{name}: expected {n} bounds (±inf for none), got shape "
                             f"{np.shape(value)}")
    if np.isnan(arr).any():
        raise ModelError(f"{name}: NaN entries; use ±inf for an unbounded component")
    return arr


def _check_equilibration(weight: Any, form: Any) -> float:
    """The step equilibration weight ``ρ >= 0``, once ``form`` is checked to be ``"mean"``
    or ``"delta"`` (:class:`FesdProblem` and the fronts over it)."""
    if form not in ("mean", "delta"):
        raise ModelError(f"equilibration_form: expected 'mean' or 'delta', got {form!r}")
    return check_positive("equilibration", weight, allow_zero=True)


@dataclass(frozen=True, eq=False)
class FesdProblem:
    """Optimal control of a piecewise-smooth system in Stewart's form by FESD (the module
    docstring): least ``∫ L(x, u) dt + L_T(x(T))`` from ``x0``, optionally to ``x_final``.

    Parameters
    ----------
    systems : StewartSystem or sequence of StewartSystem
        The layers (their fields summed).
    x0 : array_like (n,)
        Initial state.
    T : float
        Horizon.
    stages : int
        Number of control stages ``N`` (one input each).
    elements : int
        Finite elements per stage ``N_fe``.
    inputs : int
        Number of inputs ``p`` (the size of ``u`` the fields receive).
    stage_cost : callable, optional
        ``L(x, u)`` (default ``|u|²``), integrated as ``Σ h_k L(x_{k+1}, u_k)``.
    terminal_cost : callable, optional
        ``L_T(x)`` (default none).
    x_final : array_like (n,), optional
        Final state (NaN components free; default free).
    u_min, u_max : array_like (p,), optional
        Input bounds (a scalar applies to every input).
    x_min, x_max : array_like (n,), optional
        State bounds at every element boundary (``±inf`` for none).
    switch_detection : bool
        Free element lengths with cross complementarity, or a fixed grid.
    equidistant_control_grid : bool
        Each stage lasts ``T / N`` (only its elements move), or only ``Σ h = T``.
    element_bounds : (float, float)
        Each element's length within these multiples of ``h̄`` (``0 <= low < 1 < high``).
    equilibration : float
        Step equilibration weight ``ρ >= 0``.
    equilibration_form : {"mean", "delta"}
        The penalty: distance of each length to ``h̄``, or difference of consecutive lengths
        within a stage.
    warm_homotopy : bool
        Each relaxed solve starts from the previous one's primal and dual solution at a
        small barrier; ``False``: from its primal solution alone at IPOPT's default barrier
        (as nosnoc does), more iterations, and the iterate may leave the branch the first
        relaxations chose — on nosnoc's ``motor_with_friction`` this reaches nosnoc's
        optimum, 0.06 % below the warm homotopy's. Both are local optima.
    start : {"consistent", "centred"}
        The algebraic variables of the first solve: consistent with the guess's states (on
        each element the field of its end's region, ``λ`` and ``μ`` from the switching
        functions), or centred as nosnoc starts them (``θ = λ = 1 / n_f`` in each layer,
        ``μ = 1``; nosnoc's start when ``σ0 = 1``), which leaves the first relaxed solve
        to choose the regions — on SimpleCar from rest with ``σ0 = 1``, 115 IPOPT
        iterations in that solve instead of 207, to the same optimum.

    Raises
    ------
    DimensionError
        Shapes that disagree (a field or switching function of the wrong size included).
    ModelError
        A bad value, or a callable that CasADi cannot trace.
    """

    systems: Any
    x0: Any
    T: float
    stages: int
    elements: int = 2
    inputs: int = 0
    stage_cost: Callable[..., Any] | None = None
    terminal_cost: Callable[..., Any] | None = None
    x_final: Any = None
    u_min: Any = None
    u_max: Any = None
    x_min: Any = None
    x_max: Any = None
    switch_detection: bool = True
    equidistant_control_grid: bool = True
    element_bounds: tuple[float, float] = (0.1, 10.0)
    equilibration: float = 0.0
    equilibration_form: str = "mean"
    warm_homotopy: bool = True
    start: str = "consistent"
    n: int = field(init=False)
    traced: _Traced = field(init=False, repr=False)
    _built: dict[str, Any] = field(init=False, repr=False, default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        layers = (self.systems,) if isinstance(self.systems, StewartSystem) else tuple(
            self.systems) if isinstance(self.systems, Sequence) else ()
        if not layers or not all(isinstance(s, StewartSystem) for s in layers):
            raise ModelError("systems: expected a StewartSystem or a non-empty sequence of "
                             f"them, got {type(self.systems).__name__}")
        set_(self, "systems", layers)
        x0 = as_vector("x0", self.x0)
        n = x0.shape[0]
        set_(self, "n", n)
        set_(self, "x0", x0)
        set_(self, "T", check_positive("T", self.T))
        set_(self, "stages", check_integer("stages", self.stages, minimum=1))
        set_(self, "elements", check_integer("elements", self.elements, minimum=1))
        p = check_integer("inputs", self.inputs, minimum=0)
        set_(self, "inputs", p)
        for name in ("stage_cost", "terminal_cost"):
            if getattr(self, name) is not None and not callable(getattr(self, name)):
                raise ModelError(f"{name}: expected a callable, got "
                                 f"{type(getattr(self, name)).__name__}")
        set_(self, "x_final", None if self.x_final is None
             else _vector_with_nan("x_final", self.x_final, n))
        for name in ("u_min", "u_max"):
            set_(self, name, _bound(name, getattr(self, name), p))
        for name in ("x_min", "x_max"):
            set_(self, name, _x_bound(name, getattr(self, name), n))
        set_(self, "switch_detection", check_bool("switch_detection", self.switch_detection))
        set_(self, "equidistant_control_grid",
             check_bool("equidistant_control_grid", self.equidistant_control_grid))
        lo, hi = (check_positive("element_bounds", v, allow_zero=True)
                  for v in self.element_bounds)
        if not lo < 1.0 < hi:
            raise ModelError(f"element_bounds: ({lo:g}, {hi:g}) must hold the uniform length "
                             "strictly inside (low < 1 < high)")
        set_(self, "element_bounds", (lo, hi))
        set_(self, "equilibration", _check_equilibration(self.equilibration,
                                                        self.equilibration_form))
        set_(self, "warm_homotopy", check_bool("warm_homotopy", self.warm_homotopy))
        if self.start not in ("consistent", "centred"):
            raise ModelError(f"start: expected 'consistent' or 'centred', got {self.start!r}")
        set_(self, "traced", _Traced(layers, n, p, self.stage_cost, self.terminal_cost))

    @property
    def free_lengths(self) -> bool:
        """Whether the element lengths are unknowns."""
        return self.switch_detection and (self.elements > 1
                                          or not self.equidistant_control_grid)

    def cost_of(self, t: ArrayLike, x: ArrayLike, u: ArrayLike, *,
                penalty: bool = False) -> float:
        """The cost ``Σ_k h_k L(x_{k+1}, u_k) + L_T(x_K)`` of a trajectory on this problem's
        element grid (e.g. another solver's plan, to compare optima by one formula), with
        ``penalty`` plus the step equilibration's (the objective the solver minimises).

        Parameters
        ----------
        t : array_like (K + 1,)
            Element boundaries.
        x : array_like (K + 1, n)
            States at the boundaries.
        u : array_like (N, p)
            Input of each stage.
        penalty : bool
            Add the step equilibration penalty.

        Returns
        -------
        float

        Raises
        ------
        DimensionError
            Shapes that disagree with the problem's grid.
        """
        tt = as_vector("t", t, self.stages * self.elements + 1)
        X = self._states("x", x)
        U = as_matrix("u", np.reshape(u, (self.stages, self.inputs)) if np.size(u) ==
                      self.stages * self.inputs else u, rows=self.stages, cols=self.inputs)
        nlp = self._transcription()
        if penalty:   # the transcription's own objective, on numbers
            return float(nlp.cost({"X": X.T, "U": U.T, "H": np.diff(tt)}))
        return nlp.plan_cost(X.T, U.T, np.diff(tt))

    def residual_of(self, x: ArrayLike, theta: ArrayLike) -> float:
        """The complementarity residual of a plan given by its states and its fields'
        weights (e.g. another solver's, to compare plans by one formula): the largest
        ``|min(θ, λ)|`` over the pairs ``θ_k ⟂ λ_k`` and, with switch detection, the cross
        pairs ``θ_k ⟂ λ_{k-1}`` (the first element's against ``λ`` at ``x0``), ``λ``
        recomputed from the states (``λ = g(x) - min g`` per layer, its value wherever
        the pairs hold), so that no solver's own multipliers enter.

        Parameters
        ----------
        x : array_like (K + 1, n)
            States at the element boundaries.
        theta : array_like (K, n_θ)
            The fields' weights on each element (the layers' rows stacked, as
            :attr:`FesdPlan.theta`).

        Returns
        -------
        float

        Raises
        ------
        DimensionError
            Shapes that disagree with the problem's grid.
        """
        K = self.stages * self.elements
        X = self._states("x", x)
        nlp = self._transcription()
        TH = as_matrix("theta", theta, rows=K, cols=nlp.nth).T
        G = nlp._g_columns(X.T)
        LAM = G - np.column_stack([nlp._per_layer_min(G[:, k]) for k in range(K + 1)])
        first = np.abs(np.minimum(TH[:, 0], LAM[:, 0])).max() if self.switch_detection \
            else 0.0
        return max(residual(nlp, {"TH": TH, "LAM": LAM[:, 1:]}), float(first))

    def _states(self, name: str, x: ArrayLike) -> FloatArray:
        """``x`` checked as the states at the K + 1 element boundaries."""
        return as_matrix(name, x, rows=self.stages * self.elements + 1, cols=self.n)

    def _transcription(self) -> _FesdNLP:
        """The transcription, built once per problem (solves and evaluations share it)."""
        if "builder" not in self._built:
            self._built["builder"] = _FesdNLP(self)
        return self._built["builder"]

    def solve(self, relaxation: Relaxation | None = None, *,
              guess: ArrayLike | None = None) -> FesdPlan:
        """Solve the Scholtes homotopy (and its polish) of the transcription.

        Parameters
        ----------
        relaxation : Relaxation, optional
            The homotopy (default :class:`Relaxation()`).
        guess : array_like (K + 1, n), optional
            States on the uniform element grid to start from; default the straight line
            from ``x0`` to ``x_final`` (``x0`` where it is free). The regions, inputs
            (least squares on the fields linearised in ``u``) and multipliers of the start
            are made consistent with them.

        Returns
        -------
        FesdPlan

        Raises
        ------
        SolverError
            IPOPT failed on a relaxed problem.
        """
        relaxation = Relaxation() if relaxation is None else check_type(
            "relaxation", relaxation, Relaxation)
        states = None if guess is None else self._states("guess", guess).T
        nlp = self._transcription()
        built = self._built
        stages: list[dict[str, Any]] = []
        sol, polished = solve_homotopy(nlp, nlp.guess(states), relaxation, stages,
                                       warm=self.warm_homotopy, built=built)
        H = np.atleast_1d(np.asarray(sol["H"], float))
        t = np.concatenate([[0.0], np.cumsum(H)])
        cost = nlp.plan_cost(sol["X"], sol["U"], H)
        return FesdPlan(t=t, x=np.asarray(sol["X"]).T.copy(), u=np.asarray(sol["U"]).T.copy(),
                        t_stages=t[::self.elements].copy(), theta=np.asarray(sol["TH"]).T.copy(),
                        cost=cost, objective=float(sol["cost"]), residual=residual(nlp, sol),
                        stats={**stage_stats(stages, polished),
                               "switch_detection": self.switch_detection})


def _row(h: Any) -> Any:
    """Element lengths as a 1 × K row: CasADi symbols reshaped, numbers as a ``DM``."""
    ca = require_casadi()
    if isinstance(h, (ca.MX, ca.SX)):
        return ca.reshape(h, 1, h.numel())
    return ca.DM(np.asarray(h, float).reshape(1, -1))


class _FesdNLP:
    """The NLP of a :class:`FesdProblem` (a :class:`~nscontrol.optimal.homotopy.Builder`)."""

    def __init__(self, problem: FesdProblem) -> None:
        self.p = problem
        self.tr = problem.traced
        self.K = problem.stages * problem.elements
        self.hbar = problem.T / self.K
        self.nth = int(self.tr.rows[-1])
        g0 = self._g(problem.x0)
        self.lam_start = g0 - self._per_layer_min(g0)
        self._element_fn: Any = None      # the mapped functions, built on first use
        self._stage_cost_fn: Any = None

    def _g(self, x: FloatArray) -> FloatArray:
        return np.asarray(self.tr.g(x), float).reshape(-1)

    def _per_layer_min(self, g: FloatArray) -> FloatArray:
        r = self.tr.rows
        return np.concatenate([np.full(r[i + 1] - r[i], g[r[i]:r[i + 1]].min(axis=0))
                               for i in range(len(r) - 1)])

    def guess(self, X: FloatArray | None = None) -> dict[str, Any]:
        """The states ``X`` (``(n, K + 1)``) on the uniform grid, with everything else
        consistent with them: the regions of each element's end (``θ``, ``λ``, ``μ``) and
        the inputs that best make each stage's steps (least squares on the fields
        linearised about ``u = 0``, clipped to the bounds). A guess whose algebraic
        variables contradict its states starts the homotopy in a poor local optimum. With
        ``start="centred"`` the algebraic variables are nosnoc's centred start instead."""
        p, K, h, r = self.p, self.K, self.hbar, self.tr.rows
        if X is None:
            xf = p.x0 if p.x_final is None else np.where(np.isnan(p.x_final), p.x0, p.x_final)
            X = p.x0[:, None] + (xf - p.x0)[:, None] * np.linspace(0, 1, K + 1)[None, :]
        G = self._g_columns(X[:, 1:])
        TH, LAM, MU = np.zeros_like(G), np.empty_like(G), np.empty((len(r) - 1, K))
        for li in range(len(r) - 1):
            block = G[r[li]:r[li + 1]]
            TH[r[li] + np.argmin(block, axis=0), np.arange(K)] = 1.0
            MU[li] = block.min(axis=0)
            LAM[r[li]:r[li + 1]] = block - MU[li]
        U = self._inputs(X, TH)
        if p.start == "centred":   # after the inputs, which take the regions of the states
            for li in range(len(r) - 1):
                TH[r[li]:r[li + 1]] = LAM[r[li]:r[li + 1]] = 1.0 / (r[li + 1] - r[li])
            MU[:] = 1.0
        return {"X": X, "U": U, "TH": TH, "LAM": LAM, "MU": MU, "H": np.full(K, h)}

    def _g_columns(self, X: FloatArray) -> FloatArray:
        """``g(x)`` of every column of ``X`` (the layers' rows stacked), one mapped call."""
        return np.asarray(self.tr.g.map(X.shape[1])(X), float).reshape(self.nth, -1)

    def _linearised(self, X: FloatArray, TH: FloatArray) -> tuple[FloatArray, FloatArray]:
        """At each element end ``x_{k+1}`` (the columns of ``X``) and ``u = 0``: the field
        ``Σ_i F_i θ_i`` (an ``n × K`` array) and its derivative in ``u`` (``K × n × q``),
        the fields' weights ``TH``; one mapped call."""
        n, q, K = self.p.n, self.p.inputs, X.shape[1]
        f, du = self.tr.field.map(K)(X, np.zeros((q, K)), TH)
        return (np.asarray(f, float).reshape(n, K),
                np.asarray(du, float).reshape(n, K, q).transpose(1, 0, 2))

    def _inputs(self, X: FloatArray, TH: FloatArray) -> FloatArray:
        p, h, ne = self.p, self.hbar, self.p.elements
        q = p.inputs
        U = np.zeros((q, p.stages))
        if q == 0:
            return U
        f, J = self._linearised(X[:, 1:], TH)
        for s in range(p.stages):
            ks = range(s * ne, (s + 1) * ne)
            rhs = np.concatenate([(X[:, k + 1] - X[:, k]) / h - f[:, k] for k in ks])
            U[:, s] = np.linalg.lstsq(np.vstack([J[k] for k in ks]), rhs, rcond=None)[0]
        return np.clip(U, -np.inf if p.u_min is None else p.u_min[:, None],
                       np.inf if p.u_max is None else p.u_max[:, None])

    def variables(self, opti: Any) -> dict[str, Any]:
        p, K = self.p, self.K
        var = {"X": opti.variable(p.n, K + 1), "U": opti.variable(p.inputs, p.stages),
               "TH": opti.variable(self.nth, K), "LAM": opti.variable(self.nth, K),
               "MU": opti.variable(len(self.tr.sizes), K)}
        var["H"] = opti.variable(K) if p.free_lengths else np.full(K, self.hbar)
        return var

    def _element(self) -> Any:
        """One element's rows as a CasADi function of ``(x_k, x_{k+1}, u, θ, λ, μ, h)``:
        the implicit Euler step and the algebraic rows ``g(x_{k+1}) - λ - μ``. Built once and
        mapped over the K elements (one call node instead of K copies written out in
        Python: the transcription is built several times faster)."""
        if self._element_fn is None:
            ca, p, tr = require_casadi(), self.p, self.tr
            xk, xn = ca.SX.sym("xk", p.n), ca.SX.sym("xn", p.n)
            u, h = ca.SX.sym("u", p.inputs), ca.SX.sym("h")
            th, lam = ca.SX.sym("th", self.nth), ca.SX.sym("lam", self.nth)
            mu = ca.SX.sym("mu", len(tr.sizes))
            mu_rows = ca.vertcat(*[ca.repmat(mu[i], tr.sizes[i], 1)
                                   for i in range(len(tr.sizes))])
            f = tr.field(xn, u, th)[0]
            self._element_fn = ca.Function("element", [xk, xn, u, th, lam, mu, h],
                                           [xn - xk - h * f, tr.g(xn) - lam - mu_rows]
                                           ).map(self.K)
        return self._element_fn

    def _stage_of_element(self) -> list[int]:
        """The control stage of each element (the column of ``U`` it holds)."""
        return [k // self.p.elements for k in range(self.K)]

    def constraints(self, opti: Any, var: dict[str, Any]) -> None:
        ca, p, tr, K = require_casadi(), self.p, self.tr, self.K
        X, U, TH, H = var["X"], var["U"], var["TH"], var["H"]
        steps, algebraic = self._element()(X[:, :K], X[:, 1:], U[:, self._stage_of_element()],
                                           TH, var["LAM"], var["MU"], _row(H))
        # one subject_to per family (each call costs); column-major: element by element
        opti.subject_to(ca.vec(steps) == 0)
        opti.subject_to(ca.vec(algebraic) == 0)
        opti.subject_to(ca.vec(ca.vertcat(*[ca.sum1(TH[tr.rows[i]:tr.rows[i + 1], :])
                                            for i in range(len(tr.sizes))])) == 1)
        opti.subject_to(X[:, 0] == p.x0)
        if p.x_final is not None:
            idx = np.flatnonzero(~np.isnan(p.x_final)).tolist()
            if idx:
                opti.subject_to(X[idx, K] == p.x_final[idx])
        for bound, sign in ((p.u_min, 1.0), (p.u_max, -1.0)):
            if bound is not None:
                opti.subject_to(ca.vec(sign * (U - np.tile(bound[:, None], (1, p.stages))))
                                >= 0)
        for xb, sign in ((p.x_min, 1.0), (p.x_max, -1.0)):
            idx = [] if xb is None else np.flatnonzero(np.isfinite(xb)).tolist()
            if idx:
                opti.subject_to(ca.vec(sign * (X[idx, 1:] - np.tile(xb[idx, None], (1, K))))
                                >= 0)
        if p.switch_detection:
            left = np.flatnonzero(self.lam_start > 0).tolist()
            if left:   # a region inactive at x0 stays off on the first element
                opti.subject_to(TH[left, 0] == 0)
        if p.free_lengths:
            self._lengths(opti, H)

    def _lengths(self, opti: Any, H: Any) -> None:
        ca, p = require_casadi(), self.p
        if p.equidistant_control_grid:
            for s in range(p.stages):
                opti.subject_to(ca.sum1(H[s * p.elements:(s + 1) * p.elements])
                                == p.T / p.stages)
        else:
            opti.subject_to(ca.sum1(H) == p.T)
        lo, hi = p.element_bounds
        opti.subject_to(opti.bounded(lo * self.hbar, H, hi * self.hbar))

    def cost(self, var: dict[str, Any]) -> Any:
        ca, p, K = require_casadi(), self.p, self.K
        X, U, H = var["X"], var["U"], var["H"]
        J = ca.mtimes(self._stage_costs(X, U), ca.vec(_row(H)))
        J = J + self.tr.Lt(X[:, K])
        if p.equilibration and p.free_lengths:
            if p.equilibration_form == "mean":
                J = J + p.equilibration * ca.sumsqr(H - self.hbar)
            else:
                ne = p.elements
                J = J + p.equilibration * sum(ca.sumsqr(H[s * ne + 1:(s + 1) * ne]
                                                        - H[s * ne:(s + 1) * ne - 1])
                                              for s in range(p.stages))
        return J

    def _stage_costs(self, X: Any, U: Any) -> Any:
        """``L(x_{k+1}, u_k)`` of every element, a 1 × K row (symbols or numbers): the
        stage cost mapped over the elements."""
        if self._stage_cost_fn is None:
            self._stage_cost_fn = self.tr.L.map(self.K)
        return self._stage_cost_fn(X[:, 1:], U[:, self._stage_of_element()])

    def plan_cost(self, X: FloatArray, U: FloatArray, H: FloatArray) -> float:
        """``Σ h_k L(x_{k+1}, u_k) + L_T(x_K)`` of a numeric solution."""
        X, U = np.asarray(X, float).reshape(self.p.n, -1), np.asarray(U, float).reshape(
            self.p.inputs, -1)
        L = np.asarray(self._stage_costs(X, U), float).reshape(-1)
        return float(L @ np.asarray(H, float).reshape(-1) + float(self.tr.Lt(X[:, self.K])))

    def pair_keys(self) -> list[tuple[Any, Any]]:
        """Which ``θ`` and ``λ`` entries (column-major) each pair holds."""
        m, K = self.nth, self.K
        keys = [([("TH", j) for j in range(m * K)], [("LAM", j) for j in range(m * K)])]
        if self.p.switch_detection:
            keys.append(([("TH", j + m) for j in range(m * (K - 1))],
                         [("LAM", j) for j in range(m * (K - 1))]))
        return keys

    def pairs(self, var: dict[str, Any], ops: Any) -> list[tuple[Any, Any]]:
        """``θ ⟂ λ`` on every element; with switch detection also the cross pairs
        ``θ_k ⟂ λ_{k-1}`` (those of the first element, against the known ``λ`` at ``x0``,
        are constraints: :meth:`constraints`)."""
        m, K = self.nth, self.K
        TH, LAM = var["TH"], var["LAM"]
        out = [(ops.select(TH, list(range(m * K))), ops.select(LAM, list(range(m * K))))]
        if self.p.switch_detection:
            out.append((ops.select(TH[:, 1:], list(range(m * (K - 1)))),
                        ops.select(LAM[:, :-1], list(range(m * (K - 1))))))
        return out

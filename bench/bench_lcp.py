"""LCP solver speed: nscontrol's methods against Siconos's Lemke and PGS, in the same run.

Scenarios: random P-matrices (n = 10, 100; Lemke and auto through ``solve_lcp``, and
``reusable``: ``LCPSolver(M)`` built once outside the timing, then ``solver.solve(q)`` timed,
the per-call cost of an application that solves with one ``M`` many times), random symmetric
positive definite matrices (n = 10, 100; PGS, Lemke and ``reusable``), the tridiagonal
Delassus matrix of a stack of N unit masses at rest (N = 10, 100, 1000, 10000; banded,
auto, Lemke, PGS) whose impulses are known
(``nscontrol.testing.lcp_problems.stack_delassus``), and the same matrix with a propagating
impact, ``q = (-1, 1e-3, ..., 1e-3)`` at contact 0 (``impact``) and at the middle contact
(``impact-mid``): Howard's worst case from ``z = 0`` (one contact per iteration, N = 1000
iterations), which the projected Thomas sweeps that start ``banded`` solve outright when the
impact reaches an end of the chain (N <= 1000) and only partly in the middle of a long one
(N = 10000: about 500 iterations). Siconos gets the same dense matrices
through temporary ``.npy`` files; its Lemke is skipped above N = 1000 (dense n^2 tableau:
seconds at N = 1000, minutes at 10000) and its PGS above N = 100 (10^4 sweeps of O(N^2)).

Like with like, both warm, both printed: ``ratio`` compares the whole Python calls
(``solve_lcp(M, q)`` against Siconos's ``sn.LCP(M, q)``, ``SolverOptions``, ``z, w`` and
the solve), ``solver_ratio`` the solvers alone (``LCPSolver(M).solve(q)`` with the solver
built once, against Siconos's solve on a problem and options built once); ``reusable``
records are solver alone against solver alone, and ``kernel_ratio`` sets the bare compiled
entry (``solve_lcp_kernel``, or the method's kernel) called from Python against Siconos's
solver alone. ``ratio`` = Siconos seconds per solve / ours (> 1: we are faster).

Siconos's own 20 LCP test problems (``shared/benchmarks/siconos-lcp``, skipped when absent;
not in ``--quick``) are solved by ``solve_lcp`` and Siconos's Lemke, whole call against
whole call: records ``lcp/siconos-suite/<problem>`` with each side's verdict (right when it
returns a verified solution of a feasible problem, or no solution of the one infeasible
problem), and ``lcp/siconos-suite/summary`` (verdicts right, the smallest time ratio at
n <= 9, the cost of ``auto``'s fallbacks where Lemke alone fails). ``accuracy`` holds both
residuals (``max |min(z, Mz + q)| / (1 + max|q|)``), both statuses, ``max |z_ours - z_ref|``
and, for the stack, both errors against the analytic impulses.

The dense random families (microseconds per call) are timed twice on each side,
interleaved (Siconos, ours, Siconos, ours), and the minimum of each side is reported: a
single Siconos run before all of ours compares two different loads of a shared machine.

Run: ``nscontrol bench lcp --json`` (``--quick`` for a smoke run).
"""


# No `from __future__ import annotations`: the CLI loads this file without registering it in
# sys.modules, and dataclasses then cannot resolve string annotations.
import os
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version

from nscontrol.numerics import _lcp_kernels as kernels
from nscontrol.numerics.lcp import LCPSolver, solve_lcp, solve_lcp_kernel
from nscontrol.testing.lcp_problems import random_p_matrix, stack_delassus

SICONOS_LEMKE_MAX = 1000
SICONOS_PGS_MAX = 100
OURS_DENSE_MAX = 1000  # our dense Lemke/PGS on the stack: same limits as Siconos's
PGS_TOL = 1e-12
PGS_MAX_ITER = 10_000
#: Families whose per-call times (microseconds) are measured twice, interleaved with Siconos;
#: so is every case up to :data:`INTERLEAVED_MAX_SIZE` (the rows of the n <= 10 goal, a few
#: microseconds per call: the speed of this shared machine moved by up to 1.7x between two
#: measurements a few seconds apart, both sides alike — an impact row once read 0.99x where
#: its twin read 1.6x).
INTERLEAVED_FAMILIES = ("random-P", "random-SPD")
INTERLEAVED_MAX_SIZE = 10
#: Which Siconos solver each of our methods is compared with.
COUNTERPART = {"lemke": "lemke", "auto": "lemke", "banded": "lemke", "pgs": "pgs",
               "reusable": "lemke"}


@dataclass(frozen=True)
class Case:
    family: str
    size: int
    M: Any  # what we pass to solve_lcp (dense or sparse)
    q: np.ndarray
    methods: tuple[str, ...]
    exact: np.ndarray | None = None

    @property
    def name(self) -> str:
        return f"{self.family}-{self.size}"

    def dense(self) -> np.ndarray:
        return self.M if isinstance(self.M, np.ndarray) else self.M.toarray()


def cases(quick: bool) -> list[Case]:
    rng = np.random.default_rng(20261122)
    out = []
    for n in (3, 10) if quick else (3, 10, 100):
        out.append(Case("random-P", n, random_p_matrix(n, rng), rng.standard_normal(n),
                        ("lemke", "auto", "reusable")))
    for n in (10,) if quick else (10, 100):
        B = rng.standard_normal((n, n))
        out.append(Case("random-SPD", n, B @ B.T / n + np.eye(n), rng.standard_normal(n),
                        ("pgs", "lemke", "reusable")))
    for n in (10, 100) if quick else (10, 100, 1000, 10_000):
        prob = stack_delassus(n)
        methods = ("banded", "auto") + (("lemke",) if n <= OURS_DENSE_MAX else ()) + (
            ("pgs",) if n <= SICONOS_PGS_MAX else ())
        out.append(Case("stack", n, prob.M, prob.q, methods, prob.z))
    for family, where in (("impact", lambda n: 0), ("impact-mid", lambda n: n // 2)):
        for n in (10, 100) if quick else (10, 100, 1000, 10_000):
            q = np.full(n, 1e-3)
            q[where(n)] = -1.0
            methods = ("banded", "auto") + (("lemke",) if n <= 100 else ())
            out.append(Case(family, n, stack_delassus(n).M, q, methods))
    return out


def siconos_results(cases_: list[Case], budget: float) -> dict[tuple[str, str], dict]:
    """Run Siconos on every case it can handle; ``{(case name, method): record}``."""
    with tempfile.TemporaryDirectory() as tmp:
        problems = []
        for case in cases_:
            wanted = sorted({COUNTERPART[m] for m in case.methods})
            wanted = [m for m in wanted if case.size <= (SICONOS_LEMKE_MAX if m == "lemke"
                                                         else SICONOS_PGS_MAX)]
            if not wanted:
                continue
            m_path, q_path = Path(tmp, f"{case.name}-M.npy"), Path(tmp, f"{case.name}-q.npy")
            np.save(m_path, case.dense())
            np.save(q_path, case.q)
            problems.append({"name": case.name, "M_npy": str(m_path), "q_npy": str(q_path),
                             "methods": wanted})
        records = run_siconos("lcp.py", {"problems": problems, "budget": budget,
                                         "pgs_tol": PGS_TOL, "pgs_max_iter": PGS_MAX_ITER},
                              timeout=900)
    return {(r["name"], r["method"]): r for r in records}


def kernel_time(case: Case, method: str, budget: float) -> float | None:
    """Seconds per call of the bare njit kernel behind ``method`` (what an integrator's
    compiled step pays: no validation, no verification, no Python)."""
    n = case.size
    z, w = np.empty(n), np.empty(n)
    q = case.q
    if method == "banded" and case.family in ("stack", "impact", "impact-mid"):
        lower, diag, upper = (np.asarray(case.M.diagonal(k), dtype=np.float64)
                              for k in (-1, 0, 1))
        return _seconds_per_call(
            lambda: kernels.tridiagonal_lcp_kernel(lower, diag, upper, q, z, w, 0), budget)
    M = case.dense()
    if method == "auto" and isinstance(case.M, np.ndarray):
        # the compiled entry of auto (choice, fallbacks, verification) for other kernels
        return _seconds_per_call(lambda: solve_lcp_kernel(M, q, z, w, 1e-12, 0), budget)
    if method in ("lemke", "reusable"):    # reusable: what auto picks for these (dense) M
        return _seconds_per_call(lambda: kernels.lemke_kernel(M, q, z, w, 0), budget)
    if method == "pgs":
        def pgs() -> None:
            z[:] = 0.0
            kernels.pgs_kernel(M, q, z, w, PGS_TOL, PGS_MAX_ITER, 1.0)
        return _seconds_per_call(pgs, budget)
    return None


def _seconds_per_call(fn, budget: float) -> float:
    """Median of individually timed calls (at most 200, within ``budget``), after one
    warm-up call: the same measurement as ``bench/siconos/lcp.py`` makes of Siconos. (A
    median of batches, ``harness.time_per_call``, counts every preemption of a loaded
    machine inside a batch; the median of single calls drops them, so both sides must use
    the same one.) One timed call when it alone exceeds the budget."""
    start = time.perf_counter()
    fn()
    once = time.perf_counter() - start
    if once > budget:
        return once
    times = []
    start = time.perf_counter()
    while True:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if time.perf_counter() - start > budget or len(times) >= 200:
            break
    times.sort()
    return times[len(times) // 2]


def solve_and_time(case: Case, method: str, budget: float) -> tuple[Any, float, float]:
    """Our result, seconds per whole call and seconds per solve of a solver built once.

    Whole call: ``solve_lcp(M, q, method=...)`` (validation, analysis, solve, verification,
    result); ``reusable`` is ``LCPSolver(M)`` built outside the timing, so both figures are
    its ``solve(q)``. Solver alone: ``LCPSolver(M, method).solve(q)``, built once."""
    M, q = case.M, case.q
    if method in ("lemke", "pgs"):
        M = case.dense()
    solver_method = "auto" if method == "reusable" else method
    solver = LCPSolver(M, solver_method)
    alone = _seconds_per_call(lambda: solver.solve(q), budget)
    if method == "reusable":
        return solver.solve(q), alone, alone
    res = solve_lcp(M, q, method=method)
    return res, _seconds_per_call(lambda: solve_lcp(M, q, method=method), budget), alone


def _compare(out: dict, ref: dict, method: str) -> None:
    """The ratios, like with like: whole call against whole call (``ratio``; ``reusable``:
    solver alone against solver alone) and solver alone against solver alone."""
    ref_whole, ref_alone = ref["whole_s_per_solve"], ref["s_per_solve"]
    ref_s = ref_alone if method == "reusable" else ref_whole
    out.update(reference_s_per_solve=ref_s, ratio=ref_s / out["ours_s_per_solve"],
               reference_whole_s_per_solve=ref_whole, reference_solver_s_per_solve=ref_alone,
               solver_ratio=ref_alone / out["ours_solver_s_per_solve"])
    kernel = out.get("ours_kernel_s_per_solve")
    if kernel:
        out["kernel_ratio"] = ref_alone / kernel


def interleave(case: Case, records: list[dict], budget: float) -> None:
    """Per-call figures of microseconds drift with the load of a shared machine between
    the Siconos run (before all of ours) and ours: time Siconos on this case again and ours
    once more, and keep the minimum of the two measurements of each side (order: Siconos,
    ours, Siconos, ours), for the whole calls and the solvers alone."""
    again = siconos_results([case], budget)
    for rec in records:
        method = rec["scenario"].rsplit("/", 1)[1]
        ref = again.get((case.name, COUNTERPART[method]))
        if ref is None or rec["reference_s_per_solve"] is None:
            continue
        _, ours, alone = solve_and_time(case, method, budget)
        rec["ours_s_per_solve"] = min(rec["ours_s_per_solve"], ours)
        rec["ours_solver_s_per_solve"] = min(rec["ours_solver_s_per_solve"], alone)
        best = {"whole_s_per_solve": min(rec["reference_whole_s_per_solve"],
                                         ref["whole_s_per_solve"]),
                "s_per_solve": min(rec["reference_solver_s_per_solve"], ref["s_per_solve"])}
        _compare(rec, best, method)
        rec["timing"] = "min of two interleaved runs per side (Siconos, ours, Siconos, ours)"


def record(case: Case, method: str, ref: dict | None, ref_note: str | None,
           budget: float) -> dict:
    res, ours, alone = solve_and_time(case, method, budget)
    accuracy: dict[str, Any] = {"ours_status": res.status, "ours_method": res.method,
                                "ours_residual": res.residual, "ours_iterations": res.iterations}
    if case.exact is not None:
        accuracy["ours_max_err_vs_analytic"] = float(np.abs(res.z - case.exact).max())
    out = {"scenario": f"lcp/{case.family}/{method}", "size": case.size,
           "ours_s_per_solve": ours, "ours_solver_s_per_solve": alone, "reference": None,
           "reference_solver": None, "reference_s_per_solve": None, "ratio": None,
           "accuracy": accuracy}
    out["ours_kernel_s_per_solve"] = kernel_time(case, method, budget)
    if ref is None:
        out["note"] = ref_note
        return out
    z_ref = np.asarray(ref["z"])
    accuracy.update(reference_info=ref["info"], reference_residual=ref["residual"],
                    reference_calls=ref["calls"],
                    max_abs_dz=float(np.abs(res.z - z_ref).max()))
    if case.exact is not None:
        accuracy["reference_max_err_vs_analytic"] = float(np.abs(z_ref - case.exact).max())
    out.update(reference=siconos_version(), reference_solver=f"siconos {ref['method']}")
    _compare(out, ref, method)
    return out


def _warm_up_kernels() -> None:
    M, q = np.array([[2.0, -1.0], [-1.0, 2.0]]), np.array([-1.0, 1.0])
    z, w, b = np.zeros(2), np.empty(2), np.array([-1.0])
    kernels.lemke_kernel(M, q, z, w, 0)
    kernels.pgs_kernel(M, q, z, w, 1e-12, 10, 1.0)
    kernels.tridiagonal_lcp_kernel(b, np.diagonal(M).copy(), b, q, z, w, 0)
    solve_lcp_kernel(M, q, z, w, 1e-12, 0)
    solve_lcp(M, q)


def run(quick: bool = False) -> Iterator[dict]:
    budget = 0.1 if quick else 0.5
    _warm_up_kernels()  # compile or load from cache outside any timing
    all_cases = cases(quick)
    ok, why = siconos_available()
    refs: dict[tuple[str, str], dict] = {}
    if ok:
        refs = siconos_results(all_cases, budget)
    for case in all_cases:
        records = []
        for method in case.methods:
            counterpart = COUNTERPART[method]
            ref = refs.get((case.name, counterpart))
            if ref is not None:
                note = None
            elif not ok:
                note = why
            else:
                limit = SICONOS_LEMKE_MAX if counterpart == "lemke" else SICONOS_PGS_MAX
                note = (f"siconos {counterpart} skipped above n = {limit} (dense solver; "
                        f"time budget)")
            records.append(record(case, method, ref, note, budget))
        if ok and (case.family in INTERLEAVED_FAMILIES or case.size <= INTERLEAVED_MAX_SIZE):
            interleave(case, records, budget)
        yield from records
    if not quick:
        yield from suite_records(budget, ok, why)



# ----------------------------------------------------------------------------- Siconos's suite

#: The one problem of the suite without solution (``shared/benchmarks/README.md``: an LP
#: feasibility test, an exact MILP and enumeration agree); every other one has a solution.
INFEASIBLE = {"lcp_Pang_isolated_sol_perturbed"}
#: Problems where Lemke alone does not end with a verified solution (``auto`` falls back):
#: the time of the fallbacks is the whole call minus that of ``method="lemke"``.
FALLBACK_PROBLEMS = ("lcp_CPS_3", "lcp_Pang_isolated_sol_perturbed")


def _suite_dir() -> Path:
    """``shared/benchmarks/siconos-lcp`` in the nearest folder above this one that has it
    (``$NSCONTROL_LCP_SUITE_DIR`` first)."""
    env = os.environ.get("NSCONTROL_LCP_SUITE_DIR")
    if env:
        return Path(env)
    for parent in Path(__file__).resolve().parents:
        candidate = parent / "shared" / "benchmarks" / "siconos-lcp"
        if candidate.is_dir():
            return candidate
    return Path("shared/benchmarks/siconos-lcp")


def read_siconos_lcp(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(M, q)`` of one of Siconos's ``lcp_*.dat`` files: ``n``, a matrix (storage 0:
    dense, values column-major; 1: sparse block, blocks row by row, each column-major),
    then ``q``; anything after ``q`` is a comment."""
    tokens = path.read_text().split()
    pos = 0

    def take(k: int = 1) -> list[str]:
        nonlocal pos
        out = tokens[pos:pos + k]
        pos += k
        return out

    n = int(take()[0])
    storage, rows, cols = (int(t) for t in take(3))
    if storage == 0:
        rows, cols = (int(t) for t in take(2))
        M = np.array(take(rows * cols), dtype=float).reshape((cols, rows)).T
    else:
        take()                                             # number of blocks
        brows, bcols = (int(t) for t in take(2))
        row_ends = [int(t) for t in take(brows)]
        col_ends = [int(t) for t in take(bcols)]
        filled1, filled2 = (int(t) for t in take(2))
        pointers = [int(t) for t in take(filled1)]
        block_cols = [int(t) for t in take(filled2)]
        M = np.zeros((rows, cols))
        for bi in range(brows):
            r0 = row_ends[bi - 1] if bi else 0
            for k in range(pointers[bi], pointers[bi + 1]):
                bj = block_cols[k]
                c0 = col_ends[bj - 1] if bj else 0
                h, w = row_ends[bi] - r0, col_ends[bj] - c0
                take()                                     # the block's number
                M[r0:r0 + h, c0:c0 + w] = np.array(take(h * w), dtype=float).reshape((w, h)).T
    q = np.array(take(rows), dtype=float)
    assert M.shape == (n, n), (path.name, M.shape)
    return np.ascontiguousarray(M), q


def _certified(M: np.ndarray, q: np.ndarray, z: np.ndarray) -> tuple[float, bool]:
    """The residual ``max|min(z, Mz + q)| / (1 + max|q|)`` of a point and whether it
    certifies a solution: at most the round-off bound of evaluating ``M z + q`` in float64,
    ``2 (n + 1) eps (max(|M||z|) + max|q|) / (1 + max|q|)`` (Higham §3.1, the bound
    ``solve_lcp`` itself applies with ``tol`` = 0), plus 1e-12 for a solver's own
    stopping tolerance; the same test for both sides."""
    n = q.shape[0]
    w = M @ z + q
    scale = 1.0 + float(np.max(np.abs(q), initial=0.0))
    res = float(np.max(np.abs(np.minimum(z, w)), initial=0.0)) / scale
    mz = float(np.max(np.abs(M) @ np.abs(z), initial=0.0))
    bound = 2 * (n + 1) * np.finfo(float).eps * (mz + scale) / scale + 1e-12
    return res, bool(np.all(np.isfinite(z)) and res <= bound)


def _suite_ours(problems: dict[str, tuple[np.ndarray, np.ndarray]], budget: float
                ) -> dict[str, dict]:
    out = {}
    for name, (M, q) in problems.items():
        res = solve_lcp(M, q)
        whole = _seconds_per_call(lambda M=M, q=q: solve_lcp(M, q), budget)
        solver = LCPSolver(M)
        alone = _seconds_per_call(lambda s=solver, q=q: s.solve(q), budget)
        rec = {"res": res, "whole": whole, "alone": alone}
        if name in FALLBACK_PROBLEMS:
            rec["lemke_only"] = _seconds_per_call(
                lambda M=M, q=q: solve_lcp(M, q, method="lemke"), budget)
        out[name] = rec
    return out


def _min_suite(a: dict[str, dict], b: dict[str, dict]) -> None:
    """``a`` updated with the smaller time of each measurement of ``b``."""
    for name, rec in b.items():
        for key in ("whole", "alone", "lemke_only"):
            if key in rec:
                a[name][key] = min(a[name][key], rec[key])


def suite_records(budget: float, ok: bool, why: str) -> Iterator[dict]:
    """Siconos's 20 LCP test problems: ours (``solve_lcp``, ``auto``) against Siconos's
    Lemke, whole call against whole call and solver alone against solver alone, both warm,
    timed twice interleaved (Siconos, ours, Siconos, ours; the minimum of each side)."""
    folder = _suite_dir()
    files = sorted(folder.glob("lcp_*.dat")) if folder.is_dir() else []
    if not files:
        return
    problems = {f.stem: read_siconos_lcp(f) for f in files}
    cases_ = [Case(name, q.shape[0], M, q, ("auto",)) for name, (M, q) in problems.items()]
    refs: dict[tuple[str, str], dict] = {}
    ours = _suite_ours(problems, budget)
    if ok:
        refs = siconos_results(cases_, budget)
        again = siconos_results(cases_, budget)
        for key, rec in again.items():
            for field_ in ("s_per_solve", "whole_s_per_solve"):
                refs[key][field_] = min(refs[key][field_], rec[field_])
        _min_suite(ours, _suite_ours(problems, budget))
    right_ours = right_ref = 0
    small_ratios, small_solver_ratios, fallback = [], [], {}
    for case, (name, (M, q)) in zip(cases_, problems.items(), strict=True):
        n = q.shape[0]
        mine = ours[name]
        res = mine["res"]
        feasible = name not in INFEASIBLE
        res_ours, cert_ours = _certified(M, q, res.z)
        ours_right = (res.success and cert_ours) if feasible else not res.success
        right_ours += ours_right
        accuracy: dict[str, Any] = {"ours_status": res.status, "ours_method": res.method,
                                    "ours_residual": res_ours, "feasible": feasible,
                                    "ours_right": ours_right, "ours_message": res.message}
        out = {"scenario": f"lcp/siconos-suite/{name}", "size": n,
               "ours_s_per_solve": mine["whole"], "ours_solver_s_per_solve": mine["alone"],
               "reference": None, "reference_solver": None, "reference_s_per_solve": None,
               "ratio": None, "accuracy": accuracy}
        if "lemke_only" in mine:
            out["ours_lemke_only_s_per_solve"] = mine["lemke_only"]
            out["fallback_s"] = mine["whole"] - mine["lemke_only"]
            fallback[name] = out["fallback_s"]
        ref = refs.get((case.name, "lemke"))
        if ref is None:
            out["note"] = why or "siconos gave no result"
            yield out
            continue
        res_ref, cert_ref = _certified(M, q, np.asarray(ref["z"]))
        ref_right = (ref["info"] == 0 and cert_ref) if feasible else not (
            ref["info"] == 0 and cert_ref)
        right_ref += ref_right
        accuracy.update(reference_info=ref["info"], reference_residual=res_ref,
                        reference_right=ref_right)
        out.update(reference=siconos_version(), reference_solver="siconos lemke")
        _compare(out, ref, "auto")
        if n <= 9:
            small_ratios.append(out["ratio"])
            small_solver_ratios.append(out["solver_ratio"])
        yield out
    summary = {"scenario": "lcp/siconos-suite/summary", "size": len(problems),
               "ours_s_per_solve": float(np.median([r["whole"] for r in ours.values()])),
               "reference": siconos_version() if refs else None, "reference_solver":
               "siconos lemke" if refs else None, "reference_s_per_solve": None, "ratio": None,
               "accuracy": {"ours_right": f"{right_ours}/{len(problems)}",
                            "reference_right": f"{right_ref}/{len(problems)}" if refs
                            else None},
               "fallback_s": fallback}
    if small_ratios:
        summary.update(min_ratio_n_le_9=min(small_ratios),
                       median_ratio_n_le_9=float(np.median(small_ratios)),
                       min_solver_ratio_n_le_9=min(small_solver_ratios),
                       median_solver_ratio_n_le_9=float(np.median(small_solver_ratios)))
    else:
        summary["note"] = why
    yield summary

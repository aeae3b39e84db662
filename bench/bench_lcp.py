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

``ratio`` = Siconos seconds per solve / ours (> 1: we are faster). ``accuracy`` holds both
residuals (``max |min(z, Mz + q)| / (1 + max|q|)``), both statuses, ``max |z_ours - z_ref|``
and, for the stack, both errors against the analytic impulses.

The dense random families (microseconds per call) are timed twice on each side,
interleaved (Siconos, ours, Siconos, ours), and the minimum of each side is reported: a
single Siconos run before all of ours compares two different loads of a shared machine.

Run: ``nscontrol bench lcp --json`` (``--quick`` for a smoke run).
"""


# No `from __future__ import annotations`: the CLI loads this file without registering it in
# sys.modules, and dataclasses then cannot resolve string annotations.
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version

from nscontrol.numerics import _lcp_kernels as kernels
from nscontrol.numerics.lcp import LCPSolver, solve_lcp
from nscontrol.testing.lcp_problems import random_p_matrix, stack_delassus

SICONOS_LEMKE_MAX = 1000
SICONOS_PGS_MAX = 100
OURS_DENSE_MAX = 1000  # our dense Lemke/PGS on the stack: same limits as Siconos's
PGS_TOL = 1e-12
PGS_MAX_ITER = 10_000
#: Families whose per-call times (microseconds) are measured twice, interleaved with Siconos.
INTERLEAVED_FAMILIES = ("random-P", "random-SPD")
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
    for n in (10,) if quick else (10, 100):
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


def solve_and_time(case: Case, method: str, budget: float) -> tuple[Any, float]:
    """Our result and seconds per solve (``reusable``: ``LCPSolver(M)`` built once, not
    timed, then ``solver.solve(q)``; otherwise ``solve_lcp`` with everything included)."""
    M, q = case.M, case.q
    if method in ("lemke", "pgs"):
        M = case.dense()
    if method == "reusable":
        solver = LCPSolver(M)
        return solver.solve(q), _seconds_per_call(lambda: solver.solve(q), budget)
    res = solve_lcp(M, q, method=method)
    return res, _seconds_per_call(lambda: solve_lcp(M, q, method=method), budget)


def interleave(case: Case, records: list[dict], budget: float) -> None:
    """Per-call figures of microseconds drift with the load of a shared machine between
    the Siconos run (before all of ours) and ours: time Siconos on this case again and ours
    once more, and keep the minimum of the two measurements of each side (order: Siconos,
    ours, Siconos, ours)."""
    again = siconos_results([case], budget)
    for rec in records:
        method = rec["scenario"].rsplit("/", 1)[1]
        ref = again.get((case.name, COUNTERPART[method]))
        if ref is None or rec["reference_s_per_solve"] is None:
            continue
        _, ours = solve_and_time(case, method, budget)
        rec["ours_s_per_solve"] = min(rec["ours_s_per_solve"], ours)
        rec["reference_s_per_solve"] = min(rec["reference_s_per_solve"], ref["s_per_solve"])
        rec["ratio"] = rec["reference_s_per_solve"] / rec["ours_s_per_solve"]
        rec["timing"] = "min of two interleaved runs per side (Siconos, ours, Siconos, ours)"


def record(case: Case, method: str, ref: dict | None, ref_note: str | None,
           budget: float) -> dict:
    res, ours = solve_and_time(case, method, budget)
    accuracy: dict[str, Any] = {"ours_status": res.status, "ours_method": res.method,
                                "ours_residual": res.residual, "ours_iterations": res.iterations}
    if case.exact is not None:
        accuracy["ours_max_err_vs_analytic"] = float(np.abs(res.z - case.exact).max())
    out = {"scenario": f"lcp/{case.family}/{method}", "size": case.size,
           "ours_s_per_solve": ours, "reference": None, "reference_solver": None,
           "reference_s_per_solve": None, "ratio": None, "accuracy": accuracy}
    kernel = kernel_time(case, method, budget)
    out["ours_kernel_s_per_solve"] = kernel
    if ref is None:
        out["note"] = ref_note
        return out
    z_ref = np.asarray(ref["z"])
    accuracy.update(reference_info=ref["info"], reference_residual=ref["residual"],
                    reference_calls=ref["calls"],
                    max_abs_dz=float(np.abs(res.z - z_ref).max()))
    if case.exact is not None:
        accuracy["reference_max_err_vs_analytic"] = float(np.abs(z_ref - case.exact).max())
    out.update(reference=siconos_version(), reference_solver=f"siconos {ref['method']}",
               reference_s_per_solve=ref["s_per_solve"], ratio=ref["s_per_solve"] / ours)
    if kernel:
        out["kernel_ratio"] = ref["s_per_solve"] / kernel
    return out


def _warm_up_kernels() -> None:
    M, q = np.array([[2.0, -1.0], [-1.0, 2.0]]), np.array([-1.0, 1.0])
    z, w, b = np.zeros(2), np.empty(2), np.array([-1.0])
    kernels.lemke_kernel(M, q, z, w, 0)
    kernels.pgs_kernel(M, q, z, w, 1e-12, 10, 1.0)
    kernels.tridiagonal_lcp_kernel(b, np.diagonal(M).copy(), b, q, z, w, 0)


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
        if ok and case.family in INTERLEAVED_FAMILIES:
            interleave(case, records, budget)
        yield from records


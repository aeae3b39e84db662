"""§5 check 3: the LCP solvers agree with brute-force enumeration on random PSD problems of
size <= 3 (W may be only PSD for redundant contacts: no solver may assume a P-matrix)."""

import itertools

import numpy as np
import pytest

from nscontrol.numerics.lcp import solve_lcp
from nscontrol.testing.lcp_problems import random_psd_matrix


def _enumerate(M, q):
    n = q.size
    best = None
    for r in range(n + 1):
        for S in itertools.combinations(range(n), r):
            z = np.zeros(n)
            if S:
                idx = list(S)
                z[idx] = np.linalg.lstsq(M[np.ix_(idx, idx)], -q[idx], rcond=None)[0]
            w = M @ z + q
            viol = max(-z.min(), -w.min(), np.abs(z * w).max())
            if best is None or viol < best[0]:
                best = (viol, z)
    return best


@pytest.mark.parametrize("method", ["lemke", "pgs", "auto"])
def test_solvers_agree_with_enumeration(method):
    rng = np.random.default_rng(12)
    for _ in range(150):
        n = int(rng.integers(1, 4))
        M = random_psd_matrix(n, int(rng.integers(1, n + 1)), rng)
        z0 = np.where(rng.random(n) < 0.5, rng.uniform(0, 1, n), 0.0)
        q = np.where(z0 > 0, 0.0, rng.uniform(0, 1, n)) - M @ z0   # solvable by construction
        viol, z_ref = _enumerate(M, q)
        scale = 1.0 + np.abs(q).max() + np.abs(M).max()
        assert viol <= 1e-12 * scale
        res = solve_lcp(M, q, method=method, tol=1e-12, max_iter=20000)
        # w = Mz + q is unique for a symmetric PSD M. Lemke and enumeration are direct
        # (errors ~ n ε κ); PGS stops at residual 1e-12 scale, which bounds the error in w by
        # about 1e-12 κ: the matrices here have κ (on their range) below 1e4 -> 1e-8
        assert np.abs((M @ res.z + q) - (M @ z_ref + q)).max() <= 1e-8 * scale

"""solve_nivp side of bench_smc.py: the super-twisting problem by a generic implicit solver.

Run by the Python of a separate environment where ``solve_nivp`` is installed (never the
project's). State ``(x, s, nu, w)`` with ``s = x + x'`` and the algebraic ``w in Sign(s)``
(solve_nivp's sign projection, ``w = proj_[-1,1](w + s)`` at a fixed point)::

    x' = s - x,   s' = (s - x) - k1 |s|^{1/2} sign(s) + nu + 0.3 sin 5t,   nu' = -k2 w,   0 = 0 (w)

Backward Euler with semismooth Newton at a fixed step ``h`` (default 1e-3), T = 6. Prints one
JSON line: ``version``, ``setup``, ``steps``, ``seconds``, ``t_reach`` (the first time from
which |s| <= 1e-8 to the end), ``max_abs_s_after`` (|s| after that time).
"""

import json
import math
import sys
import time
from importlib import metadata

import numpy as np
from solve_nivp import solve_ivp_ns

L = 1.5
K1, K2 = 1.5 * math.sqrt(L), 1.1 * L


def rhs(t, y, *_):
    x, s, nu, _w = y
    psi = math.copysign(math.sqrt(abs(s)), s) if s != 0.0 else 0.0
    return np.array([s - x, (s - x) - K1 * psi + nu + 0.3 * math.sin(5.0 * t), -K2 * y[3],
                     0.0])


def main():
    h = float(sys.argv[1]) if len(sys.argv) > 1 else 1e-3
    A = np.diag([1.0, 1.0, 1.0, 0.0])
    start = time.perf_counter()
    t, y, *_ = solve_ivp_ns(rhs, (0.0, 6.0), np.array([0.5, 0.5, 0.0, 1.0]),
                            method="backward_euler", projection="sign",
                            projection_opts={"y_indices": 1, "w_indices": 3},
                            solver="semismooth_newton", adaptive=False, h0=h, A=A)
    seconds = time.perf_counter() - start
    t, s = np.asarray(t), np.asarray(y)[:, 1]
    outside = np.flatnonzero(np.abs(s) > 1e-8)
    k = 0 if outside.size == 0 else int(outside[-1]) + 1
    t_reach = float(t[k]) if k < t.size else float("nan")
    print(json.dumps({"version": metadata.version("solve_nivp"),
                      "setup": f"backward Euler + semismooth Newton, h = {h:g}",
                      "steps": int(t.size - 1), "seconds": seconds, "t_reach": t_reach,
                      "max_abs_s_after": float(np.max(np.abs(s[k:]))) if k < t.size
                      else float("nan")}))


if __name__ == "__main__":
    main()

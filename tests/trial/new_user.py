"""The new user's first run, as the README gives it (issue 32): run by
``tests/trial/test_new_user.py`` and by ``nscontrol bench coldstart`` in a fresh process
with a fresh ``NUMBA_CACHE_DIR`` (nothing compiled yet).

Prints one JSON object on stdout: the import time, the first ``simulate``'s wall and CPU
seconds, the second's, the first impact time against its closed form ``sqrt(2 h / g)`` (the
run computed the right thing), the kernels sent to the background compiler and its process
id. The first-run notice goes to stderr. With a file name as argument, the first run's
times, states and impact times are saved there (``numpy.savez``), for comparing an
interpreted first run with a compiled one.
"""

from __future__ import annotations

import json
import sys
import time

if __name__ == "__main__":
    w0, c0 = time.perf_counter(), time.process_time()
    from nscontrol import simulate
    from nscontrol.systems import LagrangianSystem

    w1, c1 = time.perf_counter(), time.process_time()
    ball = LagrangianSystem.bouncing_ball(restitution=0.9)
    traj = simulate(ball, [1, 0], (0, 10), method="event_driven")
    w2, c2 = time.perf_counter(), time.process_time()
    simulate(ball, [1, 0], (0, 10), method="event_driven")
    w3 = time.perf_counter()
    first = float(traj.event_times("impact")[0])
    from nscontrol import _compile_background as background

    if len(sys.argv) > 1:
        import numpy as np

        np.savez(sys.argv[1], t=traj.t, x=traj.x, impacts=traj.event_times("impact"))
    print(json.dumps({"import_s": w1 - w0, "first_run_s": w2 - w1, "first_run_cpu_s": c2 - c1,
                      "second_run_s": w3 - w2, "t_end": float(traj.t[-1]),
                      "first_impact_error": abs(first - (2 / 9.81) ** 0.5),
                      "background": background.requested(),
                      "helper_pid": background.helper_pid()}))

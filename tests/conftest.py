"""Shared test configuration: a non-interactive matplotlib backend and seeded randomness."""

import os

import matplotlib

matplotlib.use("Agg")
# the tests compare compiled and Python paths and time Ctrl-C: kernels compile in the
# foreground, as numba does (the background compile is tested in tests/trial/ and
# tests/test_compile_background.py, which set it explicitly)
os.environ.setdefault("NSCONTROL_COMPILE", "wait")

import numpy as np  # noqa: E402
import pytest  # noqa: E402


def pytest_configure(config: pytest.Config) -> None:
    # the modules whose verdict rests on rounding (LMI certificates, orbits and their Floquet
    # multipliers, continuation, integrator accuracy, the LCP and LTI numerics) carry
    # ``pytestmark = pytest.mark.sensitive``; ``make test-sensitive`` reruns them under an
    # older BLAS kernel and with numba's optimiser off (tests/README.md)
    config.addinivalue_line(
        "markers", "sensitive: numerically sensitive module, rerun by make test-sensitive under "
        "OPENBLAS_CORETYPE=Sandybridge and NUMBA_OPT=0")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture
def clarabel_fails(monkeypatch) -> list:
    """Make every CVXPY solve with Clarabel raise a SolverError (other solvers run as usual);
    the list records the solvers asked for, in order."""
    import cvxpy as cp

    original = cp.Problem.solve
    attempts: list = []

    def clarabel_breaks(self, *args, **kwargs):
        attempts.append(kwargs.get("solver"))
        if kwargs.get("solver") == "CLARABEL":
            raise cp.error.SolverError("Clarabel made to fail by the test")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(cp.Problem, "solve", clarabel_breaks)
    return attempts


#: Per-test limit of the tests marked slow (the others have pyproject's ``timeout = 300``).
SLOW_TIMEOUT = 1800


def pytest_collection_modifyitems(config, items) -> None:
    """Give the tests marked ``slow`` the longer limit, unless they set their own."""
    for item in items:
        if item.get_closest_marker("slow") and not item.get_closest_marker("timeout"):
            item.add_marker(pytest.mark.timeout(SLOW_TIMEOUT))

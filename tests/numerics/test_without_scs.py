"""A lean install has no SCS (an optional extra): Clarabel alone is the default, and every
place that would have used SCS says how to install it."""

import numpy as np
import pytest

from nscontrol.errors import InfeasibleDesignError, ModelError
from nscontrol.numerics.lmi import SCS_INSTALL_HINT, lyapunov_certificate, solver_order


@pytest.fixture
def no_scs(monkeypatch):
    import cvxpy as cp

    installed = [s for s in cp.installed_solvers() if s != "SCS"]
    monkeypatch.setattr(cp, "installed_solvers", lambda: list(installed))


def test_auto_uses_clarabel_alone(no_scs):
    assert solver_order("auto") == ["CLARABEL"]


def test_asking_for_scs_says_how_to_install_it(no_scs):
    with pytest.raises(ModelError, match=r"solver: 'SCS' .* not installed.*nscontrol\[scs\]"):
        solver_order("SCS")


def test_failed_design_names_the_missing_fallback(no_scs):
    A = np.diag([1.0, -2.0])  # an unstable eigenvalue: no Lyapunov certificate exists
    with pytest.raises(InfeasibleDesignError) as info:
        lyapunov_certificate(A)
    assert SCS_INSTALL_HINT in str(info.value)


def test_pyproject_keeps_scs_optional():
    import tomllib
    from pathlib import Path

    pyproject = Path(__file__).parents[2] / "pyproject.toml"
    if not pyproject.exists():
        pytest.skip("no source tree (installed package)")
    project = tomllib.loads(pyproject.read_text())["project"]
    assert not any(d.startswith("scs") for d in project["dependencies"])
    assert project["optional-dependencies"]["scs"] == ["scs>=3.2"]
    assert isinstance(project["license"], str)  # an SPDX expression, not the deprecated table


def test_lure_observer_failure_without_scs_says_how_to_install_it(no_scs, clarabel_fails):
    from nscontrol.design.lure_observer import lure_observer_lmi

    A = np.array([[0.0, 1.0], [-1.0, -0.1]])
    with pytest.raises(InfeasibleDesignError) as info:  # Clarabel fails, no SCS to fall to
        lure_observer_lmi(A, [[0.0], [1.0]], [[0.0, 1.0]], [[1.0, 0.0]], variant="basic",
                          alpha=0.05)
    assert clarabel_fails == ["CLARABEL"]
    assert SCS_INSTALL_HINT in str(info.value)

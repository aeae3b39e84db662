"""The one place that imports CasADi (the ``optimal`` extra): a missing CasADi is an
``ImportError`` naming the extra, never a bare ``ModuleNotFoundError`` from deep inside."""

from __future__ import annotations

from typing import Any

#: What to run when CasADi is missing.
INSTALL_HINT = "pip install 'nscontrol[optimal]'"


def require_casadi() -> Any:
    """The ``casadi`` module, or an ``ImportError`` saying how to install it."""
    try:
        import casadi
    except ImportError as exc:
        raise ImportError(
            "nscontrol.optimal: trajectory optimisation needs CasADi (with its IPOPT), which "
            f"is not installed; install the optional extra: {INSTALL_HINT}") from exc
    return casadi

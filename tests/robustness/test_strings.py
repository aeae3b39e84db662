"""Class 1: strings and complex numbers where numbers are meant are refused at the boundary.

numpy parses ``"0.5"`` and unpacks ``"01"`` into two characters, and Python's ``float()``
raises its own TypeError on a complex without naming the argument; every public parameter
below must instead raise a ``ModelError`` (or ``DimensionError``) that names the argument and
says what was expected. No numerical tolerance appears here: every check is exact.
"""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol._validation import (
    as_finite_scalar,
    as_real_scalar,
    as_vector,
    check_in_interval,
    check_positive,
    check_t_span,
)
from nscontrol.errors import NscontrolError

BAD_SCALARS = ["0.5", b"0.5", np.str_("0.5"), 0.5 + 1j, np.complex128(0.5), np.array("0.5"),
               np.array([0.5 + 0j])]


def assert_refused(call, name: str, *, exc: type[Exception] = NscontrolError) -> str:
    """``call()`` raises ``exc`` (an nscontrol error, also a ValueError) whose message starts
    with the argument ``name`` and says what was expected; returns the message."""
    with pytest.raises(exc) as info:
        call()
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert msg.startswith(name), msg
    assert "expected" in msg, msg
    return msg


# ----------------------------------------------------------------------------- helpers


@pytest.mark.parametrize("value", BAD_SCALARS)
@pytest.mark.parametrize("helper", [as_real_scalar, as_finite_scalar, check_positive,
                                    lambda n, v: check_in_interval(n, v, 0.0, 1.0)])
def test_scalar_helpers_refuse_strings_and_complex(helper, value):
    assert_refused(lambda: helper("gain", value), "gain")


def test_string_message_says_what_to_do():
    msg = assert_refused(lambda: as_real_scalar("gain", "0.5"), "gain")
    assert "not text" in msg
    msg = assert_refused(lambda: as_real_scalar("gain", 1 + 2j), "gain")
    assert ".real" in msg


@pytest.mark.parametrize("value", [["0.5", "1"], [1j, 2.0], "12", np.array([b"1"])])
def test_vector_helper_refuses_strings_and_complex(value):
    assert_refused(lambda: as_vector("x0", value), "x0")


@pytest.mark.parametrize("t_span", ["01", b"01", ("0", "1"), (0.0, "1"), (0, 1 + 1j),
                                    (0, 1, 2), (1.0,), 5.0, (0, float("nan")), (1.0, 0.0)])
def test_t_span_refused(t_span):
    assert_refused(lambda: check_t_span(t_span), "t_span")


def test_finite_scalar_refuses_nan_and_inf():
    for v in (np.nan, np.inf, -np.inf):
        assert_refused(lambda v=v: as_finite_scalar("decay", v), "decay")


# ----------------------------------------------------------------------------- public API


@pytest.fixture(scope="module")
def ball():
    from nscontrol.systems.lagrangian import LagrangianSystem

    return LagrangianSystem.bouncing_ball(restitution=0.9)


@pytest.mark.parametrize("t_span", [("0", "1"), "01", (0, 1j), (0.0, 1.0, 2.0)])
def test_simulate_refuses_bad_t_span_before_running(ball, t_span):
    assert_refused(lambda: nsc.simulate(ball, [1.0, 0.0], t_span), "t_span")


@pytest.mark.parametrize("e", ["0.5", 0.5 + 0j, b"1", np.str_("0.9")])
def test_restitution_refused(e):
    from nscontrol.systems.lagrangian import LagrangianSystem

    assert_refused(lambda: LagrangianSystem.bouncing_ball(restitution=e), "restitution")
    assert_refused(lambda: LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0],
                                            restitution=e), "restitution")


def test_restitution_vector_of_strings_refused():
    from nscontrol.systems.lagrangian import LagrangianSystem

    assert_refused(lambda: LagrangianSystem.chain([1.0, 1.0, 1.0], restitution=["1", "1"]),
                   "restitution")


@pytest.fixture(scope="module")
def coulomb_plant():
    from nscontrol.laws.set_valued import Relay
    from nscontrol.systems.lure import LureSystem

    return LureSystem([[0, 1], [-1, -0.1]], [[0], [1]], [[0, 1]], Relay(1.0), C=[[1, 0]])


@pytest.mark.parametrize("frac", ["0.5", 0.5j, float("nan"), 0.0, 1.5])
def test_alpha_fraction_refused(coulomb_plant, frac):
    from nscontrol.design.lure_observer import design_lure_observer

    assert_refused(lambda: design_lure_observer(coulomb_plant, variant="basic",
                                                alpha_fraction=frac), "alpha_fraction")


@pytest.mark.parametrize("decay", [float("nan"), float("inf"), "0.5", 0.5j])
def test_lyapunov_decay_refused_before_cvxpy(decay):
    from nscontrol.numerics.lmi import lyapunov_certificate

    assert_refused(lambda: lyapunov_certificate(-np.eye(2), decay=decay), "decay")


@pytest.mark.parametrize(("call", "name"), [
    (lambda: __import__("nscontrol.numerics.lmi", fromlist=["x"]).bisect_max(
        lambda s: True, "0", 1.0), "lo"),
    (lambda: __import__("nscontrol.numerics.lti", fromlist=["x"]).Exosystem.sinusoid(
        1.0, 1.0, phase="0"), "phase"),
    (lambda: __import__("nscontrol.systems.impacting_bodies", fromlist=["x"])
        .stiffness_from_springs(2, {(0, 1): "3"}), "springs[(0, 1)]"),
    (lambda: __import__("nscontrol.numerics.scaling", fromlist=["x"]).Scaling.mechanical(
        1, "2.0"), "omega_ref"),
    (lambda: __import__("nscontrol.analysis.observability", fromlist=["x"])
        .observer_flow_norms(-np.eye(2), np.eye(2), "0.5", [0.0]), "eps"),
    (lambda: __import__("nscontrol.analysis.observability", fromlist=["x"])
        .reconstructibility(np.eye(2), [1.0, 0.0], [], "01"), "t_span"),
    (lambda: __import__("nscontrol.laws.set_valued", fromlist=["x"]).Relay(1.0).in_domain(
        [0.0], tol="0"), "tol"),
    (lambda: _mod("nscontrol.numerics.lmi").recheck_lyapunov(
        [-np.eye(2)], np.eye(2), decay="0.1"), "decay"),
    (lambda: _mod("nscontrol.design.impact_observer").place_scaled(
        np.eye(2), [[1.0, 0.0]], [-1, -2], 0.1j), "eps"),
    (lambda: _traj().resample(["0.5"]), "t_eval"),
    (lambda: _traj().resample([0.5j]), "t_eval"),
    (lambda: _traj().at("0.5"), "t"),
    (lambda: _traj().slice("0", 1.0), "t0"),
    (lambda: _mod("nscontrol.numerics.lmi").recheck_lyapunov([-np.eye(2)], np.eye(2))
        .holds(1j), "rtol"),
    (lambda: _mod("nscontrol.analysis.convergence").bisect_boundary(bool, "0", 1.0), "lo"),
    (lambda: _mod("nscontrol.analysis.observability").reconstructibility(
        np.eye(2), [1.0, 0.0], ["0.5"], (0, 1)), "impacts"),
    (lambda: _mod("nscontrol.analysis.observability").reconstructibility(
        np.eye(2), [1.0, 0.0], [0.5], (0, 1), min_dwell="1e-9"), "min_dwell"),
])
def test_other_public_scalars_refused(call, name):
    assert_refused(call, name)


def _mod(name: str):
    import importlib

    return importlib.import_module(name)


def _traj():
    from nscontrol.simulate.trajectory import Trajectory

    return Trajectory(t=[0.0, 1.0, 2.0], x=np.zeros((3, 1)))

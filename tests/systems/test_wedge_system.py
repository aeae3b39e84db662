"""The wedge-switched planar system: validation of its inputs (the argument named), Filippov's
face classification, and a run through the shared switching integrator."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import DimensionError, ModelError
from nscontrol.systems import NonlinearSystem, Wedge, WedgeSwitchedSystem
from nscontrol.systems.wedge import marker_crossings, with_marker_line
from nscontrol.testing.cycle_problems import polar_normal_form, van_der_pol

SIGMA = 0.02
S = np.sqrt(0.5)


@pytest.fixture(scope="module")
def plant():
    return polar_normal_form((-4 * SIGMA, 0.0, 5 * SIGMA, 0.0, -SIGMA), omega=1.0)[0]


def wedge_at(rho, flow=(0.0, 1.0)):
    return Wedge.symmetric([rho, 0.0], [1.0, 0.0], np.pi / 4, flow=flow)


def test_symmetric_wedge_normals_follow_the_flow():
    ccw = wedge_at(1.0)
    assert np.allclose(ccw.n_in, [S, S], atol=1e-15) and np.allclose(ccw.n_out, [S, -S])
    cw = wedge_at(1.0, flow=(0.0, -1.0))           # flow downwards: the upper face is met first
    assert np.allclose(cw.n_in, [S, -S]) and np.allclose(cw.n_out, [S, S])
    assert ccw.contains([1.5, 0.4]) and not ccw.contains([1.5, 0.6])


@pytest.mark.parametrize("kwargs,error,name", [
    ({"corner": [1.0, 0.0, 0.0], "n_in": [1, 1], "n_out": [1, -1]}, DimensionError, "corner"),
    ({"corner": [1.0, 0.0], "n_in": [0, 0], "n_out": [1, -1]}, ModelError, "n_in"),
    ({"corner": [1.0, np.nan], "n_in": [1, 1], "n_out": [1, -1]}, ModelError, "corner"),
    ({"corner": [1.0, 0.0], "n_in": [1, 1], "n_out": [2, 2]}, ModelError, "n_in, n_out"),
])
def test_wedge_refuses_bad_input(kwargs, error, name):
    with pytest.raises(error, match=name):
        Wedge(**kwargs)


@pytest.mark.parametrize("args,name", [
    (([1.0, 0.0], [1.0, 0.0], 0.0, [0.0, 1.0]), "half_angle"),
    (([1.0, 0.0], [1.0, 0.0], np.pi / 2, [0.0, 1.0]), "half_angle"),
    (([1.0, 0.0], [0.0, 0.0], 0.5, [0.0, 1.0]), "axis"),
    (([1.0, 0.0], [1.0, 0.0], 0.5, [2.0, 0.0]), "flow"),
])
def test_symmetric_refuses_bad_input(args, name):
    with pytest.raises(ModelError, match=name):
        Wedge.symmetric(*args)


def test_system_refuses_bad_input(plant):
    w = wedge_at(1.01)
    with pytest.raises(ModelError, match="plant"):
        WedgeSwitchedSystem(lambda t, x: x, w, [1.0, 0.0], 0.3)
    with pytest.raises(DimensionError, match="plant"):
        WedgeSwitchedSystem(NonlinearSystem(3, lambda t, x: -x), w, [1.0, 0.0], 0.3)
    with pytest.raises(ModelError, match="wedge"):
        WedgeSwitchedSystem(plant, (1.0, 0.0), [1.0, 0.0], 0.3)
    with pytest.raises(ModelError, match="b:"):
        WedgeSwitchedSystem(plant, w, [0.0, 0.0], 0.3)
    with pytest.raises(DimensionError, match="b"):
        WedgeSwitchedSystem(plant, w, [1.0, 0.0, 0.0], 0.3)
    with pytest.raises(ModelError, match="k"):
        WedgeSwitchedSystem(plant, w, [1.0, 0.0], np.inf)
    with pytest.raises(ModelError, match="k"):
        WedgeSwitchedSystem(plant, w, [1.0, 0.0], "0.3")
    system = WedgeSwitchedSystem(plant, w, [1.0, 0.0], 0.3)
    with pytest.raises(ModelError, match="face"):
        system.face_status(w.corner, "top")
    with pytest.raises(ModelError, match="mode"):
        system.mode_field(w.corner, "sliding")


def test_face_status_follows_filippov(plant):
    # at (ρ, 0): F1 = (g ρ, ωρ), F2 = F1 + (k, 0); n_inᵀF2 ∝ g ρ + k + ωρ changes sign at
    # k = −(1 + g)ρ: crossing above, attracting sliding below
    rho = 1.01
    system = WedgeSwitchedSystem(plant, wedge_at(rho), [1.0, 0.0], -0.62)
    assert system.face_status(system.wedge.corner, "in") == "crossing"
    assert system.crosses_only()
    sliding = system.with_gain(-1.5)
    assert sliding.face_status(sliding.wedge.corner, "in") == "attracting_sliding"
    assert not sliding.crosses_only()
    m = sliding.crossing_margins()
    assert m["in_F1"] > 0 > m["in_F2"]
    # the sliding field is tangent to the face (nᵀF_s = 0 to rounding of |F|·ε)
    fs = sliding.mode_field(sliding.wedge.corner, "slide_in")
    assert abs(sliding.wedge.n_in @ fs) <= 8 * np.finfo(float).eps * np.linalg.norm(fs)
    # faces swapped (wedge built for a downward flow): F1 leaves through n_in, F2 enters
    repelling = WedgeSwitchedSystem(plant, wedge_at(rho, flow=(0.0, -1.0)), [1.0, 0.0], 1.5)
    assert repelling.face_status(repelling.wedge.corner, "in") == "repelling_sliding"


def test_run_crosses_the_wedge_and_marks_a_section(plant):
    system = WedgeSwitchedSystem(plant, wedge_at(1.0015), [1.0, 0.0], -0.62)
    tr = simulate(system, [1.01, -0.05], (0.0, 1.0))
    kinds = [(e.kind, e.index) for e in tr.events]
    # into the wedge through H_in, out through H_out (its line crossed earlier, off the wedge)
    assert ("crossing", 0) in kinds and kinds[-1] == ("crossing", 1)
    marked, j = with_marker_line(system, [0.0, 1.0], 0.0)
    tr = simulate(marked, [1.01, -0.05], (0.0, 2 * np.pi))
    hits = marker_crossings(tr, j)
    assert len(hits) == 1 and abs(hits[0].post[1]) <= 1e-12   # event location: rounding
    with pytest.raises(ModelError, match="normal"):
        with_marker_line(system, [0.0, 0.0], 0.0)
    with pytest.raises(ModelError, match="system"):
        with_marker_line(object(), [0.0, 1.0], 0.0)


def test_van_der_pol_wedge_on_the_top():
    vdp = van_der_pol(0.1)
    w = Wedge.symmetric([0.0, 2.0], [0.0, 1.0], np.pi / 4, flow=vdp.rhs(0.0, [0.0, 2.0]))
    assert np.allclose(w.n_in, [S, S]) and np.allclose(w.n_out, [-S, S])


def test_passes_the_system_contract(plant):
    from nscontrol.testing import check_system

    system = WedgeSwitchedSystem(plant, wedge_at(1.01), [1.0, 0.0], -0.62)
    assert check_system(system).passed

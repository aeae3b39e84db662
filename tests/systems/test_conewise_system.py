"""ConewiseLinearSystem: the fan is checked by the PWA partition machinery, continuity exactly
on every facet before any design sees the model (acceptance check 8)."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import DimensionError, ModelError
from nscontrol.systems import ConewiseLinearSystem, orthant_cones

SPRING_IN = [[0.0, 1.0], [-4.0, -0.1]]
SPRING_OUT = [[0.0, 1.0], [-1.0, -0.1]]


def _quadrants(a01=0.0):
    """Ex 9.5 with (α, β) = (0.5, 0.5); ``a01`` adds a jump of A[0][0,1] (discontinuous)."""
    A = []
    for E in orthant_cones(2):
        p1, p2 = E.diagonal() > 0
        A.append(np.array([[0.5 * p1, 1.5 if p2 else 1.0], [-1.0, 1.0 if p2 else -1.0]]))
    A[0] = A[0] + np.array([[0.0, a01], [0.0, 0.0]])
    return ConewiseLinearSystem(A, [0.0, 1.0], orthant_cones(2))


def test_bimodal_fan_has_one_facet_and_locates_states():
    s = ConewiseLinearSystem.bimodal(SPRING_IN, SPRING_OUT, [0.0, 1.0], [2.0, 0.0])
    assert (s.n_states, s.n_inputs, s.n_modes) == (2, 1, 2)
    (fac,) = s.facets
    assert (fac.i, fac.j) == (0, 1)
    np.testing.assert_array_equal(fac.normal, [1.0, 0.0])
    assert s.mode([0.3, -5.0]) == 0 and s.mode([-0.3, 5.0]) == 1
    np.testing.assert_array_equal(s.f([1.0, 0.0], [2.0]), [0.0, -2.0])  # -4 + 2


def test_quadrant_fan_facets_from_the_partition_machinery():
    s = _quadrants()
    pairs = {(f.i, f.j): f.normal for f in s.facets}
    # orthant order (+,+), (+,-), (-,+), (-,-): opposite quadrants share only the origin
    assert set(pairs) == {(0, 1), (0, 2), (1, 3), (2, 3)}
    np.testing.assert_array_equal(pairs[(0, 1)], [0.0, 1.0])   # into cone 0 (x2 >= 0)
    np.testing.assert_array_equal(pairs[(0, 2)], [1.0, 0.0])
    assert s.pwa.continuous and s.pwa.n_regions == 4


def test_discontinuous_bimodal_model_refused_naming_facet_and_residual():
    # damping -0.1 vs -0.2 on x2: A_0 - A_1 = [[0, 0], [0, 0.1]] is not e cᵀ with c = e1; the
    # residual |(A_0 - A_1)(I - ccᵀ)| is 0.1 exactly (one rounding of 0.2 - 0.1)
    with pytest.raises(ModelError, match=r"^A: modes 0 and 1 are discontinuous on their shared "
                                         r"facet .*c = \[1\. 0\.\].*residual.* = 0\.1,"):
        ConewiseLinearSystem.bimodal(SPRING_IN, [[0.0, 1.0], [-1.0, -0.2]], [0.0, 1.0],
                                     [1.0, 0.0])


def test_discontinuous_fan_refused_on_the_facet_that_jumps():
    # a jump D = 0.25 e1 e2ᵀ in A_0: on the facet x2 = 0 (c = e2) D(I - ccᵀ) = 0, continuous;
    # on the facet x1 = 0 (c = e1, cone 0 against cone 2) D(I - ccᵀ) = D, residual 0.25
    with pytest.raises(ModelError, match=r"modes 0 and 2 .*c = \[1\. 0\.\].*= 0\.25"):
        _quadrants(a01=0.25)


def test_a_continuous_field_passes_the_exact_test_at_roundoff():
    # A_1 = A_2 + e cᵀ built in floating point: the residual is a few roundoffs of |A|,
    # far below CONTINUITY_RTOL = 1e-9 relative
    rng = np.random.default_rng(3)
    for _ in range(20):
        A2, e, c = rng.standard_normal((4, 4)), rng.standard_normal(4), rng.standard_normal(4)
        ConewiseLinearSystem.bimodal(A2 + np.outer(e, c), A2, rng.standard_normal(4), c)


@pytest.mark.parametrize("kwargs,match,exc", [
    (dict(A=[SPRING_IN, SPRING_OUT], B=[[0.0, 0.0], [1.0, 2.0]],
          cones=[[[1.0, 0.0]], [[-1.0, 0.0]]]), r"^B: expected full column rank", ModelError),
    (dict(A=[SPRING_IN, SPRING_OUT], B=[0.0, 1.0], cones=[[[1.0, 0.0]]]),
     r"^cones: expected 2 cones", DimensionError),
    (dict(A=[SPRING_IN, SPRING_OUT], B=[0.0, 1.0, 0.0], cones=[[[1.0, 0.0]], [[-1.0, 0.0]]]),
     r"^B", DimensionError),
    (dict(A=[SPRING_IN, SPRING_OUT], B=[0.0, 1.0], cones=[[[0.0, 0.0]], [[-1.0, 0.0]]]),
     r"^cones\[0\]: a row is zero", ModelError),
    (dict(A=[], B=[0.0, 1.0], cones=[]), r"^A: expected one matrix per cone", DimensionError),
])
def test_bad_input_refused_naming_the_argument(kwargs, match, exc):
    with pytest.raises(exc, match=match):
        ConewiseLinearSystem(**kwargs)


def test_overlapping_or_gapped_cones_refused_by_the_partition_check():
    A = [SPRING_IN, SPRING_IN]
    with pytest.raises(ModelError, match="overlap"):       # x1 >= 0 and x2 >= 0 overlap
        ConewiseLinearSystem(A, [0.0, 1.0], [[[1.0, 0.0]], [[0.0, 1.0]]])
    first_and_third = [np.eye(2), -np.eye(2)]                # two quadrants leave a gap
    with pytest.raises(ModelError, match="do not cover"):
        ConewiseLinearSystem(A, [0.0, 1.0], first_and_third)


def test_open_loop_simulates_as_its_pwa_model():
    s = ConewiseLinearSystem.bimodal(SPRING_IN, SPRING_OUT, [0.0, 1.0], [1.0, 0.0])
    tr = simulate(s.pwa, [1.0, 0.0], (0.0, 3.0), progress=False)
    assert [e.kind for e in tr.events][:1] == ["crossing"]
    # in x1 >= 0 from rest: x1'' + 0.1 x1' + 4 x1 = 0 (ω = 2, ζ = 0.025) first vanishes at
    # ω_d t = π/2 + atan(ζ/√(1 - ζ²)); the exact flow's root finder locates it to roundoff
    zeta = 0.025
    wd = 2.0 * np.sqrt(1 - zeta**2)
    t_cross = (np.pi / 2 + np.arctan(zeta / np.sqrt(1 - zeta**2))) / wd
    assert tr.events[0].time == pytest.approx(t_cross, abs=1e-9)

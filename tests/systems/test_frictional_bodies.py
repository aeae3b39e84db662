"""Friction data on LagrangianSystem: validated at construction, naming the argument."""

import numpy as np
import pytest
from scipy import sparse

from nscontrol.errors import DimensionError, ModelError
from nscontrol.systems import (
    LagrangianSystem,
    brick_stack,
    brick_stack_rest_state,
    inclined_block,
    rolling_disk,
    rolling_sphere,
)


def _block(**kwargs):
    return LagrangianSystem(np.eye(2), gap_matrix=[[0.0, 1.0]], **kwargs)


def test_negative_friction_is_refused_naming_the_contact():
    with pytest.raises(ModelError, match=r"friction\[0\]"):
        _block(friction=-0.1, tangent_matrix=[[1.0, 0.0]])


def test_non_finite_friction_is_refused():
    with pytest.raises(ModelError, match="friction"):
        _block(friction=np.nan, tangent_matrix=[[1.0, 0.0]])


def test_tangent_rows_of_the_wrong_count_are_refused():
    with pytest.raises(DimensionError, match="tangent_matrix"):
        _block(friction=0.5, tangent_matrix=np.eye(3)[:, :2])


def test_tangent_columns_of_the_wrong_count_are_refused():
    with pytest.raises(DimensionError, match="tangent_matrix"):
        _block(friction=0.5, tangent_matrix=[[1.0, 0.0, 0.0]])


def test_friction_needs_both_coefficient_and_tangents():
    with pytest.raises(ModelError, match="tangent_matrix"):
        _block(friction=0.5)
    with pytest.raises(ModelError, match="friction"):
        _block(tangent_matrix=[[1.0, 0.0]])


def test_friction_on_nonlinear_gaps_is_refused():
    with pytest.raises(ModelError, match="friction"):
        LagrangianSystem(np.eye(2), gap=lambda q: q[1:], jacobian=lambda q: np.array(
            [[0.0, 1.0]]), friction=0.5, tangent_matrix=[[1.0, 0.0]])


def test_zero_tangent_row_is_refused():
    with pytest.raises(ModelError, match="tangent_matrix"):
        _block(friction=0.5, tangent_matrix=[[0.0, 0.0]])


def test_friction_per_contact_and_dimension():
    s = LagrangianSystem(np.eye(3), gap_matrix=np.eye(3)[:2], friction=[0.1, 0.2],
                         tangent_matrix=np.eye(3)[[2, 2, 0, 0]])
    assert s.friction.tolist() == [0.1, 0.2] and s.friction_dim == 2
    assert _block().friction_dim == 0


def test_sparse_tangent_matrix_is_kept_sparse():
    s = brick_stack(50, 0.4)
    assert sparse.issparse(s.tangent_matrix) and s.tangent_matrix.shape == (100, 150)


def test_constructors():
    assert inclined_block(0.3, 0.2).n_dof == 2
    assert rolling_disk(0.3).friction_dim == 1
    assert rolling_sphere(0.3).friction_dim == 2
    with pytest.raises(ModelError, match="angle"):
        inclined_block(0.3, np.pi / 2)


def test_brick_stack_rest_state_closes_every_gap():
    s = brick_stack(7, 0.5, height=0.3)
    x0 = brick_stack_rest_state(7, height=0.3)
    # gaps are sums of two heights: round-off of a few ulps of the top (7 x 0.3)
    assert np.max(np.abs(s.gaps(x0[:21]))) <= 8 * np.finfo(float).eps * 7 * 0.3

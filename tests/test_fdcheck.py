"""The shared finite-difference checker checks itself: exact derivatives pass, and a block a
millionth the size of the rest fails when it is wrong by 1 % (which a tolerance relative to the
whole derivative would let through)."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_gradient, check_jacobian

#: Displacement-like unknowns 0-1 of size 1, pressure-like 2-3 of size 1e-6, coupled at 1e-3.
A = np.array(
    [
        [2.0, 0.5, 1e-3, 0.0],
        [0.5, 1.0, 0.0, 2e-3],
        [1e-3, 0.0, -3e-6, 1e-6],
        [0.0, 2e-3, 1e-6, -2e-6],
    ]
)
BLOCKS = [[0, 1], [2, 3]]
X0 = np.array([0.3, -0.2, 0.7, 0.1])


def linear(x: np.ndarray) -> np.ndarray:
    return A @ x


def quadratic(x: np.ndarray) -> float:
    return 0.5 * float(x @ A @ x)


def with_small_block(factor: float) -> np.ndarray:
    wrong = A.copy()
    wrong[2:, 2:] *= factor
    return wrong


def test_exact_jacobian_passes_block_by_block():
    fd = check_jacobian(linear, X0, A, blocks=BLOCKS, row_blocks=BLOCKS, step=1e-3, rtol=1e-8)
    assert fd.passed, str(fd)
    assert set(fd.block_errors) == {(0, 0), (0, 1), (1, 0), (1, 1)}


@pytest.mark.parametrize("factor", [1.01, -1.0], ids=["one_percent", "sign"])
def test_wrong_small_block_fails_block_by_block(factor):
    wrong = with_small_block(factor)
    if factor == 1.01:  # relative to the whole J d the error is about 1e-8: blurred
        assert check_jacobian(linear, X0, wrong, step=1e-3, rtol=1e-5).passed
    fd = check_jacobian(linear, X0, wrong, blocks=BLOCKS, row_blocks=BLOCKS, step=1e-3, rtol=1e-5)
    assert not fd.passed
    assert max(fd.block_errors, key=fd.block_errors.__getitem__) == (1, 1)
    assert fd.block_errors[(1, 1)] > 5e2 * fd.rtol
    assert "block (rows 1, columns 1)" in str(fd)


def test_gradient_blocks_isolate_a_weak_parameter():
    gradient = A @ X0
    assert check_gradient(quadratic, X0, gradient, blocks=BLOCKS, step=1e-3, rtol=1e-8).passed
    wrong = gradient.copy()
    wrong[3] *= 1.01
    assert check_gradient(quadratic, X0, wrong, step=1e-3, rtol=1e-5).passed
    fd = check_gradient(quadratic, X0, wrong, blocks=BLOCKS, step=1e-3, rtol=1e-5)
    assert not fd.passed and fd.block_errors[(0, 1)] > 1e2 * fd.rtol


def test_a_nan_in_any_block_fails():
    def nan_in_one_row(x: np.ndarray) -> np.ndarray:
        y = A @ x
        y[3] = np.nan
        return y

    assert not check_jacobian(nan_in_one_row, X0, A, blocks=BLOCKS, row_blocks=BLOCKS).passed
    assert not check_jacobian(nan_in_one_row, X0, A).passed


def test_an_exact_zero_block_passes_with_no_absolute_tolerance():
    """0 / 0 is an exact match, not a NaN; a wrong entry in that block still fails."""
    decoupled = A.copy()
    decoupled[:2, 2:] = decoupled[2:, :2] = 0.0
    assert check_jacobian(lambda x: decoupled @ x, X0, decoupled, blocks=BLOCKS, row_blocks=BLOCKS, atol=0.0).passed
    wrong = decoupled.copy()
    wrong[0, 2] = 1e-12
    assert not check_jacobian(lambda x: decoupled @ x, X0, wrong, blocks=BLOCKS, row_blocks=BLOCKS, atol=0.0).passed


def test_blocks_must_be_disjoint_and_inside():
    with pytest.raises(ValueError, match="blocks"):
        check_jacobian(linear, X0, A, blocks=[[0, 1], [1, 2]])
    with pytest.raises(ValueError, match="blocks"):
        check_jacobian(linear, X0, A, blocks=[[0, 4]])

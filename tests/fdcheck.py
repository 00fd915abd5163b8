"""The shared finite-difference checker of the Python tests.

Every Python-level derivative (adjoint gradients, forward sensitivities, target Jacobians) is
checked here the same way: a central difference along a random direction, compared with the
analytic directional derivative to a relative tolerance. The direction is scaled by the
magnitude of each entry of ``x`` (``scaled=True``), so that parameters of very different
sizes (mu ~ 1e4 Pa, gravity ~ 10 m/s^2) are perturbed by the same relative amount.

A single directional check measures the error relative to the whole derivative, so a part
many orders of magnitude smaller than the rest (a pressure-pressure block next to the
stiffness, a weak parameter next to a strong one) would go unchecked. Pass ``blocks`` (a
partition of ``x``) and, for Jacobians, ``row_blocks`` (a partition of ``f``): every pair
(row block, column block) is then checked on its own, along the direction restricted to the
column block and relative to that pair's own size.

Examples
--------
>>> import numpy as np
>>> check_gradient(lambda x: float(x @ x), np.array([1.0, 2.0]), np.array([2.0, 4.0])).passed
True
>>> A = np.array([[1.0, 0.0], [0.0, 1e-8]])
>>> wrong = np.array([[1.0, 0.0], [0.0, 2e-8]])
>>> check_jacobian(lambda x: A @ x, np.ones(2), wrong).passed
True
>>> check_jacobian(lambda x: A @ x, np.ones(2), wrong, blocks=[[0], [1]], row_blocks=[[0], [1]]).passed
False
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence, Union

import numpy as np
from numpy.typing import NDArray

#: A block: indices into a flat vector (an index array, a list of indices or a slice).
Block = Union[NDArray[np.int64], Sequence[int], slice]


@dataclass
class FDCheck:
    """Outcome of one check: the analytic and central-difference directional derivatives.

    With blocks, ``analytic`` and ``numeric`` are those of the worst pair and
    ``block_errors`` maps ``(row block, column block)`` to that pair's relative error."""

    analytic: NDArray[np.float64]
    numeric: NDArray[np.float64]
    error: float  # relative: |analytic - numeric| / max(|analytic|, |numeric|, atol)
    rtol: float
    step: float
    block_errors: dict[tuple[int, int], float] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.error <= self.rtol

    def __str__(self) -> str:
        worst = ""
        if len(self.block_errors) > 1:
            pair = max(self.block_errors, key=self.block_errors.__getitem__)
            worst = f" in block (rows {pair[0]}, columns {pair[1]}) of {len(self.block_errors)}"
        return (
            f"FD check {'passed' if self.passed else 'FAILED'}: relative error {self.error:.3e}{worst} "
            f"(rtol {self.rtol:g}, step {self.step:g}); analytic {np.ravel(self.analytic)[:6]}, "
            f"numeric {np.ravel(self.numeric)[:6]}"
        )


def random_direction(x: NDArray[np.float64], seed: int = 0, scaled: bool = True) -> NDArray[np.float64]:
    """A random direction with entries in [-1, 1] (times ``|x_i|`` when scaled and ``x_i != 0``)."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(-1.0, 1.0, size=np.shape(x))
    if scaled:
        scale = np.abs(np.asarray(x, dtype=np.float64))
        d = d * np.where(scale > 0, scale, 1.0)
    return d


def central_difference(
    f: Callable[[NDArray[np.float64]], NDArray[np.float64] | float],
    x: NDArray[np.float64],
    direction: NDArray[np.float64],
    step: float,
) -> NDArray[np.float64]:
    """``(f(x + h d) - f(x - h d)) / (2 h)``."""
    x = np.asarray(x, dtype=np.float64)
    plus = np.asarray(f(x + step * direction), dtype=np.float64)
    minus = np.asarray(f(x - step * direction), dtype=np.float64)
    return (plus - minus) / (2.0 * step)


def _relative_error(analytic: NDArray[np.float64], numeric: NDArray[np.float64], atol: float) -> float:
    difference = float(np.linalg.norm(analytic - numeric))
    if difference == 0.0:  # an exact match, also of an all-zero block with atol = 0 (0 / 0)
        return 0.0
    return difference / max(float(np.linalg.norm(analytic)), float(np.linalg.norm(numeric)), atol)


def _partition(blocks: Sequence[Block] | None, size: int) -> list[NDArray[np.int64]]:
    """The blocks as index arrays; one block of everything when ``None``."""
    if blocks is None:
        return [np.arange(size)]
    out = [np.arange(size)[b] if isinstance(b, slice) else np.asarray(b, dtype=np.int64).ravel() for b in blocks]
    if out:
        covered = np.concatenate(out)
        if np.unique(covered).size != covered.size or covered.size and (covered.min() < 0 or covered.max() >= size):
            raise ValueError(f"blocks: expected disjoint index sets inside 0..{size - 1}")
    return out


def _check_blocks(
    f: Callable[[NDArray[np.float64]], NDArray[np.float64] | float],
    x: NDArray[np.float64],
    directional: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    d: NDArray[np.float64],
    blocks: Sequence[Block] | None,
    row_blocks: Sequence[Block] | None,
    step: float,
    rtol: float,
    atol: float,
) -> FDCheck:
    """Every (row block, column block) pair: ``directional(d_b)`` against the central
    difference of ``f`` along ``d_b`` (``d`` restricted to column block ``b``)."""
    columns = _partition(blocks, x.size)
    worst: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None
    errors: dict[tuple[int, int], float] = {}
    for c, cols in enumerate(columns):
        d_block = np.zeros_like(d)
        d_block.ravel()[cols] = d.ravel()[cols]
        analytic = np.atleast_1d(np.asarray(directional(d_block), dtype=np.float64)).ravel()
        numeric = np.atleast_1d(central_difference(f, x, d_block, step)).ravel()
        for r, rows in enumerate(_partition(row_blocks, analytic.size)):
            error = _relative_error(analytic[rows], numeric[rows], atol)
            errors[(r, c)] = error
            if worst is None or not error <= worst[0]:  # a NaN is the worst of all
                worst = (error, analytic[rows], numeric[rows])
    assert worst is not None, "blocks: expected at least one block"
    return FDCheck(worst[1], worst[2], worst[0], rtol, step, errors)


def check_gradient(
    f: Callable[[NDArray[np.float64]], float],
    x: NDArray[np.float64],
    grad: NDArray[np.float64],
    *,
    direction: NDArray[np.float64] | None = None,
    step: float = 1e-4,
    rtol: float = 1e-5,
    atol: float = 1e-300,
    seed: int = 0,
    blocks: Sequence[Block] | None = None,
) -> FDCheck:
    """Check ``grad`` (the gradient of scalar ``f`` at ``x``) along a random direction; with
    ``blocks`` (a partition of ``x``), along its restriction to each block in turn."""
    x = np.asarray(x, dtype=np.float64)
    d = random_direction(x, seed) if direction is None else np.asarray(direction, dtype=np.float64)
    g = np.asarray(grad, dtype=np.float64).ravel()
    return _check_blocks(f, x, lambda v: np.vdot(g, v.ravel()), d, blocks, None, step, rtol, atol)


def check_jacobian(
    f: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    x: NDArray[np.float64],
    jacobian: NDArray[np.float64] | object,
    *,
    direction: NDArray[np.float64] | None = None,
    step: float = 1e-4,
    rtol: float = 1e-5,
    atol: float = 1e-300,
    seed: int = 0,
    blocks: Sequence[Block] | None = None,
    row_blocks: Sequence[Block] | None = None,
) -> FDCheck:
    """Check a Jacobian (dense or ``scipy.sparse``, ``(m, x.size)``) of vector ``f`` along a
    random direction: ``J d`` against the central difference of ``f``; with ``blocks`` /
    ``row_blocks`` (partitions of ``x`` / of ``f``), block pair by block pair."""
    x = np.asarray(x, dtype=np.float64)
    d = random_direction(x, seed) if direction is None else np.asarray(direction, dtype=np.float64)
    return _check_blocks(f, x, lambda v: jacobian @ v.ravel(), d, blocks, row_blocks, step, rtol, atol)  # type: ignore[operator]

"""The shared finite-difference checker of the Python tests.

Every Python-level derivative (adjoint gradients, forward sensitivities, target Jacobians) is
checked here the same way: a central difference along a random direction, compared with the
analytic directional derivative to a relative tolerance. The direction is scaled by the
magnitude of each entry of ``x`` (``scaled=True``), so that parameters of very different
sizes (mu ~ 1e4 Pa, gravity ~ 10 m/s^2) are perturbed by the same relative amount.

Examples
--------
>>> import numpy as np
>>> check_gradient(lambda x: float(x @ x), np.array([1.0, 2.0]), np.array([2.0, 4.0])).passed
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray


@dataclass
class FDCheck:
    """Outcome of one check: the analytic and central-difference directional derivatives."""

    analytic: NDArray[np.float64]
    numeric: NDArray[np.float64]
    error: float  # relative: |analytic - numeric| / max(|analytic|, |numeric|, atol)
    rtol: float
    step: float

    @property
    def passed(self) -> bool:
        return self.error <= self.rtol

    def __str__(self) -> str:
        return (
            f"FD check {'passed' if self.passed else 'FAILED'}: relative error {self.error:.3e} (rtol {self.rtol:g}, "
            f"step {self.step:g}); analytic {np.ravel(self.analytic)[:6]}, numeric {np.ravel(self.numeric)[:6]}"
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


def _compare(analytic: NDArray[np.float64], numeric: NDArray[np.float64], rtol: float, atol: float, step: float) -> FDCheck:
    analytic = np.asarray(analytic, dtype=np.float64)
    numeric = np.asarray(numeric, dtype=np.float64)
    denom = max(float(np.linalg.norm(analytic)), float(np.linalg.norm(numeric)), atol)
    error = float(np.linalg.norm(analytic - numeric)) / denom
    return FDCheck(analytic, numeric, error, rtol, step)


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
) -> FDCheck:
    """Check ``grad`` (the gradient of scalar ``f`` at ``x``) along a random direction."""
    x = np.asarray(x, dtype=np.float64)
    d = random_direction(x, seed) if direction is None else np.asarray(direction, dtype=np.float64)
    analytic = np.asarray(np.vdot(np.asarray(grad, dtype=np.float64).ravel(), d.ravel()))
    return _compare(analytic, central_difference(f, x, d, step), rtol, atol, step)


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
) -> FDCheck:
    """Check a Jacobian (dense or ``scipy.sparse``, ``(m, x.size)``) of vector ``f`` along a
    random direction: ``J d`` against the central difference of ``f``."""
    x = np.asarray(x, dtype=np.float64)
    d = random_direction(x, seed) if direction is None else np.asarray(direction, dtype=np.float64)
    analytic = jacobian @ d.ravel()  # type: ignore[operator]
    return _compare(np.asarray(analytic), central_difference(f, x, d, step).ravel(), rtol, atol, step)

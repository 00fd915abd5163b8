"""What the inverse functions return: :class:`GradientResult`, :class:`FitResult` (with its
:class:`Uncertainty`) and :class:`ControlResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["GradientResult", "Uncertainty", "FitResult", "ControlResult"]


@dataclass
class GradientResult:
    """Value and gradient of an objective at the equilibrium.

    Attributes
    ----------
    value
        O(x) at the equilibrium.
    gradient
        name -> dO/dtheta (float for scalar parameters, arrays for fields, gravity, cables),
        in units of O per unit of the parameter.
    core
        The extension's raw adjoint by key: dO/d(each material parameter per element under its
        core name, "mu", "lambda" or "c10", "mu:0", ...; "density"; "gravity"; the cable
        values), with the aliases "lam" and "rho".
    result
        The :class:`~sorofem.StaticResult` the gradient was taken at.
    """

    value: float
    gradient: dict[str, Any]
    core: dict[str, NDArray[np.float64]]
    result: Any

    @property
    def vector(self) -> NDArray[np.float64]:
        """All gradient entries concatenated in the order of ``params``."""
        return np.concatenate([np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in self.gradient.values()])


@dataclass
class Uncertainty:
    """Gauss-Newton uncertainty at a least-squares optimum.

    Attributes
    ----------
    sigma
        Residual standard deviation, m: ``sqrt(|r|^2 / (N - p))``.
    covariance
        ``sigma^2 (J^T J)^-1`` in the original parameter units (``J = dr/dtheta``); infinite
        along directions the data do not determine.
    std, relative_std
        Standard deviation of each parameter, absolute and over its value.
    correlation
        Correlation matrix.
    singular_values
        Of the scaled Jacobian ``dr/d log theta`` (m per unit relative change), descending:
        a small one means a combination of parameters the data hardly see.
    condition
        Ratio of the largest to the smallest singular value.
    identifiable
        name -> whether the parameter is pinned by the data: its relative std is below 10 %
        and it has a weight above 1 % in no near-null direction (singular value below 1e-6
        of the largest).
    """

    names: list[str]
    sigma: float
    covariance: NDArray[np.float64]
    std: NDArray[np.float64]
    relative_std: NDArray[np.float64]
    correlation: NDArray[np.float64]
    singular_values: NDArray[np.float64]
    condition: float
    identifiable: dict[str, bool]

    def to_dict(self) -> dict[str, Any]:
        return {
            "sigma": self.sigma,
            "std": dict(zip(self.names, map(float, self.std))),
            "relative_std": dict(zip(self.names, map(float, self.relative_std))),
            "correlation": self.correlation.tolist(),
            "singular_values": self.singular_values.tolist(),
            "condition": self.condition,
            "identifiable": self.identifiable,
        }


@dataclass
class FitResult:
    """Outcome of :func:`estimate`.

    Attributes
    ----------
    params
        name -> fitted value (float, or an array for fields and cables).
    material
        The fitted :class:`~sorofem.NeoHookean` (per-element arrays when regions or fields).
    loss
        ``1/2 |r|^2`` at the optimum, m^2 (regularisation included).
    residual
        Root-mean-square distance of the observed points from their goals, m.
    forward_solves
        Static solves, all starts together (warm-started; failed attempts included).
    newton_iterations
        Newton iterations over those solves.
    iterations
        Optimiser iterations of the best start.
    history
        Per iteration: ``{"start", "iteration", "params", "loss", "rms", "forward_solves", "time"}``.
    uncertainty
        :class:`Uncertainty` (None for fields: too many parameters to invert).
    starts
        Per start: its initial point, final params, loss and forward solves.
    results
        One :class:`~sorofem.StaticResult` per scenario at the optimum.
    """

    params: dict[str, Any]
    material: Any
    loss: float
    residual: float
    forward_solves: int
    newton_iterations: int
    iterations: int
    method: str
    converged: bool
    message: str
    time: float
    history: list[dict[str, Any]] = field(default_factory=list)
    uncertainty: Uncertainty | None = None
    starts: list[dict[str, Any]] = field(default_factory=list)
    results: list[Any] = field(default_factory=list)

    @property
    def youngs_modulus(self) -> Any:
        """E of the fitted material, Pa."""
        return self.material.youngs_modulus

    @property
    def poisson_ratio(self) -> Any:
        """nu of the fitted material."""
        return self.material.poisson_ratio

    @property
    def shear_modulus(self) -> Any:
        return self.material.shear_modulus

    @property
    def lame_lambda(self) -> Any:
        return self.material.lame_lambda

    @property
    def result(self) -> Any:
        """The first scenario's equilibrium at the optimum."""
        return self.results[0] if self.results else None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON summary."""
        plain = lambda v: v.tolist() if isinstance(v, np.ndarray) else v  # noqa: E731
        return {
            "params": {k: plain(v) for k, v in self.params.items()},
            "material": self.material.to_dict(),
            "loss": self.loss,
            "residual_rms": self.residual,
            "forward_solves": self.forward_solves,
            "newton_iterations": self.newton_iterations,
            "iterations": self.iterations,
            "method": self.method,
            "converged": self.converged,
            "message": self.message,
            "time": self.time,
            "uncertainty": None if self.uncertainty is None else self.uncertainty.to_dict(),
            "starts": [{k: plain(v) for k, v in s.items()} for s in self.starts],
        }

    def __repr__(self) -> str:
        vals = ", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}=<{np.size(v)} values>" for k, v in self.params.items())
        return f"FitResult({vals}, residual={self.residual:.3g} m, forward_solves={self.forward_solves}, method={self.method!r})"


@dataclass
class ControlResult:
    """Outcome of :func:`control`.

    Attributes
    ----------
    actuation
        ``(c,)`` alpha of each controlled cable (in the order of ``cables``).
    distance
        Root-mean-square distance of the target's points from their goals, m.
    max_distance
        Largest distance of a target point from its goal, m.
    reachable
        ``distance <= tolerance``.
    tolerance
        The distance counted as reached, m.
    points
        ``(k, 3)`` where the target's points end up (the closest reachable configuration).
    result
        The :class:`~sorofem.StaticResult` at ``actuation``.
    message
        What happened, including "not reachable" and which bounds are active.
    """

    actuation: NDArray[np.float64]
    distance: float
    max_distance: float
    reachable: bool
    tolerance: float
    points: NDArray[np.float64]
    result: Any
    forward_solves: int
    iterations: int
    message: str
    time: float
    active_bounds: list[str] = field(default_factory=list)
    history: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "actuation": self.actuation.tolist(),
            "distance": self.distance,
            "max_distance": self.max_distance,
            "reachable": self.reachable,
            "tolerance": self.tolerance,
            "points": self.points.tolist(),
            "forward_solves": self.forward_solves,
            "iterations": self.iterations,
            "message": self.message,
            "time": self.time,
            "active_bounds": self.active_bounds,
        }

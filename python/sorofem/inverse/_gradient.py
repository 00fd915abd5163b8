"""The adjoint gradient of an objective of the static equilibrium: :func:`gradient`."""

from __future__ import annotations

import math
import numbers
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import describe
from ..errors import InputError
from ..solver import SolveOptions
from ..static import solve_static
from ..targets import BoundContactForce, BoundTarget, Target
from ._parameters import Parameters, core_sensitivities
from ._problem import DEFAULT_TOLERANCE, bind
from .results import GradientResult

__all__ = ["gradient"]


def _call_objective(objective: Any, positions: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
    """``objective(positions)`` checked: a finite value and a finite ``(n, 3)`` derivative; what
    the user's function raises or returns wrongly becomes an :class:`InputError` naming it."""
    n = len(positions)
    try:
        out = objective(positions.copy())
    except Exception as exc:  # noqa: BLE001 - the user's code may raise anything
        raise InputError(f"objective: the callable raised {type(exc).__name__}: {exc}") from None
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise InputError(f"objective: expected the callable to return (value, d value / d positions), got {describe(out)}")
    value, dx = out
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise InputError(f"objective: expected a finite number as the value, got {describe(value)}")
    try:
        arr = np.asarray(dx, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"objective: expected the derivative as an array of shape ({n}, 3), got {describe(dx)}") from None
    if arr.shape != (n, 3) or not np.all(np.isfinite(arr)):
        what = f"shape {arr.shape}" if arr.shape != (n, 3) else "non-finite values"
        raise InputError(f"objective: expected the derivative as finite values of shape ({n}, 3), got {what}")
    return float(value), arr


def gradient(
    body: Any,
    objective: Any,
    params: str | Sequence[str] = ("shear_modulus", "lame_lambda"),
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    *,
    regions: Mapping[str, ArrayLike] | None = None,
    cables: Sequence[Any] | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    load_steps: int = 1,
    initial: Any = None,
    options: SolveOptions | None = None,
) -> GradientResult:
    """Value and adjoint gradient of an objective of the static equilibrium.

    Parameters
    ----------
    body
        The body, at the parameter values where the gradient is wanted.
    objective
        A :class:`~sorofem.Target` (objective ``1/2 |r|^2``, m^2) or a callable
        ``f(positions (n, 3)) -> (value, d value / d positions (n, 3))``.
    params
        Names from :data:`PARAMETERS` (see the module docstring).
    gravity, tolerance, max_iterations, load_steps, initial, options
        As for :func:`sorofem.solve_static`.
    regions, cables
        Element regions for ``"name:region"`` parameters; the cables of cable parameters
        (default: all).

    Returns
    -------
    GradientResult

    Examples
    --------
    >>> g = sf.gradient(body, sf.Target.nodes([80], [[0.4, 0.1, -0.2]]), ["shear_modulus"],
    ...                 gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> g.gradient["shear_modulus"]  # m^2 / Pa                          # doctest: +SKIP
    """
    p = Parameters(body, params, regions, cables)
    theta = p.current(gravity)
    if options is None:
        options = SolveOptions(tolerance, max_iterations, load_steps)
    result = solve_static(body, gravity, initial=initial, options=options)
    if isinstance(objective, (Target, BoundTarget, BoundContactForce)):
        value, dx = bind(objective, body).misfit(result.positions)
    elif callable(objective):
        value, dx = _call_objective(objective, result.positions)
    else:
        raise InputError(f"objective: expected a Target or a callable, got {type(objective).__name__}")
    # solve_static just left the model at this equilibrium with the body's own parameters.
    model = body.core_model()
    core = core_sensitivities(model.adjoint(np.ascontiguousarray(dx)))
    grad = p.pullback(core, theta)
    return GradientResult(float(value), p.as_dict(grad), core, result)

"""Control: the cable actuations that bring a target as close as possible, :func:`control`."""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import MAX_EVALUATIONS, boolean, count, describe, positive_scalar
from ..errors import InputError
from ..progress import Progress
from ..solver import SolveOptions
from ._optimizers import Recorder, scipy_minimize
from ._parameters import Parameters
from ._problem import DEFAULT_TOLERANCE, Problem, final_results
from ._problem import scenarios as make_scenarios
from .results import ControlResult

__all__ = ["control"]


def _alpha_bounds(bounds: Any, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(lo, hi)`` alphas per controlled cable: finite, ``0 < lo <= hi``."""
    if bounds is None:
        return np.full(n, 0.3), np.full(n, 1.0)
    try:
        arr = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (n, 2):
        raise InputError(f"bounds: expected one (lo, hi) per controlled cable, shape ({n}, 2), got {describe(bounds)}")
    lo, hi = arr[:, 0], arr[:, 1]
    if not np.all(np.isfinite(arr) & (lo > 0) & (lo <= hi)):
        raise InputError(f"bounds: expected finite 0 < lo <= hi for every cable, got {arr.tolist()}")
    return lo, hi


def _alphas(x0: Any, n: int) -> NDArray[np.float64]:
    try:
        theta0 = np.asarray(x0, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        theta0 = np.zeros(0)
    if theta0.shape != (n,) or not np.all(np.isfinite(theta0) & (theta0 > 0)):
        raise InputError(f"x0: expected {n} finite alphas > 0, got {describe(x0)}")
    return theta0


def control(
    body: Any,
    target: Any,
    cables: Sequence[Any] | None = None,
    bounds: Sequence[tuple[float, float]] | None = None,
    x0: ArrayLike | None = None,
    *,
    method: str = "l-bfgs-b",
    tolerance: float = 1e-3,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    solve_tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    load_steps: int = 1,
    max_evaluations: int = 100,
    xtol: float = 1e-10,
    ftol: float = 1e-14,
    initial: Any = None,
    verbose: bool = False,
    progress: bool | None = None,
    options: SolveOptions | None = None,
) -> ControlResult:
    """Cable actuations that bring a target as close as possible.

    Minimises ``1/2 |r|^2`` over the actuation alpha of the chosen cables (in log alpha,
    within ``bounds``), with the adjoint gradient (``"l-bfgs-b"``) or without
    (``"nelder-mead"``). When the target cannot be reached, the result is the closest
    reachable configuration and ``reachable`` is False.

    Parameters
    ----------
    body
        The body with its cables; their actuations are left unchanged.
    target
        A :class:`~sorofem.Target`.
    cables
        The cables to actuate (:class:`~sorofem.Cable` or indices), default all.
    bounds
        One ``(lo, hi)`` alpha range per cable (default ``(0.3, 1.0)``).
    x0
        Initial alphas (default: the middle of the bounds; a cable at rest length is slack
        and has no gradient).
    tolerance
        Distance (RMS over the target's points, m) counted as reached; default 1 mm.
    gravity, solve_tolerance, max_iterations, load_steps
        Options of the static solves.
    options
        ``solve_tolerance``, ``max_iterations`` and ``load_steps`` as one
        :class:`~sorofem.solver.SolveOptions`, which replaces them when given.
    max_evaluations
        Budget of solves.
    initial
        Positions ``(n_nodes, 3)`` or a :class:`~sorofem.StaticResult` to warm-start the first
        solve from (e.g. the previous control's ``result`` when following a moving target).
    verbose
        Print one line per iteration on stderr.
    progress
        A progress line on stderr, ticked after every forward solve, with the iteration and
        the loss: ``None`` (default) only when stderr is a terminal and the search lasts more
        than half a second, ``True`` always, ``False`` never (see :mod:`sorofem.progress`).

    Returns
    -------
    ControlResult

    Examples
    --------
    >>> ctl = sf.control(body, sf.Target.points(rest, goal), cables=[cable], bounds=[(0.3, 1.0)],
    ...                  gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> ctl.actuation, ctl.reachable, ctl.distance  # doctest: +SKIP
    """
    if not isinstance(method, str) or method not in ("l-bfgs-b", "nelder-mead"):
        raise InputError(f"method: expected 'l-bfgs-b' or 'nelder-mead', got {describe(method)}")
    tolerance = positive_scalar(tolerance, "tolerance")
    max_evaluations = count(max_evaluations, "max_evaluations", 1, MAX_EVALUATIONS)
    xtol, ftol = positive_scalar(xtol, "xtol"), positive_scalar(ftol, "ftol")
    verbose = boolean(verbose, "verbose")
    if cables is not None and (isinstance(cables, (str, bytes)) or not isinstance(cables, Sequence)):
        raise InputError(f"cables: expected a list of cables (sorofem.Cable or indices), got {describe(cables)}")
    t0 = time.perf_counter()
    p = Parameters(body, ["cable_actuation"], cables=cables)
    n = p.size
    lo_a, hi_a = _alpha_bounds(bounds, n)
    lo, hi = np.log(lo_a), np.log(hi_a)
    theta0 = np.sqrt(lo_a * hi_a) if x0 is None else _alphas(x0, n)
    solve = SolveOptions(solve_tolerance, max_iterations, load_steps) if options is None else options
    scs = make_scenarios(body, target, None if initial is None else [{"initial": initial}], gravity, solve)
    problem = Problem(body, p, scs)
    problem.progress = bar = Progress(desc=f"control ({method})", unit="solves", enabled=progress)
    record = Recorder(problem, verbose, None, 0, t0)
    try:
        s, iters, _, msg = scipy_minimize(problem, np.clip(np.log(theta0), lo, hi), lo, hi, record, method, max_evaluations, xtol, ftol)
        alpha = np.exp(s)
        st = p.state(alpha)
        results = final_results(body, body.material, st, scs, p)
    finally:
        bar.close()
        problem.restore()
    result = results[0]
    bound = scs[0].target
    distance = bound.rms(result.positions)
    reachable = distance <= tolerance
    active = [
        f"cable {int(c)}: alpha at its {'lower' if abs(s[i] - lo[i]) < 1e-9 else 'upper'} bound {alpha[i]:.4g}"
        for i, c in enumerate(p.blocks[0].cables)
        if abs(s[i] - lo[i]) < 1e-9 or abs(s[i] - hi[i]) < 1e-9
    ]
    if reachable:
        message = f"reached: RMS distance {distance:.3g} m <= tolerance {tolerance:g} m"
    else:
        message = (
            f"not reachable: the closest configuration found is {distance:.3g} m (RMS) from the target, "
            f"above the tolerance {tolerance:g} m" + (f"; {'; '.join(active)}" if active else "")
        )
    return ControlResult(
        actuation=alpha,
        distance=distance,
        max_distance=bound.max_distance(result.positions),
        reachable=bool(reachable),
        tolerance=float(tolerance),
        points=bound.points(result.positions),
        result=result,
        forward_solves=problem.forward_solves + len(results),
        iterations=iters,
        message=message + f" ({msg})",
        time=time.perf_counter() - t0,
        active_bounds=active,
        history=record.entries,
        targets=[(sc.name, sc.target) for sc in scs],
    )

"""Control: the cable commands (spring actuations, tendon pulls or tensions) that bring a target
as close as possible, :func:`control`."""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import MAX_EVALUATIONS, boolean, count, describe, positive_scalar
from ..cables import cable_index
from ..errors import InputError
from ..progress import Progress
from ..solver import SolveOptions
from ._control_dynamics import ScheduleResult, control_schedule
from ._optimizers import Recorder, scipy_minimize
from ._parameters import Parameters
from ._problem import DEFAULT_TOLERANCE, Problem, final_results
from ._problem import scenarios as make_scenarios
from .results import ControlResult

__all__ = ["control"]


def _bound_pairs(bounds: Any, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(lo, hi)`` per controlled cable, shape ``(n, 2)`` (each cable's kind checks its own)."""
    try:
        arr = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (n, 2):
        raise InputError(f"bounds: expected one (lo, hi) per controlled cable, shape ({n}, 2), got {describe(bounds)}")
    return arr[:, 0], arr[:, 1]


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
    dynamics: dict[str, Any] | None = None,
) -> ControlResult | ScheduleResult:
    """Cable commands that bring a target as close as possible; with ``dynamics``, a cable
    schedule that brings it there at a time T and keeps it there.

    Minimises ``1/2 |r|^2`` over the commands of the chosen cables, within ``bounds``: the
    actuation alpha of a spring cable (in log alpha), the pull of a tendon driven by its pull
    (in metres) or the tension of one driven by its tension (in newtons), with the adjoint
    gradient (``"l-bfgs-b"``) or without (``"nelder-mead"``). When the target cannot be
    reached, the result is the closest reachable configuration and ``reachable`` is False.

    Parameters
    ----------
    body
        The body with its cables; their actuations are left unchanged.
    target
        A :class:`~sorofem.Target`.
    cables
        The cables to actuate (:class:`~sorofem.Cable` or indices), default all.
    bounds
        One ``(lo, hi)`` range per cable in its command's units: alpha (default
        ``(0.3, 1.0)``), pull in m (default ``(0, L0 / 4)``, ``L0`` the tendon's rest length)
        or tension in N (no default: give it).
    x0
        Initial commands (default: the middle of the bounds, geometric for alphas; a cable
        at rest length is slack and has no gradient).
    tolerance
        Distance (RMS over the target's points, m) counted as reached; default 1 mm. For a
        :meth:`~sorofem.Target.contact_force` target: the force error ``|r|`` in N.
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
    dynamics
        Optimise an open-loop schedule instead (docs/tutorials/control.md, "A schedule in
        time"): the commands of the chosen cables at ``keyframe_times`` (s; piecewise linear
        between them, from the current command at t = 0, held after the last) that minimise
        the mean of ``1/2 |r|^2`` over the frames from ``reach_time`` (T, s, a frame's time)
        to the end of the run (m^2). Keys ``dt``, ``steps``, ``keyframe_times``,
        ``reach_time`` (required), ``damping``, ``initial``, ``initial_velocity`` (as for
        :func:`sorofem.simulate`) and ``checkpoint_every`` (as for
        :func:`~sorofem.inverse.trajectory_gradient`). Every time step is solved to
        ``solve_tolerance`` in at most ``max_iterations`` (``load_steps`` does not apply);
        ``x0`` is one command per cable or ``(k, c)`` keyframe values; ``tolerance`` bounds
        the RMS distance at T and at every frame after it; ``max_evaluations`` counts
        simulations (each with its adjoint); L-BFGS-B only.

    Returns
    -------
    ControlResult
        Or, with ``dynamics``, a :class:`~sorofem.inverse.ScheduleResult` (the schedule, its
        trajectory, the distance at T and the swing after it).

    Examples
    --------
    >>> ctl = sf.control(body, sf.Target.points(rest, goal), cables=[cable], bounds=[(0.3, 1.0)],
    ...                  gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> ctl.actuation, ctl.reachable, ctl.distance  # doctest: +SKIP

    Reach the goal at T = 0.5 s and hold it until 1.5 s, with keyframes every 0.1 s:

    >>> plan = sf.control(body, target, cables=[cable], bounds=[(0.3, 1.0)], gravity=(0, 0, -9.81),
    ...                   dynamics=dict(dt=0.01, steps=150, keyframe_times=[0.1, 0.2, 0.3, 0.4, 0.5],
    ...                                 reach_time=0.5, damping=(1.0, 0.0), initial=rest))  # doctest: +SKIP
    >>> plan.schedule, plan.distance, plan.swing  # doctest: +SKIP
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
    ids = list(range(len(body.cables))) if cables is None else [_cable_id(body, c, i) for i, c in enumerate(cables)]
    if not ids:
        raise InputError("cables: expected at least one cable to control")
    if len(set(ids)) != len(ids):
        raise InputError(f"cables: a cable is listed twice: {ids}")
    kinds = [_COMMAND_PARAMETER[body.commands[c][0]] for c in ids]
    names = [k for k in ("cable_actuation", "cable_pull", "cable_tension") if k in kinds]
    p = Parameters(body, names, cables={k: [c for c, kind in zip(ids, kinds) if kind == k] for k in names})
    n = p.size
    # theta (and s) are grouped by command kind; the user's values follow ``ids``.
    order = np.array([next(b.offset + list(b.cables).index(c) for b in p.blocks if b.kind == kind)
                      for c, kind in zip(ids, kinds)])
    if bounds is None:
        bounds = [_default_bounds(body, c, kind) for c, kind in zip(ids, kinds)]
    lo_u, hi_u = _bound_pairs(bounds, n)
    for i, (c, kind) in enumerate(zip(ids, kinds)):
        _check_bounds(body, c, kind, lo_u[i], hi_u[i])
    if dynamics is not None:
        if method != "l-bfgs-b" or initial is not None:
            bad = "method" if method != "l-bfgs-b" else "initial"
            raise InputError(f"{bad}: a schedule (dynamics=) is optimised by 'l-bfgs-b' from the state "
                             f"dynamics['initial']; got {bad}={describe(method if bad == 'method' else initial)}")
        solve_dyn = SolveOptions(solve_tolerance, max_iterations, load_steps) if options is None else options
        return control_schedule(
            body, target, ids, [_WORD[k] for k in kinds], lo_u, hi_u, x0, dynamics, tolerance=tolerance,
            gravity=gravity, solve_tolerance=solve_dyn.tolerance, max_iterations=solve_dyn.max_iterations,
            max_evaluations=max_evaluations, xtol=xtol, ftol=ftol, verbose=verbose, progress=progress,
        )
    if x0 is None:
        theta0_u = np.where(np.array(kinds) == "cable_actuation", np.sqrt(np.abs(lo_u * hi_u)), 0.5 * (lo_u + hi_u))
    else:
        try:
            theta0_u = np.asarray(x0, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise InputError(f"x0: expected {n} finite commands (alphas > 0), got {describe(x0)}") from None
        if theta0_u.shape != (n,) or not all(
            np.isfinite(v) and (v > 0 or kind != "cable_actuation") for v, kind in zip(theta0_u, kinds)
        ):
            raise InputError(f"x0: expected {n} finite commands (alphas > 0), got {np.asarray(x0).tolist()}")
    theta0, lo_a, hi_a = (np.empty(n) for _ in range(3))
    theta0[order], lo_a[order], hi_a[order] = theta0_u, lo_u, hi_u
    lo, hi = p.to_s(lo_a), p.to_s(hi_a)
    solve = SolveOptions(solve_tolerance, max_iterations, load_steps) if options is None else options
    scs = make_scenarios(body, target, None if initial is None else [{"initial": initial}], gravity, solve)
    problem = Problem(body, p, scs)
    problem.progress = bar = Progress(desc=f"control ({method})", unit="solves", enabled=progress)
    record = Recorder(problem, verbose, None, 0, t0)
    try:
        s, iters, _, msg = scipy_minimize(problem, np.clip(p.to_s(theta0), lo, hi), lo, hi, record, method, max_evaluations, xtol, ftol)
        theta = p.from_s(s)
        st = p.state(theta)
        results = final_results(body, body.material, st, scs, p)
    finally:
        bar.close()
        problem.restore()
    result = results[0]
    bound = scs[0].target
    distance = bound.rms(result.positions)
    reachable = distance <= tolerance
    units = "N" if bound.mode == "contact_force" else "m"
    what = "force error" if units == "N" else "RMS distance"
    active = [
        f"cable {c}: {_WORD[kind]} at its {'lower' if abs(s[i] - lo[i]) < 1e-9 else 'upper'} bound {theta[i]:.4g}"
        for c, kind, i in zip(ids, kinds, order)
        if abs(s[i] - lo[i]) < 1e-9 or abs(s[i] - hi[i]) < 1e-9
    ]
    if reachable:
        message = f"reached: {what} {distance:.3g} {units} <= tolerance {tolerance:g} {units}"
    else:
        message = (
            f"not reachable: the closest configuration found is {distance:.3g} {units} ({what}) from the target, "
            f"above the tolerance {tolerance:g} {units}" + (f"; {'; '.join(active)}" if active else "")
        )
    return ControlResult(
        actuation=theta[order],
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


#: The parameter of each cable command, and how messages call it.
_COMMAND_PARAMETER = {"actuation": "cable_actuation", "pull": "cable_pull", "tension": "cable_tension"}
_WORD = {"cable_actuation": "alpha", "cable_pull": "pull (m)", "cable_tension": "tension (N)"}


def _cable_id(body: Any, cable: Any, i: int) -> int:
    """``cables[i]``'s index in ``body.cables``; a cable the body does not have is named as ``cables[i]``."""
    try:
        return cable_index(body, cable)
    except InputError as exc:
        raise InputError(f"cables[{i}]: {str(exc).removeprefix('cable: ')}") from None


def _default_bounds(body: Any, c: int, kind: str) -> tuple[float, float]:
    if kind == "cable_actuation":
        return (0.3, 1.0)
    if kind == "cable_pull":
        return (0.0, 0.25 * body.cables[c].length)
    raise InputError(f"bounds: cable {c} is a tendon driven by its tension: give its (lo, hi) in N")


def _check_bounds(body: Any, c: int, kind: str, lo: float, hi: float) -> None:
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise InputError(f"bounds: expected finite lo <= hi for cable {c}, got ({lo:g}, {hi:g})")
    if kind == "cable_actuation" and not lo > 0:
        raise InputError(f"bounds: expected 0 < lo <= hi (alpha) for cable {c}, got ({lo:g}, {hi:g})")
    if kind == "cable_pull" and not hi < body.cables[c].length:
        raise InputError(
            f"bounds: a pull must stay below the tendon's rest length {body.cables[c].length:.6g} m, cable {c} "
            f"has hi = {hi:g} m"
        )
    if kind == "cable_tension" and not lo >= 0:
        raise InputError(f"bounds: a tension is >= 0 N, cable {c} has lo = {lo:g} N")

"""Calibration: fit material parameters so that the equilibrium meets a target, :func:`estimate`."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from ..progress import Progress
from ..solver import SolveOptions
from ._analysis import PROFILE_CONDITION, PROFILE_SPAN, material_std, profile_index, profile_span
from ._analysis import profile as profile_along
from ._optimizers import Recorder, bound_sides, levenberg_marquardt, scipy_minimize, uncertainty
from ._parameters import Parameters
from ._problem import DEFAULT_TOLERANCE, Problem, final_results, fitted_material
from ._problem import scenarios as make_scenarios
from .results import FitResult

__all__ = ["estimate"]


def _read_history(path: Path, names: list[str]) -> list[dict[str, Any]]:
    entries = []
    for line_no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interruption
        if sorted(entry.get("params", {})) != sorted(names):
            raise InputError(f"history_path: {path}:{line_no} has parameters {sorted(entry.get('params', {}))}, not {sorted(names)}")
        entries.append(entry)
    return entries


def _fit_from(problem: Problem, p: Parameters, theta_start: Any, method: str, lo: Any, hi: Any, record: Recorder,
              max_evaluations: int, xtol: float, ftol: float) -> dict[str, Any]:
    """One start of a fit: its optimum, residual, Jacobian (least squares) and history."""
    for sc in problem.scenarios:  # every start from the same beginning
        sc.initial = sc.given_initial
    solves_before, iterations_before = problem.forward_solves, problem.newton_iterations
    s0 = np.clip(p.to_s(theta_start), lo, hi)
    if method == "least-squares":
        s, r, J, iters, ok, msg = levenberg_marquardt(problem, s0, lo, hi, record, max_evaluations, xtol, ftol)
    else:
        s, iters, ok, msg = scipy_minimize(problem, s0, lo, hi, record, method, max_evaluations, xtol, ftol)
        r, J = None, None
    return {"start": theta_start, "s": s, "r": r, "J": J, "iterations": iters, "converged": ok, "message": msg,
            "history": record.entries, "forward_solves": problem.forward_solves - solves_before,
            "newton_iterations": problem.newton_iterations - iterations_before}


def _start_on_worker(k: int, theta_start: Any, setup: tuple[Any, ...]) -> dict[str, Any]:
    """One start of a fit where a Dask worker runs it: the problem is built there again (the
    body travels without its compiled model), exactly as :func:`estimate` builds it."""
    (body, target, params, regions, scenarios, gravity, solve, regularization, method, lo, hi, max_evaluations,
     xtol, ftol, t0) = setup
    p = Parameters(body, params, regions)
    problem = Problem(body, p, make_scenarios(body, target, scenarios, gravity, solve), regularization)
    try:
        return _fit_from(problem, p, theta_start, method, lo, hi, Recorder(problem, False, None, k, t0),
                         max_evaluations, xtol, ftol)
    finally:
        problem.restore()


def _remote_starts(client: Any, start_points: list[Any], first_start: int, history_file: Path | None, bar: Progress,
                   problem: Problem, setup: tuple[Any, ...]) -> list[dict[str, Any]]:
    """Every start on the workers of a Dask ``client`` at once; the runs in start order, their
    solves counted in ``problem`` and their history appended to ``history_file``."""
    for k, theta_start in enumerate(start_points):
        problem.params.check(theta_start, f"start {k}")
    futures = [client.submit(_start_on_worker, first_start + k, theta, setup, pure=False)
               for k, theta in enumerate(start_points)]
    runs = []
    for k, future in enumerate(futures):
        run = future.result()
        problem.forward_solves += run["forward_solves"]
        problem.newton_iterations += run["newton_iterations"]
        if history_file is not None:
            with history_file.open("a", encoding="utf-8") as fh:
                fh.writelines(json.dumps(entry) + "\n" for entry in run["history"])
        bar.set(problem.forward_solves, postfix=f"start {k + 1}/{len(start_points)} done")
        runs.append(run)
    return runs


def estimate(
    body: Any,
    target: Any,
    params: str | Sequence[str] = ("shear_modulus", "lame_lambda"),
    x0: Any = None,
    *,
    bounds: Any = None,
    method: str = "least-squares",
    starts: int | Sequence[Any] | None = None,
    scenarios: Sequence[Mapping[str, Any]] | None = None,
    regions: Mapping[str, ArrayLike] | None = None,
    regularization: float = 0.0,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    load_steps: int = 1,
    max_evaluations: int = 200,
    xtol: float = 1e-10,
    ftol: float = 1e-12,
    seed: int = 0,
    verbose: bool = False,
    history_path: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: bool | None = None,
    options: SolveOptions | None = None,
    client: Any = None,
    profile: bool | str | None = None,
    profile_values: ArrayLike | None = None,
) -> FitResult:
    """Fit material parameters so that the body's equilibrium meets a target.

    Minimises ``1/2 sum_scenarios |r|^2`` over the parameters, optimised in log space (logit
    for the Poisson ratio), so that mu and lambda, orders of magnitude apart, are equally
    well scaled.

    Parameters
    ----------
    body
        The body: mesh, supports, loads, cables; its material gives the values of the
        parameters not fitted.
    target
        A :class:`~sorofem.Target` (each scenario may bring its own).
    params
        Names from :data:`PARAMETERS` (material ones optionally ``"name:region"``).
    x0
        Initial values, one per name (arrays for fields), or a dict; default: the body's.
    bounds
        One ``(lo, hi)`` per name (None for open), in the parameter's units.
    method
        ``"least-squares"``: Levenberg-Marquardt on the Jacobian from forward sensitivities
        (one back-substitution per parameter, or one adjoint per residual if there are fewer
        residuals); ``"l-bfgs-b"``: adjoint gradient of ``1/2 |r|^2``; ``"nelder-mead"``:
        values only.
    starts
        More starting points: a list of x0-like values, or a number of random starts drawn
        log-uniformly within ``bounds`` (or within a factor 3 of ``x0``), ``seed`` seeding it.
        The best run wins; all are reported in ``fit.starts``.
    scenarios
        Several load cases fitted jointly: dicts with any of ``gravity``, ``actuation`` (one
        alpha per cable, or a dict cable -> alpha), ``target``, ``tolerance``,
        ``max_iterations``, ``load_steps``, ``initial``, ``name``. Default: one scenario with
        ``gravity`` and ``target``.
    regions
        name -> element mask (or indices) for ``"name:region"`` parameters.
    regularization
        Weight (m^2) of the smoothing of field parameters across element faces:
        adds ``weight sum (log mu_e - log mu_f)^2 / 2`` to the loss.
    gravity, tolerance, max_iterations, load_steps
        Solve options of the default scenario (every static solve is warm-started from the
        previous equilibrium of its scenario).
    options
        ``tolerance``, ``max_iterations`` and ``load_steps`` as one
        :class:`~sorofem.solver.SolveOptions`, which replaces them when given.
    client
        A ``dask.distributed.Client``: with more than one start, the starts run on its
        workers side by side, each an independent fit as without a client (the same path
        and optimum of every start; the body travels without its compiled model, which
        each worker builds); the final evaluation runs here. ``verbose`` lines are not
        printed for remote starts; the history file is written here as starts finish.
    max_evaluations
        Budget of objective evaluations per start (each is one solve per scenario).
    xtol, ftol
        Stop when a step changes log-parameters by less than ``xtol`` (relative), or the loss
        decreases by less than ``ftol`` relative (Nelder-Mead: simplex size and spread of the
        normalised loss).
    verbose
        Print one line per iteration on stderr.
    history_path
        Append each iteration as a JSON line here, as it goes.
    resume
        Read ``history_path`` and start from its best point (no extra starts).
    progress
        A progress line on stderr, ticked after every forward solve, with the iteration, the
        loss and the RMS misfit: ``None`` (default) only when stderr is a terminal and the fit
        lasts more than half a second, ``True`` always, ``False`` never (see
        :mod:`sorofem.progress`). The number of solves is not known in advance: the line
        counts them and shows the elapsed time (no ETA).
    profile
        Profile the misfit along one parameter (``fit.profile``, a :class:`Profile`): at each
        of its values the others are fitted again, and the likelihood-ratio interval is
        reported. ``None`` (default): along the parameter that weighs most in the worst
        determined direction, when the condition number of the scaled Jacobian exceeds
        :data:`~sorofem.inverse.PROFILE_CONDITION` (1e3) and at least two parameters are
        fitted; ``True``: that parameter, whatever the conditioning; a parameter name: that
        one; ``False``: no profile. Each point costs a fit of the other parameters.
    profile_values
        The values of the profiled parameter, in its units (default: 9 points over four
        standard errors either side of the optimum, at most a factor 1000 either way in the
        optimiser's scaling, within the bounds; from the bound for a parameter on one).

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Unknown parameter or method, bad bounds or scenarios.
    ConvergenceError
        The very first equilibrium cannot be found.

    Examples
    --------
    >>> fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6],
    ...                   gravity=(0, 0, -9.81))          # doctest: +SKIP
    >>> fit.params, fit.youngs_modulus, fit.uncertainty.relative_std  # doctest: +SKIP
    """
    methods = ("least-squares", "l-bfgs-b", "nelder-mead")
    if method not in methods:
        raise InputError(f"method: expected one of {list(methods)}, got {method!r}")
    t0 = time.perf_counter()
    p = Parameters(body, params, regions)
    if any(b.kind == "gravity" for b in p.blocks):
        raise InputError("params: 'gravity' can be differentiated (sf.gradient) but not estimated here")
    solve = SolveOptions(tolerance, max_iterations, load_steps) if options is None else options
    scs = make_scenarios(body, target, scenarios, gravity, solve)
    problem = Problem(body, p, scs, regularization)
    lo, hi = p.bounds_s(bounds)

    theta0 = p.current() if x0 is None else p.from_user(x0, "x0")
    p.check(theta0, "x0")
    history_file = None if history_path is None else Path(history_path)
    if resume:
        if history_file is None or not history_file.is_file():
            raise InputError(f"resume: needs an existing history_path, got {history_path!r}")
        entries = [e for e in _read_history(history_file, p.names) if math.isfinite(e.get("loss", math.nan))]
        if entries:
            best = min(entries, key=lambda e: e["loss"])
            theta0 = p.from_user(best["params"], "history")
        first_start = 1 + max((int(e.get("start", 0)) for e in entries), default=-1)
        start_points = [theta0]
    else:
        first_start = 0
        start_points = [theta0]
        if isinstance(starts, int):
            rng = np.random.default_rng(seed)
            s0 = p.to_s(theta0)
            a = np.where(np.isfinite(lo), lo, s0 - np.log(3.0))
            b = np.where(np.isfinite(hi), hi, s0 + np.log(3.0))
            start_points += [p.from_s(rng.uniform(a, b)) for _ in range(starts)]
        elif starts is not None:
            start_points += [p.from_user(v, f"starts[{i}]") for i, v in enumerate(starts)]

    runs: list[dict[str, Any]] = []
    bar = Progress(desc=f"estimate ({method})", unit="solves", enabled=progress)
    problem.progress = bar
    try:
        if client is not None and len(start_points) > 1:
            runs = _remote_starts(client, start_points, first_start, history_file, bar, problem, (
                body, target, params, regions, scenarios, gravity, solve, regularization, method, lo, hi,
                max_evaluations, xtol, ftol, t0))
        else:
            for k, theta_start in enumerate(start_points):
                p.check(theta_start, f"start {k}")
                if len(start_points) > 1:
                    bar.desc = f"estimate ({method}) start {k + 1}/{len(start_points)}"
                record = Recorder(problem, verbose, history_file, first_start + k, t0)
                runs.append(_fit_from(problem, p, theta_start, method, lo, hi, record, max_evaluations, xtol, ftol))
        best = min(runs, key=lambda run: run["history"][-1]["loss"] if run["history"] and math.isfinite(run["history"][-1]["loss"]) else math.inf)
        # Final evaluation at the optimum: residual and the Jacobian for the uncertainty.
        s = best["s"]
        fields = any(b.is_field for b in p.blocks)
        if best["J"] is not None and method == "least-squares":
            r, J = best["r"], best["J"]
        else:
            r, J = problem.evaluate(s, "residual" if fields else "jacobian")
        theta = p.from_s(s)
        st = p.state(theta)
        material = fitted_material(body, st)
        # J is dr/ds: for log parameters that is dr/dlog(theta), what the singular values
        # should measure; the covariance is mapped back with dtheta/ds. A parameter on a bound
        # is held there: a Gauss-Newton covariance is only valid in the interior.
        unc = None
        if not fields and J is not None:
            unc = uncertainty(p.names, theta, p.dtheta_ds(s), r, J[: problem.n_data], problem.n_data,
                              bound_sides(s, lo, hi))
            unc.material_std = material_std(body, p, theta, unc)
        fit_profile = None
        index = _profile_choice(profile, p, unc, fields)
        if index is not None:
            bar.desc = f"estimate: profile of {p.names[index] if p.size == len(p.names) else index}"
            span = profile_span(unc, index, p.dtheta_ds(s)) if unc is not None else PROFILE_SPAN
            fit_profile = profile_along(problem, s, r, index, lo, hi, values=profile_values, span=span)
        results = final_results(body, material, st, scs, p)
    finally:
        bar.close()
        problem.restore()
    loss = 0.5 * float(r @ r)
    return FitResult(
        params=p.as_dict(theta),
        material=material,
        loss=loss,
        residual=problem.rms(r),
        forward_solves=problem.forward_solves + len(results),
        newton_iterations=problem.newton_iterations,
        iterations=best["iterations"],
        method=method,
        converged=best["converged"],
        message=best["message"],
        time=time.perf_counter() - t0,
        history=[e for run in runs for e in run["history"]],
        uncertainty=unc,
        profile=fit_profile,
        targets=[(sc.name, sc.target) for sc in scs],
        starts=[
            {"x0": p.as_dict(run["start"]), "params": p.as_dict(p.from_s(run["s"])),
             "loss": run["history"][-1]["loss"] if run["history"] else math.nan,
             "forward_solves": run["forward_solves"], "iterations": run["iterations"], "converged": run["converged"]}
            for run in runs
        ],
        results=results,
    )


def _profile_choice(profile: bool | str | None, p: Parameters, unc: Any, fields: bool) -> int | None:
    """The index in theta of the parameter to profile, or None."""
    if profile is False:
        return None
    if isinstance(profile, str):
        block = next((b for b in p.blocks if b.name == profile), None)
        if block is None or block.size != 1:
            raise InputError(f"profile: expected the name of a fitted scalar parameter {p.names}, got {profile!r}")
        return block.offset
    if profile not in (None, True):
        raise InputError(f"profile: expected None, True, False or a parameter name, got {profile!r}")
    if fields or unc is None or unc.weak_direction is None:
        if profile is True:
            raise InputError("profile: needs the Jacobian of a fit of scalar parameters (no fields)")
        return None
    if profile is None and (len(p.names) < 2 or not unc.condition > PROFILE_CONDITION):
        return None
    index = profile_index(unc)
    block = next(b for b in p.blocks if b.offset <= index < b.offset + b.size)
    return index if block.size == 1 else None

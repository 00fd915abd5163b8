"""Calibration: fit material parameters so that the equilibrium meets a target, :func:`estimate`."""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .._files import check_path, write_text
from .._validate import (MAX_EVALUATIONS, MAX_STARTS, boolean, count, dask_client, describe, non_negative,
                         positive_scalar)
from ..errors import InputError
from ..io import json_text
from ..progress import Progress
from ..solver import SolveOptions
from ._analysis import PROFILE_CONDITION, PROFILE_SPAN, material_std, profile_index, profile_span
from ._analysis import profile as profile_along
from ._estimate_dynamics import estimate_dynamics
from ._optimizers import Recorder, bound_sides, levenberg_marquardt, scipy_minimize, uncertainty
from ._parameters import Parameters
from ._problem import DEFAULT_TOLERANCE, Problem, ProblemSpec, RemoteScenarios, final_results, fitted_material
from ._problem import scenarios as make_scenarios
from .results import FitResult

__all__ = ["estimate", "TornHistoryWarning", "HISTORY_VERSION"]


#: Version of the history file format (its first line, the header, says which).
HISTORY_VERSION = 1


class TornHistoryWarning(UserWarning):
    """A history file ended in a partial record (a run killed while writing it); the record was
    ignored and cut off, so that the resumed run appends whole lines."""


def _history_file(value: Any) -> Path:
    path = check_path(value, "history_path")
    if path.is_dir():
        raise InputError(f"history_path: {path} is a folder; expected a file name such as {path / 'history.jsonl'}")
    if not path.parent.is_dir():
        raise InputError(f"history_path: the folder {path.parent} of {path.name} does not exist")
    return path


def _read_history(path: Path, names: list[str]) -> tuple[dict[str, Any] | None, list[dict[str, Any]]]:
    """The header (None in a file of an older sorofem) and the records of a history file. A
    partial last line (a write cut short) is ignored, cut off the file and reported with a
    :class:`TornHistoryWarning`; anything else malformed is an :class:`InputError` naming the
    file and line."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"history_path: cannot read {path}: {exc.strerror or exc}") from None
    complete = data.rfind(b"\n") + 1
    tail = data[complete:]
    lines = data[:complete].split(b"\n")[:-1]
    if not tail.strip() and lines:
        try:
            json.loads(lines[-1])
        except ValueError:
            tail, complete, lines = lines[-1] + b"\n", complete - len(lines[-1]) - 1, lines[:-1]
    if tail.strip():
        warnings.warn(
            f"history_path: {path} ends in a partial record ({len(tail)} bytes, a write interrupted by a crash); "
            "it is ignored and cut off",
            TornHistoryWarning,
            stacklevel=3,
        )
        with path.open("r+b") as fh:
            fh.truncate(complete)
    header, records = None, []
    for line_no, raw in enumerate(lines, 1):
        if not raw.strip():
            continue
        where = f"history_path: {path}:{line_no}"
        try:
            entry = json.loads(raw)
        except ValueError:
            raise InputError(f"{where}: not a JSON record (the file is damaged, or not a history of sorofem.estimate)") from None
        if not isinstance(entry, dict):
            raise InputError(f"{where}: expected a JSON object, got {type(entry).__name__}")
        if entry.get("kind") == "header":
            header = entry
            continue
        params = entry.get("params")
        if not isinstance(params, dict) or sorted(params) != sorted(names):
            shown = sorted(params) if isinstance(params, dict) else describe(params)
            raise InputError(f"{where} has parameters {shown}, not {sorted(names)}")
        loss, start = entry.get("loss"), entry.get("start", 0)
        if not (loss is None or (isinstance(loss, (int, float)) and not isinstance(loss, bool))):
            raise InputError(f"{where}: 'loss' must be a number, got {describe(loss)}")
        if isinstance(start, bool) or not isinstance(start, int) or start < 0:
            raise InputError(f"{where}: 'start' must be an integer >= 0, got {describe(start)}")
        records.append(entry)
    return header, records


def _finite_loss(entry: Mapping[str, Any]) -> float:
    loss = entry.get("loss")
    return float(loss) if isinstance(loss, (int, float)) and math.isfinite(loss) else math.inf


def _fit_from(problem: Problem, p: Parameters, theta_start: Any, method: str, lo: Any, hi: Any, record: Recorder,
              max_evaluations: int, xtol: float, ftol: float,
              previous: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """One start of a fit: its optimum, residual, Jacobian (least squares) and history; with the
    ``previous`` iterates of an interrupted run of this start, it goes on from the last one."""
    for sc in problem.scenarios:  # every start from the same beginning
        sc.initial = sc.given_initial
    solves_before, iterations_before = problem.forward_solves, problem.newton_iterations
    s0 = np.clip(p.to_s(theta_start if not previous else p.from_user(previous[-1]["params"], "history")), lo, hi)
    if method == "least-squares":
        state = previous[-1].get("optimizer") if previous else None
        s, r, J, iters, ok, msg = levenberg_marquardt(
            problem, s0, lo, hi, record, max_evaluations, xtol, ftol, state if isinstance(state, dict) else None)
    else:
        s, iters, ok, msg = scipy_minimize(problem, s0, lo, hi, record, method, max_evaluations, xtol, ftol)
        r, J = None, None
    loss = _finite_loss(record.entries[-1]) if record.entries else math.inf
    return {"start": theta_start, "s": s, "r": r, "J": J, "iterations": iters, "converged": ok, "message": msg,
            "history": record.entries, "loss": loss, "forward_solves": problem.forward_solves - solves_before,
            "newton_iterations": problem.newton_iterations - iterations_before}


def _end_record(start: int, run: Mapping[str, Any], p: Parameters) -> dict[str, Any]:
    """The history line that closes a start (what ``resume`` needs to skip it)."""
    return {"kind": "end", "start": start,
            "params": run["history"][-1]["params"] if run["history"] else p.as_dict(p.from_s(run["s"])),
            "loss": run["loss"], "iterations": run["iterations"], "converged": run["converged"],
            "message": run["message"], "forward_solves": run["forward_solves"]}


def _start_on_worker(k: int, theta_start: Any, setup: tuple[Any, ...]) -> dict[str, Any]:
    """One start of a fit where a Dask worker runs it: the problem is built there again from
    its :class:`ProblemSpec`, exactly as :func:`estimate` builds it."""
    spec, method, lo, hi, max_evaluations, xtol, ftol, t0 = setup
    problem = spec.build()
    try:
        return _fit_from(problem, problem.params, theta_start, method, lo, hi,
                         Recorder(problem, False, None, k, t0), max_evaluations, xtol, ftol)
    finally:
        problem.restore()


def _remote_starts(client: Any, start_points: list[Any], first_start: int, history_file: Path | None, bar: Progress,
                   problem: Problem, setup: tuple[Any, ...]) -> list[dict[str, Any]]:
    """Every start on the workers of a Dask ``client`` at once; the runs in start order, their
    solves counted in ``problem`` and their history appended to ``history_file``."""
    for k, theta_start in enumerate(start_points):
        problem.params.check(theta_start, f"start {k}")
    # One run after the other fixes the barrier stiffness at the first solve of the first start,
    # and every start shares it: fixed here, it travels with the body to the workers.
    lo, hi = setup[2], setup[3]
    problem.fix_contact_stiffness(np.clip(problem.params.to_s(start_points[0]), lo, hi))
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
                fh.write(json.dumps(_end_record(first_start + k, run, problem.params)) + "\n")
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
    dynamics: Mapping[str, Any] | None = None,
) -> FitResult:
    """Fit material parameters so that the body's equilibrium meets a target, or damping (and
    material) parameters so that its motion meets recorded marker tracks (``dynamics=``).

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
        log-uniformly within ``bounds`` (or within a factor 3 of ``x0``), ``seed`` seeding it;
        at most 1,000 (a documented limit). The best run wins; all are reported in ``fit.starts``.
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
        each worker builds, but with its barrier stiffness, fixed here first by a solve at
        the first start if no solve fixed it yet); the final evaluation runs here.
        ``verbose`` lines are not printed for remote starts; the history file is written
        here as starts finish.
        With one start and several ``scenarios``, each evaluation solves the scenarios on
        its workers side by side instead, each warm-started from its last equilibrium here
        (the same fit, bit for bit; with a tendon pulled by a length, to round-off).
    max_evaluations
        Budget of objective evaluations per start (each is one solve per scenario), from 1 to
        100,000 (a documented limit).
    xtol, ftol
        Stop when a step changes log-parameters by less than ``xtol`` (relative), or the loss
        decreases by less than ``ftol`` relative (Nelder-Mead: simplex size and spread of the
        normalised loss).
    verbose
        Print one line per iteration on stderr.
    history_path
        Write the run's history here as it goes, one JSON line per record, each flushed to the
        disk before the next evaluation (:func:`sorofem.io.append_line`): a header (the
        parameters, the method and every starting point), one line per accepted iterate
        (with Levenberg-Marquardt's damping) and one line when a start ends. Without
        ``resume`` an existing file is replaced.
    resume
        Go on with the run recorded in ``history_path`` (interrupted by Ctrl-C, a crash or
        SIGKILL): its starting points come from the file (``x0`` and ``starts`` are then
        ignored), finished starts are not run again, and the start that was running goes on
        from its last recorded iterate; least-squares also restores its damping, so it takes
        the steps the uninterrupted run would have (to the solver tolerance), while
        l-bfgs-b and nelder-mead restart from that iterate. A partial last line (a write cut
        short) is ignored, cut off and reported with a :class:`TornHistoryWarning`. A file
        written by an older sorofem (no header) restarts from its best point.
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
    dynamics
        Fit to motion: the recorded run as ``dict(dt=, steps=, actuation=, damping=, initial=,
        initial_velocity=, gravity=, tolerance=, max_iterations=)`` (the arguments of
        :func:`sorofem.simulate`; ``dt`` and ``steps`` required, ``gravity``, ``tolerance``
        and ``max_iterations`` default to this function's). ``target`` is then the marker
        tracks, ``[(time, Target), ...]`` with every time a frame ``k dt`` of the run
        (:func:`sorofem.inverse.marker_tracks` builds them from a ``(frames, markers, 3)``
        array); the residual is every track's misfit at its frame. ``params`` may name
        ``"mass_damping"`` (alpha_M, 1/s), ``"stiffness_damping"`` (beta_K, s) and
        ``"cable_damping"`` (N s/m, the dashpot of the body's one spring cable) besides the
        scalar material parameters, ``density`` and ``cable_stiffness``; all are optimised in
        log space, the Rayleigh coefficients' start is ``x0`` or ``dynamics["damping"]`` (> 0
        for a fitted one), which also holds the coefficient not fitted; the dashpot's is ``x0``
        or the cable's damping (:attr:`sorofem.Body.cable_dampings`). Every trajectory is simulated by
        modified Newton to ``tolerance`` per step. ``"least-squares"`` takes its Jacobian, and
        every method its Gauss-Newton uncertainty, from the forward (tangent-linear)
        trajectory sensitivity (one extra solve per step and parameter with the step's
        factorised Hessian); ``"l-bfgs-b"`` follows the adjoint gradient
        (:func:`sorofem.trajectory_gradient`). ``fit.trajectory`` is the run at the optimum,
        ``fit.forward_solves`` counts simulated runs. ``starts``, ``scenarios``,
        ``regularization``, ``load_steps``, ``options``, ``client``, ``history_path`` and
        ``resume`` are refused with it.

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Unknown parameter or method, bad bounds or scenarios, ``x0`` naming a parameter not
        being fitted, a history file that cannot be resumed (the message names file and line).
    ParameterError
        A count or tolerance out of range (``starts``, ``max_evaluations``, ``xtol``, ...).
    ConvergenceError
        The very first equilibrium cannot be found.

    Examples
    --------
    >>> fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6],
    ...                   gravity=(0, 0, -9.81))          # doctest: +SKIP
    >>> fit.params, fit.youngs_modulus, fit.uncertainty.relative_std  # doctest: +SKIP

    From the motion of a marker at the tip, sampled every 50 ms of a 0.5 s swing:

    >>> tracks = sf.inverse.marker_tracks(times, [[0.4, 0.05, 0.05]], recorded)  # doctest: +SKIP
    >>> fit = sf.estimate(body, tracks, ["mass_damping", "stiffness_damping"],
    ...                   dynamics=dict(dt=0.01, steps=50, damping=(1.0, 0.01)),
    ...                   gravity=(0, 0, -9.81))  # doctest: +SKIP
    """
    if dynamics is not None:
        given = {"starts": starts is not None, "scenarios": scenarios is not None, "regularization": regularization != 0,
                 "load_steps": load_steps != 1, "options": options is not None, "client": client is not None,
                 "history_path": history_path is not None, "resume": resume is not False}
        refused = [name for name, on in given.items() if on]
        if refused:
            raise InputError(f"dynamics: a fit to motion does not take {', '.join(refused)} (one recorded run, "
                             "one start); leave them out")
        return estimate_dynamics(
            body, target, params, x0, dynamics=dynamics, bounds=bounds, method=method, regions=regions,
            gravity=gravity, tolerance=tolerance, max_iterations=max_iterations, max_evaluations=max_evaluations,
            xtol=xtol, ftol=ftol, verbose=verbose, progress=progress, profile=profile, profile_values=profile_values)
    methods = ("least-squares", "l-bfgs-b", "nelder-mead")
    if method not in methods:
        raise InputError(f"method: expected one of {list(methods)}, got {method!r}")
    max_evaluations = count(max_evaluations, "max_evaluations", 1, MAX_EVALUATIONS)
    xtol, ftol = positive_scalar(xtol, "xtol"), positive_scalar(ftol, "ftol")
    regularization = non_negative(regularization, "regularization")
    seed = count(seed, "seed", 0, 2**63 - 1)
    client = None if client is None else dask_client(client)
    verbose, resume = boolean(verbose, "verbose"), boolean(resume, "resume")
    if starts is not None and not isinstance(starts, (list, tuple)):
        starts = count(starts, "starts", 0, MAX_STARTS)
    elif starts is not None and len(starts) > MAX_STARTS:
        raise InputError(f"starts: expected at most {MAX_STARTS} starting points (a documented limit), got {len(starts)}")
    history_file = None if history_path is None else _history_file(history_path)
    if resume and (history_file is None or not history_file.is_file()):
        raise InputError(f"resume: needs an existing history_path, got {history_path!r}")
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
    header, records = _read_history(history_file, p.names) if resume and history_file is not None else (None, [])
    if header is not None:
        # The file's run goes on: its starting points, its finished starts, its last iterate.
        if header.get("method") != method:
            raise InputError(f"resume: {history_file} is a history of method {header.get('method')!r}, not {method!r}")
        start_points = [p.from_user(v, f"history start {k}") for k, v in enumerate(header.get("starts", []))]
    elif resume:
        # A history without a header (older sorofem): start again from its best point.
        entries = [e for e in records if math.isfinite(_finite_loss(e))]
        if entries:
            theta0 = p.from_user(min(entries, key=_finite_loss)["params"], "history")
        start_points = [theta0]
    else:
        start_points = [theta0]
        if isinstance(starts, int):
            rng = np.random.default_rng(seed)
            s0 = p.to_s(theta0)
            a = np.where(np.isfinite(lo), lo, s0 - np.log(3.0))
            b = np.where(np.isfinite(hi), hi, s0 + np.log(3.0))
            start_points += [p.from_s(rng.uniform(a, b)) for _ in range(starts)]
        elif starts is not None:
            start_points += [p.from_user(v, f"starts[{i}]") for i, v in enumerate(starts)]
    first_start = 0 if header is not None or not resume else 1 + max((int(e.get("start", 0)) for e in records), default=-1)
    if history_file is not None and not resume:
        header = {"kind": "header", "version": HISTORY_VERSION, "params": p.names, "method": method,
                  "starts": [p.as_dict(theta) for theta in start_points]}
        write_text(history_file, json_text(header, indent=None) + "\n")
    ended = {int(e["start"]): e for e in records if e.get("kind") == "end"} if header is not None else {}
    done_before = {k: [e for e in records if e.get("kind", "iteration") == "iteration" and e.get("start") == k]
                   for k in range(len(start_points))} if header is not None else {}

    runs: list[dict[str, Any]] = []
    bar = Progress(desc=f"estimate ({method})", unit="solves", enabled=progress)
    problem.progress = bar
    try:
        spec = ProblemSpec(body, target, params, regions, scenarios, gravity, solve, regularization)
        if client is not None and len(start_points) == 1 and len(scs) > 1:
            # As with the starts, the barrier stiffness the first solve would fix travels with the body.
            problem.fix_contact_stiffness(np.clip(p.to_s(start_points[0]), lo, hi))
            problem.remote = RemoteScenarios(client, spec)
        if client is not None and len(start_points) > 1:
            runs = _remote_starts(client, start_points, first_start, history_file, bar, problem,
                                  (spec, method, lo, hi, max_evaluations, xtol, ftol, t0))
        else:
            for k, theta_start in enumerate(start_points):
                p.check(theta_start, f"start {k}")
                previous = done_before.get(k, [])
                if k in ended:
                    end = ended[k]
                    runs.append({"start": theta_start, "s": p.to_s(p.from_user(end["params"], "history")), "r": None,
                                 "J": None, "iterations": int(end.get("iterations", 0)),
                                 "converged": bool(end.get("converged")), "message": str(end.get("message", "")),
                                 "history": previous, "loss": _finite_loss(end),
                                 "forward_solves": int(end.get("forward_solves", 0))})
                    continue
                if len(start_points) > 1:
                    bar.desc = f"estimate ({method}) start {k + 1}/{len(start_points)}"
                record = Recorder(problem, verbose, history_file, first_start + k, t0, previous)
                run = _fit_from(problem, p, theta_start, method, lo, hi, record, max_evaluations, xtol, ftol, previous)
                record.write(_end_record(first_start + k, run, p))
                runs.append(run)
        best = min(runs, key=lambda run: run["loss"])
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
            {"x0": p.as_dict(run["start"]), "params": p.as_dict(p.from_s(run["s"])), "loss": run["loss"],
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

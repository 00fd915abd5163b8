"""Calibration from recorded motion: :func:`sorofem.estimate` with ``dynamics=``.

The data are marker tracks, ``[(time, Target), ...]`` (:func:`marker_tracks` builds them from
an array of marker positions per frame); the model is the implicit Euler trajectory of
:func:`sorofem.simulate` from the same initial state, every step solved by modified Newton (the
default step method) to a tight tolerance. The residual is every track's ``Target.residual`` at
its frame, concatenated (m); the fit minimises ``1/2 |r|^2`` over the Rayleigh coefficients, a
spring cable's dashpot ``cable_damping`` and, optionally, the material, ``density`` and
``cable_stiffness``, each optimised in log space.

Derivatives: ``method="least-squares"`` (Levenberg-Marquardt) takes the exact Jacobian
``dr/ds`` from the forward (tangent-linear) trajectory sensitivity of the extension
(``Model::trajectory_sensitivity``: per step one factorisation of the step's Hessian at its end
and one solve per parameter), which also gives the Gauss-Newton uncertainty;
``method="l-bfgs-b"`` follows the adjoint gradient of ``1/2 |r|^2``
(:func:`sorofem.trajectory_gradient`: one forward and one backward sweep) and takes the
Jacobian once at the optimum for the uncertainty.
"""

from __future__ import annotations

import math
import numbers
import time
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._extension import core
from .._validate import MAX_EVALUATIONS, MAX_TIME_STEPS, as_finite, boolean, count, describe, non_negative
from .._validate import positive_int, positive_scalar
from ..body import Body, set_cable_values
from ..dynamics import Trajectory, evaluate_schedule, simulate
from ..errors import InputError, ParameterError
from ..materials import LOG
from ..progress import Progress
from ..static import StaticResult
from ..targets import BoundTarget, Target
from ._analysis import PROFILE_CONDITION, profile_index, profile_span
from ._analysis import profile as profile_along
from ._optimizers import Recorder, bound_sides, levenberg_marquardt, scipy_minimize, uncertainty
from ._parameters import COMMAND_PARAMETERS, Block, Parameters
from ._problem import bind, fitted_material
from ._trajectory import trajectory_gradient
from .results import FitResult

__all__ = ["estimate_dynamics", "marker_tracks", "DAMPING_PARAMETERS", "MOTION_PARAMETERS", "ESTIMATE_DYNAMICS_KEYS"]

#: The Rayleigh coefficients a fit to motion may estimate: ``mass_damping`` alpha_M (1/s) and
#: ``stiffness_damping`` beta_K (s), both optimised as their logarithm.
DAMPING_PARAMETERS = ("mass_damping", "stiffness_damping")
#: The parameters only a fit to motion estimates (statics do not see them): the Rayleigh
#: coefficients and ``cable_damping``, the dashpot (N s/m) of the body's one spring cable
#: (:meth:`sorofem.Body.set_cable_damping`). All are fitted as their logarithm.
MOTION_PARAMETERS = (*DAMPING_PARAMETERS, "cable_damping")
#: Keys of ``dynamics=``: those of :func:`sorofem.simulate` that define the recorded run.
ESTIMATE_DYNAMICS_KEYS = ("dt", "steps", "actuation", "damping", "initial", "initial_velocity", "gravity",
                          "tolerance", "max_iterations")


def marker_tracks(times: ArrayLike, rest_points: ArrayLike, positions: ArrayLike) -> list[tuple[float, Target]]:
    """Marker tracks as ``estimate(..., dynamics=...)`` and :func:`sorofem.trajectory_gradient`
    take them: ``[(time, Target.points(rest_points, positions[k])), ...]``.

    Parameters
    ----------
    times
        ``(frames,)`` s, each a multiple of the run's ``dt`` (a frame of the simulation).
    rest_points
        ``(markers, 3)`` m: where each marker sits on the body at rest (inside or on it).
    positions
        ``(frames, markers, 3)`` m: where each marker was recorded at each time (NaN for a
        marker not seen in a frame: it is left out of that frame).

    Examples
    --------
    >>> tracks = sf.inverse.marker_tracks([0.1, 0.2], [[0.4, 0.05, 0.05]],
    ...                                   [[[0.4, 0.05, 0.01]], [[0.39, 0.05, -0.02]]])  # doctest: +SKIP
    """
    t = as_finite(times, "times", (None,))
    rest = as_finite(rest_points, "rest_points", (None, 3))
    if t.size == 0 or rest.shape[0] == 0:
        raise InputError(f"times, rest_points: expected at least one frame and one marker, got {t.size} and "
                         f"{rest.shape[0]}")
    try:
        pos = np.asarray(positions, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"positions: expected an array of shape ({t.size}, {rest.shape[0]}, 3), got "
                         f"{describe(positions)}") from None
    if pos.shape != (t.size, rest.shape[0], 3):
        raise InputError(f"positions: expected shape (frames, markers, 3) = ({t.size}, {rest.shape[0]}, 3), "
                         f"got {pos.shape}")
    if np.any(np.isinf(pos)):
        raise InputError("positions: infinite values (NaN marks a marker not seen in a frame)")
    tracks = []
    for k in range(t.size):
        seen = ~np.any(np.isnan(pos[k]), axis=1)
        if seen.any():
            tracks.append((float(t[k]), Target.points(rest[seen], pos[k][seen])))
    if not tracks:
        raise InputError("positions: no marker is seen in any frame")
    return tracks


def _tracks(target: Any, body: Body, dt: float, steps: int) -> list[tuple[int, float, BoundTarget]]:
    """``[(time, Target), ...]`` as (frame, time, bound target), each time a frame's."""
    if isinstance(target, (Target, BoundTarget)) or not isinstance(target, (list, tuple)) or not target:
        raise InputError("target: with dynamics=, expected marker tracks [(time, sorofem.Target), ...] "
                         f"(see sorofem.inverse.marker_tracks), got {describe(target)}")
    out = []
    for i, entry in enumerate(target):
        if not isinstance(entry, (tuple, list)) or len(entry) != 2 or not isinstance(entry[1], (Target, BoundTarget)):
            raise InputError(f"target[{i}]: expected a (time, sorofem.Target) pair, got {describe(entry)}")
        t = entry[0]
        if isinstance(t, bool) or not isinstance(t, numbers.Real) or not math.isfinite(float(t)):
            raise InputError(f"target[{i}]: expected a finite time (s), got {describe(t)}")
        frame = round(float(t) / dt)
        if not (0 <= frame <= steps and abs(frame * dt - float(t)) <= 1e-9 * max(1.0, abs(float(t)))):
            raise ParameterError(
                f"target[{i}]: the time {float(t):g} s is not one of the simulated frames 0, dt, ..., "
                f"steps dt = {steps * dt:g} s (dt = {dt:g} s, steps = {steps})", "target")
        bound = bind(entry[1], body.mesh)
        if not isinstance(bound, BoundTarget):
            raise InputError(f"target[{i}]: a fit to motion takes targets on positions, got {describe(entry[1])}")
        out.append((frame, float(t), bound))
    return out


class DynamicParameters:
    """The fitted names of a fit to motion, all scalars, in the user's order: the Rayleigh
    coefficients, ``cable_damping`` and the names :class:`Parameters` understands (material,
    ``density``, ``cable_stiffness``), each its own block of the scaled vector ``s``."""

    def __init__(self, body: Body, names: str | Sequence[str], regions: Mapping[str, ArrayLike] | None,
                 damping: tuple[float, float]) -> None:
        if isinstance(names, str):
            names = [names]
        if not isinstance(names, (list, tuple)) or not names:
            raise InputError(f"params: expected a list of parameter names, got {describe(names)}")
        model = body.material.model
        allowed = (*MOTION_PARAMETERS, *model.estimable(), "cable_stiffness")
        fields = [n for n in model.estimable() if n.endswith("_field")]
        static_names = []
        for name in names:
            if not isinstance(name, str):
                raise InputError(f"params: expected parameter names (str), got {name!r}")
            kind = name if name in allowed else name.rpartition(":")[0]
            if kind in fields:
                raise InputError(f"params: {name!r} is a field (a value per element); a fit to motion takes scalar "
                                 f"parameters only: {list(n for n in allowed if n not in fields)}")
            if kind in COMMAND_PARAMETERS or kind == "gravity":
                raise InputError(f"params: {name!r} is not estimated from motion (the schedule is given by "
                                 "dynamics['actuation'], gravity by dynamics['gravity'])")
            if kind not in allowed or kind in MOTION_PARAMETERS and kind != name:
                known = [n for n in allowed if n not in fields]
                raise InputError(f"params: unknown parameter {name!r} for a fit to motion; expected one of {known} "
                                 "(material ones optionally ':region')")
            if name not in MOTION_PARAMETERS:
                static_names.append(name)
        if len(set(names)) != len(names):
            twice = next(n for n in names if list(names).count(n) > 1)
            raise InputError(f"params: {twice!r} given twice")
        springs = [i for i, c in enumerate(body.cables) if not c.is_tendon]
        if "cable_damping" in names and len(springs) != 1:
            raise InputError(f"params: 'cable_damping' is a spring cable's dashpot, fitted as one scalar: it needs a "
                             f"body with exactly one spring cable; this one has {len(springs)}")
        #: The spring cable whose dashpot is fitted, and its coefficient in the body (N s/m).
        self.dashpot_cable = springs[0] if "cable_damping" in names else None
        self.cable_damping0 = body.cable_dampings[springs[0]] if "cable_damping" in names else 0.0
        self.names: list[str] = list(names)
        self.static = Parameters(body, static_names, regions) if static_names else None
        self.damping0 = damping
        by_name = {b.name: b for b in self.static.blocks} if self.static is not None else {}
        for b in by_name.values():
            if b.size != 1:
                raise InputError(f"params: {b.name!r} has {b.size} values here (one per spring cable); a fit to "
                                 "motion takes scalar parameters (a body with one spring cable)")
        empty = np.zeros(0, dtype=np.int64)
        self.blocks = [
            Block(name, name, empty, empty, 1, LOG, i) if name in MOTION_PARAMETERS
            else Block(name, by_name[name].kind, by_name[name].elements, by_name[name].cables, 1,
                       by_name[name].transform, i)
            for i, name in enumerate(self.names)
        ]
        self.size = len(self.names)
        self.static_index = [i for i, n in enumerate(self.names) if n not in MOTION_PARAMETERS]

    def current(self) -> NDArray[np.float64]:
        theta = np.zeros(self.size)
        if self.static is not None:
            theta[self.static_index] = self.static.current()
        for i, name in enumerate(self.names):
            if name in DAMPING_PARAMETERS:
                theta[i] = self.damping0[DAMPING_PARAMETERS.index(name)]
            elif name == "cable_damping":
                theta[i] = self.cable_damping0
        return theta

    def from_user(self, values: Any, what: str) -> NDArray[np.float64]:
        if isinstance(values, Mapping):
            unknown = [k for k in values if k not in self.names]
            if unknown:
                raise InputError(f"{what}: {unknown} are not parameters being fitted; expected names among {self.names}")
            current = self.current()
            values = [values.get(n, current[i]) for i, n in enumerate(self.names)]
        flat = np.atleast_1d(np.asarray(values, dtype=object)).reshape(-1)
        if flat.size != self.size:
            raise InputError(f"{what}: expected {self.size} value(s), one per parameter {self.names}, got {flat.size}")
        theta = np.zeros(self.size)
        for i, v in enumerate(flat):
            if isinstance(v, bool) or not isinstance(v, numbers.Real):
                raise InputError(f"{what}: {self.names[i]!r} expects a number, got {describe(v)}")
            theta[i] = float(v)
        return theta

    def check(self, theta: NDArray[np.float64], what: str) -> None:
        for b in self.blocks:
            v = theta[b.offset]
            if not math.isfinite(v) or not bool(b.transform.contains(v)):
                where = "the cable's damping" if b.name == "cable_damping" else "dynamics['damping']"
                hint = (f" (a damping coefficient is fitted as its logarithm: give a positive start in x0 or {where})"
                        if b.name in MOTION_PARAMETERS else "")
                raise ParameterError(f"{what}: {b.name} must be {b.transform.domain()}, got {v:g}{hint}", b.name)

    def to_s(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array([float(b.transform.to_s(np.array([theta[b.offset]]))[0]) for b in self.blocks])

    def from_s(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array([float(b.transform.from_s(np.array([s[b.offset]]))[0]) for b in self.blocks])

    def dtheta_ds(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array([float(b.transform.dtheta_ds(np.array([s[b.offset]]))[0]) for b in self.blocks])

    def as_dict(self, theta: NDArray[np.float64]) -> dict[str, Any]:
        return {name: float(theta[i]) for i, name in enumerate(self.names)}

    def bounds_s(self, bounds: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Bounds in s from one ``(lo, hi)`` per name (None = open) or a dict; a damping
        coefficient's bound below 0 is refused (0 is no bound: the logarithm keeps it > 0)."""
        lo, hi = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        if bounds is None:
            return lo, hi
        if isinstance(bounds, Mapping):
            unknown = [k for k in bounds if k not in self.names]
            if unknown:
                raise InputError(f"bounds: {unknown} are not parameters being fitted; expected names among {self.names}")
            bounds = [bounds.get(name) for name in self.names]
        if not isinstance(bounds, (list, tuple, np.ndarray)) or len(bounds) != self.size:
            raise InputError(f"bounds: expected one (lo, hi) per parameter {self.names}, got {describe(bounds)}")
        for b, pair in zip(self.blocks, bounds):
            if pair is None:
                continue
            if not isinstance(pair, (list, tuple, np.ndarray)) or len(pair) != 2:
                raise InputError(f"bounds: expected (lo, hi) for {b.name!r}, got {describe(pair)}")
            for value, side in zip(pair, (lo, hi)):
                if value is None:
                    continue
                if isinstance(value, bool) or not isinstance(value, numbers.Real) or math.isnan(float(value)):
                    raise InputError(f"bounds: expected numbers or None for {b.name!r}, got {describe(value)}")
                if b.name in MOTION_PARAMETERS and float(value) < 0:
                    raise ParameterError(f"bounds: {b.name!r} is a damping coefficient, >= 0; got the bound "
                                         f"{float(value):g}", b.name)
                if b.transform.contains(float(value)):
                    side[b.offset] = float(b.transform.to_s(np.array([float(value)]))[0])
        if np.any(lo > hi):
            raise InputError(f"bounds: lower bound above upper bound for {self.names}")
        return lo, hi

    def damping(self, theta: NDArray[np.float64]) -> tuple[float, float]:
        values = list(self.damping0)
        for i, name in enumerate(self.names):
            if name in DAMPING_PARAMETERS:
                values[DAMPING_PARAMETERS.index(name)] = float(theta[i])
        return values[0], values[1]

    def body(self, body: Body, theta: NDArray[np.float64]) -> Body:
        """``body`` with the material, density, cable stiffnesses and dashpot of theta (a copy
        that shares its compiled model, or the body itself when none of those is fitted)."""
        if self.static is None and self.dashpot_cable is None:
            return body
        if self.static is None:
            fitted = body.replace()
        else:
            st = self.static.state(theta[self.static_index])
            fitted = body.replace(material=fitted_material(body, st))
            for b in self.static.blocks:
                if b.kind == "cable_stiffness":
                    for c in b.cables:
                        fitted.set_cable_stiffness(int(c), float(st.stiffness[c]))
        if self.dashpot_cable is not None:
            fitted.set_cable_damping(self.dashpot_cable, float(theta[self.names.index("cable_damping")]))
        return fitted

    def direction(self, name: str, n_cables: int) -> dict[str, Any]:
        """The forward-sensitivity direction of a motion-only parameter (one unit of it)."""
        if name == "cable_damping":
            return {name: np.eye(n_cables)[self.dashpot_cable]}
        return {name: 1.0}


class DynamicProblem:
    """Residuals of the marker tracks as a function of s, with the Jacobian (forward trajectory
    sensitivity) or the adjoint gradient; what the optimisers of
    :mod:`._optimizers` expect of a problem. ``forward_solves`` counts simulated trajectories."""

    def __init__(self, body: Body, params: DynamicParameters, tracks: list[tuple[int, float, BoundTarget]],
                 run: dict[str, Any]) -> None:
        self.body, self.params, self.tracks, self.run = body, params, tracks, run
        self.scenarios: list[Any] = []  # no static warm starts to reset
        self.forward_solves = 0
        self.newton_iterations = 0
        self.evaluations = 0
        self.n_data = sum(t.n_residuals for _, _, t in tracks)
        self.progress: Progress | None = None

    def _tick(self) -> None:
        if self.progress is not None:
            self.progress.set(self.forward_solves)

    def simulate(self, theta: NDArray[np.float64]) -> Trajectory:
        run = self.run
        traj = simulate(self.params.body(self.body, theta), run["dt"], run["steps"], actuation=run["actuation"],
                        gravity=run["gravity"], damping=self.params.damping(theta), initial=run["initial"],
                        initial_velocity=run["initial_velocity"], tolerance=run["tolerance"],
                        max_iterations=run["max_iterations"], method="modified", progress=False)
        self.forward_solves += 1
        self.newton_iterations += int(traj.iterations.sum())
        self._tick()
        return traj

    def residual_of(self, positions: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([t.residual(positions[frame]) for frame, _, t in self.tracks])

    def evaluate(self, s: NDArray[np.float64], want: str = "residual") -> tuple[NDArray[np.float64], Any]:
        """``(r, extra)``: extra is ``dr/ds`` (``want="jacobian"``), the gradient of
        ``1/2 |r|^2`` w.r.t. s (``"gradient"``) or None."""
        p = self.params
        theta = p.from_s(s)
        self.evaluations += 1
        if want == "gradient":
            return self._gradient(s, theta)
        if want != "jacobian":
            return self.residual_of(self.simulate(theta).positions), None
        positions, dx = self.sensitivities(theta)
        dts = p.dtheta_ds(s)
        columns = [np.concatenate([t.jacobian(positions[frame]) @ dx[j, frame].reshape(-1) for frame, _, t in self.tracks])
                   * dts[j] for j in range(p.size)]
        return self.residual_of(positions), np.column_stack(columns)

    def sensitivities(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The run at theta, ``(steps + 1, n, 3)`` positions, and their derivatives by each
        parameter, ``(p, steps + 1, n, 3)`` (m per unit of the parameter), from the extension's
        forward sensitivity."""
        p, run = self.params, self.run
        body = p.body(self.body, theta)
        static = iter(p.static.directions(theta[p.static_index]) if p.static is not None else [])
        directions = [p.direction(name, len(body.cables)) if name in MOTION_PARAMETERS else next(static)
                      for name in p.names]
        n = body.mesh.n_nodes
        x0, v0 = _initial_state(run["initial"], run["initial_velocity"])
        mass_damping, stiffness_damping = p.damping(theta)
        model = body.core_model()
        try:
            out = core().trajectory_sensitivity(
                model, run["gravity"], body.forces.copy(), body.prescribed_displacement.copy(), run["dt"],
                evaluate_schedule(body, run["actuation"], run["dt"], run["steps"]), directions, mass_damping,
                stiffness_damping, x0, v0, run["tolerance"], run["max_iterations"])
        finally:
            set_cable_values(model, body.commands, body.cable_stiffnesses, body.cable_dampings)
        self.forward_solves += 1
        self.newton_iterations += int(np.sum(out["iterations"]))
        self._tick()
        positions = np.asarray(out["positions"], dtype=np.float64).reshape(-1, n, 3)
        return positions, np.asarray(out["dx"], dtype=np.float64).reshape(len(directions), -1, n, 3)

    def _gradient(self, s: NDArray[np.float64], theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], Any]:
        p, run = self.params, self.run
        objective = [(t, target) for _, t, target in self.tracks]
        out = trajectory_gradient(
            p.body(self.body, theta), objective, p.names, dt=run["dt"], steps=run["steps"], actuation=run["actuation"],
            gravity=run["gravity"], damping=p.damping(theta), initial=run["initial"],
            initial_velocity=run["initial_velocity"], tolerance=run["tolerance"], max_iterations=run["max_iterations"])
        self.forward_solves += 1
        self.newton_iterations += int(out.iterations.sum())
        self._tick()
        g = np.array([float(np.ravel(out.gradient[name])[0]) for name in p.names])
        return self.residual_of(out.positions), g * p.dtheta_ds(s)

    def restore(self) -> None:
        self.body.core_model()

    def rms(self, r: NDArray[np.float64]) -> float:
        data = r[: self.n_data]
        return float(np.sqrt(data @ data / max(self.n_data // 3, 1)))


def _initial_state(initial: Any, velocity: Any) -> tuple[Any, Any]:
    """Initial positions and velocities (None: rest, at rest) of ``dynamics['initial']`` and
    ``['initial_velocity']``, as :func:`sorofem.simulate` reads them."""
    x0, v0 = initial, None
    if isinstance(initial, Trajectory):
        x0, v0 = initial.final_positions, initial.velocities
    elif isinstance(initial, StaticResult):
        x0 = initial.positions
    if velocity is not None:
        v0 = velocity
    return x0, v0


def _run_options(dynamics: Any, gravity: ArrayLike, tolerance: float, max_iterations: int, body: Body) -> dict[str, Any]:
    """The recorded run's arguments from ``dynamics=`` (checked as :func:`sorofem.simulate`
    checks them), ``gravity``, ``tolerance`` and ``max_iterations`` filling what it leaves out."""
    if not isinstance(dynamics, Mapping):
        raise InputError(f"dynamics: expected a dict with dt, steps and optionally {list(ESTIMATE_DYNAMICS_KEYS[2:])}, "
                         f"got {describe(dynamics)}")
    unknown = sorted(set(dynamics) - set(ESTIMATE_DYNAMICS_KEYS))
    if unknown:
        raise InputError(f"dynamics: unknown keys {unknown}; expected {list(ESTIMATE_DYNAMICS_KEYS)}")
    for key in ("dt", "steps"):
        if key not in dynamics:
            raise InputError(f"dynamics: needs {key!r} (the recorded run's time step and number of steps)")
    dt = positive_scalar(dynamics["dt"], "dynamics['dt']")
    steps = positive_int(dynamics["steps"], "dynamics['steps']", MAX_TIME_STEPS)
    damping = dynamics.get("damping", (0.0, 0.0))
    if not isinstance(damping, (tuple, list)) or len(damping) != 2:
        raise ParameterError(f"dynamics['damping']: expected (alpha_M, beta_K), got {describe(damping)}", "damping")
    damping = (non_negative(damping[0], "dynamics['damping'][0] (alpha_M)"),
               non_negative(damping[1], "dynamics['damping'][1] (beta_K)"))
    initial = dynamics.get("initial")
    if initial is not None and not isinstance(initial, (StaticResult, Trajectory)):
        initial = as_finite(initial, "dynamics['initial']", (body.mesh.n_nodes, 3))
    velocity = dynamics.get("initial_velocity")
    if velocity is not None:
        velocity = as_finite(velocity, "dynamics['initial_velocity']", (body.mesh.n_nodes, 3))
    return {
        "dt": dt, "steps": steps, "actuation": dynamics.get("actuation"), "damping": damping, "initial": initial,
        "initial_velocity": velocity,
        "gravity": as_finite(dynamics.get("gravity", gravity), "gravity", (3,)),
        "tolerance": positive_scalar(dynamics.get("tolerance", tolerance), "tolerance"),
        "max_iterations": positive_int(dynamics.get("max_iterations", max_iterations), "max_iterations", 10_000),
    }


def estimate_dynamics(
    body: Any,
    target: Any,
    params: str | Sequence[str],
    x0: Any,
    *,
    dynamics: Any,
    bounds: Any,
    method: str,
    regions: Mapping[str, ArrayLike] | None,
    gravity: ArrayLike,
    tolerance: float,
    max_iterations: int,
    max_evaluations: int,
    xtol: float,
    ftol: float,
    verbose: bool,
    progress: bool | None,
    profile: bool | str | None,
    profile_values: ArrayLike | None,
) -> FitResult:
    """:func:`sorofem.estimate` with ``dynamics=`` (its docstring, "Fit to motion", says what is
    fitted and how); the keyword arguments that make no sense for a trajectory have been refused
    by the caller."""
    t0 = time.perf_counter()
    if not isinstance(body, Body):
        raise InputError(f"body: expected a sorofem.Body, got {describe(body)}")
    if method not in ("least-squares", "l-bfgs-b", "nelder-mead"):
        raise InputError(f"method: expected one of ['least-squares', 'l-bfgs-b', 'nelder-mead'], got {method!r}")
    max_evaluations = count(max_evaluations, "max_evaluations", 1, MAX_EVALUATIONS)
    xtol, ftol = positive_scalar(xtol, "xtol"), positive_scalar(ftol, "ftol")
    verbose = boolean(verbose, "verbose")
    run = _run_options(dynamics, gravity, tolerance, max_iterations, body)
    tracks = _tracks(target, body, run["dt"], run["steps"])
    p = DynamicParameters(body, params, regions, run["damping"])
    lo, hi = p.bounds_s(bounds)
    theta0 = p.current() if x0 is None else p.from_user(x0, "x0")
    p.check(theta0, "x0")
    if isinstance(profile, str) and profile not in p.names:
        raise InputError(f"profile: expected the name of a fitted parameter {p.names}, got {profile!r}")
    problem = DynamicProblem(body, p, tracks, run)
    bar = Progress(desc=f"estimate from motion ({method})", unit="runs", enabled=progress)
    problem.progress = bar
    try:
        record = Recorder(problem, verbose, None, 0, t0)  # type: ignore[arg-type]
        s0 = np.clip(p.to_s(theta0), lo, hi)
        if method == "least-squares":
            s, r, J, iterations, converged, message = levenberg_marquardt(
                problem, s0, lo, hi, record, max_evaluations, xtol, ftol)  # type: ignore[arg-type]
        else:
            s, iterations, converged, message = scipy_minimize(
                problem, s0, lo, hi, record, method, max_evaluations, xtol, ftol)  # type: ignore[arg-type]
            r, J = problem.evaluate(s, "jacobian")
        theta = p.from_s(s)
        unc = uncertainty(p.names, theta, p.dtheta_ds(s), r, J, problem.n_data, bound_sides(s, lo, hi))
        index = _profile_index(profile, p, unc)
        fit_profile = None
        if index is not None:
            bar.desc = f"estimate from motion: profile of {p.names[index]}"
            span = profile_span(unc, index, p.dtheta_ds(s))
            fit_profile = profile_along(problem, s, r, index, lo, hi, values=profile_values,  # type: ignore[arg-type]
                                        span=span)
        fitted = p.body(body, theta)
        trajectory = problem.simulate(theta)
    finally:
        bar.close()
        problem.restore()
    return FitResult(
        params=p.as_dict(theta),
        material=fitted.material,
        loss=0.5 * float(r @ r),
        residual=problem.rms(r),
        forward_solves=problem.forward_solves,
        newton_iterations=problem.newton_iterations,
        iterations=iterations,
        method=method,
        converged=converged,
        message=message,
        time=time.perf_counter() - t0,
        history=record.entries,
        uncertainty=unc,
        profile=fit_profile,
        starts=[{"x0": p.as_dict(theta0), "params": p.as_dict(theta), "loss": 0.5 * float(r @ r),
                 "forward_solves": problem.forward_solves, "iterations": iterations, "converged": converged}],
        targets=[(t, target) for _, t, target in tracks],
        trajectory=trajectory,
    )


def _profile_index(profile: bool | str | None, p: DynamicParameters, unc: Any) -> int | None:
    """The index of the parameter to profile, or None (the rule of the static fit)."""
    if profile is False:
        return None
    if isinstance(profile, str):
        if profile not in p.names:
            raise InputError(f"profile: expected the name of a fitted parameter {p.names}, got {profile!r}")
        return p.names.index(profile)
    if profile not in (None, True):
        raise InputError(f"profile: expected None, True, False or a parameter name, got {profile!r}")
    if unc.weak_direction is None or (profile is None and (p.size < 2 or not unc.condition > PROFILE_CONDITION)):
        return None
    return profile_index(unc)


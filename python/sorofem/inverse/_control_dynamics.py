"""Open-loop schedule optimisation: the cable keyframes that bring a target to its goal at a
time T and keep it there, the dynamic path of :func:`sorofem.control` (``dynamics=``).

The unknowns are the values ``v`` ``(k, c)`` of ``c`` cables' commands at ``k`` keyframe
times; each cable's schedule is the piecewise-linear :class:`~sorofem.dynamics.Keyframes`
through them (from the body's current command at ``t = 0`` when the first keyframe is later),
held after the last one. With ``N = steps``, ``i_T = T / dt`` and the hold frames
``i = i_T, ..., N`` (``n_H = N - i_T + 1`` of them), the objective is the mean of the static
control's misfit over the hold frames,

    J(v) = 1 / n_H  sum_{i = i_T}^{N}  1/2 |r(x_i(v))|^2      (m^2)

``r = W x_i - goal`` the target's residual (``3 p`` values for ``p`` points, m), ``x_i`` the
positions of frame ``i`` (time ``i dt``) of the implicit Euler trajectory of
:func:`sorofem.simulate`. Every frame of the hold counts the same: the target must be reached
at T and any swing after it costs as much as missing it. ``dJ/dv`` is the discrete adjoint of
:func:`~sorofem.inverse.trajectory_gradient`; L-BFGS-B minimises ``J / J(v0)`` over the values
scaled to their bounds, ``(v - lo) / (hi - lo)`` in [0, 1].
"""

from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._text import plural
from .._validate import MAX_MAGNITUDE, MAX_TIME_STEPS, as_finite, describe, non_negative, positive_int, positive_scalar
from ..body import Body
from ..dynamics import Keyframes, Trajectory, simulate
from ..errors import InputError, ParameterError, SolverError
from ..progress import Progress
from ..static import StaticResult
from ..targets import BoundContactForce, BoundTarget
from ._problem import bind
from ._trajectory import trajectory_gradient

__all__ = ["DYNAMICS_KEYS", "ScheduleResult", "ScheduleProblem", "control_schedule", "dynamics_options"]

#: The keys of ``control(..., dynamics={...})``: the first four are required; ``dt``,
#: ``steps``, ``damping``, ``initial``, ``initial_velocity`` as for :func:`sorofem.simulate`,
#: ``checkpoint_every`` as for :func:`sorofem.inverse.trajectory_gradient`.
DYNAMICS_KEYS = ("dt", "steps", "keyframe_times", "reach_time", "damping", "initial", "initial_velocity",
                 "checkpoint_every")
_REQUIRED = DYNAMICS_KEYS[:4]


@dataclass
class ScheduleOptions:
    """The checked ``dynamics`` dict."""

    dt: float
    steps: int
    keyframe_times: NDArray[np.float64]
    reach_frame: int
    damping: tuple[float, float]
    initial: NDArray[np.float64] | None
    initial_velocity: NDArray[np.float64] | None
    checkpoint_every: int | None

    @property
    def reach_time(self) -> float:
        return self.reach_frame * self.dt


def dynamics_options(dynamics: Any, body: Body) -> ScheduleOptions:
    """Check ``dynamics`` (see :data:`DYNAMICS_KEYS`); every error names its key."""
    if not isinstance(dynamics, Mapping):
        raise InputError(f"dynamics: expected a dict with the keys {', '.join(_REQUIRED)} (and optionally "
                         f"{', '.join(DYNAMICS_KEYS[4:])}), got {describe(dynamics)}")
    unknown = sorted(map(str, set(dynamics) - set(DYNAMICS_KEYS)))
    if unknown:
        raise InputError(f"dynamics: unknown keys {unknown}; expected {', '.join(DYNAMICS_KEYS)}")
    missing = [k for k in _REQUIRED if k not in dynamics]
    if missing:
        raise InputError(f"dynamics: missing {', '.join(repr(k) for k in missing)}; the required keys are "
                         f"{', '.join(_REQUIRED)}")
    dt = positive_scalar(dynamics["dt"], "dynamics['dt']")
    steps = positive_int(dynamics["steps"], "dynamics['steps']", MAX_TIME_STEPS)
    end = dt * steps
    if not end <= MAX_MAGNITUDE:
        raise ParameterError(f"dynamics['dt']: the run dt * steps lasts {end:g} s, above the documented limit "
                             f"{MAX_MAGNITUDE:g} s", "dynamics['dt']")
    times = _keyframe_times(dynamics["keyframe_times"], end)
    reach = dynamics["reach_time"]
    name = "dynamics['reach_time']"
    if isinstance(reach, bool) or not isinstance(reach, numbers.Real) or not math.isfinite(float(reach)):
        raise ParameterError(f"{name}: expected a time in s, got {describe(reach)}", name)
    ratio = float(reach) / dt
    frame = round(ratio) if math.isfinite(ratio) else -1
    if not (1 <= frame <= steps and abs(frame * dt - float(reach)) <= 1e-9 * max(1.0, abs(float(reach)))):
        raise ParameterError(f"{name}: expected the time of a frame, a multiple of dt = {dt:g} s in "
                             f"[{dt:g}, {end:g}] s (the run ends at dt * steps), got {float(reach):g} s", name)
    damping = dynamics.get("damping", (0.0, 0.0))
    if not isinstance(damping, (tuple, list)) or len(damping) != 2:
        raise ParameterError(f"dynamics['damping']: expected (alpha_M, beta_K), got {describe(damping)}",
                             "dynamics['damping']")
    rayleigh = (non_negative(damping[0], "dynamics['damping'][0] (alpha_M, 1/s)"),
                non_negative(damping[1], "dynamics['damping'][1] (beta_K, s)"))
    n = body.mesh.n_nodes
    initial, velocity = dynamics.get("initial"), dynamics.get("initial_velocity")
    if isinstance(initial, Trajectory):
        initial, velocity = initial.final_positions, initial.velocities if velocity is None else velocity
    elif isinstance(initial, StaticResult):
        initial = initial.positions
    x0 = None if initial is None else as_finite(initial, "dynamics['initial']", (n, 3))
    v0 = None if velocity is None else as_finite(velocity, "dynamics['initial_velocity']", (n, 3))
    every = dynamics.get("checkpoint_every")
    every = None if every is None else positive_int(every, "dynamics['checkpoint_every']", MAX_TIME_STEPS)
    return ScheduleOptions(dt, steps, times, frame, rayleigh, x0, v0, every)


def _keyframe_times(value: Any, end: float) -> NDArray[np.float64]:
    name = "dynamics['keyframe_times']"
    try:
        times = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}: expected increasing times in s, got {describe(value)}", name) from None
    if times.ndim != 1 or times.size == 0 or not np.all(np.isfinite(times)):
        raise ParameterError(f"{name}: expected a non-empty list of finite times in s, got {describe(value)}", name)
    order = np.flatnonzero(np.diff(times) <= 0)
    if order.size:
        i = int(order[0])
        raise ParameterError(f"{name}: expected strictly increasing times, got {times[i + 1]:g} s after "
                             f"{times[i]:g} s (keyframes {i} and {i + 1})", name)
    if times[0] < 0 or times[-1] > end * (1 + 1e-12):
        bad = times[0] if times[0] < 0 else times[-1]
        raise ParameterError(f"{name}: expected times within the run, 0 to dt * steps = {end:g} s, got {bad:g} s",
                             name)
    return times


class ScheduleProblem:
    """``J(v)`` of the module docstring and its gradient, over the keyframe values ``v``
    ``(k, c)`` of the cables ``ids`` (columns in that order).

    Examples
    --------
    >>> problem = ScheduleProblem(body, target.bind(body.mesh), [0], options, gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> value, gradient = problem.evaluate(np.full((4, 1), 0.8))  # m^2, m^2 per unit of command  # doctest: +SKIP
    """

    def __init__(self, body: Body, target: BoundTarget, ids: Sequence[int], options: ScheduleOptions,
                 gravity: ArrayLike = (0.0, 0.0, 0.0), tolerance: float = 1e-10, max_iterations: int = 50) -> None:
        self.body, self.target, self.ids, self.options = body, target, list(ids), options
        self.gravity = np.asarray(gravity, dtype=np.float64)
        self.tolerance, self.max_iterations = tolerance, max_iterations
        #: A fixed keyframe at t = 0 with the current command when the first one is later.
        self.lead = options.keyframe_times[0] > 0
        self.simulations = 0
        o = options
        self.hold = np.arange(o.reach_frame, o.steps + 1)
        self._last: tuple[bytes, float, NDArray[np.float64], NDArray[np.float64]] | None = None

    def schedule(self, values: NDArray[np.float64]) -> dict[int, Keyframes]:
        """Each controlled cable's :class:`Keyframes` through ``values`` ``(k, c)``."""
        times = self.options.keyframe_times
        commands = self.body.actuations
        out = {}
        for j, c in enumerate(self.ids):
            column = values[:, j]
            if self.lead:
                out[c] = Keyframes(np.column_stack([np.r_[0.0, times], np.r_[commands[c], column]]))
            else:
                out[c] = Keyframes(np.column_stack([times, column]))
        return out

    def objective(self, positions: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        """``J`` and ``dJ/dx`` ``(steps + 1, n_nodes, 3)`` of a trajectory's positions."""
        weight = 1.0 / self.hold.size
        value, derivative = 0.0, np.zeros_like(positions)
        for i in self.hold:
            v, d = self.target.misfit(positions[i])
            value += weight * v
            derivative[i] = weight * d
        return value, derivative

    def distances(self, positions: NDArray[np.float64]) -> NDArray[np.float64]:
        """RMS distance (m) of the target's points from their goals at each hold frame."""
        return np.array([self.target.rms(positions[i]) for i in self.hold])

    def evaluate(self, values: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        """``(J, dJ/dv (k, c))``: one simulation and its adjoint (cached for the last ``values``)."""
        values = np.asarray(values, dtype=np.float64)
        key = values.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1], self._last[2]
        o = self.options
        self.simulations += 1
        out = trajectory_gradient(
            self.body, self.objective, [f"keyframes:{c}" for c in self.ids], dt=o.dt, steps=o.steps,
            actuation=self.schedule(values), gravity=self.gravity, damping=o.damping, initial=o.initial,
            initial_velocity=o.initial_velocity, tolerance=self.tolerance, max_iterations=self.max_iterations,
            checkpoint_every=o.checkpoint_every,
        )
        skip = 1 if self.lead else 0
        gradient = np.column_stack([out.gradient[f"keyframes:{c}"][skip:] for c in self.ids])
        self._last = (key, out.value, gradient, out.positions)
        return out.value, gradient

    @property
    def last_positions(self) -> NDArray[np.float64] | None:
        return None if self._last is None else self._last[3]


@dataclass
class ScheduleResult:
    """Outcome of :func:`sorofem.control` with ``dynamics=``: an open-loop cable schedule.

    Attributes
    ----------
    schedule
        Controlled cable index -> its :class:`~sorofem.dynamics.Keyframes` (with the fixed
        keyframe at t = 0 when the first optimised one is later): pass it as
        ``sf.simulate(..., actuation=schedule)``.
    keyframe_times
        ``(k,)`` times of the optimised keyframes, s.
    actuation
        ``(k, c)`` keyframe values, one column per controlled cable (in the order of
        ``cables``): alpha, pull (m) or tension (N).
    trajectory
        The :class:`~sorofem.Trajectory` the schedule produces (every frame saved).
    objective
        ``J``, m^2: the mean over the frames from T to the end of ``1/2 |r|^2``
        (docs/tutorials/control.md, "A schedule in time").
    distance, max_distance
        At the reach time T: RMS distance of the target's points from their goals and the
        largest one, m.
    swing
        The largest RMS distance over the frames after T, m (0 when T is the last frame): how
        far the target strays while it should be held.
    reachable
        ``max(distance, swing) <= tolerance``: reached at T and held to the end.
    tolerance
        The distance counted as reached, m.
    reach_time
        T, s.
    points
        ``(p, 3)`` where the target's points are at T, m.
    simulations
        Simulations run (each gradient: one simulation and its adjoint sweep; plus the final
        trajectory).
    iterations
        L-BFGS-B iterations.
    message
        What happened, including "not reachable" and which keyframes sit on a bound.
    time
        Wall-clock time, s.
    active_bounds
        The keyframes on a bound, as text.
    history
        One record per iteration: objective (m^2), distance at T and swing (m), simulations.
    """

    schedule: dict[int, Keyframes]
    keyframe_times: NDArray[np.float64]
    actuation: NDArray[np.float64]
    trajectory: Trajectory
    objective: float
    distance: float
    max_distance: float
    swing: float
    reachable: bool
    tolerance: float
    reach_time: float
    points: NDArray[np.float64]
    simulations: int
    iterations: int
    message: str
    time: float
    active_bounds: list[str] = field(default_factory=list)
    history: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "schedule": {str(c): np.column_stack([k.times, k.values]).tolist() for c, k in self.schedule.items()},
            "keyframe_times": self.keyframe_times.tolist(),
            "actuation": self.actuation.tolist(),
            "objective": self.objective,
            "distance": self.distance,
            "max_distance": self.max_distance,
            "swing": self.swing,
            "reachable": self.reachable,
            "tolerance": self.tolerance,
            "reach_time": self.reach_time,
            "points": self.points.tolist(),
            "simulations": self.simulations,
            "iterations": self.iterations,
            "message": self.message,
            "time": self.time,
            "active_bounds": self.active_bounds,
        }


def control_schedule(
    body: Body,
    target: Any,
    ids: Sequence[int],
    words: Sequence[str],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    x0: ArrayLike | None,
    dynamics: Any,
    *,
    tolerance: float,
    gravity: ArrayLike,
    solve_tolerance: float,
    max_iterations: int,
    max_evaluations: int,
    xtol: float,
    ftol: float,
    verbose: bool,
    progress: bool | None,
) -> ScheduleResult:
    """The dynamic path of :func:`sorofem.control`: ``ids`` the controlled cables, ``words``
    their commands in messages ("alpha", "pull (m)", ...), ``lo``/``hi`` their checked bounds
    ``(c,)``; the other arguments as there."""
    t0 = time.perf_counter()
    options = dynamics_options(dynamics, body)
    bound = bind(target, body)
    if isinstance(bound, BoundContactForce):
        raise InputError("target: a contact force is not a target of a schedule (dynamics= takes point, node "
                         "and surface targets)")
    k, c = options.keyframe_times.size, len(ids)
    v0 = _start(x0, lo, hi, words, k, c)
    width = hi - lo
    scale = np.where(width > 0, width, 1.0)
    problem = ScheduleProblem(body, bound, ids, options, gravity, solve_tolerance, max_iterations)
    bar = Progress(desc="control (schedule)", unit="simulations", enabled=progress)
    history: list[dict[str, Any]] = []

    def values_of(u: NDArray[np.float64]) -> NDArray[np.float64]:
        return lo + np.asarray(u, dtype=np.float64).reshape(k, c) * scale

    def record(u: NDArray[np.float64]) -> None:
        value, _ = problem.evaluate(values_of(u))
        d = problem.distances(problem.last_positions)
        entry = {"iteration": len(history), "objective": value, "distance": float(d[0]),
                 "swing": float(d[1:].max(initial=0.0)), "simulations": problem.simulations,
                 "time": time.perf_counter() - t0}
        history.append(entry)
        shown = f"it {entry['iteration']}, J {value:.4e} m^2, at T {d[0]:.3g} m, swing {entry['swing']:.3g} m"
        bar.set(problem.simulations, postfix=shown)
        if verbose:
            bar.print(f"[schedule it {entry['iteration']:3d}] {shown}, {problem.simulations} simulations, "
                      f"t {entry['time']:.2f} s")

    from scipy.optimize import minimize

    try:
        u0 = np.clip((v0 - lo) / scale, 0.0, np.where(width > 0, 1.0, 0.0)).ravel()
        j0 = max(problem.evaluate(values_of(u0))[0], 1e-300)
        record(u0)

        def fun(u: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
            try:
                value, gradient = problem.evaluate(values_of(u))
            except SolverError:
                return 1e10, np.zeros_like(u)
            return value / j0, (gradient * scale).ravel() / j0

        upper = np.tile(np.where(width > 0, 1.0, 0.0), k)
        res = minimize(fun, u0, jac=True, method="L-BFGS-B", bounds=list(zip(np.zeros(k * c), upper)),
                       callback=lambda u, *_: record(u),
                       options={"maxfun": max_evaluations, "maxiter": max_evaluations, "ftol": ftol,
                                "gtol": xtol * 1e-3})
        u = np.asarray(res.x, dtype=np.float64)
        values = values_of(u)
        objective, _ = problem.evaluate(values)
        schedule = problem.schedule(values)
        o = options
        trajectory = simulate(body, o.dt, o.steps, actuation=schedule, gravity=gravity, damping=o.damping,
                              initial=o.initial, initial_velocity=o.initial_velocity, tolerance=solve_tolerance,
                              max_iterations=max_iterations, method="modified", progress=False)
    finally:
        bar.close()
    distances = problem.distances(trajectory.positions)
    at_t = trajectory.positions[o.reach_frame]
    distance, swing = float(distances[0]), float(distances[1:].max(initial=0.0))
    reachable = max(distance, swing) <= tolerance
    active = [
        f"cable {ids[j]}: {words[j]} at t = {o.keyframe_times[i]:g} s at its "
        f"{'lower' if u.reshape(k, c)[i, j] <= 1e-9 else 'upper'} bound {values[i, j]:.4g}"
        for i in range(k) for j in range(c)
        if width[j] > 0 and (u.reshape(k, c)[i, j] <= 1e-9 or u.reshape(k, c)[i, j] >= 1 - 1e-9)
    ]
    if reachable:
        message = (f"reached at T = {o.reach_time:g} s and held: RMS distance {distance:.3g} m at T, swing "
                   f"{swing:.3g} m after it, <= tolerance {tolerance:g} m")
    else:
        message = (f"not reachable: the closest schedule found is {distance:.3g} m (RMS distance) from the target "
                   f"at T = {o.reach_time:g} s and strays {swing:.3g} m after it, above the tolerance "
                   f"{tolerance:g} m" + (f"; {plural(len(active), 'keyframe')} on a bound: {'; '.join(active)}" if active else ""))
    return ScheduleResult(
        schedule=schedule,
        keyframe_times=o.keyframe_times.copy(),
        actuation=values,
        trajectory=trajectory,
        objective=float(objective),
        distance=distance,
        max_distance=bound.max_distance(at_t),
        swing=swing,
        reachable=bool(reachable),
        tolerance=float(tolerance),
        reach_time=o.reach_time,
        points=bound.points(at_t),
        simulations=problem.simulations + 1,
        iterations=int(res.get("nit", 0)),
        message=message + f" ({res.message})",
        time=time.perf_counter() - t0,
        active_bounds=active,
        history=history,
    )


def _start(x0: ArrayLike | None, lo: NDArray[np.float64], hi: NDArray[np.float64], words: Sequence[str],
           k: int, c: int) -> NDArray[np.float64]:
    """The first keyframe values ``(k, c)``: ``x0`` given per cable ``(c,)`` (every keyframe) or
    per keyframe ``(k, c)``; by default the middle of the bounds (geometric for alphas)."""
    if x0 is None:
        middle = np.where(np.array(words) == "alpha", np.sqrt(np.abs(lo * hi)), 0.5 * (lo + hi))
        return np.tile(middle, (k, 1))
    try:
        arr = np.asarray(x0, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape == (c,):
        arr = np.tile(arr, (k, 1))
    if arr.shape != (k, c) or not np.all(np.isfinite(arr)):
        raise InputError(f"x0: expected {c} finite commands (one per cable) or ({k}, {c}) keyframe values "
                         f"(keyframes, cables), got {describe(x0)}")
    return arr

"""Dynamics: implicit Euler time stepping with lumped mass, Rayleigh damping and cable schedules.

Each time step of length ``dt`` minimises the incremental potential

    1/2 |u - u_n - dt v_n|_M^2 / dt^2 + 1/2 |u - u_n|_D^2 / dt + Pi(u)

over the displacements ``u`` (``M``: lumped mass, ``rho V / 4`` per tet and node;
``D = alpha_M M + beta_K K``: Rayleigh damping; ``Pi``: elastic, cable and load potential),
then sets ``v = (u - u_n) / dt``. The stiffness-proportional part damps the rate of the internal
force, ``beta_K (F(u) - F(u_n)) / dt``, which is ``beta_K K v`` for small steps. Implicit Euler is unconditionally stable and dissipates
energy (it is first-order accurate), which is what a quasi-static soft robot needs; use a small
``dt`` to follow oscillations accurately. A step whose Newton solve fails is split in halves
(counted in :attr:`Trajectory.cutbacks`).

Cable actuation varies over time through a **schedule** (see :func:`simulate`); the alpha of
step ``s`` is its value at the end of the step, ``t = (s + 1) dt``.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
>>> traj = sf.simulate(body, dt=0.01, steps=50, gravity=(0, 0, -9.81), damping=(5.0, 0.0))  # doctest: +SKIP
>>> traj.positions.shape                                                                    # doctest: +SKIP
(51, 81, 3)
"""

from __future__ import annotations

import numbers
import os
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._chunks import Joined, shift_step_in_message
from ._deprecated import moved
from ._text import plural
from ._validate import (
    MAX_MAGNITUDE,
    MAX_NEWTON_ITERATIONS,
    MAX_TIME_STEPS,
    as_finite,
    describe,
    non_negative,
    positive_int,
    positive_scalar,
)
from ._pvd import PvdWriter
from .body import Body, set_cable_values
from .cables import attached_rest_lengths, cable_index, segment_tensions
from .errors import ConvergenceError, InputError, Interrupted, ParameterError, ShapeError
from .progress import Progress
from .solver import SolveReport
from .static import StaticResult, check_finite_solution, check_magnitudes

__all__ = ["Keyframes", "Trajectory", "PvdWriter", "simulate", "evaluate_schedule"]


class Keyframes:
    """A piecewise-linear function of time through ``[time, value]`` keyframes, held
    constant before the first and after the last: an actuation schedule for one cable.

    Parameters
    ----------
    points
        ``[[t0, a0], [t1, a1], ...]`` with non-decreasing times (s); at least one keyframe.

    Examples
    --------
    >>> import sorofem as sf
    >>> pull = sf.dynamics.Keyframes([[0.0, 1.0], [0.5, 0.6]])
    >>> pull(0.25), pull(2.0)
    (0.8, 0.6)
    """

    def __init__(self, points: ArrayLike) -> None:
        try:
            arr = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            raise ShapeError(f"keyframes: expected [[time, value], ...], got {describe(points)}") from None
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 1:
            raise ShapeError(f"keyframes: expected shape (k, 2) with k >= 1, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ParameterError("keyframes: expected finite times and values", "keyframes")
        if np.any(np.diff(arr[:, 0]) < 0):
            raise ParameterError(f"keyframes: times must not decrease, got {arr[:, 0].tolist()}", "keyframes")
        self.times = arr[:, 0].copy()
        self.values = arr[:, 1].copy()

    def __call__(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values))

    def __repr__(self) -> str:
        return f"Keyframes({np.column_stack([self.times, self.values]).tolist()})"


def _call_schedule(schedule: Callable[[float], Any], t: float, name: str) -> Any:
    """``schedule(t)``; an exception inside the user's function becomes a :class:`ParameterError`
    naming the schedule and the time."""
    try:
        return schedule(t)
    except Exception as exc:  # noqa: BLE001 - the user's code may raise anything
        raise ParameterError(f"{name}: the schedule raised {type(exc).__name__} at t = {t:g} s: {exc}", name) from None


def _alpha_column(entry: Any, times: NDArray[np.float64], current: float, name: str) -> NDArray[np.float64]:
    """One cable's alphas at ``times``: a constant, ``None`` (hold ``current``), a callable of
    time, or a sequence of one alpha per step."""
    if entry is None:
        return np.full(times.size, current)
    if isinstance(entry, numbers.Real) and not isinstance(entry, bool):
        return np.full(times.size, float(entry))
    if callable(entry):
        values = []
        for t in times:
            value = _call_schedule(entry, float(t), name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ParameterError(f"{name}: the schedule returned {describe(value)} at t = {t:g} s; expected a number", name)
            values.append(float(value))
        return np.array(values)
    try:
        arr = np.asarray(entry, dtype=np.float64)
    except (TypeError, ValueError):
        raise ShapeError(f"{name}: expected a number, a callable of time or {times.size} alphas, got {describe(entry)}") from None
    if arr.shape != times.shape:
        raise ShapeError(f"{name}: expected a number, a callable of time or {times.size} alphas (one per step), got shape {arr.shape}")
    return arr


def evaluate_schedule(
    body: Body, schedule: Any, dt: float, steps: int
) -> NDArray[np.float64]:
    """Evaluate an actuation schedule into the ``(steps, n_cables)`` array of alphas.

    ``schedule`` is one of

    * ``None``: every cable keeps its current actuation (``body.actuations``);
    * a number: every cable at this constant alpha from the first step on (a sudden change);
    * a callable ``t -> alpha`` (a body with one cable) or ``t -> [alpha per cable]``;
    * a sequence with one entry per cable, each a number, ``None`` (hold), a callable of time
      or ``steps`` alphas;
    * a dict ``{cable or index: entry}``; cables not named hold their actuation;
    * an array ``(steps, n_cables)``.

    Step ``s`` is evaluated at ``t = (s + 1) dt``. Every alpha must be finite and > 0. A
    tendon's entries are its command (:attr:`sorofem.Body.commands`): its pull (m, shorter than
    its rest length) or its tension (N, >= 0).

    Examples
    --------
    >>> alphas = sf.dynamics.evaluate_schedule(body, lambda t: 1 - 0.4 * min(t, 1), 0.1, 20)  # doctest: +SKIP
    """
    dt = positive_scalar(dt, "dt")
    steps = positive_int(steps, "steps", MAX_TIME_STEPS)
    n_cables = len(body.cables)
    current = body.actuations
    times = dt * np.arange(1, steps + 1)
    if isinstance(schedule, np.ndarray) and schedule.ndim == 1:
        schedule = list(schedule)
    if schedule is None:
        out = np.tile(np.asarray(current, dtype=np.float64), (steps, 1)).reshape(steps, n_cables)
    elif isinstance(schedule, numbers.Real) and not isinstance(schedule, bool):
        out = np.full((steps, n_cables), float(schedule))
    elif isinstance(schedule, np.ndarray) and schedule.ndim == 2:
        if schedule.shape != (steps, n_cables):
            raise ShapeError(f"actuation: expected shape ({steps}, {n_cables}) (steps, cables), got shape {schedule.shape}")
        out = np.asarray(schedule, dtype=np.float64).copy()
    elif isinstance(schedule, Mapping):
        out = np.tile(np.asarray(current, dtype=np.float64), (steps, 1)).reshape(steps, n_cables)
        for key, entry in schedule.items():
            c = cable_index(body, key)
            out[:, c] = _alpha_column(entry, times, current[c], f"actuation[{c}]")
    elif callable(schedule):
        values = [_call_schedule(schedule, float(t), "actuation") for t in times]
        if n_cables == 0:
            raise InputError("actuation: the body has no cables to actuate")
        if all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in values):
            if n_cables != 1:
                raise InputError(
                    f"actuation: a schedule returning one alpha needs a body with one cable, this one has "
                    f"{n_cables}; return one alpha per cable or pass {{cable: schedule}}"
                )
            out = np.array(values, dtype=np.float64).reshape(steps, 1)
        else:
            try:
                out = np.array(values, dtype=np.float64)
            except (TypeError, ValueError):
                raise ParameterError(f"actuation: the schedule returned {describe(values[0])}; expected numbers", "actuation") from None
            if out.shape != (steps, n_cables):
                raise ShapeError(f"actuation: the schedule must return {n_cables} alphas (one per cable), got shape {out.shape[1:]}")
    elif isinstance(schedule, Sequence) and not isinstance(schedule, str):
        if len(schedule) != n_cables:
            raise ShapeError(f"actuation: expected one entry per cable ({n_cables}), got {len(schedule)}")
        out = np.empty((steps, n_cables))
        for c, entry in enumerate(schedule):
            out[:, c] = _alpha_column(entry, times, current[c], f"actuation[{c}]")
    else:
        raise InputError(f"actuation: expected None, a callable, a sequence or a dict, got {describe(schedule)}")
    for c, (kind, _) in enumerate(body.commands):
        column = out[:, c]
        if kind == "actuation":
            bad, expected = ~(np.isfinite(column) & (column > 0)), "alphas must be finite and > 0"
        elif kind == "pull":
            length = body.cables[c].length
            bad = ~(np.isfinite(column) & (column < length))
            expected = f"pulls must be finite and shorter than the tendon's rest length {length:.6g} m"
        else:
            bad, expected = ~(np.isfinite(column) & (column >= 0)), "tensions must be finite and >= 0 N"
        if np.any(bad):
            s = int(np.argwhere(bad)[0, 0])
            raise ParameterError(
                f"actuation: {expected}, got {out[s, c]} for cable {c} at step {s} (t = {times[s]:g} s)",
                "actuation",
            )
    return np.ascontiguousarray(out)


class Trajectory:
    """The result of :func:`simulate`: saved frames of a time integration.

    Attributes
    ----------
    body
        The simulated body.
    dt
        Time step, s.
    times
        Time of each saved frame, ``(frames,)``, s; frame 0 is the initial state.
    positions
        Node positions of each frame, ``(frames, n_nodes, 3)``, m.
    velocities
        Final node velocities, ``(n_nodes, 3)``, m/s.
    kinetic_energy
        ``1/2 v^T M v`` of each frame, ``(frames,)``, J.
    iterations
        Newton iterations of each time step, ``(steps,)`` (sub-steps of a cut-back step added).
    factorizations
        Numeric factorisations of each time step's Hessian, ``(steps,)`` (the same way).
    single_precision_factorizations
        How many of them, over the run, were computed in single precision: the kept
        factorisations of ``"modified"`` and ``"linearly_implicit"`` steps, unless single
        precision was not accurate enough for the body (then every factorisation from that
        one on is in double precision) or displacement-controlled tendons or the mixed
        formulation ask for double precision.
    residuals
        The relative residual each time step ended with, ``(steps,)``: below ``tolerance``
        unless ``method="linearly_implicit"``.
    cutbacks
        How many time steps were split because Newton failed.
    cable_points
        Per frame, one ``(k, 3)`` array per cable, m.
    cable_tension, cable_pull
        Per frame, per cable: a tendon's tension (N) and pulled length ``L0 - L`` (m);
        ``None`` for a spring chain.
    actuation
        The commands used, ``(steps, n_cables)``: alphas (pulls or tensions for tendons).
    timings
        ``{"simulate": s}``, the wall-clock time of the integration, and the core's time per
        phase over all steps, s: ``assembly``, ``factorization``, ``solve`` (triangular
        solves), ``line_search``, ``contact``, ``step_bound``, ``total``.
    contact_forces
        With obstacles: the force they exert on each node at each frame, ``(frames, n_nodes,
        3)``, N (``None`` without obstacles).
    obstacle_forces
        Total force of each obstacle on the body, ``(frames, n_obstacles, 3)``, N.
    obstacle_translations
        Where each obstacle is (its path's translation), ``(frames, n_obstacles, 3)``, m.
    min_distances
        Smallest distance to each obstacle, ``(frames, n_obstacles)``, m (NaN: nothing near).
    active_contacts
        Contact stencils closer than ``dhat`` per obstacle, ``(frames, n_obstacles)``.
    iterate_min_distances
        Minimum distance to the obstacles at every accepted Newton iterate of every step
        (``inf``: nothing within ``dhat``): all > 0.
    """

    def __init__(self, body: Body, dt: float, out: Mapping[str, Any], actuation: NDArray[np.float64], elapsed: float) -> None:
        self.body = body
        self.mesh = body.mesh
        self.dt = dt
        self.times = np.asarray(out["times"], dtype=np.float64)
        self.positions = np.asarray(out["positions"], dtype=np.float64).reshape(self.times.size, -1, 3)
        self.velocities = np.asarray(out["velocities"], dtype=np.float64)
        self.kinetic_energy = np.asarray(out["kinetic_energy"], dtype=np.float64)
        self.iterations = np.asarray(out["iterations"], dtype=np.int64)
        self.factorizations = np.asarray(out["factorizations"], dtype=np.int64)
        self.residuals = np.asarray(out["residuals"], dtype=np.float64)
        self.cutbacks = int(out.get("cutbacks", 0))
        self.single_precision_factorizations = int(out.get("single_precision_factorizations", 0))
        self.cable_points = [[np.asarray(p, dtype=np.float64) for p in frame] for frame in out.get("cable_points", [])]
        self.cable_tension: list[list[float | None]] = [list(frame) for frame in out.get("tendon_tensions", [])]
        self.cable_pull: list[list[float | None]] = [list(frame) for frame in out.get("tendon_pulls", [])]
        self.actuation = actuation
        #: The cables' alphas before the first step, ``(n_cables,)``.
        self.initial_actuation = np.asarray(body.actuations, dtype=np.float64)
        self.timings = {"simulate": elapsed, **{k: float(v) for k, v in out.get("timings", {}).items()}}
        contact = out.get("contact")
        k = len(body.obstacles)
        frames = self.times.size

        def field(key: str, shape: tuple[int, ...], dtype: Any = np.float64) -> NDArray[Any] | None:
            return None if contact is None else np.asarray(contact[key], dtype=dtype).reshape(frames, *shape)

        self.contact_forces = field("forces", (-1, 3))
        self.obstacle_forces = field("obstacle_forces", (k, 3))
        self.obstacle_translations = field("translations", (k, 3))
        self.min_distances = field("min_distance", (k,))
        self.active_contacts = field("active", (k,), np.int64)
        self.iterate_min_distances = np.asarray([] if contact is None else contact["iterate_min_distances"],
                                                dtype=np.float64)

    @property
    def n_frames(self) -> int:
        return int(self.times.size)

    @property
    def displacement(self) -> NDArray[np.float64]:
        """``positions - mesh.points``, ``(frames, n_nodes, 3)``, m."""
        return self.positions - self.mesh.points

    @property
    def final_positions(self) -> NDArray[np.float64]:
        """Positions of the last frame, ``(n_nodes, 3)``, m."""
        return self.positions[-1]

    def cable_tensions(self, frame: int = -1) -> list[NDArray[np.float64]]:
        """Tension of every segment at a saved frame, one ``(k - 1,)`` array per cable (N),
        from the frame's cable points and the alphas of the step that produced it (a
        tendon's segments all carry its tension, :attr:`cable_tension`)."""
        frame = range(self.n_frames)[frame]
        step = int(round(self.times[frame] / self.dt)) - 1
        alphas = self.actuation[step] if step >= 0 else self.initial_actuation
        return [
            np.full(cable.n_segments, float(self.cable_tension[frame][c] or 0.0)) if cable.is_tendon
            else segment_tensions(cable, self.cable_points[frame][c], float(alphas[c]),
                                  attached_rest_lengths(self.body, c))
            for c, cable in enumerate(self.body.cables)
        ]

    def write_pvd(self, directory: str | os.PathLike[str], name: str = "trajectory", *, run_id: int | None = None) -> Path:
        """Write ``directory/name.pvd`` and one ``directory/name/frame_NNNNN.vtu`` per frame
        (ParaView reads the ``.pvd`` as a time series).

        Each ``.vtu`` holds the deformed tetrahedra (point data ``displacement``, cell data
        ``J``) and, when the body has cables, the cables as line cells after the tets (their
        points appended after the nodes; a segment's ``J`` is its stretch, deformed over rest
        length). Every file is written to a temporary name and
        renamed (:func:`sorofem.io.atomic_path`), the ``.pvd`` last, so it only ever lists
        complete frames. ``run_id`` marks every file (see :class:`PvdWriter`). Returns the
        ``.pvd`` path.
        """
        writer = PvdWriter(self.body, directory, name, run_id=run_id)
        writer.add(self.times, self.positions, self.cable_points, self.contact_forces)
        return writer.close()

    def to_dict(self) -> dict[str, Any]:
        """Summary for ``summary.json`` (plain JSON types)."""
        return {
            "dt": self.dt,
            "steps": int(self.iterations.size),
            "frames": self.n_frames,
            "final_time": float(self.times[-1]),
            "newton_iterations": int(self.iterations.sum()),
            "max_iterations_per_step": int(self.iterations.max(initial=0)),
            "mean_iterations_per_step": float(self.iterations.mean()) if self.iterations.size else 0.0,
            "cutbacks": self.cutbacks,
            "factorizations": int(self.factorizations.sum()),
            "single_precision_factorizations": self.single_precision_factorizations,
            "final_kinetic_energy": float(self.kinetic_energy[-1]),
            "max_kinetic_energy": float(self.kinetic_energy.max()),
            "max_displacement": float(np.linalg.norm(self.displacement[-1], axis=1).max(initial=0.0)),
            "final_actuation": self.actuation[-1].tolist() if self.actuation.size else [],
            **self._contact_dict(),
            "timings": dict(self.timings),
        }

    def _contact_dict(self) -> dict[str, Any]:
        """``{"contact": ...}`` (per obstacle: the final and the largest force, the smallest
        distance over the frames) when the body has obstacles."""
        if self.obstacle_forces is None or self.min_distances is None or self.active_contacts is None:
            return {}
        magnitude = np.linalg.norm(self.obstacle_forces, axis=2)
        obstacles = []
        for k, placement in enumerate(self.body.obstacles):
            distances = self.min_distances[:, k]
            near = distances[np.isfinite(distances)]
            obstacles.append({
                **placement.to_dict(),
                "final_force": self.obstacle_forces[-1, k].tolist(),
                "max_force": float(magnitude[:, k].max(initial=0.0)),
                "min_distance": float(near.min()) if near.size else None,
                "max_active_contacts": int(self.active_contacts[:, k].max(initial=0)),
            })
        finite = self.iterate_min_distances[np.isfinite(self.iterate_min_distances)]
        return {"contact": {
            "obstacles": obstacles,
            "min_iterate_distance": float(finite.min()) if finite.size else None,
        }}

    def __repr__(self) -> str:
        return (
            f"Trajectory(frames={self.n_frames}, t_end={self.times[-1]:.4g} s, "
            f"iterations={int(self.iterations.sum())}, cutbacks={self.cutbacks})"
        )


#: The step methods of :func:`simulate`, accurate (converged steps) ones first.
STEP_METHODS = ("modified", "newton", "linearly_implicit")
#: Newton's relative residual tolerance of every step of :func:`simulate` when none is given
#: (the trajectory gradient's too, so that it differentiates the same run).
DEFAULT_STEP_TOLERANCE = 1e-8


def simulate(
    body: Body,
    dt: float,
    steps: int,
    actuation: Any = None,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    *,
    damping: tuple[float, float] = (0.0, 0.0),
    initial: "ArrayLike | StaticResult | Trajectory | None" = None,
    initial_velocity: ArrayLike | None = None,
    save_every: int = 1,
    tolerance: float = DEFAULT_STEP_TOLERANCE,
    max_iterations: int = 50,
    progress: bool | None = None,
    on_frames: Callable[[NDArray[np.float64], NDArray[np.float64], list[Any]], None] | None = None,
    method: str = "modified",
) -> Trajectory:
    """Integrate the body's motion in time with implicit Euler (see the module docstring).

    Parameters
    ----------
    body
        The body: density > 0 everywhere (the mass matrix must be positive), its supports,
        nodal forces and cables.
    dt
        Time step, s, > 0.
    steps
        Number of time steps, >= 1.
    actuation
        Cable schedule, see :func:`evaluate_schedule`; default: hold ``body.actuations``.
    gravity
        ``(3,)``, m/s^2.
    damping
        Rayleigh coefficients ``(alpha_M, beta_K)``: mass-proportional (1/s) and
        stiffness-proportional (s), both >= 0.
    initial
        Initial positions ``(n_nodes, 3)``, a :class:`StaticResult`, or a :class:`Trajectory`
        to continue (its last frame and final velocities); default: the rest shape.
    initial_velocity
        ``(n_nodes, 3)`` m/s; default: at rest (or the velocities of an ``initial`` trajectory).
    save_every
        Save every this many steps (the initial and the last state are always saved).
    tolerance, max_iterations
        Newton's relative residual tolerance and iteration limit per step. The fast mode is
        ``method="modified"`` with a loose ``tolerance`` such as ``1e-2`` (each step converged
        to 1 % of its load): on the hammerbot's swing its tip stays within 0.2 % of a
        tight-tolerance run at about half the default's time (BENCHMARKS.md, "Dynamics").
    method
        How each step's minimisation is solved (see :data:`STEP_METHODS`): ``"modified"``
        (default) keeps the Hessian's factorisation across iterations and steps, rotated with
        the body, and refactorises where the residual falls by less than a quarter in an
        iteration; ``"newton"`` refactorises at every iteration. Both converge every step to
        ``tolerance``, so their trajectories agree to it. ``"linearly_implicit"`` takes one
        iteration per step (SOFA's linearised implicit Euler): less accurate and more
        dissipative, with an error no tolerance controls (19 % of the hammerbot's tip motion,
        6 % of a cantilever's; BENCHMARKS.md); each step's remaining residual is in
        :attr:`Trajectory.residuals`.
    progress
        A progress line on stderr (steps done, simulated time, Newton iterations per step,
        cutbacks, elapsed time, ETA): ``None`` (default) only when stderr is a terminal and the
        run lasts more than half a second, ``True`` always, ``False`` never; see
        :mod:`sorofem.progress`. With the line shown the steps run in chunks of about 0.2 s
        (same states; a body with free cable nodes runs in one piece, only the clock moves).
    on_frames
        Called with the frames saved since the last call, ``(times (k,), positions (k, n_nodes,
        3), cable_points)`` (per frame, one ``(p, 3)`` array per cable), as the integration
        goes: e.g. :meth:`PvdWriter.add`, so that the frames are on disk while it runs. With it
        the steps run in chunks of about 0.2 s, as with the progress line.

    Returns
    -------
    Trajectory
        The body's own actuation (``body.actuations``) is left unchanged.

    Raises
    ------
    ParameterError
        An argument out of range (``steps`` and ``save_every`` at most 1,000,000,
        ``max_iterations`` at most 10,000, ``dt * steps`` at most 1e150 s: documented limits),
        or loads and stiffnesses too large (:func:`sorofem.static.check_magnitudes`).
    ConvergenceError
        A step failed even after splitting it six times.
    SolverError
        The integration produced non-finite values.
    Interrupted
        Ctrl-C: the step running stops before its next Newton iteration; ``err.result`` is the
        :class:`Trajectory` of the chunks of steps done when the steps run in chunks (with a
        progress line or ``on_frames``), else None (also before the first chunk ended).

    Examples
    --------
    Pull a cable over half a second and hold it:

    >>> pull = sf.dynamics.Keyframes([[0.0, 1.0], [0.5, 0.7]])           # doctest: +SKIP
    >>> traj = sf.simulate(body, 0.01, 100, actuation={cable: pull},     # doctest: +SKIP
    ...                    gravity=(0, 0, -9.81), damping=(2.0, 0.01))
    >>> traj.write_pvd("results/pull")                                   # doctest: +SKIP
    """
    if not isinstance(body, Body):
        raise InputError(f"body: expected a sorofem.Body, got {describe(body)}")
    dt = positive_scalar(dt, "dt")
    steps = positive_int(steps, "steps", MAX_TIME_STEPS)
    if not dt * steps <= MAX_MAGNITUDE:
        raise ParameterError(f"dt: the simulated time dt * steps is {dt * steps:g} s, above the documented limit "
                             f"{MAX_MAGNITUDE:g} s", "dt")
    save_every = positive_int(save_every, "save_every", MAX_TIME_STEPS)
    tol = positive_scalar(tolerance, "tolerance")
    iters = positive_int(max_iterations, "max_iterations", MAX_NEWTON_ITERATIONS)
    if method not in STEP_METHODS:
        raise ParameterError(f"method: expected one of {', '.join(map(repr, STEP_METHODS))}, got {method!r}", "method")
    g = as_finite(gravity, "gravity", (3,))
    if on_frames is not None and not callable(on_frames):
        raise InputError(f"on_frames: expected a callable or None, got {describe(on_frames)}")
    if not isinstance(damping, (tuple, list)) or len(damping) != 2:
        raise ParameterError(f"damping: expected (alpha_M, beta_K), got {describe(damping)}", "damping")
    mass_damping = non_negative(damping[0], "damping[0] (alpha_M)")
    stiffness_damping = non_negative(damping[1], "damping[1] (beta_K)")
    _, _, rho = body.material.per_element(body.mesh.n_tets)
    if not np.all(rho > 0):
        raise ParameterError(
            f"density: dynamics needs a mass, density > 0 in every tet; got {float(rho.min())} kg/m^3",
            "density",
        )
    n = body.mesh.n_nodes
    v0 = None
    if isinstance(initial, Trajectory):
        x0: Any = initial.final_positions
        v0 = initial.velocities
    elif isinstance(initial, StaticResult):
        x0 = initial.positions
    else:
        x0 = initial
    x0 = None if x0 is None else as_finite(x0, "initial", (n, 3))
    if initial_velocity is not None:
        v0 = as_finite(initial_velocity, "initial_velocity", (n, 3))
    alphas = evaluate_schedule(body, actuation, dt, steps)
    check_magnitudes(body, g)

    model = body.core_model()
    forces, prescribed = body.forces, body.prescribed_displacement
    start = time.perf_counter()

    def run(n: int, a: NDArray[np.float64], x: Any, v: Any, every: int) -> dict[str, Any]:
        return model.simulate(
            g, forces.copy(), prescribed.copy(), dt, n, a,
            mass_damping, stiffness_damping, x, v, tol, iters, every, method=method,
        )

    bar = Progress(total=steps, desc="simulate", unit="steps", enabled=progress)
    joined = Joined()
    try:
        if (not (bar.active or on_frames is not None) or _has_free_cable_nodes(body)
                or any(o.path is not None for o in body.obstacles)):
            # Free cable nodes' velocities do not survive a restart, and obstacle paths run on
            # the time of one call: one piece, a moving clock.
            out = run(steps, alphas, x0, v0, save_every)
            check_finite_solution(out, None, "the time integration")
            bar.set(steps, postfix=_step_postfix(out, steps, dt))
            if on_frames is not None:
                on_frames(out["times"], np.asarray(out["positions"]).reshape(-1, n, 3), list(out.get("cable_points", [])))
        else:
            out = _run_in_chunks(run, steps, save_every, alphas, x0, v0, dt, bar, joined, on_frames)
    except ConvergenceError as err:
        if isinstance(err.report, dict):
            err.report = SolveReport.from_dict(err.report, body.formulation)
        raise
    except KeyboardInterrupt as stop:
        partial = None
        if joined.done:
            partial = Trajectory(body, dt, joined.output(), alphas[: joined.done], time.perf_counter() - start)
        raise Interrupted(
            f"simulate: interrupted after {joined.done} of {steps} steps", partial, getattr(stop, "signal", "SIGINT")
        ) from None
    finally:
        bar.close()
        # The extension leaves the last step's commands in the model; the body's own stay in charge.
        set_cable_values(model, body.commands, body.cable_stiffnesses, body.cable_dampings)
    return Trajectory(body, dt, out, alphas, time.perf_counter() - start)


def _has_free_cable_nodes(body: Body) -> bool:
    if not any(getattr(c, "outside", "error") == "free" for c in body.cables):
        return False
    try:
        return any(p.kind == "free" for cable in body.cable_placements() for p in cable)
    except InputError:
        return True  # the extension reports the problem when it simulates


def _step_postfix(out: Mapping[str, Any], done: int, dt: float) -> str:
    iterations = np.asarray(out["iterations"])
    per_step = float(iterations.mean()) if iterations.size else 0.0
    return _postfix(done * dt, per_step, int(out.get("cutbacks", 0)))


def _postfix(t: float, per_step: float, cutbacks: int) -> str:
    return f"t={t:.4g} s, {per_step:.1f} it/step, {plural(cutbacks, 'cutback')}"


#: Wall-clock target of one chunk of steps while a progress line is shown, s.
CHUNK_SECONDS = 0.2


def _run_in_chunks(
    run: Callable[..., dict[str, Any]], steps: int, save_every: int, alphas: NDArray[np.float64],
    x0: Any, v0: Any, dt: float, bar: Progress, joined: Joined,
    on_frames: Callable[..., None] | None = None,
) -> dict[str, Any]:
    """Integrate ``steps`` steps as consecutive calls of ``run`` (each continuing from the
    previous one's last positions and velocities), so that ``bar`` moves, ``on_frames`` receives
    the new frames and Ctrl-C is answered in between; ``joined`` collects their outputs into
    what one call would return (and holds what was done when an interruption stops the loop).

    Chunk boundaries never cross a save point (a multiple of ``save_every``) except from
    another one, so every chunk saves exactly the frames the whole run would: with local
    ``save_every`` when the chunk starts on a save point and spans whole intervals, otherwise
    only its end, kept if that is a save point. The first chunk is one step; later ones aim at
    :data:`CHUNK_SECONDS` each."""
    t_offset, size = 0.0, 1
    x, v = x0, v0
    while joined.done < steps:
        done = joined.done
        n = min(size, steps - done)
        if done % save_every == 0 and (n >= save_every or done + n == steps):
            if done + n != steps:
                n -= n % save_every
            every = save_every
        else:
            n = min(n, save_every - done % save_every)
            every = n
        end = done + n
        tick = time.perf_counter()
        try:
            out = run(n, alphas[done:end], x, v, every)
        except ConvergenceError as err:
            shift_step_in_message(err, done, t_offset)
            raise
        check_finite_solution(out, None, "the time integration")
        per_step = (time.perf_counter() - tick) / n
        times = np.asarray(out["times"], dtype=np.float64)
        positions = np.asarray(out["positions"], dtype=np.float64).reshape(times.size, -1, 3)
        keep = slice(0 if done == 0 else 1, None)
        if end % save_every and end != steps:
            keep = slice(keep.start, -1)  # the end of a chunk inside a save interval
        new_times, new_positions = t_offset + times[keep], positions[keep]
        new_cables = list(out.get("cable_points", []))[keep]
        joined.times.append(new_times)
        joined.positions.append(new_positions)
        joined.kinetic_energy.append(np.asarray(out["kinetic_energy"], dtype=np.float64)[keep])
        joined.cable_points.extend(new_cables)
        joined.tendon_tensions.extend(list(out.get("tendon_tensions", []))[keep])
        joined.tendon_pulls.extend(list(out.get("tendon_pulls", []))[keep])
        if out.get("contact") is not None:
            joined.contact.append(out["contact"] | {
                key: np.asarray(out["contact"][key])[keep]
                for key in ("forces", "obstacle_forces", "translations", "min_distance", "active")
            })
        joined.iterations.append(np.asarray(out["iterations"], dtype=np.int64))
        joined.factorizations.append(np.asarray(out["factorizations"], dtype=np.int64))
        joined.residuals.append(np.asarray(out["residuals"], dtype=np.float64))
        joined.cutbacks += int(out.get("cutbacks", 0))
        joined.single_precision_factorizations += int(out.get("single_precision_factorizations", 0))
        for phase, seconds in out.get("timings", {}).items():
            joined.timings[phase] = joined.timings.get(phase, 0.0) + float(seconds)
        joined.velocities = out["velocities"]
        joined.done = end
        x, v = positions[-1], np.asarray(out["velocities"], dtype=np.float64)
        t_offset += float(times[-1])
        if on_frames is not None and new_times.size:
            on_frames(new_times, new_positions, new_cables)
        iterations = np.concatenate(joined.iterations)
        bar.set(end, postfix=_postfix(t_offset, float(iterations.mean()), joined.cutbacks))
        size = max(1, int(CHUNK_SECONDS / max(per_step, 1e-9)))
    return joined.output()


def _has_dynamics() -> bool:
    return True


__getattr__ = moved(__name__, {"has_dynamics": (lambda: _has_dynamics, "nothing: every build has time stepping")})

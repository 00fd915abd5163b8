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
import re
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._deprecated import moved
from ._text import plural
from ._validate import as_finite, describe, non_negative, positive_int, positive_scalar
from .body import Body
from .cables import attached_rest_lengths, cable_index, segment_tensions
from .errors import ConvergenceError, InputError, ParameterError, ShapeError
from .progress import Progress
from .solver import SolveReport
from .static import StaticResult

__all__ = ["Keyframes", "Trajectory", "simulate", "evaluate_schedule"]


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
            value = entry(float(t))
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ParameterError(f"{name}: the schedule returned {describe(value)} at t = {t:g} s; expected a number", name)
            values.append(float(value))
        return np.array(values)
    arr = np.asarray(entry, dtype=np.float64)
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

    Step ``s`` is evaluated at ``t = (s + 1) dt``. Every alpha must be finite and > 0.

    Examples
    --------
    >>> alphas = sf.dynamics.evaluate_schedule(body, lambda t: 1 - 0.4 * min(t, 1), 0.1, 20)  # doctest: +SKIP
    """
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
        values = [schedule(float(t)) for t in times]
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
    bad = ~(np.isfinite(out) & (out > 0))
    if np.any(bad):
        s, c = (int(i) for i in np.argwhere(bad)[0])
        raise ParameterError(
            f"actuation: alphas must be finite and > 0, got {out[s, c]} for cable {c} at step {s} (t = {times[s]:g} s)",
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
    residuals
        The relative residual each time step ended with, ``(steps,)``: below ``tolerance``
        unless ``method="linearly_implicit"``.
    cutbacks
        How many time steps were split because Newton failed.
    cable_points
        Per frame, one ``(k, 3)`` array per cable, m.
    actuation
        The alphas used, ``(steps, n_cables)``.
    timings
        ``{"simulate": s}``: wall-clock time of the integration.
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
        self.cable_points = [[np.asarray(p, dtype=np.float64) for p in frame] for frame in out.get("cable_points", [])]
        self.actuation = actuation
        #: The cables' alphas before the first step, ``(n_cables,)``.
        self.initial_actuation = np.asarray(body.actuations, dtype=np.float64)
        self.timings = {"simulate": elapsed}

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
        from the frame's cable points and the alphas of the step that produced it."""
        frame = range(self.n_frames)[frame]
        step = int(round(self.times[frame] / self.dt)) - 1
        alphas = self.actuation[step] if step >= 0 else self.initial_actuation
        return [
            segment_tensions(cable, self.cable_points[frame][c], float(alphas[c]), attached_rest_lengths(self.body, c))
            for c, cable in enumerate(self.body.cables)
        ]

    def write_pvd(self, directory: str | os.PathLike[str], name: str = "trajectory") -> Path:
        """Write ``directory/name.pvd`` and one ``directory/name/frame_NNNNN.vtu`` per frame
        (ParaView reads the ``.pvd`` as a time series).

        Each ``.vtu`` holds the deformed tetrahedra (point data ``displacement``, cell data
        ``J``) and, when the body has cables, the cables as line cells after the tets (their
        points appended after the nodes). Returns the ``.pvd`` path.
        """
        import meshio

        directory = Path(directory)
        frames_dir = directory / name
        frames_dir.mkdir(parents=True, exist_ok=True)
        model = self.body.core_model()
        tets = self.mesh.tets
        rest_cables = [c.points for c in self.body.cables]
        lines = None
        if rest_cables:
            offsets = np.cumsum([self.mesh.n_nodes] + [len(p) for p in rest_cables])
            lines = np.vstack(
                [np.column_stack([np.arange(a, b - 1), np.arange(a + 1, b)]) for a, b in zip(offsets[:-1], offsets[1:])]
            ).astype(np.int64)
        entries = []
        for f in range(self.n_frames):
            x = self.positions[f]
            j = np.asarray(model.element_fields(x)["J"], dtype=np.float64)
            points, disp = x, x - self.mesh.points
            cells: list[tuple[str, NDArray[np.int64]]] = [("tetra", tets)]
            cell_j = [j]
            if lines is not None and f < len(self.cable_points):
                cable_x = np.vstack(self.cable_points[f])
                points = np.vstack([x, cable_x])
                disp = np.vstack([disp, cable_x - np.vstack(rest_cables)])
                cells.append(("line", lines))
                cell_j.append(np.full(len(lines), np.nan))
            file = frames_dir / f"frame_{f:05d}.vtu"
            meshio.write(file, meshio.Mesh(points, cells, point_data={"displacement": disp}, cell_data={"J": cell_j}))
            entries.append(
                f'    <DataSet timestep="{float(self.times[f])!r}" group="" part="0" '
                f"file={quoteattr(f'{name}/{file.name}')}/>"
            )
        pvd = directory / f"{name}.pvd"
        pvd.write_text(
            '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            + "\n".join(entries)
            + "\n  </Collection>\n</VTKFile>\n",
            encoding="utf-8",
        )
        return pvd

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
            "final_kinetic_energy": float(self.kinetic_energy[-1]),
            "max_kinetic_energy": float(self.kinetic_energy.max()),
            "max_displacement": float(np.linalg.norm(self.displacement[-1], axis=1).max(initial=0.0)),
            "final_actuation": self.actuation[-1].tolist() if self.actuation.size else [],
            "timings": dict(self.timings),
        }

    def __repr__(self) -> str:
        return (
            f"Trajectory(frames={self.n_frames}, t_end={self.times[-1]:.4g} s, "
            f"iterations={int(self.iterations.sum())}, cutbacks={self.cutbacks})"
        )


#: The step methods of :func:`simulate`, accurate (converged steps) ones first.
STEP_METHODS = ("modified", "newton", "linearly_implicit")


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
    tolerance: float = 1e-8,
    max_iterations: int = 50,
    progress: bool | None = None,
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
        Newton's relative residual tolerance and iteration limit per step.
    method
        How each step's minimisation is solved (see :data:`STEP_METHODS`): ``"modified"``
        (default) keeps the Hessian's factorisation across iterations and steps and
        refactorises where the residual falls by less than a quarter in an iteration;
        ``"newton"`` refactorises at every iteration. Both converge every step to
        ``tolerance``, so their trajectories agree to it. ``"linearly_implicit"`` takes one
        iteration per step (SOFA's linearised implicit Euler): fast, less accurate and more
        dissipative; each step's remaining residual is in :attr:`Trajectory.residuals`
        (BENCHMARKS.md gives the accuracy on the hammerbot).
    progress
        A progress line on stderr (steps done, simulated time, Newton iterations per step,
        cutbacks, elapsed time, ETA): ``None`` (default) only when stderr is a terminal and the
        run lasts more than half a second, ``True`` always, ``False`` never; see
        :mod:`sorofem.progress`. With the line shown the steps run in chunks of about 0.2 s
        (same states; a body with free cable nodes runs in one piece, only the clock moves).

    Returns
    -------
    Trajectory
        The body's own actuation (``body.actuations``) is left unchanged.

    Raises
    ------
    ConvergenceError
        A step failed even after splitting it six times.

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
    steps = positive_int(steps, "steps")
    save_every = positive_int(save_every, "save_every")
    tol = positive_scalar(tolerance, "tolerance")
    iters = positive_int(max_iterations, "max_iterations")
    if method not in STEP_METHODS:
        raise ParameterError(f"method: expected one of {', '.join(map(repr, STEP_METHODS))}, got {method!r}", "method")
    g = as_finite(gravity, "gravity", (3,))
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

    model = body.core_model()
    forces, prescribed = body.forces, body.prescribed_displacement
    start = time.perf_counter()

    def run(n: int, a: NDArray[np.float64], x: Any, v: Any, every: int) -> dict[str, Any]:
        return model.simulate(
            g, forces.copy(), prescribed.copy(), dt, n, a,
            mass_damping, stiffness_damping, x, v, tol, iters, every, method=method,
        )

    bar = Progress(total=steps, desc="simulate", unit="steps", enabled=progress)
    try:
        if not bar.active:
            out = run(steps, alphas, x0, v0, save_every)
        elif _has_free_cable_nodes(body):
            # Free cable nodes' velocities do not survive a restart: one piece, a moving clock.
            out = run(steps, alphas, x0, v0, save_every)
            bar.set(steps, postfix=_step_postfix(out, steps, dt))
        else:
            out = _run_in_chunks(run, steps, save_every, alphas, x0, v0, dt, bar)
    except ConvergenceError as err:
        if isinstance(err.report, dict):
            err.report = SolveReport.from_dict(err.report, body.formulation)
        raise
    finally:
        bar.close()
        # The extension leaves the last step's alphas in the model; the body's own stay in charge.
        for c, alpha in enumerate(body.actuations):
            model.set_actuation(c, alpha)
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
_STEP_IN_MESSAGE = re.compile(r"time step (\d+) \(t = ([0-9.eE+-]+) s\)")


def _run_in_chunks(
    run: Callable[..., dict[str, Any]], steps: int, save_every: int, alphas: NDArray[np.float64],
    x0: Any, v0: Any, dt: float, bar: Progress,
) -> dict[str, Any]:
    """Integrate ``steps`` steps as consecutive calls of ``run`` (each continuing from the
    previous one's last positions and velocities), so that ``bar`` moves in between, and join
    their outputs into what one call would return.

    Chunk boundaries never cross a save point (a multiple of ``save_every``) except from
    another one, so every chunk saves exactly the frames the whole run would: with local
    ``save_every`` when the chunk starts on a save point and spans whole intervals, otherwise
    only its end, kept if that is a save point. The first chunk is one step; later ones aim at
    :data:`CHUNK_SECONDS` each."""
    joined: dict[str, Any] = {"times": [], "positions": [], "kinetic_energy": [], "cable_points": [],
                              "iterations": [], "factorizations": [], "residuals": [], "cutbacks": 0,
                              "velocities": None}
    done, t_offset, size = 0, 0.0, 1
    x, v = x0, v0
    while done < steps:
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
            _shift_step_in_message(err, done, t_offset)
            raise
        per_step = (time.perf_counter() - tick) / n
        times = np.asarray(out["times"], dtype=np.float64)
        positions = np.asarray(out["positions"], dtype=np.float64).reshape(times.size, -1, 3)
        keep = slice(0 if done == 0 else 1, None)
        if end % save_every and end != steps:
            keep = slice(keep.start, -1)  # the end of a chunk inside a save interval
        joined["times"].append(t_offset + times[keep])
        joined["positions"].append(positions[keep])
        joined["kinetic_energy"].append(np.asarray(out["kinetic_energy"], dtype=np.float64)[keep])
        joined["cable_points"].extend(list(out.get("cable_points", []))[keep])
        joined["iterations"].append(np.asarray(out["iterations"], dtype=np.int64))
        joined["factorizations"].append(np.asarray(out["factorizations"], dtype=np.int64))
        joined["residuals"].append(np.asarray(out["residuals"], dtype=np.float64))
        joined["cutbacks"] += int(out.get("cutbacks", 0))
        joined["velocities"] = out["velocities"]
        x, v = positions[-1], np.asarray(out["velocities"], dtype=np.float64)
        t_offset += float(times[-1])
        done = end
        iterations = np.concatenate(joined["iterations"])
        bar.set(done, postfix=_postfix(t_offset, float(iterations.mean()), joined["cutbacks"]))
        size = max(1, int(CHUNK_SECONDS / max(per_step, 1e-9)))
    return {
        "times": np.concatenate(joined["times"]),
        "positions": np.concatenate(joined["positions"]),
        "velocities": joined["velocities"],
        "kinetic_energy": np.concatenate(joined["kinetic_energy"]),
        "cable_points": joined["cable_points"],
        "iterations": np.concatenate(joined["iterations"]),
        "factorizations": np.concatenate(joined["factorizations"]),
        "residuals": np.concatenate(joined["residuals"]),
        "cutbacks": joined["cutbacks"],
    }


def _shift_step_in_message(err: ConvergenceError, first_step: int, t_offset: float) -> None:
    """A chunk's error counts steps and time from the chunk's start: make them global."""

    def shift(match: re.Match[str]) -> str:
        return f"time step {int(match[1]) + first_step} (t = {float(match[2]) + t_offset:.4f} s)"

    if err.args and isinstance(err.args[0], str):
        err.args = (_STEP_IN_MESSAGE.sub(shift, err.args[0]), *err.args[1:])
    if isinstance(err.report, dict) and isinstance(err.report.get("message"), str):
        err.report["message"] = _STEP_IN_MESSAGE.sub(shift, err.report["message"])


def _has_dynamics() -> bool:
    return True


__getattr__ = moved(__name__, {"has_dynamics": (lambda: _has_dynamics, "nothing: every build has time stepping")})

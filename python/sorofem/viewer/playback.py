"""The playback of a time integration: :class:`TrajectoryView`, :func:`build_trajectory_view` and
:func:`view_trajectory`; and a scene's ``[dynamics]`` integrated in pieces that report progress
and can be cancelled (:func:`simulate_in_chunks`, what the scene view's "simulate" runs)."""

from __future__ import annotations

import math
import numbers
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from ..body import Body
from ..dynamics import Trajectory, evaluate_schedule, simulate
from ..errors import ConvergenceError, InputError
from ..scene import Scene
from ..static import StaticResult
from . import serving
from .colours import colour_bar_html, colour_by_magnitude, surface_edges, surface_glb
from .contact import obstacle_meshes, obstacle_offsets
from .frames import Frames, load_frames
from .serving import CORE_LOCK
from .style import (
    CABLE_COLOUR,
    FIXED_COLOUR,
    OBSTACLE_COLOUR,
    OBSTACLE_OPACITY,
    PLAYBACK_FPS,
    REST_COLOUR,
    SPEEDS,
    WIREFRAME_THICKNESS,
)

__all__ = ["TrajectoryView", "build_trajectory_view", "view_trajectory", "simulate_in_chunks", "CHUNK_SECONDS"]

#: Wall-clock target of one piece of :func:`simulate_in_chunks` (how often progress is shown
#: and a cancel is noticed), s.
CHUNK_SECONDS = 0.25


def _speed_label(speed: float) -> str:
    return f"{speed:g}x"


@dataclass
class TrajectoryView:
    """The playback :func:`build_trajectory_view` put on a server: GUI handles and state.

    Setting ``slider.value`` shows that frame (as dragging the slider does); :meth:`play`,
    :meth:`pause` and :meth:`show` drive it from Python.

    Attributes
    ----------
    frames
        What is played.
    frame
        Index of the frame shown.
    playing
        Whether the playback runs.
    speed
        Playback speed, multiples of real time (1: one simulated second per second).
    loop
        Start again at the end (else stop on the last frame).
    surface
        The surface (a GLB node: the frame's surface node positions, coloured by displacement
        magnitude on one scale for the whole motion).
    wireframe
        The surface's edges in the same colours (line segments, shown instead of ``surface``).
    colour_bar
        The colour bar (HTML: the map, ``|u|`` in mm from 0 to ``vmax``).
    cables
        One line-segments handle per cable.
    obstacles
        One mesh handle per obstacle of the trajectory's body (none when played from a
        ``.pvd``, which does not record them), placed at ``obstacle_offsets[frame]``.
    obstacle_offsets
        ``(frames, n_obstacles, 3)`` each obstacle's translation along its path at each frame, m.
    slider, play_button, speed_dropdown, loop_checkbox, wireframe_checkbox, status, header
        The GUI handles.
    frames_shown
        How many frames have been drawn (the initial one included).
    """

    server: Any
    frames: Frames
    surface_faces: NDArray[np.int64]
    surface_nodes: NDArray[np.int64]
    vmax: float
    frame: int = 0
    playing: bool = False
    speed: float = 1.0
    loop: bool = True
    surface: Any = None
    wireframe: Any = None
    colour_bar: Any = None
    cables: list[Any] = field(default_factory=list)
    obstacles: list[Any] = field(default_factory=list)
    obstacle_offsets: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0, 3)), repr=False)
    rest: Any = None
    slider: Any = None
    play_button: Any = None
    speed_dropdown: Any = None
    loop_checkbox: Any = None
    wireframe_checkbox: Any = None
    status: Any = None
    #: The markdown line above the controls (what is played).
    header: Any = None
    frames_shown: int = 0
    #: The surface's unique edges ``(e, 2)`` in surface-node numbering (the wireframe's segments).
    surface_edges: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64),
                                          repr=False)
    _lock: threading.RLock = field(default_factory=threading.RLock, repr=False)
    _thread: threading.Thread | None = field(default=None, repr=False)
    _closed: bool = field(default=False, repr=False)
    #: Everything build_trajectory_view put on the server (scene nodes, then GUI controls), for remove().
    _handles: list[Any] = field(default_factory=list, repr=False)

    @property
    def surface_vertices(self) -> NDArray[np.float64]:
        """Positions of the surface nodes in the frame shown, ``(k, 3)``, m."""
        return self.frames.positions[self.frame][self.surface_nodes]

    @property
    def time(self) -> float:
        """Time of the frame shown, s."""
        return float(self.frames.times[self.frame])

    # -- frames ----------------------------------------------------------------------

    def surface_colours(self, frame: int) -> NDArray[np.uint8]:
        """RGBA colours ``(k, 4)`` of the surface nodes at ``frame``: displacement magnitude on
        viridis, 0 .. ``vmax``."""
        displacement = self.frames.positions[frame][self.surface_nodes] - self.frames.mesh.points[self.surface_nodes]
        return colour_by_magnitude(np.linalg.norm(displacement, axis=1), self.vmax)

    def _surface_glb(self, frame: int) -> bytes:
        vertices = self.frames.positions[frame][self.surface_nodes]
        return surface_glb(vertices, self.surface_faces, self.surface_colours(frame))

    def _wireframe(self, frame: int) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
        vertices = self.frames.positions[frame][self.surface_nodes]
        return (vertices[self.surface_edges].astype(np.float32),
                self.surface_colours(frame)[:, :3][self.surface_edges])

    def _cable_segments(self, frame: int, c: int) -> NDArray[np.float32]:
        points = self.frames.cable_points[frame][c]
        return np.stack([points[:-1], points[1:]], axis=1).astype(np.float32)

    def show(self, frame: int) -> None:
        """Show frame ``frame`` (clamped to the range): move and colour the surface (or its
        wireframe, whichever is shown) and move the cables, and update the status. Does not
        move the slider (set ``slider.value`` to do both)."""
        with self._lock:
            frame = min(max(int(frame), 0), self.frames.n_frames - 1)
            self.frame = frame
            # Only the shown one of surface and wireframe is redrawn (the other on the switch).
            if self.surface is not None and self.surface.visible:
                self.surface.glb_data = self._surface_glb(frame)
            if self.wireframe is not None and self.wireframe.visible:
                self.wireframe.points, self.wireframe.colors = self._wireframe(frame)
            for c, handle in enumerate(self.cables):
                handle.points = self._cable_segments(frame, c)
            for k, handle in enumerate(self.obstacles):
                handle.position = self.obstacle_offsets[frame, k]
            if self.status is not None:
                self.status.content = self._summary()
            self.frames_shown += 1

    def _summary(self) -> str:
        f, k = self.frames, self.frame
        u = np.linalg.norm(f.positions[k] - f.mesh.points, axis=1).max(initial=0.0)
        lines = [f"frame {k} / {f.n_frames - 1}, **t = {f.times[k]:.4g} s**",
                 f"max |u| = {u * 1e3:.3g} mm (colour scale: the whole motion)"]
        if f.kinetic_energy is not None:
            lines.append(f"kinetic energy {f.kinetic_energy[k]:.3e} J")
        if f.actuation is not None:
            tensions = f.trajectory.cable_tensions(k) if f.trajectory is not None else None
            # Per cable a tendon's tension, None for a spring chain (nothing without tendons).
            per_frame = f.trajectory.cable_tension if f.trajectory is not None else []
            tendons = per_frame[k] if k < len(per_frame) else []
            for c in range(f.n_cables):
                tendon = tendons[c] if c < len(tendons) else None
                if tendon is not None:
                    pulled = f.trajectory.cable_pull[k][c]
                    lines.append(f"cable {c} (tendon): {'**slack**, ' if tendon <= 0 else ''}tension {tendon:.4g} N, "
                                 f"pull {pulled * 1e3:.4g} mm")
                    continue
                text = f"cable {c}: alpha {f.actuation[k, c]:.3f}"
                if tensions is not None and tensions[c].size:
                    text += f", tension {tensions[c].min():.3g} .. {tensions[c].max():.3g} N"
                lines.append(text)
        return "  \n".join(lines)

    # -- playback --------------------------------------------------------------------

    def _set_frame(self, frame: int) -> None:
        """Move the slider (which shows the frame through its callback) or show directly."""
        if self.slider is not None and int(round(self.slider.value)) != frame:
            self.slider.value = frame
        elif frame != self.frame or self.frames_shown == 0:
            self.show(frame)

    def _set_button(self) -> None:
        if self.play_button is not None:
            self.play_button.label = "pause" if self.playing else "play"
            self.play_button.icon = "player-pause" if self.playing else "player-play"

    def play(self) -> None:
        """Start (or resume) the playback; from the first frame if the last one is shown."""
        with self._lock:
            if self._closed or self.playing or self.frames.n_frames < 2:
                return
            if self.frame >= self.frames.n_frames - 1:
                self._set_frame(0)
            self.playing = True
            self._set_button()
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="sorofem-playback", daemon=True)
                self._thread.start()

    def pause(self) -> None:
        """Stop the playback on the frame shown."""
        with self._lock:
            self.playing = False
            self._set_button()

    def toggle(self) -> None:
        """Play if paused, pause if playing (the button)."""
        if self.playing:
            self.pause()
        else:
            self.play()

    def set_speed(self, speed: float) -> None:
        """Playback speed, multiples of real time (> 0)."""
        if isinstance(speed, bool) or not (isinstance(speed, numbers.Real) and math.isfinite(speed) and speed > 0):
            raise InputError(f"speed: expected a number > 0 (multiples of real time), got {speed!r}")
        with self._lock:
            self.speed = float(speed)

    def close(self) -> None:
        """Stop the playback thread (the server is the caller's to stop)."""
        with self._lock:
            self._closed = True
            self.playing = False
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join()

    def own(self, handle: Any) -> None:
        """Take ``handle`` (a scene node or control put on the server by someone else, like the
        scene view's "back to static" button) off the server together with this view's own in
        :meth:`remove`."""
        with self._lock:
            self._handles.append(handle)

    def remove(self) -> None:
        """Stop the playback and take the view off the server: its scene nodes and its controls
        (what the scene view's "back to static" does)."""
        self.close()
        with self._lock:
            handles, self._handles = self._handles, []
        for handle in handles:
            handle.remove()

    def _run(self) -> None:
        """The playback thread: advances a clock by ``speed`` times the real time elapsed and
        shows the last frame at or before it, at most PLAYBACK_FPS times a second; a frame
        picked on the slider meanwhile restarts the clock there. At the end (the last frame is
        held for the median frame spacing) it starts again or stops."""
        times = self.frames.times
        spacing = np.diff(times)
        hold = float(np.median(spacing)) if spacing.size else 0.0
        last_index = len(times) - 1
        with self._lock:
            clock, shown = float(times[self.frame]), self.frame
        before = time.perf_counter()
        while True:
            with self._lock:
                if not self.playing or self._closed:
                    self._thread = None
                    return
                now = time.perf_counter()
                if self.frame != shown:  # moved on the slider
                    clock = float(times[self.frame])
                clock += (now - before) * self.speed
                before = now
                if clock >= times[-1] + hold:
                    if self.loop:  # wrap around (several times over at a high speed)
                        clock = float(times[0]) + (clock - float(times[0])) % (float(times[-1]) + hold - float(times[0]))
                        k = min(max(int(np.searchsorted(times, clock, side="right")) - 1, 0), last_index)
                        self._set_frame(k)
                    else:
                        self._set_frame(last_index)
                        self.playing = False
                        self._set_button()
                        self._thread = None
                        return
                else:
                    k = min(max(int(np.searchsorted(times, clock, side="right")) - 1, 0), last_index)
                    if k != self.frame:
                        self._set_frame(k)
                shown = self.frame
            time.sleep(1.0 / PLAYBACK_FPS)


def build_trajectory_view(
    source: Trajectory | Frames | str | os.PathLike[str],
    server: Any,
    *,
    speed: float = 1.0,
    loop: bool = True,
    play: bool = False,
) -> TrajectoryView:
    """Put the playback of a motion on ``server`` (a ``viser.ViserServer``).

    Parameters
    ----------
    source
        A :class:`~sorofem.Trajectory`, a ``.pvd`` file written by
        :meth:`~sorofem.Trajectory.write_pvd`, or a folder with ``trajectory.pvd`` (see
        :func:`load_frames`).
    server
        Where to draw: a ``viser.ViserServer`` (every tab sees the same playback) or a
        ``viser.ClientHandle`` (one tab's own); nothing is started or blocked here.
    speed
        Initial playback speed, multiples of real time.
    loop
        Initial state of the loop toggle.
    play
        Start playing at once.

    Returns
    -------
    TrajectoryView
        Setting ``view.slider.value = k`` shows frame ``k`` exactly as dragging the slider does;
        ``view.play()`` / ``view.pause()`` as the button; ``view.close()`` stops the playback
        thread.

    Raises
    ------
    InputError
        Nothing to play at ``source``, or a bad ``speed``.
    """
    frames = load_frames(source)
    mesh = frames.mesh
    faces = mesh.boundary_faces()
    nodes = np.unique(faces)
    remap = np.full(mesh.n_nodes, -1, dtype=np.int64)
    remap[nodes] = np.arange(nodes.size)
    moved = frames.positions[:, nodes] - mesh.points[nodes]
    vmax = float(np.linalg.norm(moved, axis=2).max(initial=0.0))
    view = TrajectoryView(server=server, frames=frames, surface_faces=remap[faces], surface_nodes=nodes, vmax=vmax,
                          loop=bool(loop))
    view.set_speed(speed)

    lo = frames.positions.reshape(-1, 3).min(axis=0)
    hi = frames.positions.reshape(-1, 3).max(axis=0)
    size = float(np.linalg.norm(hi - lo)) or 1.0
    centre = 0.5 * (lo + hi)
    server.scene.set_up_direction("+z")
    serving.place_camera(server, centre, centre + size * np.array([0.35, -1.1, 0.55]))
    view.surface_edges = surface_edges(view.surface_faces)
    view.surface = server.scene.add_glb("/motion/surface", glb_data=view._surface_glb(0))
    points, colours = view._wireframe(0)
    view.wireframe = server.scene.add_line_segments("/motion/wireframe", points, colours,
                                                    thickness=WIREFRAME_THICKNESS, thickness_units="screen",
                                                    visible=False)
    view.rest = server.scene.add_mesh_simple(
        "/motion/rest", mesh.points[nodes].astype(np.float32), view.surface_faces, color=REST_COLOUR,
        wireframe=True, visible=False,
    )
    view._handles += [view.surface, view.wireframe, view.rest]
    if frames.fixed_nodes.size:
        view._handles.append(server.scene.add_point_cloud(
            "/motion/fixed", mesh.points[frames.fixed_nodes].astype(np.float32), FIXED_COLOUR,
            point_size=0.01 * size, point_shape="circle", precision="float32",
        ))
    for c in range(frames.n_cables):
        view.cables.append(server.scene.add_line_segments(
            f"/motion/cables/{c}", view._cable_segments(0, c), CABLE_COLOUR, thickness=3.0, thickness_units="screen",
        ))
    view._handles += view.cables
    body = frames.trajectory.body if frames.trajectory is not None else None
    if body is not None and body.obstacles:
        view.obstacle_offsets = obstacle_offsets(body, frames.times)
        for k, (vertices, triangles) in enumerate(obstacle_meshes(body, moved=False)):
            view.obstacles.append(server.scene.add_mesh_simple(
                f"/motion/obstacles/{k}", vertices.astype(np.float32), triangles.astype(np.uint32),
                color=OBSTACLE_COLOUR, opacity=OBSTACLE_OPACITY, side="double", position=view.obstacle_offsets[0, k],
            ))
        view._handles += view.obstacles

    gui = server.gui
    name = Path(frames.source).name if frames.source != "trajectory" else "trajectory"
    view.header = gui.add_markdown(
        f"**{name}**: {mesh.n_nodes} nodes, {mesh.n_tets} tets, {frames.n_cables} cable(s), "
        f"{frames.n_frames} frames, t = {frames.times[0]:.4g} .. {frames.times[-1]:.4g} s"
    )
    view._handles.append(view.header)
    last = frames.n_frames - 1
    view.slider = gui.add_slider("frame", min=0, max=max(last, 1), step=1, initial_value=0, disabled=last < 1,
                                 hint="saved frame; its time is in the status below")
    view.slider.on_update(lambda event: view.show(int(round(event.target.value))))
    view.play_button = gui.add_button("play", icon="player-play", disabled=last < 1)
    view.play_button.on_click(lambda _: view.toggle())
    options = sorted(set(SPEEDS) | {view.speed})
    view.speed_dropdown = gui.add_dropdown(
        "speed (x real time)", [_speed_label(v) for v in options], initial_value=_speed_label(view.speed),
    )
    view.speed_dropdown.on_update(lambda event: view.set_speed(float(event.target.value.rstrip("x"))))
    view.loop_checkbox = gui.add_checkbox("loop", initial_value=view.loop)

    def _set_loop(event: Any) -> None:
        view.loop = bool(event.target.value)

    view.loop_checkbox.on_update(_set_loop)
    wireframe = view.wireframe_checkbox = gui.add_checkbox("wireframe (see the cables)", initial_value=False)
    show_rest = gui.add_checkbox("show rest shape", initial_value=False)

    def _toggle(_: Any) -> None:
        with view._lock:
            view.surface.visible = not wireframe.value
            view.wireframe.visible = wireframe.value
            view.rest.visible = show_rest.value
            view.show(view.frame)  # draws the one now shown

    for box in (wireframe, show_rest):
        box.on_update(_toggle)
    view.colour_bar = gui.add_html(colour_bar_html("displacement", 0.0, vmax))
    view.status = gui.add_markdown("")
    view._handles += [view.slider, view.play_button, view.speed_dropdown, view.loop_checkbox, wireframe, show_rest,
                      view.colour_bar, view.status]
    view.show(0)
    if play:
        view.play()
    return view


def view_trajectory(
    source: Trajectory | Frames | str | os.PathLike[str],
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    speed: float = 1.0,
    loop: bool = True,
    play: bool = True,
    block: bool = True,
) -> TrajectoryView:
    """Serve the playback of a motion at ``http://host:port`` (see :func:`build_trajectory_view`).

    With ``block=True`` (scripts) it serves until Ctrl-C, then stops the server; with
    ``block=False`` (Jupyter, an interactive session) it returns at once and the server runs
    in the background until ``view.server.stop()``.

    Examples
    --------
    >>> trajectory = sf.simulate(body, 0.01, 200, gravity=(0, 0, -9.81), damping=(2.0, 0.0))  # doctest: +SKIP
    >>> view = view_trajectory(trajectory, speed=0.5, block=False)    # doctest: +SKIP
    >>> view.slider.value = 10                                         # doctest: +SKIP
    """
    viser = serving.require_viser()
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        view = build_trajectory_view(source, server, speed=speed, loop=loop, play=play)
    except BaseException:
        server.stop()
        raise
    print(f"sorofem view: {view.frames.source} ({view.frames.n_frames} frames) at http://{host}:{server.get_port()}"
          + (" (Ctrl-C to stop)" if block else ""), flush=True)
    if block:
        serving.wait_until_interrupted(server, view.close)
    return view


def _has_free_cable_nodes(body: Body) -> bool:
    """Whether a cable of ``body`` has nodes of its own (``outside="free"``), whose velocities a
    restarted :func:`sorofem.simulate` does not carry over."""
    if not any(getattr(c, "outside", "error") == "free" for c in body.cables):
        return False
    try:
        return any(p.kind == "free" for cable in body.cable_placements() for p in cable)
    except InputError:
        return True  # the simulation reports the problem


def simulate_in_chunks(
    scene: Scene,
    body: Body,
    equilibrium: StaticResult | None = None,
    *,
    on_progress: Callable[[int, int, float], None] | None = None,
    cancel: threading.Event | None = None,
) -> Trajectory | None:
    """:meth:`Scene.simulate` of ``body`` in consecutive pieces of about :data:`CHUNK_SECONDS`,
    each continuing from the last one's positions and velocities, so that the caller sees the
    progress and can stop: the same frames as one call (a piece spans whole ``save_every``
    intervals).

    Parameters
    ----------
    scene
        A scene with ``[dynamics]`` (its time step, steps, schedule, damping, gravity, solver).
    body
        The body to integrate (with ``initial = "static"``, from ``equilibrium``, solved here
        when None).
    on_progress
        Called after each piece with ``(steps done, steps, simulated time in s)``.
    cancel
        When set, the run stops after the piece under way and None is returned.

    Returns
    -------
    Trajectory or None
        The whole motion (``timings["simulate"]`` the wall time of all pieces), or None when
        cancelled.

    Raises
    ------
    InputError
        The scene has no ``[dynamics]`` table.
    ConvergenceError
        A time step failed; the message names the step counted from the start.
    """
    d = scene.dynamics
    if d is None:
        raise InputError(f"{scene.path}: the scene has no [dynamics] table")
    dt, steps, save_every = float(d["dt"]), int(d["steps"]), int(d["save_every"])
    initial: Any = None
    if d["initial"] == "static":
        initial = equilibrium if equilibrium is not None else scene.solve(body=body)
    if _has_free_cable_nodes(body):  # one piece: free cable nodes do not survive a restart
        with CORE_LOCK:
            trajectory = scene.simulate(body=body, equilibrium=initial, progress=False)
        if on_progress is not None:
            on_progress(steps, steps, steps * dt)
        return None if cancel is not None and cancel.is_set() else trajectory
    alphas = evaluate_schedule(body, d["actuation"], dt, steps)
    options = dict(gravity=scene.gravity, damping=(d["mass_damping"], d["stiffness_damping"]),
                   tolerance=scene.solve_options.tolerance, max_iterations=scene.solve_options.max_iterations,
                   progress=False)
    pieces: list[Trajectory] = []
    velocity = None
    done, size = 0, save_every
    start = time.perf_counter()
    while done < steps:
        if cancel is not None and cancel.is_set():
            return None
        n = min(size, steps - done)
        tick = time.perf_counter()
        try:
            with CORE_LOCK:  # one piece at a time on a compiled model shared between tabs
                    piece = simulate(body, dt, n, alphas[done:done + n], initial=initial, initial_velocity=velocity,
                                 save_every=save_every, **options)
        except ConvergenceError as err:
            err.args = (f"in the steps {done + 1} .. {done + n} (t = {done * dt:.4g} .. {(done + n) * dt:.4g} s): "
                        f"{err.args[0] if err.args else err}", *err.args[1:])
            raise
        pieces.append(piece)
        initial, velocity = piece.final_positions, piece.velocities
        done += n
        if on_progress is not None:
            on_progress(done, steps, done * dt)
        per_step = (time.perf_counter() - tick) / n
        size = save_every * max(1, int(CHUNK_SECONDS / max(per_step, 1e-9)) // save_every)
    return _join(body, dt, pieces, alphas, time.perf_counter() - start)


def _join(body: Body, dt: float, pieces: list[Trajectory], alphas: NDArray[np.float64], elapsed: float) -> Trajectory:
    """One trajectory of consecutive pieces (each piece's first frame is the previous one's last)."""
    offsets = np.cumsum([0.0] + [p.times[-1] for p in pieces[:-1]])
    out = {
        "times": np.concatenate([p.times[k > 0:] + t for k, (p, t) in enumerate(zip(pieces, offsets))]),
        "positions": np.concatenate([p.positions[k > 0:] for k, p in enumerate(pieces)]),
        "kinetic_energy": np.concatenate([p.kinetic_energy[k > 0:] for k, p in enumerate(pieces)]),
        "cable_points": [frame for k, p in enumerate(pieces) for frame in p.cable_points[k > 0:]],
        "iterations": np.concatenate([p.iterations for p in pieces]),
        "factorizations": np.concatenate([p.factorizations for p in pieces]),
        "residuals": np.concatenate([p.residuals for p in pieces]),
        "cutbacks": sum(p.cutbacks for p in pieces),
        "velocities": pieces[-1].velocities,
    }
    return Trajectory(body, dt, out, alphas, elapsed)

"""The playback of a time integration: :class:`TrajectoryView`, :func:`build_trajectory_view` and
:func:`view_trajectory`."""

from __future__ import annotations

import math
import numbers
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..dynamics import Trajectory
from ..errors import InputError
from . import serving
from .colours import colour_by_magnitude
from .frames import Frames, load_frames
from .style import CABLE_COLOUR, FIXED_COLOUR, PLAYBACK_FPS, REST_COLOUR, SPEEDS, SURFACE_COLOUR

__all__ = ["TrajectoryView", "build_trajectory_view", "view_trajectory"]


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
        The surface mesh handle; its ``vertices`` are the shown frame's surface node positions.
    colours
        Surface nodes coloured by displacement magnitude (a point cloud handle).
    cables
        One line-segments handle per cable.
    slider, play_button, speed_dropdown, loop_checkbox, status, header
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
    colours: Any = None
    cables: list[Any] = field(default_factory=list)
    rest: Any = None
    slider: Any = None
    play_button: Any = None
    speed_dropdown: Any = None
    loop_checkbox: Any = None
    status: Any = None
    #: The markdown line above the controls (what is played).
    header: Any = None
    frames_shown: int = 0
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

    def _colours(self, frame: int) -> NDArray[np.uint8]:
        displacement = self.frames.positions[frame][self.surface_nodes] - self.frames.mesh.points[self.surface_nodes]
        return colour_by_magnitude(np.linalg.norm(displacement, axis=1), self.vmax)[:, :3]

    def _cable_segments(self, frame: int, c: int) -> NDArray[np.float32]:
        points = self.frames.cable_points[frame][c]
        return np.stack([points[:-1], points[1:]], axis=1).astype(np.float32)

    def show(self, frame: int) -> None:
        """Show frame ``frame`` (clamped to the range): move the surface, the coloured nodes
        and the cables, and update the status. Does not move the slider (set ``slider.value``
        to do both)."""
        with self._lock:
            frame = min(max(int(frame), 0), self.frames.n_frames - 1)
            self.frame = frame
            if self.surface is not None:
                self.surface.vertices = self.surface_vertices.astype(np.float32)
            if self.colours is not None:
                self.colours.points = self.surface_vertices.astype(np.float32)
                self.colours.colors = self._colours(frame)
            for c, handle in enumerate(self.cables):
                handle.points = self._cable_segments(frame, c)
            if self.status is not None:
                self.status.content = self._summary()
            self.frames_shown += 1

    def _summary(self) -> str:
        f, k = self.frames, self.frame
        u = np.linalg.norm(f.positions[k] - f.mesh.points, axis=1).max(initial=0.0)
        lines = [f"frame {k} / {f.n_frames - 1}, **t = {f.times[k]:.4g} s**",
                 f"max |u| = {u * 1e3:.3g} mm (colours 0 .. {self.vmax * 1e3:.3g} mm over the motion)"]
        if f.kinetic_energy is not None:
            lines.append(f"kinetic energy {f.kinetic_energy[k]:.3e} J")
        if f.actuation is not None:
            tensions = f.trajectory.cable_tensions(k) if f.trajectory is not None else None
            for c in range(f.n_cables):
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
        Where to draw; nothing is started or blocked here.
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
    server.initial_camera.look_at = tuple(centre)
    server.initial_camera.position = tuple(centre + size * np.array([0.35, -1.1, 0.55]))
    first = frames.positions[0][nodes].astype(np.float32)
    view.surface = server.scene.add_mesh_simple("/motion/surface", first, view.surface_faces, color=SURFACE_COLOUR,
                                                side="double")
    view.colours = server.scene.add_point_cloud(
        "/motion/displacement", first, view._colours(0), point_size=0.008 * size, point_shape="circle",
        precision="float32",
    )
    view.rest = server.scene.add_mesh_simple(
        "/motion/rest", mesh.points[nodes].astype(np.float32), view.surface_faces, color=REST_COLOUR,
        wireframe=True, visible=False,
    )
    view._handles += [view.surface, view.colours, view.rest]
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
    wireframe = gui.add_checkbox("wireframe (see the cables)", initial_value=False)
    coloured = gui.add_checkbox("colour the nodes by |u|", initial_value=True)
    show_rest = gui.add_checkbox("show rest shape", initial_value=False)

    def _toggle(_: Any) -> None:
        view.surface.wireframe = wireframe.value
        view.colours.visible = coloured.value
        view.rest.visible = show_rest.value

    for box in (wireframe, coloured, show_rest):
        box.on_update(_toggle)
    view.status = gui.add_markdown("")
    view._handles += [view.slider, view.play_button, view.speed_dropdown, view.loop_checkbox, wireframe, coloured,
                      show_rest, view.status]
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

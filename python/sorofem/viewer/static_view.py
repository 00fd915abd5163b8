"""The interactive view of a scene's static equilibrium: cable sliders (alpha, or a tendon's pull
or tension), the formulation, the colour field and its colour bar, the obstacles and contact
forces, and the button that simulates the scene's ``[dynamics]`` (with its progress and a cancel
button) and plays the motion in place."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..body import FORMULATIONS, Body
from ..cables import DEFAULT_ALPHA_STEP
from ..errors import InputError, SorofemError
from ..plot import COLOR_FIELDS
from ..scene import Scene
from ..static import StaticResult, actuate
from .colours import colour_bar_html, colour_field, colour_range, nodal_field, surface_edges, surface_glb
from .commands import CommandSlider, cable_lines, command_slider, is_slack
from .contact import contact_arrows, obstacle_lines, obstacle_meshes
from .frames import Frames
from .playback import TrajectoryView, build_trajectory_view, simulate_in_chunks
from .serving import CORE_LOCK, place_camera
from .style import (
    ALPHA_RANGE,
    ARROW_COLOUR,
    ARROW_HEAD,
    ARROW_SHAFT,
    CABLE_COLOUR,
    DRAG_COLOUR,
    DRAG_ITERATIONS,
    DRAG_STIFFNESS_PER_MU,
    DRAG_TOLERANCE,
    FIXED_COLOUR,
    OBSTACLE_COLOUR,
    OBSTACLE_OPACITY,
    PULL_STEP_FRACTION,
    REST_COLOUR,
    SIMULATE_LABEL,
    SLACK_COLOUR,
    WIREFRAME_THICKNESS,
)

__all__ = ["View", "build_view", "rebuild_body"]


def rebuild_body(body: Body, formulation: str) -> Body:
    """A copy of ``body`` (mesh, material, supports, forces, cables and their actuations) in
    another formulation: ``body.replace(formulation=formulation)``.

    Raises
    ------
    ParameterError
        ``formulation="mixed"`` with ``lame_lambda = 0`` somewhere.
    """
    return body.replace(formulation=formulation)


@dataclass
class View:
    """The interactive view :func:`build_view` put on a server: GUI handles and current state.

    Attributes
    ----------
    server
        Where it is drawn: a ``viser.ViserServer`` (one view every tab shares) or a
        ``viser.ClientHandle`` (one tab's own view, see :func:`sorofem.viewer.serve`).
    body
        The body being solved (replaced when the formulation changes).
    result
        The last equilibrium shown.
    sliders
        One slider per cable, in cable order, for its command (:attr:`sorofem.Body.commands`):
        the alpha of a spring chain, the pull in mm or the tension in N of a tendon
        (:attr:`slider_specs` says which); setting ``.value`` moves the cable there from the
        last equilibrium (:meth:`set_command`).
    formulation
        The standard/mixed dropdown; setting ``.value`` rebuilds the body and re-solves.
    surface
        The deformed surface (a GLB node; its vertex colours show ``colour_by``).
    status
        Markdown with the last solve's report or error.
    simulate_button, motion, back_button
        The button that simulates the scene's ``[dynamics]`` and plays it in the page
        (:meth:`simulate`), the :class:`TrajectoryView` shown meanwhile (None at the static
        view) and its "back to static" button (:meth:`show_static`).
    progress_bar, cancel_button
        Shown while a simulation runs: its progress (percent of the steps) and the button
        that stops it (:meth:`cancel`).
    colour_bar
        HTML: the colour map of ``colour_by`` with its range and unit.
    obstacles, arrows, contact_panel
        One translucent mesh per obstacle of the body, the contact forces as arrows (redrawn
        after each solve) and the side panel's markdown: the arrows' scale and each
        obstacle's total force (both None without obstacles).
    """

    server: Any
    scene: Scene
    body: Body
    result: StaticResult
    surface_faces: NDArray[np.int64]
    surface_nodes: NDArray[np.int64]
    sliders: list[Any] = field(default_factory=list)
    #: What each slider shows (label, range, units) and how its value becomes a command.
    slider_specs: list[CommandSlider] = field(default_factory=list)
    formulation: Any = None
    surface: Any = None
    #: The deformed surface's edges in the surface's colours (line segments; shown instead of
    #: ``surface`` to see the cables inside).
    wireframe: Any = None
    cables: list[Any] = field(default_factory=list)
    obstacles: list[Any] = field(default_factory=list)
    arrows: Any = None
    contact_panel: Any = None
    status: Any = None
    #: Static solves shown so far (the initial one included).
    solves: int = 0
    #: The "simulate [dynamics]" button (disabled, with a hint, when the scene has no [dynamics]).
    simulate_button: Any = None
    #: The playback of the last simulation while it is shown in place of the static view, else None.
    motion: TrajectoryView | None = None
    #: The playback's "back to static" button (None while the static view is shown).
    back_button: Any = None
    #: Simulations run from the page.
    simulations: int = 0
    #: The field the surface is coloured by (one of :data:`COLOR_FIELDS`) and its dropdown.
    colour_by: str = "displacement"
    colour_dropdown: Any = None
    colour_bar: Any = None
    #: The "wireframe (see the cables)" checkbox.
    wireframe_checkbox: Any = None
    progress_bar: Any = field(default=None, repr=False)  # viser's repr of it fails
    cancel_button: Any = None
    #: Command steps and Newton iterations (summed over the steps) of the last slider move.
    move_steps: int = 0
    move_iterations: int = 0
    #: The surface's unique edges ``(e, 2)`` in surface-node numbering (the wireframe's segments).
    surface_edges: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64),
                                          repr=False)
    _lock: threading.RLock = field(default_factory=threading.RLock, repr=False)
    #: Slider targets not yet reached, ``{cable: command}``: a drag that goes on while a move runs
    #: redirects it instead of queueing one solve per slider position.
    _targets: dict[int, float] = field(default_factory=dict, repr=False)
    _targets_lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _moving: bool = field(default=False, repr=False)
    _cancel: threading.Event = field(default_factory=threading.Event, repr=False)
    _closed: bool = field(default=False, repr=False)
    #: Stiffness of the spring that pulls a grabbed node towards the pointer, N/m.
    drag_stiffness: float = 0.0
    #: The grabbed node (shift + drag on the surface), or None; its spring's anchor (the
    #: pointer, m) and force on the node (N).
    dragged: int | None = None
    drag_anchor: NDArray[np.float64] | None = field(default=None, repr=False)
    drag_force: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3), repr=False)
    #: The spring drawn from the grabbed node to the pointer (line segments, hidden otherwise).
    drag_line: Any = field(default=None, repr=False)
    #: Node displacement per unit force at the grabbed node, ``(3, 3)`` m/N, measured at the grab.
    _compliance: NDArray[np.float64] | None = field(default=None, repr=False)
    _pending_anchor: NDArray[np.float64] | None = field(default=None, repr=False)
    _pulling: bool = field(default=False, repr=False)
    #: The static view's scene nodes and controls (hidden while a motion plays).
    _static_nodes: list[Any] = field(default_factory=list, repr=False)
    _static_controls: list[Any] = field(default_factory=list, repr=False)
    #: Re-applies the wireframe / rest-shape checkboxes to the scene nodes.
    _apply_toggles: Any = field(default=None, repr=False)

    @property
    def surface_vertices(self) -> NDArray[np.float64]:
        """Deformed positions of the surface nodes shown, ``(k, 3)``, m."""
        return self.result.positions[self.surface_nodes]

    # -- solving -------------------------------------------------------------------

    def _solve(self, body: Body, initial: StaticResult | None) -> StaticResult:
        with CORE_LOCK:
            return self.scene.solve(body=body, initial=initial)

    def set_command(self, cable: int, value: float) -> None:
        """Move cable ``cable`` to the command ``value`` (what its slider calls): the actuation
        alpha of a spring chain, the pull (m) or the tension (N) of a tendon, whichever drives
        it (:attr:`sorofem.Body.commands`). It goes by continuation from the equilibrium shown,
        each solve warm-started from the last one and each equilibrium shown as it is reached;
        a step that fails is halved, as :func:`sorofem.actuate` does.

        The standard formulation goes in one step. The mixed one goes in steps of at most
        :data:`sorofem.cables.DEFAULT_ALPHA_STEP` in alpha or ``PULL_STEP_FRACTION`` of a
        tendon's rest length in pull (a tension in one step): its Newton iterations grow fast
        with the step (the cable cantilever from alpha 0.3 to 0.7: 153 iterations in one step,
        65 in eight), while the standard one's do not (8 in one step, 46 in eight).

        A new target set meanwhile (the slider dragged on) redirects the move. A cable that
        cannot get there keeps the last equilibrium reached and the status says so."""
        with self._targets_lock:
            self._targets[cable] = float(value)
            if self._moving:
                return  # the move under way takes the new target at its next step
            self._moving = True
        try:
            while True:
                with self._targets_lock:
                    if not self._targets:
                        self._moving = False
                        return
                    cable, alpha = self._targets.popitem()
                self._move(cable, alpha)
        except BaseException:
            with self._targets_lock:
                self._moving = False
            raise

    #: Old name of :meth:`set_command` (from when every cable was a spring chain).
    set_actuation = set_command

    def _move(self, cable: int, alpha: float) -> None:
        with self._lock:
            steps = iterations = 0
            kind = self.body.commands[cable][0]
            largest = math.inf
            if self.body.formulation == "mixed" and kind != "tension":
                length = self.body.cables[cable].length
                largest = DEFAULT_ALPHA_STEP if kind == "actuation" else PULL_STEP_FRACTION * length
            while (current := self.body.actuations[cable]) != alpha:
                with self._targets_lock:
                    alpha = self._targets.pop(cable, alpha)
                if alpha == current:
                    break
                step = current + math.copysign(min(abs(alpha - current), largest), alpha - current)
                if abs(alpha - step) < 1e-12:
                    step = alpha
                try:
                    with CORE_LOCK:
                        path = actuate(self.body, cable, [step], self.scene.gravity, initial=self.result,
                                       tolerance=self.scene.solve_options.tolerance,
                                       max_iterations=self.scene.solve_options.max_iterations)
                except SorofemError as exc:
                    reached = getattr(exc, "results", None) or []
                    if reached:
                        self._show(reached[-1])
                    word = {"actuation": "alpha", "pull": "pull (m)", "tension": "tension (N)"}[kind]
                    self._report_error(f"cable {cable}: no equilibrium at {word} = {step:g} ({exc}); kept {word} = "
                                       f"{self.body.actuations[cable]:g}")
                    return
                steps += len(path)
                iterations += sum(r.report.iterations for r in path)
                self.move_steps, self.move_iterations = steps, iterations
                self._show(path[-1])

    def set_formulation(self, formulation: str) -> None:
        """Rebuild the body in ``formulation`` ("standard" or "mixed") and re-solve, warm-started
        from the equilibrium shown."""
        with self._lock:
            if formulation == self.body.formulation:
                return
            try:
                body = rebuild_body(self.body, formulation)
                result = self._solve(body, self.result)
            except SorofemError as exc:
                self._report_error(f"{formulation}: {exc}; kept {self.body.formulation}")
                return
            self.body = body
            self._show(result)

    # -- pulling a node with a spring ---------------------------------------------------

    def grab(self, point: Any) -> int:
        """Grab the surface node nearest to ``point`` ``(3,)`` m (where a shift + drag on the
        surface starts) with a spring of stiffness :attr:`drag_stiffness`, anchored there.

        Its compliance (node displacement per unit force, ``(3, 3)``) is measured by three
        small probe solves; :meth:`drag_to` uses it to solve the spring's force.

        Returns
        -------
        int
            The grabbed node.
        """
        with self._lock:
            if self.dragged is not None:
                self._release()
            point = np.asarray(point, dtype=np.float64).reshape(3)
            vertices = self.surface_vertices
            node = int(self.surface_nodes[np.argmin(np.linalg.norm(vertices - point, axis=1))])
            lo, hi = self.body.mesh.bounds
            probe = 1e-4 * self.drag_stiffness * float(np.linalg.norm(hi - lo))
            compliance = np.zeros((3, 3))
            for axis in range(3):
                force = np.zeros(3)
                force[axis] = probe
                self.body.add_force([node], force)
                try:
                    probed = self._solve(self.body, self.result)
                finally:
                    self.body.add_force([node], -force)
                compliance[:, axis] = (probed.positions[node] - self.result.positions[node]) / probe
            self.dragged, self._compliance = node, compliance
            self.drag_anchor = self.result.positions[node].copy()
            self.drag_force = np.zeros(3)
            return node

    def drag_to(self, point: Any) -> None:
        """Move the grabbed node's spring anchor to ``point`` ``(3,)`` m and solve for the
        equilibrium in which the node carries the spring force ``k (anchor - x_node)``.

        The force is found by a quasi-Newton iteration on ``F = k (p - x(F))``: the Jacobian
        ``I + k C`` starts from the compliance ``C`` measured at the grab and follows Broyden's
        update (one warm-started solve per iteration, at most ``DRAG_ITERATIONS``). Anchors
        that arrive while it runs (a drag goes on) redirect it: the last one wins."""
        with self._targets_lock:
            self._pending_anchor = np.asarray(point, dtype=np.float64).reshape(3)
            if self._pulling:
                return
            self._pulling = True
        try:
            while True:
                with self._targets_lock:
                    anchor, self._pending_anchor = self._pending_anchor, None
                    if anchor is None:
                        self._pulling = False
                        return
                self._pull(anchor)
        except BaseException:
            with self._targets_lock:
                self._pulling = False
            raise

    def _pull(self, anchor: NDArray[np.float64]) -> None:
        with self._lock:
            node, compliance = self.dragged, self._compliance
            if node is None or compliance is None:
                return
            self.drag_anchor = anchor
            k = self.drag_stiffness
            result = self.result
            for _ in range(DRAG_ITERATIONS):
                residual = self.drag_force - k * (anchor - result.positions[node])
                if np.linalg.norm(residual) <= DRAG_TOLERANCE * max(np.linalg.norm(self.drag_force), 1e-12):
                    break
                step = -np.linalg.solve(np.eye(3) + k * compliance, residual)
                self.body.add_force([node], step)
                try:
                    solved = self._solve(self.body, result)
                except SorofemError as exc:
                    self.body.add_force([node], -step)
                    self._report_error(f"pulling node {node}: no equilibrium ({exc}); kept the last one")
                    break
                # Broyden's update keeps the compliance true to the secant as the body deforms.
                moved = solved.positions[node] - result.positions[node]
                compliance = compliance + np.outer(moved - compliance @ step, step) / float(step @ step)
                self.drag_force = self.drag_force + step
                result = solved
            self._compliance = compliance
            self._show(result)

    def release(self) -> None:
        """Let go of the grabbed node (the end of a shift + drag): its spring force is removed
        and the body re-solved."""
        with self._lock:
            self._release()

    def _release(self) -> None:
        if self.dragged is None:
            return
        self.body.add_force([self.dragged], -self.drag_force)
        self.dragged, self.drag_anchor, self._compliance = None, None, None
        self.drag_force = np.zeros(3)
        try:
            result = self._solve(self.body, self.result)
        except SorofemError as exc:
            self._report_error(f"release: no equilibrium ({exc})")
            return
        self._show(result)

    def _on_drag(self, event: Any) -> None:
        if event.phase == "start":
            self.grab(event.start_position)
        elif event.phase == "update" and self.dragged is not None:
            self.drag_to(event.end_position)
        elif event.phase == "end":
            self.release()

    # -- the motion --------------------------------------------------------------------

    def simulate(self, play: bool = True) -> TrajectoryView | None:
        """Integrate the scene's ``[dynamics]`` and play the motion in the page in place of the
        static view (what the "simulate [dynamics]" button does).

        The body is the one shown: its formulation and the cable actuations set with the
        sliders (cables without ``[dynamics] actuation`` keyframes hold them); with
        ``initial = "static"`` the motion starts from the equilibrium shown. While it runs
        (in pieces, :func:`simulate_in_chunks`) the page shows the steps done and a cancel
        button (:meth:`cancel`). The playback (:func:`build_trajectory_view`, with a "back to
        static" button) then replaces the static view's surface and controls until
        :meth:`show_static`.

        Returns
        -------
        TrajectoryView or None
            The playback (``self.motion``); None when the simulation failed or was cancelled
            (the status says which, and the static view stays).

        Raises
        ------
        InputError
            The scene has no ``[dynamics]`` table.
        """
        d = self.scene.dynamics
        if d is None:
            raise InputError(f"{self.scene.path}: the scene has no [dynamics] table to simulate")
        with self._lock:
            if self.motion is not None:
                return self.motion
            self._cancel.clear()
            self._set_busy(True)
            started = time.perf_counter()
            reached = [0]

            def progress(done: int, steps: int, t: float) -> None:
                reached[0] = done
                if self.progress_bar is not None:
                    self.progress_bar.value = 100.0 * done / steps
                if self.status is not None:
                    self.status.content = self._summary() + (
                        f"  \n**simulating**: step {done} of {steps}, t = {t:.4g} s, "
                        f"{time.perf_counter() - started:.1f} s elapsed")

            progress(0, d["steps"], 0.0)
            try:
                trajectory = simulate_in_chunks(self.scene, self.body, self.result, on_progress=progress,
                                                cancel=self._cancel)
            except SorofemError as exc:
                self._set_busy(False)
                self._report_error(f"simulation failed: {exc}")
                return None
            self._set_busy(False)
            if trajectory is None:
                self._report_error(f"simulation cancelled after {reached[0]} of {d['steps']} steps", label="cancelled")
                return None
            if self.status is not None:
                self.status.content = self._summary()
            self.simulations += 1
            self._show_static_view(False)
            frames = Frames.from_trajectory(trajectory, source=str(self.scene.path))
            motion = build_trajectory_view(frames, self.server)
            self.back_button = self.server.gui.add_button(
                "back to static", icon="arrow-back-up", order=motion.header.order + 0.5,
                hint="leave the playback: the static equilibrium with its cable sliders",
            )
            self.back_button.on_click(lambda _: self.show_static())
            motion.own(self.back_button)
            self.motion = motion
        if play:
            motion.play()
        return motion

    def cancel(self) -> None:
        """Stop the simulation under way after its current piece (the cancel button); the
        static view stays. Nothing happens when none runs."""
        self._cancel.set()

    def show_static(self) -> None:
        """Remove the playback of :meth:`simulate` and show the static view again (the "back to
        static" button); nothing to do when it is shown."""
        with self._lock:
            motion, self.motion, self.back_button = self.motion, None, None
            if motion is None:
                return
            motion.remove()
            self._show_static_view(True)

    def close(self) -> None:
        """Cancel a simulation under way and stop a playback (a tab that goes away); the
        server is the caller's to stop."""
        self._closed = True
        self._cancel.set()
        with self._lock:
            if self.motion is not None:
                self.motion.close()

    def _set_busy(self, busy: bool) -> None:
        """Disable the static controls while a simulation runs; show its progress and the
        cancel button meanwhile."""
        for handle in self._static_controls:
            if hasattr(handle, "disabled") and handle is not self.simulate_button:
                handle.disabled = busy
        if self.simulate_button is not None:
            self.simulate_button.disabled = busy
            self.simulate_button.label = "simulating ..." if busy else SIMULATE_LABEL
        for handle in (self.progress_bar, self.cancel_button):
            if handle is not None:
                handle.visible = busy
        if self.cancel_button is not None:
            self.cancel_button.disabled = False

    def _show_static_view(self, visible: bool) -> None:
        for handle in self._static_nodes + self._static_controls:
            handle.visible = visible
        if self.arrows is not None:  # shown only where there is contact to show
            self.arrows.visible = False
            if visible:
                self._show_contact(self.result)
        if visible and self._apply_toggles is not None:
            self._apply_toggles(None)

    # -- drawing -------------------------------------------------------------------

    def surface_colours(self) -> NDArray[np.uint8]:
        """RGBA colours ``(k, 4)`` of the surface nodes: ``colour_by`` on its map."""
        values, _ = nodal_field(self.result, self.colour_by)
        return colour_field(values[self.surface_nodes], self.colour_by)[0]

    def _cable_segments(self, c: int) -> NDArray[np.float64]:
        points = self.result.cable_points[c]
        return np.stack([points[:-1], points[1:]], axis=1)

    def set_colour(self, field_name: str) -> None:
        """Colour the surface by ``field_name`` (one of :data:`COLOR_FIELDS`; what the "colour
        by" dropdown does). ``pressure`` needs the mixed formulation: otherwise the status says
        so and the colouring is kept."""
        # Setting the dropdown from here calls back with the value already in force: nothing
        # to do, and the lock is held by the caller then.
        if field_name == self.colour_by:
            return
        with self._lock:
            if field_name == "pressure" and self.result.pressure is None:
                self._report_error("colour by pressure: switch the formulation to mixed first")
                if self.colour_dropdown is not None:
                    self.colour_dropdown.value = self.colour_by
                return
            nodal_field(self.result, field_name)  # validates the name
            self.colour_by = field_name
            self._show(self.result, count=False)

    def _show(self, result: StaticResult, count: bool = True) -> None:
        if result.pressure is None and self.colour_by == "pressure":
            self.colour_by = "displacement"  # back to standard: no pressure to show
            if self.colour_dropdown is not None:
                self.colour_dropdown.value = self.colour_by
        self.result = result
        self.solves += int(count)
        if self._closed:
            return  # the tab has gone: nothing to draw on
        colours = self.surface_colours()
        vertices = self.surface_vertices
        if self.surface is not None:
            self.surface.glb_data = surface_glb(vertices, self.surface_faces, colours)
        if self.wireframe is not None:
            self.wireframe.points = vertices[self.surface_edges].astype(np.float32)
            self.wireframe.colors = colours[:, :3][self.surface_edges]
        if self.colour_bar is not None:
            values, _ = nodal_field(result, self.colour_by)
            self.colour_bar.content = colour_bar_html(self.colour_by, *colour_range(values[self.surface_nodes],
                                                                                    self.colour_by))
        for c, handle in enumerate(self.cables):
            handle.points = self._cable_segments(c).astype(np.float32)
            colour = np.array(SLACK_COLOUR if is_slack(result, c) else CABLE_COLOUR, dtype=np.uint8)
            if not np.array_equal(handle.colors, colour):
                handle.colors = colour
        if self.arrows is not None:
            self._show_contact(result)
        if self.drag_line is not None:
            if self.dragged is not None and self.drag_anchor is not None:
                self.drag_line.points = np.array([[result.positions[self.dragged], self.drag_anchor]], dtype=np.float32)
            self.drag_line.visible = self.dragged is not None
        if self.status is not None:
            self.status.content = self._summary()

    def _show_contact(self, result: StaticResult) -> None:
        """Redraw the contact force arrows and the side panel's totals per obstacle."""
        lo, hi = self.body.mesh.bounds
        arrows = contact_arrows(result, float(np.linalg.norm(hi - lo)))
        # No arrow at all is sent as one of zero length, hidden.
        self.arrows.points = (arrows.segments if arrows.nodes.size else np.zeros((1, 2, 3))).astype(np.float32)
        self.arrows.visible = bool(arrows.nodes.size) and self.motion is None
        self.contact_panel.content = "  \n".join([arrows.legend, *obstacle_lines(result)])

    def _summary(self) -> str:
        r = self.result
        lines = [
            f"**{self.body.formulation}**, {r.report.iterations} Newton iterations, "
            f"{r.report.timings.get('total', float('nan')) * 1e3:.0f} ms",
            f"max |u| = {r.max_displacement * 1e3:.3g} mm",
        ]
        if self.move_steps:
            lines.append(f"last slider move: {self.move_steps} step(s), {self.move_iterations} Newton iterations")
        lines += cable_lines(r)
        if self.dragged is not None:
            lines.append(f"pulling node {self.dragged} with {np.linalg.norm(self.drag_force):.3g} N")
        return "  \n".join(lines)

    def _report_error(self, message: str, label: str = "error") -> None:
        if self.status is not None:
            self.status.content = self._summary() + f"  \n**{label}**: {message}"


def build_view(
    scene: Scene,
    server: Any,
    *,
    alpha_range: tuple[float, float] = ALPHA_RANGE,
    body: Body | None = None,
    equilibrium: StaticResult | None = None,
) -> View:
    """Solve ``scene`` and put the interactive view of it on ``server``.

    Parameters
    ----------
    scene
        A :class:`sorofem.Scene`.
    server
        Where to draw: a ``viser.ViserServer`` (every tab shares the view: its sliders,
        checkboxes and camera) or a ``viser.ClientHandle`` (one tab's own view; ``sorofem
        view`` gives each tab one, see :func:`sorofem.viewer.serving.per_client`). Nothing is
        started or blocked here.
    alpha_range
        ``(min, max)`` of the spring cables' alpha sliders, widened to include each one's
        actuation. A tendon's slider is its pull in mm (0 .. a quarter of its rest length) or
        its tension in N, as its command is (``sorofem.viewer.commands.command_slider``).
    body
        The body to solve and move with the sliders (default: ``scene.body``, modified in
        place); pass ``scene.body.replace()`` to leave the scene's alone.
    equilibrium
        Its equilibrium, if already solved (default: solved here).

    Returns
    -------
    View
        Its ``sliders``, ``formulation`` dropdown, ``simulate_button`` and ``surface`` handle;
        setting a slider's ``.value`` from Python re-solves exactly as dragging it does, and
        ``simulate_button.value = True`` simulates and plays as a click does.

    Raises
    ------
    ConvergenceError
        The scene's own static solve does not converge.
    """
    body = scene.body if body is None else body
    if equilibrium is None:
        with CORE_LOCK:
            equilibrium = scene.solve(body=body)
    result = equilibrium
    faces = body.mesh.boundary_faces()
    nodes = np.unique(faces)
    remap = np.full(body.mesh.n_nodes, -1, dtype=np.int64)
    remap[nodes] = np.arange(nodes.size)
    view = View(server=server, scene=scene, body=body, result=result, surface_faces=remap[faces], surface_nodes=nodes,
                solves=1, surface_edges=surface_edges(remap[faces]))
    initial_colour = scene.output.get("color_by", "displacement") if hasattr(scene, "output") else "displacement"
    view.colour_by = initial_colour if (initial_colour != "pressure" or result.pressure is not None) else "displacement"

    lo, hi = body.mesh.bounds
    size = float(np.linalg.norm(hi - lo))
    server.scene.set_up_direction("+z")
    colours = view.surface_colours()
    view.surface = server.scene.add_glb("/body/deformed",
                                        glb_data=surface_glb(view.surface_vertices, view.surface_faces, colours))
    view.wireframe = server.scene.add_line_segments(
        "/body/deformed_wireframe", view.surface_vertices[view.surface_edges].astype(np.float32),
        colours[:, :3][view.surface_edges], thickness=WIREFRAME_THICKNESS, thickness_units="screen", visible=False,
    )
    centre = 0.5 * (lo + hi)
    place_camera(server, centre, centre + size * np.array([0.35, -1.1, 0.55]))
    rest = server.scene.add_mesh_simple(
        "/body/rest", body.mesh.points[nodes].astype(np.float32), view.surface_faces,
        color=REST_COLOUR, wireframe=True, visible=False,
    )
    view._static_nodes += [view.surface, view.wireframe, rest]
    if body.fixed_nodes.size:
        view._static_nodes.append(server.scene.add_point_cloud(
            "/body/fixed", body.mesh.points[body.fixed_nodes].astype(np.float32), FIXED_COLOUR,
            point_size=0.01 * size, point_shape="circle",
        ))
    for c in range(len(body.cables)):
        view.cables.append(server.scene.add_line_segments(
            f"/cables/{c}", view._cable_segments(c).astype(np.float32), CABLE_COLOUR,
            thickness=3.0, thickness_units="screen",
        ))
    view._static_nodes += view.cables
    for k, (vertices, triangles) in enumerate(obstacle_meshes(body)):
        view.obstacles.append(server.scene.add_mesh_simple(
            f"/obstacles/{k}", vertices.astype(np.float32), triangles.astype(np.uint32), color=OBSTACLE_COLOUR,
            opacity=OBSTACLE_OPACITY, side="double",
        ))
    view._static_nodes += view.obstacles
    if body.obstacles:
        view.arrows = server.scene.add_arrows("/contact/forces", np.zeros((1, 2, 3), dtype=np.float32), ARROW_COLOUR,
                                              shaft_radius=ARROW_SHAFT * size, head_radius=0.4 * ARROW_HEAD * size,
                                              head_length=ARROW_HEAD * size, visible=False)
    mu = body.material.per_element(body.mesh.n_tets)[0]
    view.drag_stiffness = DRAG_STIFFNESS_PER_MU * float(np.mean(mu)) * size
    view.drag_line = server.scene.add_line_segments("/drag", np.zeros((1, 2, 3), dtype=np.float32), DRAG_COLOUR,
                                                    thickness=3.0, thickness_units="screen", visible=False)
    view.surface.on_drag("left", modifier="shift")(view._on_drag)
    view._static_nodes.append(view.drag_line)

    gui = server.gui
    header = gui.add_markdown(f"**{scene.path.name}**: {body.mesh.n_nodes} nodes, {body.mesh.n_tets} tets, "
                              f"{len(body.cables)} cable(s), {len(body.obstacles)} obstacle(s)  \nshift + drag on the "
                              f"body: pull a node with a spring of {view.drag_stiffness:.3g} N/m")
    view.formulation = gui.add_dropdown("formulation", list(FORMULATIONS), initial_value=body.formulation)
    view.formulation.on_update(lambda event: view.set_formulation(event.target.value))
    for c in range(len(body.cables)):
        spec = command_slider(body, c, alpha_range)
        slider = gui.add_slider(spec.label, min=spec.min, max=spec.max, step=spec.step, initial_value=spec.initial,
                                hint=spec.hint)
        slider.on_update(lambda event, spec=spec: view.set_command(spec.cable, spec.command(event.target.value)))
        view.sliders.append(slider)
        view.slider_specs.append(spec)
    view.colour_dropdown = gui.add_dropdown("colour by", list(COLOR_FIELDS), initial_value=view.colour_by,
                                            hint="pressure: mixed formulation only")
    view.colour_dropdown.on_update(lambda event: view.set_colour(str(event.target.value)))
    view.colour_bar = gui.add_html("")
    see_through = view.wireframe_checkbox = gui.add_checkbox("wireframe (see the cables)", initial_value=False)
    show_rest = gui.add_checkbox("show rest shape", initial_value=False)

    def _toggle(_: Any) -> None:
        view.surface.visible = not see_through.value
        view.wireframe.visible = see_through.value
        rest.visible = show_rest.value

    see_through.on_update(_toggle)
    show_rest.on_update(_toggle)
    view._apply_toggles = _toggle
    dynamics = scene.dynamics
    if dynamics is None:
        hint = "the scene has no [dynamics] table: add one (dt, steps) to simulate and play its motion here"
    else:
        start = "the equilibrium shown" if dynamics["initial"] == "static" else "rest"
        hint = (f"integrate the scene's [dynamics] ({dynamics['steps']} steps of {dynamics['dt']:g} s, implicit "
                f"Euler) from {start}, with the formulation and cable actuations set here, and play the motion")
    view.simulate_button = gui.add_button(SIMULATE_LABEL, icon="movie", disabled=dynamics is None, hint=hint)
    view.simulate_button.on_click(lambda _: view.simulate())
    view.progress_bar = gui.add_progress_bar(0.0, visible=False)
    view.cancel_button = gui.add_button("cancel", icon="player-stop", visible=False,
                                        hint="stop the simulation; the static view stays")
    view.cancel_button.on_click(lambda _: view.cancel())
    view.status = gui.add_markdown("")
    if view.arrows is not None:
        view.contact_panel = gui.add_markdown("")
    view._show(result, count=False)
    view._static_controls += [header, view.formulation, *view.sliders, view.colour_dropdown, view.colour_bar,
                              see_through, show_rest, view.simulate_button, view.status]
    if view.contact_panel is not None:
        view._static_controls.append(view.contact_panel)
    return view

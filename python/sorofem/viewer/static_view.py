"""The interactive view of a scene's static equilibrium: cable sliders, the formulation, the colour
field, and the button that simulates the scene's ``[dynamics]`` and plays the motion in place."""

from __future__ import annotations

import io
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..body import FORMULATIONS, Body
from ..errors import ConvergenceError, InputError, SorofemError
from ..plot import COLOR_FIELDS
from ..scene import Scene
from ..static import StaticResult, actuate
from .colours import colour_field, nodal_field
from .frames import Frames
from .playback import TrajectoryView, build_trajectory_view
from .style import ALPHA_RANGE, ALPHA_STEP, CABLE_COLOUR, FIXED_COLOUR, REST_COLOUR, SIMULATE_LABEL

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
        The ``viser.ViserServer``.
    body
        The body being solved (replaced when the formulation changes).
    result
        The last equilibrium shown.
    sliders
        One actuation slider per cable, in cable order; setting ``.value`` re-solves.
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
    """

    server: Any
    scene: Scene
    body: Body
    result: StaticResult
    surface_faces: NDArray[np.int64]
    surface_nodes: NDArray[np.int64]
    sliders: list[Any] = field(default_factory=list)
    formulation: Any = None
    surface: Any = None
    #: The deformed surface as a wireframe (shown instead of ``surface`` to see the cables inside).
    wireframe: Any = None
    cables: list[Any] = field(default_factory=list)
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
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
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
        return self.scene.solve(body=body, initial=initial)

    def set_actuation(self, cable: int, alpha: float) -> None:
        """Set cable ``cable``'s actuation and re-solve from the last equilibrium (what the slider
        calls). A jump that fails is retried by continuation from the previous alpha."""
        with self._lock:
            previous = self.body.actuations[cable]
            if alpha == previous:
                return
            self.body.set_actuation(cable, alpha)
            try:
                result = self._solve(self.body, self.result)
            except ConvergenceError:
                self.body.set_actuation(cable, previous)
                try:
                    result = actuate(
                        self.body, cable, alpha, self.scene.gravity, initial=self.result,
                        tolerance=self.scene.solve_options.tolerance,
                        max_iterations=self.scene.solve_options.max_iterations,
                    )[-1]
                except SorofemError as exc:
                    self.body.set_actuation(cable, previous)
                    self._report_error(f"cable {cable}: no equilibrium at alpha = {alpha:g} ({exc}); kept alpha = {previous:g}")
                    return
            self._show(result)

    def set_formulation(self, formulation: str) -> None:
        """Rebuild the body in ``formulation`` ("standard" or "mixed") and re-solve."""
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

    # -- the motion --------------------------------------------------------------------

    def simulate(self, play: bool = True) -> TrajectoryView | None:
        """Integrate the scene's ``[dynamics]`` and play the motion in the page in place of the
        static view (what the "simulate [dynamics]" button does).

        The body is the one shown: its formulation and the cable actuations set with the
        sliders (cables without ``[dynamics] actuation`` keyframes hold them); with
        ``initial = "static"`` the motion starts from the equilibrium shown. The playback
        (:func:`build_trajectory_view`, with a "back to static" button) replaces the static
        view's surface and controls until :meth:`show_static`.

        Returns
        -------
        TrajectoryView or None
            The playback (``self.motion``); None when the simulation failed (the error is in the
            status, and the static view stays).

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
            self._set_busy(True)
            if self.status is not None:
                self.status.content = self._summary() + (
                    f"  \n**simulating** {d['steps']} steps of {d['dt']:g} s ...")
            try:
                trajectory = self.scene.simulate(body=self.body, equilibrium=self.result)
            except SorofemError as exc:
                self._set_busy(False)
                self._report_error(f"simulation failed: {exc}")
                return None
            self._set_busy(False)
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

    def show_static(self) -> None:
        """Remove the playback of :meth:`simulate` and show the static view again (the "back to
        static" button); nothing to do when it is shown."""
        with self._lock:
            motion, self.motion, self.back_button = self.motion, None, None
            if motion is None:
                return
            motion.remove()
            self._show_static_view(True)

    def _set_busy(self, busy: bool) -> None:
        """Disable the static controls while a simulation runs."""
        for handle in self._static_controls:
            if hasattr(handle, "disabled") and handle is not self.simulate_button:
                handle.disabled = busy
        if self.simulate_button is not None:
            self.simulate_button.disabled = busy
            self.simulate_button.label = "simulating ..." if busy else SIMULATE_LABEL

    def _show_static_view(self, visible: bool) -> None:
        for handle in self._static_nodes + self._static_controls:
            handle.visible = visible
        if visible and self._apply_toggles is not None:
            self._apply_toggles(None)

    # -- drawing -------------------------------------------------------------------

    def _surface_glb(self) -> bytes:
        import trimesh

        values, _ = nodal_field(self.result, self.colour_by)
        colours, _ = colour_field(values[self.surface_nodes], self.colour_by)
        mesh = trimesh.Trimesh(self.surface_vertices, self.surface_faces, vertex_colors=colours, process=False)
        with io.BytesIO() as buffer:
            mesh.export(buffer, file_type="glb")
            return buffer.getvalue()

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
        if self.surface is not None:
            self.surface.glb_data = self._surface_glb()
        if self.wireframe is not None:
            self.wireframe.vertices = self.surface_vertices.astype(np.float32)
        for c, handle in enumerate(self.cables):
            handle.points = self._cable_segments(c).astype(np.float32)
        if self.status is not None:
            self.status.content = self._summary()

    def _summary(self) -> str:
        r = self.result
        lines = [
            f"**{self.body.formulation}**, {r.report.iterations} Newton iterations, "
            f"{r.report.timings.get('total', float('nan')) * 1e3:.0f} ms",
            f"max |u| = {r.max_displacement * 1e3:.3g} mm",
        ]
        values, label = nodal_field(r, self.colour_by)
        lines.append(f"colours: {label}, {colour_field(values[self.surface_nodes], self.colour_by)[1]}")
        for c, tension in enumerate(r.cable_tensions):
            lines.append(f"cable {c}: alpha {r.actuations[c]:.3f}, tension {tension.min():.3g} .. {tension.max():.3g} N")
        return "  \n".join(lines)

    def _report_error(self, message: str) -> None:
        if self.status is not None:
            self.status.content = self._summary() + f"  \n**error**: {message}"


def build_view(scene: Scene, server: Any, *, alpha_range: tuple[float, float] = ALPHA_RANGE) -> View:
    """Solve ``scene`` and put the interactive view of it on ``server`` (a ``viser.ViserServer``).

    Parameters
    ----------
    scene
        A :class:`sorofem.Scene`; its body is solved (and modified by the sliders) in place.
    server
        Where to draw; nothing is started or blocked here.
    alpha_range
        ``(min, max)`` of the cable sliders, widened to include each cable's actuation.

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
    body = scene.body
    result = scene.solve()
    faces = body.mesh.boundary_faces()
    nodes = np.unique(faces)
    remap = np.full(body.mesh.n_nodes, -1, dtype=np.int64)
    remap[nodes] = np.arange(nodes.size)
    view = View(server=server, scene=scene, body=body, result=result, surface_faces=remap[faces], surface_nodes=nodes,
                solves=1)

    lo, hi = body.mesh.bounds
    size = float(np.linalg.norm(hi - lo))
    server.scene.set_up_direction("+z")
    view.surface = server.scene.add_glb("/body/deformed", glb_data=view._surface_glb())
    view.wireframe = server.scene.add_mesh_simple(
        "/body/deformed_wireframe", view.surface_vertices.astype(np.float32), view.surface_faces,
        color=(60, 60, 60), wireframe=True, visible=False,
    )
    centre = 0.5 * (lo + hi)
    server.initial_camera.look_at = tuple(centre)
    server.initial_camera.position = tuple(centre + size * np.array([0.35, -1.1, 0.55]))
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

    gui = server.gui
    header = gui.add_markdown(f"**{scene.path.name}**: {body.mesh.n_nodes} nodes, {body.mesh.n_tets} tets, "
                              f"{len(body.cables)} cable(s)")
    view.formulation = gui.add_dropdown("formulation", list(FORMULATIONS), initial_value=body.formulation)
    view.formulation.on_update(lambda event: view.set_formulation(event.target.value))
    for c, alpha in enumerate(body.actuations):
        slider = gui.add_slider(
            f"cable {c} alpha", min=min(alpha_range[0], alpha), max=max(alpha_range[1], alpha),
            step=ALPHA_STEP, initial_value=float(alpha), hint="1 = rest length, < 1 = pulled",
        )
        slider.on_update(lambda event, c=c: view.set_actuation(c, float(event.target.value)))
        view.sliders.append(slider)
    initial_colour = scene.output.get("color_by", "displacement") if hasattr(scene, "output") else "displacement"
    view.colour_by = initial_colour if (initial_colour != "pressure" or result.pressure is not None) else "displacement"
    view._show(result, count=False)
    view.colour_dropdown = gui.add_dropdown("colour by", list(COLOR_FIELDS), initial_value=view.colour_by,
                                            hint="pressure: mixed formulation only")
    view.colour_dropdown.on_update(lambda event: view.set_colour(str(event.target.value)))
    see_through = gui.add_checkbox("wireframe (see the cables)", initial_value=False)
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
    view.status = gui.add_markdown(view._summary())
    view._static_controls += [header, view.formulation, *view.sliders, view.colour_dropdown, see_through, show_rest,
                              view.simulate_button, view.status]
    return view

"""Interactive 3-D views in the browser (``sorofem view``), built on viser: a scene's static
equilibrium with live cable sliders, or the playback of a time integration.

The view shows the deformed boundary surface coloured by displacement magnitude (viridis, scaled
to the current maximum) or, chosen in the "colour by" dropdown, by von Mises stress, pressure
(mixed formulation) or J (diverging maps centred on 0 and 1), the cables as red polylines, the fixed nodes as blue points and,
optionally, the rest shape. The control panel has one slider per cable that sets its actuation
alpha and re-solves, warm-started from the last equilibrium (``body.set_actuation(i, alpha)``,
then :func:`sorofem.solve_static` with ``initial=`` the last result; a jump that does not
converge is retried by continuation, :func:`sorofem.actuate`), and a dropdown that switches
between the standard and the mixed formulation. A scene with ``[dynamics]`` is shown at its
static equilibrium, and its button "simulate [dynamics]" (:meth:`View.simulate`; disabled, with
a hint, when the scene has none) integrates the motion with the formulation and cable
actuations set in the page and plays it in the same page with the playback controls below,
until "back to static" (:meth:`View.show_static`). A trajectory of your own plays with
:func:`view_trajectory`.

**Playback** (:func:`build_trajectory_view`, :func:`view_trajectory`): a
:class:`~sorofem.Trajectory` returned by :func:`sorofem.simulate`, or the ``.pvd`` series that
:meth:`~sorofem.Trajectory.write_pvd` and ``sorofem run`` write, is shown frame by frame with a
frame slider, a play/pause button, the playback speed (multiples of real time) and a loop
toggle. Each frame moves the vertices of the one surface mesh, the cables and the
displacement-coloured surface nodes (one colour scale, 0 .. the largest displacement of the
whole motion); nothing is re-created.

Needs the optional extra ``pip install "sorofem[viewer]"`` (viser). :func:`build_view` takes any
``viser.ViserServer``, so it runs without a browser (that is how it is tested); ``_cli`` starts the
server and waits.

Examples
--------
>>> import viser                                             # doctest: +SKIP
>>> import sorofem as sf
>>> from sorofem.viewer import build_view
>>> server = viser.ViserServer(host="127.0.0.1", port=8080)  # doctest: +SKIP
>>> view = build_view(sf.Scene.load("examples/scenes/cable_cantilever.toml"), server)  # doctest: +SKIP
>>> view.sliders[0].value = 0.7     # re-solves, as dragging the slider does  # doctest: +SKIP
>>> view.result.actuations                                   # doctest: +SKIP
[0.7]
>>> motion = view.simulate()     # a scene with [dynamics]: as the button; plays  # doctest: +SKIP
>>> view.show_static()           # as "back to static"       # doctest: +SKIP

Play a motion (serves on http://127.0.0.1:8080 until Ctrl-C):

>>> from sorofem.viewer import view_trajectory
>>> trajectory = sf.simulate(body, dt=0.01, steps=200, gravity=(0, 0, -9.81))  # doctest: +SKIP
>>> view_trajectory(trajectory)                              # doctest: +SKIP
>>> view_trajectory("results/run")   # a run's folder, or results/run/trajectory.pvd  # doctest: +SKIP
"""

from __future__ import annotations

import io
import math
import numbers
import os
import threading
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .errors import InputError, SorofemError

if TYPE_CHECKING:
    from .dynamics import Trajectory
    from .model import Body, Mesh, StaticResult
    from .scene import Scene

__all__ = [
    "View",
    "build_view",
    "colour_by_magnitude",
    "COLOUR_FIELDS",
    "nodal_field",
    "colour_field",
    "rebuild_body",
    "Frames",
    "load_frames",
    "TrajectoryView",
    "build_trajectory_view",
    "view_trajectory",
]

#: Actuation range of the cable sliders (widened to include a scene's own actuation).
ALPHA_RANGE = (0.3, 1.2)
ALPHA_STEP = 0.005
CABLE_COLOUR = (220, 40, 40)
FIXED_COLOUR = (40, 90, 230)
REST_COLOUR = (180, 180, 180)
SURFACE_COLOUR = (120, 170, 215)
#: Playback speeds offered, in multiples of real time.
SPEEDS = (0.01, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 100.0)
#: Most frames per second the playback sends to the browser (denser frames are skipped).
PLAYBACK_FPS = 30.0
#: Label of the scene view's button that simulates the scene's [dynamics] and plays the motion.
SIMULATE_LABEL = "simulate [dynamics]"


def _require_viser() -> Any:
    try:
        import viser
    except ImportError:
        raise InputError(
            "sorofem view needs the optional dependency viser: pip install 'sorofem[viewer]'"
        ) from None
    return viser


#: Fields the static view can colour the surface by (the dropdown "colour by").
COLOUR_FIELDS = ("displacement", "von_mises", "pressure", "J")


def nodal_field(result: "StaticResult", field_name: str) -> tuple[NDArray[np.float64], str]:
    """Per node the value of ``field_name`` and its label: ``displacement`` (|u|, m),
    ``pressure`` (Pa, the mixed formulation's nodal field), or the element fields
    ``von_mises`` (Pa) and ``J`` averaged over each node's elements, weighted by volume.

    Raises
    ------
    InputError
        An unknown field, or ``pressure`` of a result without one (standard formulation).
    """
    if field_name not in COLOUR_FIELDS:
        raise InputError(f"colour field: expected one of {list(COLOUR_FIELDS)}, got {field_name!r}")
    if field_name == "displacement":
        return np.linalg.norm(result.displacement, axis=1), "|u| [m]"
    if field_name == "pressure":
        if result.pressure is None:
            raise InputError("colour field 'pressure': only the mixed formulation has a pressure field")
        return np.asarray(result.pressure, dtype=np.float64), "pressure [Pa]"
    values = np.asarray(result.von_mises if field_name == "von_mises" else result.J, dtype=np.float64)
    mesh = result.mesh
    weight = np.repeat(mesh.volumes, 4)
    total = np.bincount(mesh.tets.reshape(-1), weights=weight * np.repeat(values, 4), minlength=mesh.n_nodes)
    volume = np.bincount(mesh.tets.reshape(-1), weights=weight, minlength=mesh.n_nodes)
    return total / np.where(volume > 0, volume, 1.0), "von Mises [Pa]" if field_name == "von_mises" else "J"


def colour_field(values: NDArray[np.float64], field_name: str) -> tuple[NDArray[np.uint8], str]:
    """RGBA colours ``(n, 4)`` of a field and a description of the scale: magnitudes
    (displacement, von Mises) on viridis from 0 to their maximum, signed fields on a diverging
    map centred on their neutral value (pressure on 0, J on 1), symmetric about it."""
    from matplotlib import colormaps

    if field_name in ("pressure", "J"):
        centre = 0.0 if field_name == "pressure" else 1.0
        spread = float(np.max(np.abs(values - centre), initial=0.0))
        scaled = 0.5 + 0.5 * (values - centre) / spread if spread > 0 else np.full_like(values, 0.5)
        colours = (colormaps["coolwarm"](np.clip(scaled, 0.0, 1.0)) * 255).round().astype(np.uint8)
        return colours, f"{centre - spread:.3g} .. {centre + spread:.3g} (blue .. red)"
    return colour_by_magnitude(values), f"0 .. {float(np.max(values, initial=0.0)):.3g}"


def colour_by_magnitude(values: NDArray[np.float64], vmax: float | None = None) -> NDArray[np.uint8]:
    """RGBA colours ``(n, 4)`` uint8 of ``values`` on the viridis map, 0 .. ``vmax`` (default: max)."""
    from matplotlib import colormaps

    top = float(np.max(values)) if vmax is None else float(vmax)
    scaled = values / top if top > 0 else np.zeros_like(values)
    return (colormaps["viridis"](np.clip(scaled, 0.0, 1.0)) * 255).round().astype(np.uint8)


def rebuild_body(body: "Body", formulation: str) -> "Body":
    """A copy of ``body`` (mesh, material, supports, forces, cables and their actuations) in
    another formulation.

    Raises
    ------
    ParameterError
        ``formulation="mixed"`` with ``lame_lambda = 0`` somewhere.
    """
    from .model import Body

    new = Body(body.mesh, body.material, formulation, volumetric=body.volumetric, pressure_mass=body.pressure_mass)
    if body.fixed_nodes.size:
        new.fix(body.fixed_nodes, body.prescribed_displacement)
    forces = body.forces
    loaded = np.flatnonzero(np.any(forces != 0, axis=1))
    if loaded.size:
        new.add_force(loaded, forces[loaded])
    for cable, alpha in zip(body.cables, body.actuations):
        new.set_actuation(new.add_cable(cable), alpha)
    return new


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
    scene: "Scene"
    body: "Body"
    result: "StaticResult"
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
    motion: "TrajectoryView | None" = None
    #: The playback's "back to static" button (None while the static view is shown).
    back_button: Any = None
    #: Simulations run from the page.
    simulations: int = 0
    #: The field the surface is coloured by (one of :data:`COLOUR_FIELDS`) and its dropdown.
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

    def _solve(self, body: "Body", initial: "StaticResult | None") -> "StaticResult":
        from .model import solve_static

        return solve_static(body, self.scene.gravity, initial=initial, **self.scene.solver)

    def set_actuation(self, cable: int, alpha: float) -> None:
        """Set cable ``cable``'s actuation and re-solve from the last equilibrium (what the slider
        calls). A jump that fails is retried by continuation from the previous alpha."""
        from .cables import actuate
        from .errors import ConvergenceError

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
                        tolerance=self.scene.solver["tolerance"], max_iterations=self.scene.solver["max_iterations"],
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

    def simulate(self, play: bool = True) -> "TrajectoryView | None":
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
            motion._handles.append(self.back_button)
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
        """Colour the surface by ``field_name`` (one of :data:`COLOUR_FIELDS`; what the "colour
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

    def _show(self, result: "StaticResult", count: bool = True) -> None:
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


def build_view(scene: "Scene", server: Any, *, alpha_range: tuple[float, float] = ALPHA_RANGE) -> View:
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
    from .model import FORMULATIONS

    body = scene.body
    result = scene.solve()
    faces = body.mesh.boundary_faces()
    nodes = np.unique(faces)
    remap = np.full(body.mesh.n_nodes, -1, dtype=np.int64)
    remap[nodes] = np.arange(nodes.size)
    view = View(server=server, scene=scene, body=body, result=result, surface_faces=remap[faces], surface_nodes=nodes,
                solves=1)

    lo, hi = body.mesh.bounds()
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
    view.colour_dropdown = gui.add_dropdown("colour by", list(COLOUR_FIELDS), initial_value=view.colour_by,
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


# ---------------------------------------------------------------------------
# Playback of a time integration


@dataclass
class Frames:
    """The saved frames of a motion, as :func:`build_trajectory_view` plays them.

    Attributes
    ----------
    times
        ``(f,)`` time of each frame, s.
    positions
        ``(f, n_nodes, 3)`` node positions, m.
    mesh
        The rest mesh (its boundary is the surface shown).
    cable_points
        Per frame, one ``(k, 3)`` array per cable, m (empty lists without cables).
    fixed_nodes
        Indices of the supported nodes (empty when read from a ``.pvd``, which does not record
        them).
    kinetic_energy
        ``(f,)`` J, or None (not in a ``.pvd``).
    actuation
        ``(f, n_cables)`` alpha in force at each frame, or None (not in a ``.pvd``).
    trajectory
        The :class:`~sorofem.Trajectory` they come from, if any.
    source
        A label: the ``.pvd`` path or ``"trajectory"``.
    """

    times: NDArray[np.float64]
    positions: NDArray[np.float64]
    mesh: "Mesh"
    cable_points: list[list[NDArray[np.float64]]]
    fixed_nodes: NDArray[np.int64]
    kinetic_energy: NDArray[np.float64] | None = None
    actuation: NDArray[np.float64] | None = None
    trajectory: "Trajectory | None" = None
    source: str = "trajectory"

    @property
    def n_frames(self) -> int:
        return int(self.times.size)

    @property
    def n_cables(self) -> int:
        return len(self.cable_points[0]) if self.cable_points else 0

    @classmethod
    def from_trajectory(cls, trajectory: "Trajectory", source: str = "trajectory") -> "Frames":
        """The frames of a :class:`~sorofem.Trajectory` (no copy of the positions)."""
        n_cables = len(trajectory.body.cables)
        actuation = None
        if n_cables:
            steps = np.rint(trajectory.times / trajectory.dt).astype(np.int64) - 1
            initial = np.asarray(trajectory._initial_actuation, dtype=np.float64).reshape(1, n_cables)
            table = np.vstack([initial, trajectory.actuation.reshape(-1, n_cables)])
            actuation = table[np.clip(steps + 1, 0, len(table) - 1)]
        return cls(
            times=trajectory.times, positions=trajectory.positions, mesh=trajectory.mesh,
            cable_points=trajectory.cable_points if n_cables else [[] for _ in range(trajectory.n_frames)],
            fixed_nodes=trajectory.body.fixed_nodes, kinetic_energy=trajectory.kinetic_energy,
            actuation=actuation, trajectory=trajectory, source=source,
        )

    @classmethod
    def read_pvd(cls, path: str | os.PathLike[str]) -> "Frames":
        """Read a ``.pvd`` time series written by :meth:`sorofem.Trajectory.write_pvd` (or
        ``sorofem run`` with ``[dynamics]``): one ``.vtu`` per frame with the tetrahedra and,
        after the nodes, the cable points joined by line cells.

        The rest shape is the first frame's points minus its ``displacement`` point data (the
        first frame itself when there is none).

        Raises
        ------
        InputError
            The file or a frame is missing or unreadable, has no tetrahedra, or the frames do
            not have the same points.
        """
        import meshio

        from .model import Mesh

        path = Path(path)
        try:
            root = ET.parse(path).getroot()
        except (OSError, ET.ParseError) as exc:
            raise InputError(f"{path}: cannot read the .pvd collection ({exc})") from None
        datasets = root.findall("./Collection/DataSet")
        if not datasets:
            raise InputError(f"{path}: no <DataSet> entries in the .pvd collection")
        times, positions, cable_points = [], [], []
        tets = chains = None
        rest = None
        n = n_points = 0
        for i, entry in enumerate(datasets):
            file = entry.get("file")
            if not file:
                raise InputError(f"{path}: <DataSet> {i} has no file attribute")
            frame_path = path.parent / file
            try:
                frame = meshio.read(frame_path)
            except Exception as exc:  # noqa: BLE001 - meshio raises many kinds
                raise InputError(f"{path}: frame {i} ({frame_path}) cannot be read: {exc}") from None
            try:
                times.append(float(entry.get("timestep", i)))
            except ValueError:
                raise InputError(f"{path}: <DataSet> {i} has timestep={entry.get('timestep')!r}, not a number") from None
            points = np.asarray(frame.points, dtype=np.float64)
            if tets is None:
                tet_blocks = [b.data for b in frame.cells if b.type == "tetra"]
                if not tet_blocks:
                    raise InputError(f"{path}: frame 0 ({frame_path}) has no tetrahedra")
                tets = np.vstack(tet_blocks).astype(np.int64)
                lines = [b.data for b in frame.cells if b.type == "line"]
                lines_arr = np.vstack(lines).astype(np.int64) if lines else np.zeros((0, 2), dtype=np.int64)
                n = int(lines_arr.min()) if lines_arr.size else len(points)
                chains = _chains(lines_arr)
                n_points = len(points)
                displacement = frame.point_data.get("displacement")
                rest = points[:n] - (0.0 if displacement is None else np.asarray(displacement, dtype=np.float64)[:n])
            elif len(points) != n_points:
                raise InputError(f"{path}: frame {i} has {len(points)} points, frame 0 has {n_points}")
            positions.append(points[:n])
            cable_points.append([points[chain] for chain in chains])
        assert tets is not None and rest is not None
        return cls(
            times=np.array(times), positions=np.stack(positions), mesh=Mesh(rest, tets),
            cable_points=cable_points, fixed_nodes=np.zeros(0, dtype=np.int64), source=str(path),
        )


def _chains(lines: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Point indices of each polyline in a list of line cells (consecutive cells sharing an end
    form one polyline, as write_pvd writes the cables)."""
    chains: list[list[int]] = []
    for a, b in lines.tolist():
        if chains and chains[-1][-1] == a:
            chains[-1].append(b)
        else:
            chains.append([a, b])
    return [np.array(c, dtype=np.int64) for c in chains]


def load_frames(source: "Trajectory | Frames | str | os.PathLike[str]") -> Frames:
    """The frames to play from a :class:`~sorofem.Trajectory`, a ``.pvd`` file, or a folder
    holding ``trajectory.pvd`` (the ``--out`` folder of ``sorofem run``) or exactly one
    ``.pvd``.

    Raises
    ------
    InputError
        Nothing to play at ``source``.
    """
    from .dynamics import Trajectory

    if isinstance(source, Frames):
        return source
    if isinstance(source, Trajectory):
        return Frames.from_trajectory(source)
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"expected a sorofem.Trajectory, a .pvd file or a folder, got {type(source).__name__}")
    path = Path(source)
    if path.is_dir():
        candidates = [path / "trajectory.pvd"] if (path / "trajectory.pvd").is_file() else sorted(path.glob("*.pvd"))
        if len(candidates) != 1:
            found = ", ".join(c.name for c in candidates) or "none"
            raise InputError(f"{path}: expected trajectory.pvd or exactly one .pvd file in the folder, found {found}")
        path = candidates[0]
    elif not path.is_file():
        raise InputError(f"{path}: no such file or folder")
    if path.suffix.lower() != ".pvd":
        raise InputError(f"{path}: expected a .pvd time series (written by Trajectory.write_pvd or sorofem run)")
    return Frames.read_pvd(path)


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
    source: "Trajectory | Frames | str | os.PathLike[str]",
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
    source: "Trajectory | Frames | str | os.PathLike[str]",
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
    viser = _require_viser()
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        view = build_trajectory_view(source, server, speed=speed, loop=loop, play=play)
    except BaseException:
        server.stop()
        raise
    print(f"sorofem view: {view.frames.source} ({view.frames.n_frames} frames) at http://{host}:{server.get_port()}"
          + (" (Ctrl-C to stop)" if block else ""), flush=True)
    if block:
        _serve(server, view.close)
    return view


def _serve(server: Any, on_stop: Any = None) -> None:
    """Wait until Ctrl-C, then stop the server."""
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        if on_stop is not None:
            on_stop()
        server.stop()


def _cli(path: Path, host: str = "127.0.0.1", port: int = 8080, trajectory: bool = False) -> int:
    """``sorofem view PATH``: serve a view until interrupted (Ctrl-C); returns the exit code 0.

    ``PATH`` is a scene (its static equilibrium with cable sliders; with ``trajectory=True`` its
    ``[dynamics]`` are simulated and played), a ``.pvd`` time series, or a folder holding
    ``trajectory.pvd`` (``sorofem run``'s ``--out`` folder), which is played.
    """
    from .scene import Scene

    viser = _require_viser()
    path = Path(path)
    playback = path.is_dir() or path.suffix.lower() == ".pvd"
    if playback:
        source: Any = load_frames(path)
    else:
        scene = Scene.load(path)
        if trajectory:
            if scene.dynamics is None:
                raise InputError(f"{path}: --trajectory needs a [dynamics] table in the scene")
            source = Frames.from_trajectory(scene.simulate(), source=str(path))
    server = viser.ViserServer(host=host, port=port, verbose=False)
    on_stop = None
    try:
        if playback or trajectory:
            view = build_trajectory_view(source, server, play=True)
            on_stop = view.close
            what = f"{path} ({view.frames.n_frames} frames)"
        else:
            build_view(scene, server)
            what = str(path)
    except BaseException:
        server.stop()
        raise
    print(f"sorofem view: {what} at http://{host}:{server.get_port()} (Ctrl-C to stop)", flush=True)
    _serve(server, on_stop)
    return 0

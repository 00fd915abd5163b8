"""Interactive 3-D view of a scene in the browser (``sorofem view SCENE.toml``), built on viser.

The view shows the deformed boundary surface coloured by displacement magnitude (viridis, scaled
to the current maximum), the cables as red polylines, the fixed nodes as blue points and,
optionally, the rest shape. The control panel has one slider per cable that sets its actuation
alpha and re-solves, warm-started from the last equilibrium (``body.set_actuation(i, alpha)``,
then :func:`sorofem.solve_static` with ``initial=`` the last result; a jump that does not
converge is retried by continuation, :func:`sorofem.actuate`), and a dropdown that switches
between the standard and the mixed formulation. A scene with ``[dynamics]`` is shown at its
static equilibrium.

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
"""

from __future__ import annotations

import io
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .errors import InputError, SorofemError

if TYPE_CHECKING:
    from .model import Body, StaticResult
    from .scene import Scene

__all__ = ["View", "build_view", "colour_by_magnitude", "rebuild_body"]

#: Actuation range of the cable sliders (widened to include a scene's own actuation).
ALPHA_RANGE = (0.3, 1.2)
ALPHA_STEP = 0.005
CABLE_COLOUR = (220, 40, 40)
FIXED_COLOUR = (40, 90, 230)
REST_COLOUR = (180, 180, 180)


def _require_viser() -> Any:
    try:
        import viser
    except ImportError:
        raise InputError(
            "sorofem view needs the optional dependency viser: pip install 'sorofem[viewer]'"
        ) from None
    return viser


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
        The deformed surface (a GLB node; its vertex colours are the displacement magnitude).
    status
        Markdown with the last solve's report or error.
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
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

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

    # -- drawing -------------------------------------------------------------------

    def _surface_glb(self) -> bytes:
        import trimesh

        magnitude = np.linalg.norm(self.result.displacement[self.surface_nodes], axis=1)
        mesh = trimesh.Trimesh(
            self.surface_vertices, self.surface_faces, vertex_colors=colour_by_magnitude(magnitude), process=False
        )
        with io.BytesIO() as buffer:
            mesh.export(buffer, file_type="glb")
            return buffer.getvalue()

    def _cable_segments(self, c: int) -> NDArray[np.float64]:
        points = self.result.cable_points[c]
        return np.stack([points[:-1], points[1:]], axis=1)

    def _show(self, result: "StaticResult") -> None:
        self.result = result
        self.solves += 1
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
            f"max |u| = {r.max_displacement * 1e3:.3g} mm (colour scale 0 .. max)",
        ]
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
        Its ``sliders``, ``formulation`` dropdown and ``surface`` handle; setting a slider's
        ``.value`` from Python re-solves exactly as dragging it does.

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
    if body.fixed_nodes.size:
        server.scene.add_point_cloud(
            "/body/fixed", body.mesh.points[body.fixed_nodes].astype(np.float32), FIXED_COLOUR,
            point_size=0.01 * size, point_shape="circle",
        )
    for c in range(len(body.cables)):
        view.cables.append(server.scene.add_line_segments(
            f"/cables/{c}", view._cable_segments(c).astype(np.float32), CABLE_COLOUR,
            thickness=3.0, thickness_units="screen",
        ))

    gui = server.gui
    gui.add_markdown(f"**{scene.path.name}**: {body.mesh.n_nodes} nodes, {body.mesh.n_tets} tets, "
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
    see_through = gui.add_checkbox("wireframe (see the cables)", initial_value=False)
    show_rest = gui.add_checkbox("show rest shape", initial_value=False)

    def _toggle(_: Any) -> None:
        view.surface.visible = not see_through.value
        view.wireframe.visible = see_through.value
        rest.visible = show_rest.value

    see_through.on_update(_toggle)
    show_rest.on_update(_toggle)
    view.status = gui.add_markdown(view._summary())
    return view


def _cli(scene_path: Path, host: str = "127.0.0.1", port: int = 8080) -> int:
    """``sorofem view``: serve the view until interrupted (Ctrl-C); returns the exit code 0."""
    from .scene import Scene

    viser = _require_viser()
    scene = Scene.load(scene_path)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    try:
        build_view(scene, server)
        print(f"sorofem view: {scene_path} at http://{host}:{server.get_port()} (Ctrl-C to stop)", flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        return 0
    finally:
        server.stop()

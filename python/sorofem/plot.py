"""Static PNG figures of results, rendered offscreen with matplotlib's Agg canvas.

The figures are drawn on a :class:`matplotlib.figure.Figure` with an Agg canvas rather
than through ``pyplot``, so importing or calling this module never changes the user's
matplotlib backend and never opens a window.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
>>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
>>> sf.plot.plot_rest_and_deformed(result, "/tmp/shape.png")
>>> sf.plot.plot_convergence(result.report, "/tmp/convergence.png")
"""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import NDArray

from .dynamics import Trajectory
from .errors import InputError
from .obstacles import obstacle_surface
from .solver import SolveReport
from .static import StaticResult

__all__ = ["plot_rest_and_deformed", "plot_convergence", "plot_trajectory", "COLOR_FIELDS", "FIELD_CENTRES",
           "result_field"]

#: Fields a result can be coloured by (``shape.png``, the scene's ``[output] color_by``, the
#: viewer's "colour by"): the nodal displacement magnitude and pressure (mixed formulation only),
#: and the element fields von Mises stress and J.
COLOR_FIELDS = ("displacement", "von_mises", "pressure", "J")
#: Signed fields, drawn on a diverging map centred on their unloaded value; the others are
#: magnitudes, drawn from 0.
FIELD_CENTRES = {"pressure": 0.0, "J": 1.0}
_LABELS = {
    "displacement": "displacement magnitude |u| [m]",
    "von_mises": "von Mises stress [Pa]",
    "pressure": "pressure p [Pa]",
    "J": "volume ratio J = det F",
}


def result_field(result: StaticResult, name: str, what: str = "color_by") -> tuple[NDArray[np.float64], bool, str]:
    """The values of colour field ``name`` of a result, whether they are nodal (else one per
    tetrahedron), and their label with units.

    Raises
    ------
    InputError
        ``name`` is not one of :data:`COLOR_FIELDS`, or is ``"pressure"`` for a result without
        a pressure field (standard formulation); ``what`` names the option in the message.
    """
    if name not in COLOR_FIELDS:
        raise InputError(f"{what}: expected one of {', '.join(map(repr, COLOR_FIELDS))}, got {name!r}")
    if name == "displacement":
        return np.linalg.norm(result.displacement, axis=1), True, _LABELS[name]
    if name == "pressure":
        if result.pressure is None:
            raise InputError(
                f"{what}='pressure': the result has no pressure field (only the mixed formulation has one); "
                "colour by 'displacement', 'von_mises' or 'J'"
            )
        return np.asarray(result.pressure, dtype=np.float64), True, _LABELS[name]
    values = result.von_mises if name == "von_mises" else result.J
    return np.asarray(values, dtype=np.float64), False, _LABELS[name]


def _new_figure(figsize: tuple[float, float]):  # -> Figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=120)
    FigureCanvasAgg(fig)
    return fig


def _boundary_edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges of a triangle set, ``(e, 2)``."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0)


def _shaded(rgba: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Darken faces turned away from a light above the viewer, so the 3-D shape stays
    readable where the colour is uniform (done here: matplotlib's own shading varies by version)."""
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    light = np.array([-0.4, -0.6, 0.7])
    light /= np.linalg.norm(light)
    out = rgba.copy()
    out[:, :3] *= (0.55 + 0.45 * np.abs(normals @ light))[:, None]
    return out


def _face_owners(tets: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The tetrahedron each boundary triangle belongs to, ``(k,)``."""
    local = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    every = np.sort(tets[:, local].reshape(-1, 3), axis=1)
    _, ids = np.unique(np.vstack([every, np.sort(faces, axis=1)]), axis=0, return_inverse=True)
    ids = ids.reshape(-1)
    tet_of = np.empty(int(ids.max()) + 1, dtype=np.int64)
    tet_of[ids[: len(every)]] = np.arange(len(every)) // 4  # a boundary face occurs in one tet only
    return tet_of[ids[len(every):]]


def _surface_field(result: StaticResult, faces: np.ndarray, color_by: str) -> tuple[np.ndarray, np.ndarray, str]:
    """Per boundary triangle the value of ``color_by`` (nodal fields averaged over the triangle,
    element fields of the tetrahedron it belongs to), all values (for the colour bar), and its label."""
    values, nodal, label = result_field(result, color_by)
    face_values = values[faces].mean(axis=1) if nodal else values[_face_owners(result.mesh.tets, faces)]
    return face_values, values, label


def plot_rest_and_deformed(
    result: StaticResult,
    path: str | os.PathLike[str],
    title: str | None = None,
    color_by: str = "displacement",
) -> None:
    """Rest shape (grey wireframe) and deformed surface coloured by a field, as a PNG; the
    body's cables, if any, in red (rest shape dashed); its obstacles translucent grey, with the
    contact forces on the nodes as black arrows.

    Axes share one scale so shapes are not distorted.

    Parameters
    ----------
    result
        A :class:`~sorofem.StaticResult`.
    path
        Output PNG file.
    title
        Figure title; default: the maximum displacement.
    color_by
        One of :data:`COLOR_FIELDS`: ``"displacement"`` (``|u|``, m, viridis from 0),
        ``"von_mises"`` (Pa, viridis from 0), ``"pressure"`` (Pa, mixed formulation only; blue
        negative, red positive, symmetric about 0) or ``"J"`` (volume ratio; blue compressed,
        red dilated, symmetric about 1).

    Raises
    ------
    InputError
        An unknown ``color_by``, or ``"pressure"`` for a result without pressure.
    """
    from matplotlib import cm, colormaps, colors
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    mesh = result.mesh
    faces = mesh.boundary_faces()
    rest = mesh.points
    deformed = result.positions
    face_value, values, bar_label = _surface_field(result, faces, color_by)
    vmax_u = float(np.linalg.norm(result.displacement, axis=1).max(initial=0.0))

    fig = _new_figure((8.0, 6.0))
    ax = fig.add_subplot(projection="3d")

    edges = _boundary_edges(faces)
    ax.add_collection3d(Line3DCollection(rest[edges], colors=(0.5, 0.5, 0.5, 0.35), linewidths=0.4))

    if color_by in FIELD_CENTRES:  # diverging, symmetric about the unloaded value
        centre = FIELD_CENTRES[color_by]
        half = float(np.abs(values - centre).max(initial=0.0)) or (1.0 if color_by == "pressure" else 1e-6)
        norm = colors.Normalize(vmin=centre - half, vmax=centre + half)
        cmap = colormaps["coolwarm"]
    else:
        top = float(values.max(initial=0.0))
        norm = colors.Normalize(vmin=0.0, vmax=top if top > 0 else 1.0)
        cmap = colormaps["viridis"]
    surface = Poly3DCollection(
        deformed[faces], facecolors=_shaded(cmap(norm(face_value)), deformed[faces]), edgecolors="none"
    )
    ax.add_collection3d(surface)

    cable_points = getattr(result, "cable_points", None) or []
    if cable_points:
        # Cables run inside the body: draw them on top of the surface, rest dashed.
        ax.computed_zorder = False
        for c, (cable, points) in enumerate(zip(result.body.cables, cable_points)):
            label = "cables (rest dashed)" if c == 0 else None
            ax.plot(*cable.points.T, color="tab:red", linestyle="--", linewidth=0.8, alpha=0.6, zorder=10)
            ax.plot(*points.T, color="tab:red", marker="o", markersize=2.5, linewidth=1.6, zorder=11, label=label)
        ax.legend(loc="upper left")

    both = np.vstack([rest, deformed])
    lo, hi = both.min(axis=0), both.max(axis=0)
    obstacles = _draw_obstacles(ax, result, lo, hi)
    if len(obstacles):
        # Obstacles widen the view, but not by more than half the body's size on each side.
        margin = 0.5 * (hi - lo)
        lo = np.minimum(lo, np.maximum(obstacles.min(axis=0), lo - margin))
        hi = np.maximum(hi, np.minimum(obstacles.max(axis=0), hi + margin))
    span = hi - lo
    # A flat direction would make a zero-height box; give it a sliver of the largest span.
    span = np.maximum(span, 0.02 * float(span.max() or 1.0))
    center = 0.5 * (lo + hi)
    ax.set_xlim(center[0] - span[0] / 2, center[0] + span[0] / 2)
    ax.set_ylim(center[1] - span[1] / 2, center[1] + span[1] / 2)
    ax.set_zlim(center[2] - span[2] / 2, center[2] + span[2] / 2)
    ax.set_box_aspect(tuple(span))
    for axis, length in zip((ax.xaxis, ax.yaxis, ax.zaxis), span):
        # Short axes of a slender body get fewer ticks so their labels do not overlap.
        axis.set_major_locator(MaxNLocator(nbins=4 if length > 0.3 * span.max() else 1))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.view_init(elev=20, azim=-60)

    mappable = cm.ScalarMappable(norm=norm, cmap=cmap)
    mappable.set_array(values)
    fig.colorbar(mappable, ax=ax, shrink=0.6, pad=0.1, label=bar_label)
    ax.set_title(title if title is not None else f"rest (grey) and deformed; max |u| = {vmax_u:.3g} m")
    fig.savefig(os.fspath(path))


def _draw_obstacles(ax, result: StaticResult, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.float64]:
    """Draws the body's obstacles (where they are at t = 0) and the contact forces; returns the
    drawn obstacle vertices, ``(k, 3)``."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    placements = getattr(result.body, "obstacles", ())
    if not placements:
        return np.zeros((0, 3))
    centre, size = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    drawn = []
    for placement in placements:
        vertices, triangles = obstacle_surface(placement.obstacle, 0.6 * (hi - lo), centre)
        if placement.path is not None:
            vertices = vertices + [np.interp(0.0, placement.path[:, 0], placement.path[:, k]) for k in (1, 2, 3)]
        ax.add_collection3d(Poly3DCollection(vertices[triangles], facecolors=(0.55, 0.55, 0.6, 0.25),
                                             edgecolors=(0.3, 0.3, 0.35, 0.3), linewidths=0.3))
        drawn.append(vertices)
    forces = result.contact_forces
    magnitude = np.linalg.norm(forces, axis=1)
    loaded = magnitude > 1e-3 * float(magnitude.max(initial=0.0))
    if loaded.any():
        scale = 0.15 * size / float(magnitude.max())
        x = result.positions[loaded]
        ax.quiver(*x.T, *(scale * forces[loaded]).T, color="black", linewidth=0.8,
                  label=f"contact forces (max {magnitude.max():.3g} N per node)")
        ax.legend(loc="upper left")
    return np.vstack(drawn)


def plot_convergence(
    report: SolveReport,
    path: str | os.PathLike[str],
    tolerance: float | None = None,
) -> None:
    """Relative residual against Newton iteration (log scale), as a PNG.

    Parameters
    ----------
    report
        A :class:`~sorofem.SolveReport` (a ``ConvergenceError.report`` works too).
    path
        Output PNG file.
    tolerance
        If given, drawn as a dashed horizontal line.
    """
    residuals = np.asarray(report.residual_history, dtype=np.float64)
    fig = _new_figure((6.0, 4.0))
    ax = fig.add_subplot()
    if residuals.size:
        # Zeros (exact solves) cannot be shown on a log axis; clip to the smallest double.
        shown = np.clip(residuals, np.finfo(float).tiny, None)
        ax.semilogy(np.arange(1, residuals.size + 1), shown, "o-", markersize=4)
    else:
        ax.set_yscale("log")
        ax.text(0.5, 0.5, "no iterations recorded", ha="center", va="center", transform=ax.transAxes)
    if tolerance is not None:
        ax.axhline(tolerance, color="grey", linestyle="--", linewidth=1, label=f"tolerance {tolerance:g}")
        ax.legend()
    ax.set_xlabel("Newton iteration")
    ax.set_ylabel("relative residual norm")
    status = "converged" if report.converged else "not converged"
    ax.set_title(f"Newton: {status} after {report.iterations} iterations")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.fspath(path))


def plot_trajectory(trajectory: Trajectory, path: str | os.PathLike[str], title: str | None = None) -> None:
    """Largest displacement and kinetic energy (log scale) against time, as a PNG.

    Parameters
    ----------
    trajectory
        A :class:`~sorofem.Trajectory`.
    path
        Output PNG file.
    title
        Figure title; default: steps, time step and Newton iterations.
    """
    fig = _new_figure((6.5, 5.0))
    ax, ax_e = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2, sharex=None)
    t = trajectory.times
    ax.plot(t, np.linalg.norm(trajectory.displacement, axis=2).max(axis=1))
    ax.set_ylabel("max |u| [m]")
    ax.grid(True, alpha=0.3)
    energy = np.asarray(trajectory.kinetic_energy)
    positive = energy > 0
    if np.any(positive):
        ax_e.semilogy(t[positive], energy[positive])
    else:
        ax_e.set_yscale("log")
        ax_e.text(0.5, 0.5, "at rest throughout", ha="center", va="center", transform=ax_e.transAxes)
    ax_e.set_xlabel("time [s]")
    ax_e.set_ylabel("kinetic energy [J]")
    ax_e.grid(True, which="both", alpha=0.3)
    steps = int(trajectory.iterations.size)
    ax.set_title(title if title is not None else (
        f"{steps} steps of {trajectory.dt:g} s, {int(trajectory.iterations.sum())} Newton iterations, "
        f"{trajectory.cutbacks} cutbacks"
    ))
    fig.tight_layout()
    fig.savefig(os.fspath(path))

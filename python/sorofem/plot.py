"""Figures of results, following matplotlib's convention: each function draws into ``ax=``
(an Axes of the user's figure, in a notebook say) or, without it, into a new
:class:`matplotlib.figure.Figure`, returns that Figure, and writes it to ``path`` when given.

A new Figure is drawn on an Agg canvas rather than through ``pyplot``, so importing or calling
this module never changes the user's matplotlib backend and never opens a window (in Jupyter,
the returned Figure displays itself as the cell's value).

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
>>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
>>> fig = sf.plot.plot_rest_and_deformed(result, "/tmp/shape.png")
>>> fig = sf.plot.plot_convergence(result.report, "/tmp/convergence.png")
>>> import matplotlib.pyplot as plt                                         # doctest: +SKIP
>>> fig, ax = plt.subplots()                                                # doctest: +SKIP
>>> sf.plot.plot_convergence(result.report, ax=ax)                          # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from ._text import plural
from .dynamics import Trajectory
from .errors import InputError
from .obstacles import obstacle_surface
from .solver import SolveReport
from .static import StaticResult

__all__ = ["plot_rest_and_deformed", "plot_convergence", "plot_trajectory", "plot_fit", "plot_profile",
           "COLOR_FIELDS", "FIELD_CENTRES", "result_field"]

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
    if not isinstance(name, str) or name not in COLOR_FIELDS:
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


def _new_figure(figsize: tuple[float, float]) -> Any:
    """A Figure on an Agg canvas (no pyplot, no window)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=120)
    FigureCanvasAgg(fig)
    return fig


def _axes(ax: Any, count: int, figsize: tuple[float, float], name: str, **subplot: Any) -> tuple[Any, list[Any]]:
    """The Figure and ``count`` Axes to draw into: ``ax`` (an Axes when ``count`` is 1, else a
    sequence of ``count`` Axes), or new ones stacked on a new Figure."""
    if ax is None:
        fig = _new_figure(figsize)
        return fig, [fig.add_subplot(count, 1, k + 1, **subplot) for k in range(count)]
    axes = [ax] if count == 1 and not isinstance(ax, Sequence) and not isinstance(ax, np.ndarray) else list(np.ravel(ax))
    if len(axes) != count or not all(hasattr(a, "plot") for a in axes):
        raise InputError(f"{name}: expected {'a matplotlib Axes' if count == 1 else f'{count} matplotlib Axes'}, "
                         f"got {type(ax).__name__}")
    return axes[0].figure, axes


def _finish(fig: Any, path: str | os.PathLike[str] | None, own: bool) -> Any:
    if own:
        fig.tight_layout()
    if path is not None:
        fig.savefig(os.fspath(path))
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
    path: str | os.PathLike[str] | None = None,
    title: str | None = None,
    color_by: str = "displacement",
    *,
    ax: Any = None,
) -> Any:
    """Rest shape (grey wireframe) and deformed surface coloured by a field, with a colour bar;
    the body's cables, if any, in red (rest shape dashed); its obstacles translucent grey, with
    the contact forces on the nodes as black arrows. Returns the Figure.

    Axes share one scale so shapes are not distorted.

    Parameters
    ----------
    result
        A :class:`~sorofem.StaticResult`.
    path
        Write the figure here (PNG, PDF, SVG: the suffix decides); None: only return it.
    title
        Figure title; default: the maximum displacement.
    color_by
        One of :data:`COLOR_FIELDS`: ``"displacement"`` (``|u|``, m, viridis from 0),
        ``"von_mises"`` (Pa, viridis from 0), ``"pressure"`` (Pa, mixed formulation only; blue
        negative, red positive, symmetric about 0) or ``"J"`` (volume ratio; blue compressed,
        red dilated, symmetric about 1).
    ax
        A 3-D Axes to draw into (``fig.add_subplot(projection="3d")``); default: a new Figure.

    Raises
    ------
    InputError
        An unknown ``color_by``, or ``"pressure"`` for a result without pressure.
    """
    from matplotlib import cm, colormaps, colors
    from matplotlib.ticker import FixedLocator, MaxNLocator, ScalarFormatter
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    mesh = result.mesh
    faces = mesh.boundary_faces()
    rest = mesh.points
    deformed = result.positions
    face_value, values, bar_label = _surface_field(result, faces, color_by)
    vmax_u = float(np.linalg.norm(result.displacement, axis=1).max(initial=0.0))

    own = ax is None
    if not own and not hasattr(ax, "add_collection3d"):
        raise InputError(f"ax: expected a 3-D matplotlib Axes (projection='3d'), got {type(ax).__name__}")
    fig, (ax,) = _axes(ax, 1, (8.0, 6.0), "ax", projection="3d")

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
    # Seen from azimuth -60 the y axis starts where x ends and z rises where y ends: y's ticks
    # keep off both ends and z's off its lower end, so no two labels meet at a corner. Short
    # axes of a slender body get a single tick, at their middle.
    for axis, length, mid, keep_off in zip((ax.xaxis, ax.yaxis, ax.zaxis), span, center,
                                           ((False, False), (True, True), (True, False))):
        if length > 0.3 * span.max():
            lo_tick, hi_tick = mid - length / 2, mid + length / 2
            margin = 0.12 * length
            ticks = MaxNLocator(nbins=4).tick_values(lo_tick, hi_tick)
            ticks = [t for t in ticks if lo_tick + margin * keep_off[0] - 1e-12 * length <= t
                     <= hi_tick - margin * keep_off[1] + 1e-12 * length]
        else:  # one round value near the middle (0 rather than -3e-05 on a centred axis)
            step = 10.0 ** (math.floor(math.log10(length)) - 1) if length > 0 else 1.0
            ticks = [round(mid / step) * step + 0.0]
        axis.set_major_locator(FixedLocator(ticks))
        axis.set_major_formatter(ScalarFormatter(useOffset=False))
    # Labels clear their tick labels; a short axis has one tick, and its label stays close.
    pads = [(8 if axis_long else 2) + (4 if k == 2 else 0) for k, axis_long in enumerate(span > 0.3 * span.max())]
    ax.set_xlabel("x [m]", labelpad=pads[0])
    ax.set_ylabel("y [m]", labelpad=pads[1])
    ax.set_zlabel("z [m]", labelpad=pads[2])
    ax.view_init(elev=20, azim=-60)

    mappable = cm.ScalarMappable(norm=norm, cmap=cmap)
    mappable.set_array(values)
    fig.colorbar(mappable, ax=ax, shrink=0.6, pad=0.15, label=bar_label)
    ax.set_title(title if title is not None else f"rest (grey) and deformed; max |u| = {vmax_u:.3g} m")
    if path is not None:
        fig.savefig(os.fspath(path))
    return fig


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
    path: str | os.PathLike[str] | None = None,
    tolerance: float | None = None,
    *,
    ax: Any = None,
) -> Any:
    """Relative residual against Newton iteration (log scale); returns the Figure.

    Iteration 0 is the initial residual, so "converged after n iterations" ends at n.

    Parameters
    ----------
    report
        A :class:`~sorofem.SolveReport` (a ``ConvergenceError.report`` works too).
    path
        Write the figure here; None: only return it.
    tolerance
        If given, drawn as a dashed horizontal line.
    ax
        An Axes to draw into; default: a new Figure.
    """
    from matplotlib.ticker import MaxNLocator

    residuals = np.asarray(report.residual_history, dtype=np.float64)
    own = ax is None
    fig, (ax,) = _axes(ax, 1, (6.0, 4.0), "ax")
    if residuals.size:
        # Zeros (exact solves) cannot be shown on a log axis; clip to the smallest double.
        shown = np.clip(residuals, np.finfo(float).tiny, None)
        ax.semilogy(np.arange(residuals.size), shown, "o-", markersize=4)
    else:
        ax.set_yscale("log")
        ax.text(0.5, 0.5, "no iterations recorded", ha="center", va="center", transform=ax.transAxes)
    if tolerance is not None:
        ax.axhline(tolerance, color="grey", linestyle="--", linewidth=1, label=f"tolerance {tolerance:g}")
        ax.legend()
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("Newton iteration (0: initial residual)")
    ax.set_ylabel("relative residual norm")
    status = "converged" if report.converged else "not converged"
    ax.set_title(f"Newton: {status} after {plural(report.iterations, 'iteration')}")
    ax.grid(True, which="both", alpha=0.3)
    return _finish(fig, path, own)


def plot_trajectory(
    trajectory: Trajectory, path: str | os.PathLike[str] | None = None, title: str | None = None, *, ax: Any = None
) -> Any:
    """Largest displacement and kinetic energy (log scale) against time; returns the Figure.

    Parameters
    ----------
    trajectory
        A :class:`~sorofem.Trajectory`.
    path
        Write the figure here; None: only return it.
    title
        Title of the upper panel; default: steps, time step and Newton iterations.
    ax
        Two Axes to draw into (displacement, kinetic energy); default: a new Figure.
    """
    own = ax is None
    fig, (ax, ax_e) = _axes(ax, 2, (6.5, 5.0), "ax")
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
        f"{plural(steps, 'step')} of {trajectory.dt:g} s, {plural(int(trajectory.iterations.sum()), 'Newton iteration')}, "
        f"{plural(trajectory.cutbacks, 'cutback')}"
    ))
    return _finish(fig, path, own)


def plot_fit(result: Any, path: str | os.PathLike[str] | None = None, *, ax: Any = None) -> Any:
    """What an inverse problem reached: the target's goal points (data, open circles) against
    where the model puts the observed points (dots), projected on the plane of the two
    coordinates they spread most along, and the RMS misfit against the optimiser's iteration
    (iteration 0: the starting point; one line per start). Returns the Figure.

    Parameters
    ----------
    result
        A :class:`~sorofem.inverse.FitResult` (:func:`sorofem.estimate`) or
        :class:`~sorofem.inverse.ControlResult` (:func:`sorofem.control`).
    path
        Write the figure here (``fit.png`` of ``sorofem estimate`` and ``control``).
    ax
        Two Axes to draw into (markers, misfit history); default: a new Figure.
    """
    own = ax is None
    if own:
        fig = _new_figure((10.0, 4.5))
        axes = [fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)]
    else:
        fig, axes = _axes(ax, 2, (10.0, 4.5), "ax")
    ax_m, ax_h = axes
    markers = result.markers()
    # Contact-force targets observe a force (N) where the others observe points (shown in mm).
    targets = getattr(result, "targets", [])
    forces = bool(targets) and all(getattr(t, "mode", "") == "contact_force" for _, t in targets)
    unit, scale, quantity = ("N", 1.0, "F_") if forces else ("mm", 1e3, "")
    if markers:
        every = np.vstack([np.vstack([model, goal]) for model, goal, _ in markers])
        span = every.max(axis=0) - every.min(axis=0)
        i, j = np.sort(np.argsort(span)[-2:])
        names = "xyz"
        for k, (model, goal, name) in enumerate(markers):
            colour = f"C{k}"
            label = f" ({name})" if len(markers) > 1 else ""
            if len(goal) <= 300:  # few points: join each to its goal
                ax_m.plot(np.c_[model[:, i], goal[:, i]].T, np.c_[model[:, j], goal[:, j]].T, color="grey",
                          linewidth=0.5, alpha=0.6)
            ax_m.scatter(goal[:, i], goal[:, j], s=14, facecolors="none", edgecolors=colour, linewidths=0.7,
                         label=f"data (goal){label}")
            ax_m.scatter(model[:, i], model[:, j], s=4, color="k" if len(markers) == 1 else colour,
                         label=f"model{label}")
        ax_m.set_aspect("equal", adjustable="datalim")
        ax_m.set_xlabel(f"{quantity}{names[i]} [{'N' if forces else 'm'}]")
        ax_m.set_ylabel(f"{quantity}{names[j]} [{'N' if forces else 'm'}]")
        ax_m.legend(loc="best", fontsize="small")
        distances = np.concatenate([np.linalg.norm(model - goal, axis=1) for model, goal, _ in markers])
        ax_m.set_title(f"{distances.size} {'force' if forces else 'point'}{'s' if distances.size != 1 else ''}: "
                       f"rms {scale * np.sqrt(np.mean(distances**2)):.3g} {unit}, "
                       f"max {scale * distances.max(initial=0.0):.3g} {unit}", fontsize="medium")
    history = [e for e in result.history if np.isfinite(e.get("rms", np.nan))]
    starts = sorted({int(e.get("start", 0)) for e in history})
    for start in starts:
        rows = [e for e in history if int(e.get("start", 0)) == start]
        ax_h.plot([e["iteration"] for e in rows], [scale * e["rms"] for e in rows], "o-", markersize=3,
                  label=f"start {start}" if len(starts) > 1 else None)
    rms = np.array([e["rms"] for e in history])
    if rms.size and rms.min() > 0 and rms.max() / rms.min() > 10:  # a log axis only when it spans decades
        ax_h.set_yscale("log")
    if len(starts) > 1:
        ax_h.legend(fontsize="small")
    from matplotlib.ticker import MaxNLocator

    ax_h.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax_h.set_xlabel("iteration (0: the start)")
    ax_h.set_ylabel(f"{'force error' if forces else 'rms misfit'} [{unit}]")
    ax_h.grid(True, which="both", alpha=0.3)
    ax_h.set_title("misfit history", fontsize="medium")
    return _finish(fig, path, own)


def plot_profile(profile: Any, path: str | os.PathLike[str] | None = None, *, ax: Any = None) -> Any:
    """The misfit along a profiled parameter (the others re-fitted at each value), with the
    likelihood-ratio interval shaded and the re-fitted parameters on a second axis. Returns the
    Figure.

    Parameters
    ----------
    profile
        A :class:`~sorofem.inverse.FitResult` with a profile (its symbols and units label the
        axes) or a :class:`~sorofem.inverse.Profile`.
    path
        Write the figure here.
    ax
        An Axes to draw into (the second axis is its twin); default: a new Figure.

    Raises
    ------
    InputError
        A FitResult without a profile (``sf.estimate(..., profile=True)`` computes one).
    """
    symbol = getattr(profile, "symbol", None)
    if hasattr(profile, "params") and hasattr(profile, "uncertainty"):  # a FitResult
        if profile.profile is None:
            raise InputError("profile: the fit has no profile; pass profile=True (or a parameter name) to sf.estimate")
        profile = profile.profile
    label = symbol if callable(symbol) else (lambda n: (n, ""))

    def axis_label(name: str) -> str:
        sym, units = label(name)
        return f"{sym} [{units}]" if units else sym

    own = ax is None
    fig, (ax,) = _axes(ax, 1, (6.5, 4.5), "ax")
    values, rms = np.asarray(profile.values), np.asarray(profile.rms)
    ok = np.isfinite(rms)
    ax.plot(values[ok], rms[ok] * 1e3, "o-", color="C0", label="rms misfit")
    lo, hi = profile.interval
    if np.isfinite(lo) and np.isfinite(hi):
        ax.axvspan(lo, hi, color="C0", alpha=0.12, label=f"{100 * profile.confidence:g} % interval")
    if getattr(profile, "log_scale", False):
        ax.set_xscale("log")
    ax.set_xlabel(axis_label(profile.name))
    ax.set_ylabel("rms misfit [mm]", color="C0")
    ax.grid(True, which="both", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if profile.params:
        twin = ax.twinx()
        for k, (name, fitted) in enumerate(profile.params.items()):
            fitted = np.asarray(fitted)
            line, = twin.plot(values[ok], fitted[ok], "s--", color=f"C{k + 1}", markersize=4,
                              label=f"{label(name)[0]} re-fitted")
            handles.append(line)
            labels.append(line.get_label())
        twin.set_ylabel(", ".join(axis_label(n) for n in profile.params))
    ax.legend(handles, labels, loc="best", fontsize="small")
    ax.set_title(f"profile of {label(profile.name)[0]}: the others re-fitted at each value", fontsize="medium")
    return _finish(fig, path, own)

"""Colours of the viewer's surfaces: the colour fields of :mod:`sorofem.plot` averaged to the nodes,
and their maps (viridis for magnitudes, a diverging map centred on the neutral value otherwise)."""

from __future__ import annotations

import io

import numpy as np
from numpy.typing import NDArray

from ..plot import COLOR_FIELDS, FIELD_CENTRES, result_field
from ..static import StaticResult

__all__ = ["COLOR_FIELDS", "DISPLAY_UNITS", "nodal_field", "colour_field", "colour_by_magnitude", "colour_range",
           "colour_bar_html", "surface_edges", "surface_glb"]


def nodal_field(result: StaticResult, field_name: str) -> tuple[NDArray[np.float64], str]:
    """Per node the value of ``field_name`` (one of :data:`sorofem.plot.COLOR_FIELDS`) and its
    label: ``displacement`` (|u|, m), ``pressure`` (Pa, the mixed formulation's nodal field), or
    the element fields ``von_mises`` (Pa) and ``J`` averaged over each node's elements, weighted
    by volume.

    Raises
    ------
    InputError
        An unknown field, or ``pressure`` of a result without one (standard formulation).
    """
    values, nodal, label = result_field(result, field_name, what="colour field")
    if nodal:
        return values, label
    mesh = result.mesh
    weight = np.repeat(mesh.volumes, 4)
    total = np.bincount(mesh.tets.reshape(-1), weights=weight * np.repeat(values, 4), minlength=mesh.n_nodes)
    volume = np.bincount(mesh.tets.reshape(-1), weights=weight, minlength=mesh.n_nodes)
    return total / np.where(volume > 0, volume, 1.0), label


def colour_field(values: NDArray[np.float64], field_name: str) -> tuple[NDArray[np.uint8], str]:
    """RGBA colours ``(n, 4)`` of a field and a description of the scale: magnitudes
    (displacement, von Mises) on viridis from 0 to their maximum, signed fields on a diverging
    map centred on their neutral value (:data:`sorofem.plot.FIELD_CENTRES`: pressure on 0, J on
    1), symmetric about it."""
    from matplotlib import colormaps

    if field_name in FIELD_CENTRES:
        centre = FIELD_CENTRES[field_name]
        spread = colour_range(values, field_name)[1] - centre
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


#: How the colour bar shows each field: (unit, factor from SI). Displacements in mm and
#: stresses in kPa read better than m and Pa at soft-robot scales.
DISPLAY_UNITS = {"displacement": ("mm", 1e3), "von_mises": ("kPa", 1e-3), "pressure": ("kPa", 1e-3), "J": ("", 1.0)}
_BAR_TITLES = {"displacement": "|u|", "von_mises": "von Mises stress", "pressure": "pressure p", "J": "J = det F"}


def colour_range(values: NDArray[np.float64], field_name: str) -> tuple[float, float]:
    """The ``(low, high)`` values :func:`colour_field` maps to the ends of its colour map, in
    the field's SI unit: ``0 .. max`` for magnitudes, symmetric about the neutral value for
    signed fields."""
    if field_name in FIELD_CENTRES:
        centre = FIELD_CENTRES[field_name]
        spread = float(np.max(np.abs(values - centre), initial=0.0))
        return centre - spread, centre + spread
    return 0.0, float(np.max(values, initial=0.0))


def colour_bar_html(field_name: str, low: float, high: float) -> str:
    """A horizontal colour bar (HTML, a CSS gradient sampled from the map) titled with the
    field and its unit (:data:`DISPLAY_UNITS`), with the values at both ends and the middle.

    Examples
    --------
    >>> "mm" in colour_bar_html("displacement", 0.0, 0.012)
    True
    """
    from matplotlib import colormaps

    name = "coolwarm" if field_name in FIELD_CENTRES else "viridis"
    stops = ", ".join(
        "rgb({},{},{}) {:.0f}%".format(*(np.round(np.array(colormaps[name](s)[:3]) * 255).astype(int)), 100 * s)
        for s in np.linspace(0.0, 1.0, 11)
    )
    unit, factor = DISPLAY_UNITS[field_name]
    title = _BAR_TITLES[field_name] + (f" [{unit}]" if unit else "")
    ticks = "".join(f"<span>{v * factor:.3g}</span>" for v in (low, 0.5 * (low + high), high))
    return (
        '<div style="font-size:0.8em;padding:0 0.25em">'
        f'<div style="margin-bottom:2px">{title}</div>'
        f'<div style="height:0.9em;border-radius:2px;background:linear-gradient(to right, {stops})"></div>'
        f'<div style="display:flex;justify-content:space-between">{ticks}</div></div>'
    )


def surface_edges(faces: NDArray[np.int64]) -> NDArray[np.int64]:
    """The unique edges ``(e, 2)`` of triangles ``faces`` ``(f, 3)``, each once, lower index
    first: what a wireframe draws."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0)


def surface_glb(vertices: NDArray[np.float64], faces: NDArray[np.int64], colours: NDArray[np.uint8]) -> bytes:
    """A binary glTF of the triangle surface ``(vertices (k, 3), faces (f, 3))`` with RGBA vertex
    colours ``(k, 4)`` (what viser's ``add_glb`` shows; its plain meshes take one colour)."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, vertex_colors=colours, process=False)
    with io.BytesIO() as buffer:
        mesh.export(buffer, file_type="glb")
        return buffer.getvalue()

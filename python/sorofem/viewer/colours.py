"""Colours of the viewer's surfaces: the colour fields of :mod:`sorofem.plot` averaged to the nodes,
and their maps (viridis for magnitudes, a diverging map centred on the neutral value otherwise)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..plot import COLOR_FIELDS, FIELD_CENTRES, result_field
from ..static import StaticResult

__all__ = ["COLOR_FIELDS", "nodal_field", "colour_field", "colour_by_magnitude"]


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

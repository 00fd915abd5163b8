"""Rigid obstacles the body touches: half-spaces, spheres, boxes and triangle surfaces.

The body never passes through an obstacle: contact follows Incremental Potential Contact (a
log barrier on the distances between the body's boundary and the obstacle, active below the
distance ``dhat``, and a Newton line search bounded by continuous collision detection), with
optional Coulomb friction. Add obstacles with :meth:`sorofem.Body.add_obstacle`; the solves
then report the contact forces.

Examples
--------
>>> import sorofem as sf
>>> table = sf.Plane(point=(0, 0, 0), normal=(0, 0, 1))
>>> ball = sf.Sphere(center=(0.2, 0, 0.1), radius=0.03)
>>> crate = sf.Box(min=(0.3, -0.05, 0), max=(0.4, 0.05, 0.1))
>>> crate.is_closed, crate.vertices.shape
(True, (8, 3))
"""

from __future__ import annotations

import os
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._extension import core
from ._validate import as_finite, describe, positive_scalar
from .errors import InputError, MeshError
from .io import read_surface

__all__ = ["Obstacle", "Plane", "Sphere", "Box", "MeshObstacle", "OpenSurfaceWarning", "obstacle_surface"]


class OpenSurfaceWarning(UserWarning):
    """A triangle surface used as an obstacle is not closed: it is a sheet the body cannot
    cross, not a solid, and its orientation is not checked by the solver."""


class Obstacle:
    """A rigid obstacle (base class): :class:`Plane`, :class:`Sphere`, :class:`Box` or a triangle
    surface from :meth:`Obstacle.mesh`.

    Attributes
    ----------
    kind
        ``"plane"``, ``"sphere"``, ``"box"`` or ``"mesh"``.
    """

    kind: str = ""

    def to_core(self) -> dict[str, Any]:
        """The description the extension takes (``kind`` and the geometry, SI units)."""
        raise NotImplementedError

    @property
    def is_closed(self) -> bool:
        """Whether the obstacle bounds a solid (always, except open triangle surfaces)."""
        return True

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types: ``kind`` and the geometry (a mesh gives its vertex and triangle
        counts, not its arrays)."""
        out: dict[str, Any] = {}
        for key, value in self.to_core().items():
            out[key] = value.tolist() if isinstance(value, np.ndarray) else value
        return out

    @staticmethod
    def mesh(
        source: str | os.PathLike[str] | tuple[ArrayLike, ArrayLike],
        scale: float = 1.0,
        *,
        one_sided: bool = False,
    ) -> "MeshObstacle":
        """A triangle surface as an obstacle, from a file or from arrays.

        Parameters
        ----------
        source
            A surface file (STL, OBJ, PLY, OFF, anything :func:`sorofem.io.read_surface` reads)
            or ``(vertices (n, 3), triangles (m, 3))``.
        scale
            Factor applied to the coordinates (``1e-3`` for a file in millimetres).
        one_sided
            Accept an open surface (not every edge shared by two triangles) as a sheet the body
            cannot cross: without it an open surface is an error, since it bounds no solid.

        Raises
        ------
        MeshError
            Degenerate triangles, indices out of range, or an open surface without
            ``one_sided=True``.

        Warns
        -----
        OpenSurfaceWarning
            For an open surface accepted with ``one_sided=True``.

        Examples
        --------
        >>> import numpy as np, sorofem as sf
        >>> ramp = sf.Obstacle.mesh((np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.2]]), np.array([[0, 1, 2]])),
        ...                         one_sided=True)  # doctest: +SKIP
        """
        scale = positive_scalar(scale, "scale")
        if isinstance(source, tuple):
            if len(source) != 2:
                raise InputError(f"source: expected a file or (vertices, triangles), got a tuple of {len(source)}")
            vertices = as_finite(source[0], "vertices", (None, 3)) * scale
            try:
                triangles = np.asarray(source[1])
            except (TypeError, ValueError):
                raise InputError(f"triangles: expected an integer array (m, 3), got {describe(source[1])}") from None
            if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
                raise InputError(f"triangles: expected an integer array of shape (m, 3), got {describe(source[1])}")
            name = "(vertices, triangles)"
        elif isinstance(source, (str, os.PathLike)):
            surface = read_surface(source, scale)
            vertices, triangles, name = surface.vertices, surface.faces, str(source)
        else:
            raise InputError(f"source: expected a surface file or (vertices, triangles), got {describe(source)}")
        return MeshObstacle(vertices, triangles, one_sided=one_sided, name=name)


class Plane(Obstacle):
    """The half-space on the side of a plane that ``normal`` points to: the body stays there.

    Parameters
    ----------
    point
        A point of the plane ``(3,)``, m.
    normal
        Its normal ``(3,)`` (any length > 0), pointing towards the body.

    Examples
    --------
    >>> import sorofem as sf
    >>> sf.Plane((0, 0, -0.05), (0, 0, 2)).normal.tolist()
    [0.0, 0.0, 1.0]
    """

    kind = "plane"

    def __init__(self, point: ArrayLike, normal: ArrayLike) -> None:
        self.point = as_finite(point, "point", (3,))
        normal = as_finite(normal, "normal", (3,))
        length = float(np.linalg.norm(normal))
        if length == 0.0:
            raise InputError("normal: expected a nonzero vector, got [0, 0, 0]")
        self.normal = normal / length

    def to_core(self) -> dict[str, Any]:
        return {"kind": self.kind, "point": self.point, "normal": self.normal}

    def __repr__(self) -> str:
        return f"Plane(point={self.point.tolist()}, normal={self.normal.tolist()})"


class Sphere(Obstacle):
    """A solid ball; the body stays outside.

    Parameters
    ----------
    center
        ``(3,)``, m.
    radius
        m, > 0.
    """

    kind = "sphere"

    def __init__(self, center: ArrayLike, radius: float) -> None:
        self.center = as_finite(center, "center", (3,))
        self.radius = positive_scalar(radius, "radius")

    def to_core(self) -> dict[str, Any]:
        return {"kind": self.kind, "center": self.center, "radius": self.radius}

    def __repr__(self) -> str:
        return f"Sphere(center={self.center.tolist()}, radius={self.radius:g})"


class _TriangleObstacle(Obstacle):
    """An obstacle the solver sees as triangles: its vertices (m) and triangles."""

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]
    _closed: bool = True

    def _take_geometry(self) -> None:
        checked = core().check_obstacle(self.to_core())
        self.vertices = np.asarray(checked["vertices"], dtype=np.float64)
        self.triangles = np.asarray(checked["triangles"], dtype=np.int64)
        self._closed = bool(checked["closed"])

    @property
    def is_closed(self) -> bool:
        return self._closed


class Box(_TriangleObstacle):
    """A solid box: axis-aligned from ``min`` to ``max``, or oriented (:meth:`Box.oriented`).
    The solver sees its 12 triangles, so its edges and corners are sharp.

    Parameters
    ----------
    min, max
        Opposite corners ``(3,)``, m, with ``max > min`` in every coordinate.

    Examples
    --------
    >>> import numpy as np, sorofem as sf
    >>> turned = sf.Box.oriented(center=(0, 0, 0), half_extents=(0.1, 0.05, 0.05),
    ...                          rotation=[[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    >>> turned.half_extents.tolist()
    [0.1, 0.05, 0.05]
    """

    kind = "box"

    def __init__(self, min: ArrayLike, max: ArrayLike) -> None:  # noqa: A002 - the natural names
        lo = as_finite(min, "min", (3,))
        hi = as_finite(max, "max", (3,))
        if np.any(hi <= lo):
            raise InputError(f"box: expected max > min in every coordinate, got min {lo.tolist()}, max {hi.tolist()}")
        self.center = 0.5 * (lo + hi)
        self.half_extents = 0.5 * (hi - lo)
        self.rotation = np.eye(3)
        self._take_geometry()

    @classmethod
    def oriented(cls, center: ArrayLike, half_extents: ArrayLike, rotation: ArrayLike) -> "Box":
        """The box ``center + R diag(half_extents) [-1, 1]^3``.

        Parameters
        ----------
        center
            ``(3,)``, m.
        half_extents
            ``(3,)``, m, each > 0.
        rotation
            ``(3, 3)`` rotation matrix ``R`` (``R^T R = I``, ``det R = 1``).
        """
        box = cls.__new__(cls)
        box.center = as_finite(center, "center", (3,))
        box.half_extents = as_finite(half_extents, "half_extents", (3,))
        box.rotation = as_finite(rotation, "rotation", (3, 3))
        box._take_geometry()
        return box

    def to_core(self) -> dict[str, Any]:
        return {"kind": self.kind, "center": self.center, "half_extents": self.half_extents,
                "rotation": np.ascontiguousarray(self.rotation)}

    def __repr__(self) -> str:
        return f"Box(center={self.center.tolist()}, half_extents={self.half_extents.tolist()})"


class MeshObstacle(_TriangleObstacle):
    """A rigid triangle surface (see :meth:`Obstacle.mesh`, which builds one from a file).

    Parameters
    ----------
    vertices
        ``(n, 3)``, m.
    triangles
        ``(m, 3)`` vertex indices, 0-based; a closed surface should be oriented outwards.
    one_sided
        Accept an open surface (see :meth:`Obstacle.mesh`).
    name
        What messages call it.
    """

    kind = "mesh"

    def __init__(self, vertices: ArrayLike, triangles: ArrayLike, *, one_sided: bool = False,
                 name: str = "(vertices, triangles)") -> None:
        self.vertices = as_finite(vertices, "vertices", (None, 3))
        self.triangles = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64))
        self.name = name
        try:
            self._take_geometry()
        except InputError as err:
            raise MeshError(f"obstacle mesh {name}: {err}") from None
        if not self._closed:
            if not one_sided:
                raise MeshError(
                    f"obstacle mesh {name}: the surface is open (some edge is not shared by exactly two triangles "
                    "of opposite orientation), so it bounds no solid; pass one_sided=True to use it as a sheet "
                    "the body cannot cross"
                )
            warnings.warn(
                f"obstacle mesh {name}: open surface used as a one-sided sheet. Its orientation is not checked: "
                "the body may start on either side but can never cross it; make sure its triangles (right-hand "
                "rule) face the body, as a closed mesh's face outwards",
                OpenSurfaceWarning,
                stacklevel=3,
            )

    def to_core(self) -> dict[str, Any]:
        return {"kind": self.kind, "vertices": np.ascontiguousarray(self.vertices),
                "triangles": np.ascontiguousarray(self.triangles)}

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "name": self.name, "vertices": int(len(self.vertices)),
                "triangles": int(len(self.triangles)), "closed": self._closed}

    def __repr__(self) -> str:
        return f"MeshObstacle({self.name}, {len(self.vertices)} vertices, {len(self.triangles)} triangles)"


def obstacle_surface(
    obstacle: Obstacle, extent: ArrayLike, around: ArrayLike = (0.0, 0.0, 0.0)
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Triangles to draw an obstacle with: a plane as the rectangle where it crosses the box of
    half-sizes ``extent`` ``(3,)`` (m) centred on ``around`` (approximately: the projection of
    the box onto the plane), a sphere as a UV sphere, boxes and meshes as they are."""
    if isinstance(obstacle, _TriangleObstacle):
        return obstacle.vertices, obstacle.triangles
    if isinstance(obstacle, Sphere):
        theta, phi = np.meshgrid(np.linspace(0, np.pi, 13), np.linspace(0, 2 * np.pi, 25), indexing="ij")
        points = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
        vertices = obstacle.center + obstacle.radius * points.reshape(-1, 3)
        rows, cols = theta.shape
        quads = [(i * cols + j, i * cols + j + 1, (i + 1) * cols + j + 1, (i + 1) * cols + j)
                 for i in range(rows - 1) for j in range(cols - 1)]
        triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int64)
        return vertices, triangles
    if isinstance(obstacle, Plane):
        axis = np.eye(3)[int(np.argmin(np.abs(obstacle.normal)))]
        u = np.cross(obstacle.normal, axis)
        u /= np.linalg.norm(u)
        v = np.cross(obstacle.normal, u)
        centre = np.asarray(around, dtype=np.float64)
        centre = centre - obstacle.normal * float(np.dot(centre - obstacle.point, obstacle.normal))
        half = np.abs(np.asarray(extent, dtype=np.float64))
        du, dv = float(np.dot(np.abs(u), half)), float(np.dot(np.abs(v), half))
        corners = [centre + a * du * u + b * dv * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        return np.array(corners), np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    raise InputError(f"obstacle: expected a sorofem obstacle, got {describe(obstacle)}")

"""The tetrahedral mesh: rest coordinates, tetrahedra, node queries, reading and writing.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> mesh.n_nodes, mesh.n_tets
(81, 192)
>>> mesh.nodes_on_plane(point=(0, 0, 0), normal=(1, 0, 0)).size
9
"""

from __future__ import annotations

import math
import numbers
import os
import warnings
from functools import cached_property
from pathlib import Path
from typing import Callable, NamedTuple, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._extension import core
from ._files import check_path
from ._formats import read_volume, refuse_overwrite, write_volume
from ._validate import MAX_INDEX, MESH_SIZE, as_finite, as_float_array, check_memory, count, describe, positive_scalar
from .errors import InputError, MeshError, ParameterError, ShapeError

__all__ = ["Mesh", "Bounds", "ORIENTATIONS"]


class Bounds(NamedTuple):
    """Axis-aligned bounding box: ``min`` and ``max``, each ``(3,)``, m.

    Calling it (``mesh.bounds()``, from when :attr:`Mesh.bounds` was a method) still works for
    one release and warns; use the property ``mesh.bounds``.
    """

    min: NDArray[np.float64]
    max: NDArray[np.float64]

    def __call__(self) -> "Bounds":
        warnings.warn("Mesh.bounds() is deprecated: bounds is a property, use mesh.bounds (without the call)",
                      DeprecationWarning, stacklevel=2)
        return self

#: Bytes a mesh holds per node and per tetrahedron while it is built (the extension's arrays,
#: NumPy's copy and the checked copy): the estimate :meth:`Mesh.box` checks against the
#: machine's memory before it allocates anything.
MESH_BYTES_PER_NODE = 3 * 24
MESH_BYTES_PER_TET = 3 * 32

#: What :class:`Mesh` does with inverted tetrahedra: swap two nodes, or raise.
ORIENTATIONS: tuple[str, ...] = ("reorient", "reject")


def _check_size(extent: NDArray[np.float64], name: str) -> None:
    """A :class:`MeshError` unless the bounding-box diagonal of ``extent`` (its edge lengths, m)
    is within the documented :data:`~sorofem._validate.MESH_SIZE`."""
    top = float(np.max(np.abs(extent)))
    diagonal = top * float(np.linalg.norm(extent / top)) if top > 0 else 0.0
    if not MESH_SIZE[0] <= diagonal <= MESH_SIZE[1]:
        raise MeshError(
            f"{name}: the mesh's size (bounding-box diagonal) is {diagonal:g} m; expected from {MESH_SIZE[0]:g} "
            f"to {MESH_SIZE[1]:g} m (a documented limit: beyond it volumes and stiffnesses leave the range of "
            "float64; check the units, e.g. a scale of 1e-3 for millimetres)"
        )


class Mesh:
    """A linear tetrahedral mesh (rest configuration).

    Parameters
    ----------
    points
        Node coordinates, shape ``(n_nodes, 3)``, metres.
    tets
        Node indices of each tetrahedron, shape ``(n_tets, 4)``, 0-based integers.
    orientation
        ``"reorient"`` (default) swaps two nodes of every inverted tetrahedron (negative
        signed volume) and records them in :attr:`reoriented`; ``"reject"`` raises
        :class:`~sorofem.MeshError` instead.

    Raises
    ------
    ShapeError
        Wrong shapes or dtypes.
    MeshError
        Non-finite coordinates, indices out of range, degenerate tetrahedra.

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    >>> mesh.n_nodes, mesh.n_tets, round(float(mesh.volumes[0]), 6)
    (4, 1, 0.166667)
    """

    def __init__(self, points: ArrayLike, tets: ArrayLike, orientation: str = "reorient") -> None:
        if not isinstance(orientation, str) or orientation not in ORIENTATIONS:
            raise InputError(f"orientation: expected one of {ORIENTATIONS}, got {orientation!r}")
        pts = as_float_array(points, "points", (None, 3))
        tet_arr = np.asarray(tets)
        if tet_arr.size == 0 and tet_arr.ndim < 2:
            tet_arr = tet_arr.reshape(0, 4).astype(np.int64)
        if tet_arr.dtype == np.bool_ or not np.issubdtype(tet_arr.dtype, np.integer):
            raise ShapeError(f"tets: expected an integer array of node indices, got {describe(tet_arr)}")
        if tet_arr.ndim != 2 or tet_arr.shape[1] != 4:
            raise ShapeError(f"tets: expected shape (m, 4), got shape {tet_arr.shape}")
        if len(tet_arr) == 0:
            raise MeshError("tets: the mesh has no tetrahedra")
        tet_arr = np.ascontiguousarray(tet_arr, dtype=np.int64)
        # Cheap checks here give messages with Python-side context; the extension
        # repeats them and adds the geometric ones (degenerate, inverted).
        if not np.all(np.isfinite(pts)):
            row = int(np.argwhere(~np.isfinite(pts))[0, 0])
            raise MeshError(f"points: expected finite coordinates, got {pts[row].tolist()} at node {row}")
        _check_size(pts.max(axis=0) - pts.min(axis=0) if len(pts) else np.zeros(3), "points")
        if tet_arr.min() < 0 or tet_arr.max() >= len(pts):
            bad = int(np.argwhere((tet_arr < 0) | (tet_arr >= len(pts)))[0, 0])
            raise MeshError(
                f"tets: node indices must be in [0, {len(pts)}), got {tet_arr[bad].tolist()} in tet {bad}"
            )
        checked, reoriented = core().check_mesh(pts, tet_arr, orientation)
        pts.setflags(write=False)
        checked = np.ascontiguousarray(checked, dtype=np.int64)
        checked.setflags(write=False)
        self._points = pts
        self._tets = checked
        self._reoriented = np.asarray(reoriented, dtype=np.int64)
        self._reoriented.setflags(write=False)
        #: The file this mesh was read from (set by :func:`sorofem.io.read_mesh`), so
        #: writers can refuse to overwrite it.
        self.source: Path | None = None
        #: The file's integer tag of each tetrahedron (a Gmsh physical group, a TetGen region
        #: attribute, a Medit reference), ``(n_tets,)`` int64 in the order of :attr:`tets`, or
        #: None (set by :func:`sorofem.io.read_mesh`; kept by :meth:`scaled` and :meth:`transformed`).
        self.cell_tags: NDArray[np.int64] | None = None

    # -- constructors -------------------------------------------------------------

    @classmethod
    def box(
        cls,
        size: ArrayLike = (1.0, 1.0, 1.0),
        cells: ArrayLike = (1, 1, 1),
        origin: ArrayLike = (0.0, 0.0, 0.0),
    ) -> "Mesh":
        """A box ``[origin, origin + size]`` split into ``cells`` hexahedra of 6 tets each.

        Node ``(i, j, k)`` of the grid has index ``i + (nx+1) * (j + (ny+1) * k)``.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
        >>> mesh.n_nodes, mesh.n_tets
        (81, 192)
        """
        size_arr = as_finite(size, "size", (3,))
        if np.any(size_arr <= 0):
            raise ParameterError(f"size: expected three positive lengths, got {size_arr.tolist()}", "size")
        _check_size(size_arr, "size")
        values = cells.tolist() if isinstance(cells, np.ndarray) else cells
        if not isinstance(values, (list, tuple)) or len(values) != 3:
            raise ParameterError(f"cells: expected three integers from 1 to {MAX_INDEX}, got {describe(cells)}", "cells")
        nx, ny, nz = cells_list = [count(c, "cells", 1, MAX_INDEX) for c in values]
        n_nodes, n_tets = (nx + 1) * (ny + 1) * (nz + 1), 6 * nx * ny * nz
        check_memory(MESH_BYTES_PER_NODE * n_nodes + MESH_BYTES_PER_TET * n_tets,
                     f"a box of {nx} x {ny} x {nz} cells ({n_tets:.3g} tetrahedra)", "cells")
        origin_arr = as_finite(origin, "origin", (3,))
        points, tets = core().box_mesh(size_arr, np.array(cells_list, dtype=np.int64), origin_arr)
        return cls(points, tets)

    @classmethod
    def read(cls, path: str | os.PathLike[str], scale: float = 1.0) -> "Mesh":
        """Read a mesh file: the ``.tet`` text format, Gmsh ``.msh`` (2.2, 4.x; also fTetWild's),
        a TetGen ``.node``/``.ele`` pair (0- or 1-based) or anything else meshio reads.

        Only the linear tetrahedra are kept: triangles, lines and points beside them (Gmsh
        physical surfaces, for instance) are skipped and nodes no tetrahedron uses are dropped;
        other volume cells (``tetra10``, hexahedra) are an error. A per-tetrahedron integer tag
        in the file (Gmsh physical group, TetGen region attribute) becomes :attr:`cell_tags`.
        :func:`sorofem.io.read_mesh` is the same function.

        Raises
        ------
        FileNotFoundError
            No such file (for TetGen: either file of the pair).
        MeshError
            A malformed ``.tet`` line (the message gives file and line), no tetrahedra, volume
            cells other than linear tetrahedra (``tetra10``, hexahedra, ...), or an invalid mesh.

        Examples
        --------
        >>> mesh = sf.Mesh.read("box2.tet", scale=1.0)  # doctest: +SKIP
        """
        path = check_path(path, "path")
        if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not (0 < scale < float("inf")):
            raise ParameterError(f"scale: expected a finite positive number, got {scale!r}", "scale")
        points, tets, tags = read_volume(path)
        try:
            mesh = cls(points * float(scale), tets)
        except InputError as exc:
            raise MeshError(f"{path}: {exc}") from None
        mesh.source = path
        if tags is not None:
            tags.setflags(write=False)
            mesh.cell_tags = tags
        return mesh

    def write(self, path: str | os.PathLike[str]) -> None:
        """Write the mesh as ``.tet`` (full float precision) or through meshio, by the suffix of
        ``path`` (:func:`sorofem.io.write_mesh` is the same function).

        Raises
        ------
        InputError
            ``path`` is the file the mesh was read from (:attr:`source`).
        """
        path = check_path(path, "path")
        refuse_overwrite(path, self.source)
        write_volume(path, self._points, self._tets)

    def scaled(self, factor: float) -> "Mesh":
        """A copy with coordinates multiplied by ``factor`` (> 0, so orientation is kept)."""
        factor = positive_scalar(factor, "factor")
        return self._derived(self._points * factor, self._tets)

    # -- data -----------------------------------------------------------------------

    @property
    def points(self) -> NDArray[np.float64]:
        """Rest coordinates, ``(n_nodes, 3)`` float64, read-only."""
        return self._points

    @property
    def tets(self) -> NDArray[np.int64]:
        """Tetrahedra, ``(n_tets, 4)`` int64, read-only, positively oriented."""
        return self._tets

    @property
    def n_nodes(self) -> int:
        return int(self._points.shape[0])

    @property
    def n_tets(self) -> int:
        return int(self._tets.shape[0])

    @property
    def reoriented(self) -> NDArray[np.int64]:
        """Indices of the tetrahedra that were inverted in the input and have been fixed."""
        return self._reoriented

    @cached_property
    def volumes(self) -> NDArray[np.float64]:
        """Rest volume of each tetrahedron, ``(n_tets,)``, m^3."""
        vol = np.asarray(core().rest_volumes(self._points, self._tets), dtype=np.float64)
        vol.setflags(write=False)
        return vol

    def boundary_faces(self) -> NDArray[np.int64]:
        """Outward-oriented boundary triangles, ``(k, 3)`` int64 (computed once)."""
        faces = self.__dict__.get("_boundary_faces")
        if faces is None:
            faces = np.asarray(core().boundary_faces(self._points, self._tets), dtype=np.int64)
            faces.setflags(write=False)
            self.__dict__["_boundary_faces"] = faces
        return faces

    @property
    def bounds(self) -> Bounds:
        """Axis-aligned bounding box ``(min, max)``, each ``(3,)``, m: ``lo, hi = mesh.bounds``."""
        return Bounds(self._points.min(axis=0), self._points.max(axis=0))

    @property
    def size(self) -> float:
        """Length of the bounding-box diagonal, m: the mesh's length scale."""
        lo, hi = self.bounds
        return float(np.linalg.norm(hi - lo))

    # -- node queries -----------------------------------------------------------------

    def nodes_in_box(self, min: ArrayLike, max: ArrayLike) -> NDArray[np.int64]:  # noqa: A002
        """Sorted indices of the nodes inside the closed box ``[min, max]``.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
        >>> mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)).size
        9
        """
        lo = as_float_array(min, "min", (3,))
        hi = as_float_array(max, "max", (3,))
        if np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
            raise InputError(f"min, max: expected numbers, got {lo.tolist()}, {hi.tolist()}")
        if np.any(lo > hi):
            raise InputError(f"min, max: expected min <= max componentwise, got {lo.tolist()} and {hi.tolist()}")
        inside = np.all((self._points >= lo) & (self._points <= hi), axis=1)
        return np.flatnonzero(inside).astype(np.int64)

    def nodes_on_plane(self, point: ArrayLike, normal: ArrayLike, tol: float = 1e-9) -> NDArray[np.int64]:
        """Sorted indices of the nodes within a distance of the plane through ``point``.

        Parameters
        ----------
        point, normal
            A point on the plane and its normal (any non-zero length).
        tol
            Tolerance **relative to the mesh size** (bounding-box diagonal): a node is
            on the plane when its distance is at most ``tol * mesh.size``. Relative so
            that the same value works for a mesh in metres or in millimetres.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
        >>> mesh.nodes_on_plane(point=(1, 0, 0), normal=(1, 0, 0)).size
        9
        """
        p = as_finite(point, "point", (3,))
        n = as_finite(normal, "normal", (3,))
        length = float(np.linalg.norm(n))
        if length == 0:
            raise InputError("normal: expected a non-zero vector, got [0, 0, 0]")
        if isinstance(tol, bool) or not isinstance(tol, numbers.Real) or not (tol >= 0 and math.isfinite(tol)):
            raise InputError(f"tol: expected a finite number >= 0, got {describe(tol)}")
        dist = np.abs((self._points - p) @ (n / length))
        return np.flatnonzero(dist <= tol * self.size).astype(np.int64)

    def nodes_where(self, predicate: Callable[[NDArray[np.float64]], ArrayLike]) -> NDArray[np.int64]:
        """Sorted indices of the nodes for which ``predicate(points)`` is true.

        ``predicate`` receives all rest coordinates ``(n_nodes, 3)`` at once and returns a
        boolean mask ``(n_nodes,)``.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
        >>> mesh.nodes_where(lambda p: p[:, 0] > 0.99).size
        9
        """
        mask = np.asarray(predicate(self._points))
        if mask.dtype != np.bool_ or mask.shape != (self.n_nodes,):
            raise ShapeError(
                f"predicate: expected it to return a boolean mask of shape ({self.n_nodes},), "
                f"got {describe(mask)}"
            )
        return np.flatnonzero(mask).astype(np.int64)

    def __repr__(self) -> str:
        lo, hi = self.bounds
        fmt = lambda v: "[" + ", ".join(f"{x:.4g}" for x in v) + "]"  # noqa: E731
        extra = f", reoriented={self._reoriented.size}" if self._reoriented.size else ""
        src = f", source='{self.source}'" if self.source is not None else ""
        return f"Mesh(n_nodes={self.n_nodes}, n_tets={self.n_tets}, bounds={fmt(lo)}..{fmt(hi)}{extra}{src})"

    # -- axis permutation ---------------------------------------------------------------

    #: Names accepted by :meth:`transformed`: an old axis, optionally signed.
    AXIS_NAMES: tuple[str, ...] = ("x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z")

    def transformed(self, axes: Sequence[str]) -> "Mesh":
        """A copy with its axes permuted and flipped: new coordinate ``i`` is old axis ``axes[i]``.

        ``axes`` is a signed permutation of the old axes, three of :attr:`AXIS_NAMES`, each of
        x, y, z once. ``["x", "-z", "y"]`` turns a mesh drawn with y up into one with z up
        (new y = -old z, new z = old y). Node and element indices are kept. A reflection (an odd
        number of swaps and sign flips) would invert every tetrahedron: two nodes of each are
        swapped so that the tets stay positively oriented; :attr:`reoriented` is carried over
        from this mesh (it lists the tets inverted in the input file, not these).

        Raises
        ------
        ParameterError
            ``axes`` is not a signed permutation of x, y, z.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.02), cells=(4, 1, 1))
        >>> [float(v) for v in mesh.transformed(["x", "-z", "y"]).bounds[1]]
        [0.4, 0.0, 0.1]
        """
        names = list(axes) if isinstance(axes, (list, tuple)) else None
        if (
            names is None
            or len(names) != 3
            or not all(isinstance(a, str) and a in self.AXIS_NAMES for a in names)
            or sorted(a[-1] for a in names) != ["x", "y", "z"]
        ):
            raise ParameterError(
                "axes: expected a signed permutation of the axes, three of "
                f"{', '.join(repr(a) for a in self.AXIS_NAMES)} with each of x, y, z once "
                f"(e.g. ['x', '-z', 'y']), got {axes!r}",
                "axes",
            )
        order = ["xyz".index(name[-1]) for name in names]
        signs = np.array([-1.0 if name.startswith("-") else 1.0 for name in names])
        # det = sign of the permutation times the product of the signs; + 0.0 turns -0.0 into 0.0.
        inversions = sum(order[i] > order[j] for i in range(3) for j in range(i + 1, 3))
        det = (-1.0) ** inversions * float(np.prod(signs))
        tets = self._tets if det > 0 else self._tets[:, [0, 2, 1, 3]]
        return self._derived(self._points[:, order] * signs + 0.0, tets)

    def _derived(self, points: NDArray[np.float64], tets: NDArray[np.int64]) -> "Mesh":
        """A mesh of new coordinates (and tets already positively oriented) that keeps this
        one's :attr:`reoriented`, :attr:`source` and :attr:`cell_tags`."""
        mesh = Mesh(points, tets, orientation="reject")
        mesh._reoriented = self._reoriented
        mesh.source = self.source
        mesh.cell_tags = self.cell_tags
        return mesh

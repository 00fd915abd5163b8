"""Meshes, materials, bodies and the static solve: the model-building API.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
>>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
>>> result.displacement.shape
(81, 3)
>>> result.report.converged
True
"""

from __future__ import annotations

import math
import numbers
import os
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import (
    ConvergenceError,
    InputError,
    MeshError,
    ParameterError,
    ShapeError,
)

try:
    from . import _core
except ImportError as _exc:  # pragma: no cover - only before `make build`
    _core = None
    _CORE_IMPORT_ERROR: ImportError | None = _exc
else:
    _CORE_IMPORT_ERROR = None

__all__ = [
    "FORMULATIONS",
    "VOLUMETRIC_MEASURES",
    "PRESSURE_MASSES",
    "Mesh",
    "NeoHookean",
    "Body",
    "SolveReport",
    "StaticResult",
    "solve_static",
]

#: Formulations the solver accepts: displacement only, or displacement + nodal pressure.
FORMULATIONS: tuple[str, ...] = ("standard", "mixed")
#: Volumetric measures ``c(J)`` of the energy ``lambda/2 c(J)^2``: ``ln J`` or ``J - 1``.
VOLUMETRIC_MEASURES: tuple[str, ...] = ("log", "linear")
#: Pressure mass matrices of the mixed formulation.
PRESSURE_MASSES: tuple[str, ...] = ("consistent", "lumped")

_ORIENTATIONS = ("reorient", "reject")


def _core_module() -> Any:
    if _core is None:
        raise ImportError(
            "the compiled extension sorofem._core is not available; build it with `make build`"
        ) from _CORE_IMPORT_ERROR
    return _core


# ---------------------------------------------------------------------------
# Small validation helpers: every message names the parameter, the expectation and
# what was given, so a user can act on it without reading the source.


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    return f"{type(value).__name__} {value!r}"


def _as_float_array(value: ArrayLike, name: str, shape: tuple[int | None, ...]) -> NDArray[np.float64]:
    """Convert to a C-contiguous float64 array of the given shape (None = any length)."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name}: expected a numeric array, got {_describe(value)} ({exc})") from None
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ) or arr.dtype == np.bool_:
        raise ShapeError(f"{name}: expected a real numeric array, got {_describe(arr)}")
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        expected = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ShapeError(f"{name}: expected shape {expected}, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _as_finite(value: ArrayLike, name: str, shape: tuple[int | None, ...]) -> NDArray[np.float64]:
    arr = _as_float_array(value, name, shape)
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name}: expected finite values, got {arr[tuple(bad)]} at index {tuple(int(i) for i in bad)}")
    return arr


def _as_index_array(value: ArrayLike, name: str, n_nodes: int) -> NDArray[np.int64]:
    """Node indices as a 1-D int64 array; a boolean mask of length n_nodes is accepted too."""
    arr = np.asarray(value)
    if arr.dtype == np.bool_:
        if arr.shape != (n_nodes,):
            raise ShapeError(f"{name}: a boolean mask must have shape ({n_nodes},), got shape {arr.shape}")
        return np.flatnonzero(arr).astype(np.int64)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.size == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.issubdtype(arr.dtype, np.integer):
        raise ShapeError(f"{name}: expected integer node indices, got {_describe(arr)}")
    if arr.ndim != 1:
        raise ShapeError(f"{name}: expected a 1-D array of node indices, got shape {arr.shape}")
    arr = arr.astype(np.int64)
    bad = (arr < 0) | (arr >= n_nodes)
    if np.any(bad):
        raise InputError(
            f"{name}: node indices must be in [0, {n_nodes}), got {int(arr[bad][0])} "
            f"({int(bad.sum())} out of range)"
        )
    return arr


def _vector_per_node(value: ArrayLike, name: str, k: int) -> NDArray[np.float64]:
    """A (3,) vector broadcast to k nodes, or a (k, 3) array."""
    arr = np.asarray(value)
    if arr.ndim == 1:
        vec = _as_finite(arr, name, (3,))
        return np.broadcast_to(vec, (k, 3)).copy()
    return _as_finite(arr, name, (k, 3))


def _positive_scalar(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ParameterError(f"{name}: expected a positive number, got {_describe(value)}", name)
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ParameterError(f"{name}: expected a finite positive number, got {value}", name)
    return value


def _positive_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ParameterError(f"{name}: expected an integer >= 1, got {_describe(value)}", name)
    return int(value)


# ---------------------------------------------------------------------------
# Mesh


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
        if orientation not in _ORIENTATIONS:
            raise InputError(f"orientation: expected one of {_ORIENTATIONS}, got {orientation!r}")
        pts = _as_float_array(points, "points", (None, 3))
        tet_arr = np.asarray(tets)
        if tet_arr.size == 0 and tet_arr.ndim < 2:
            tet_arr = tet_arr.reshape(0, 4).astype(np.int64)
        if tet_arr.dtype == np.bool_ or not np.issubdtype(tet_arr.dtype, np.integer):
            raise ShapeError(f"tets: expected an integer array of node indices, got {_describe(tet_arr)}")
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
        if tet_arr.min() < 0 or tet_arr.max() >= len(pts):
            bad = int(np.argwhere((tet_arr < 0) | (tet_arr >= len(pts)))[0, 0])
            raise MeshError(
                f"tets: node indices must be in [0, {len(pts)}), got {tet_arr[bad].tolist()} in tet {bad}"
            )
        checked, reoriented = _core_module().check_mesh(pts, tet_arr, orientation)
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
        size_arr = _as_finite(size, "size", (3,))
        if np.any(size_arr <= 0):
            raise ParameterError(f"size: expected three positive lengths, got {size_arr.tolist()}", "size")
        cells_arr = np.asarray(cells)
        if cells_arr.shape != (3,) or not np.issubdtype(cells_arr.dtype, np.integer) or np.any(cells_arr < 1):
            raise ParameterError(f"cells: expected three integers >= 1, got {_describe(cells_arr)}", "cells")
        origin_arr = _as_finite(origin, "origin", (3,))
        points, tets = _core_module().box_mesh(size_arr, cells_arr.astype(np.int64), origin_arr)
        return cls(points, tets)

    @classmethod
    def read(cls, path: str | os.PathLike[str], scale: float = 1.0) -> "Mesh":
        """Read a mesh file: the ``.tet`` text format, Gmsh ``.msh`` (2.2, 4.x; also fTetWild's),
        a TetGen ``.node``/``.ele`` pair (0- or 1-based) or anything else meshio reads.

        Only the linear tetrahedra are kept: triangles, lines and points beside them (Gmsh
        physical surfaces, for instance) are skipped and nodes no tetrahedron uses are dropped;
        other volume cells (``tetra10``, hexahedra) are an error. A per-tetrahedron integer tag
        in the file (Gmsh physical group, TetGen region attribute) becomes :attr:`cell_tags`.
        See :func:`sorofem.io.read_mesh`.

        Examples
        --------
        >>> mesh = sf.Mesh.read("box2.tet", scale=1.0)  # doctest: +SKIP
        """
        from .io import read_mesh

        return read_mesh(path, scale=scale)

    def write(self, path: str | os.PathLike[str]) -> None:
        """Write the mesh (``.tet`` or any meshio format); see :func:`sorofem.io.write_mesh`."""
        from .io import write_mesh

        write_mesh(path, self)

    def scaled(self, factor: float) -> "Mesh":
        """A copy with coordinates multiplied by ``factor`` (> 0, so orientation is kept)."""
        factor = _positive_scalar(factor, "factor")
        mesh = Mesh(self._points * factor, self._tets, orientation="reject")
        mesh._reoriented = self._reoriented
        mesh.source = self.source
        mesh.cell_tags = self.cell_tags
        return mesh

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
        vol = np.asarray(_core_module().rest_volumes(self._points, self._tets), dtype=np.float64)
        vol.setflags(write=False)
        return vol

    def boundary_faces(self) -> NDArray[np.int64]:
        """Outward-oriented boundary triangles, ``(k, 3)`` int64 (computed once)."""
        faces = self.__dict__.get("_boundary_faces")
        if faces is None:
            faces = np.asarray(_core_module().boundary_faces(self._points, self._tets), dtype=np.int64)
            faces.setflags(write=False)
            self.__dict__["_boundary_faces"] = faces
        return faces

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned bounding box ``(min, max)``, each ``(3,)``."""
        return self._points.min(axis=0), self._points.max(axis=0)

    @property
    def size(self) -> float:
        """Length of the bounding-box diagonal, m: the mesh's length scale."""
        lo, hi = self.bounds()
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
        lo = _as_float_array(min, "min", (3,))
        hi = _as_float_array(max, "max", (3,))
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
        p = _as_finite(point, "point", (3,))
        n = _as_finite(normal, "normal", (3,))
        length = float(np.linalg.norm(n))
        if length == 0:
            raise InputError("normal: expected a non-zero vector, got [0, 0, 0]")
        if isinstance(tol, bool) or not isinstance(tol, numbers.Real) or not (tol >= 0 and math.isfinite(tol)):
            raise InputError(f"tol: expected a finite number >= 0, got {_describe(tol)}")
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
                f"got {_describe(mask)}"
            )
        return np.flatnonzero(mask).astype(np.int64)

    def __repr__(self) -> str:
        lo, hi = self.bounds()
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
        >>> [float(v) for v in mesh.transformed(["x", "-z", "y"]).bounds()[1]]
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
        mesh = Mesh(self._points[:, order] * signs + 0.0, tets, orientation="reject")
        mesh._reoriented = self._reoriented
        mesh.source = self.source
        mesh.cell_tags = self.cell_tags
        return mesh


# ---------------------------------------------------------------------------
# Material


def _material_value(value: Any, name: str) -> float | NDArray[np.float64]:
    """A scalar or a 1-D per-element array, finite."""
    if isinstance(value, bool):
        raise ParameterError(f"{name}: expected a number or a per-element array, got {value!r}", name)
    if isinstance(value, numbers.Real):
        out: float | NDArray[np.float64] = float(value)
        if not math.isfinite(out):
            raise ParameterError(f"{name}: expected a finite value, got {out}", name)
        return out
    try:
        arr = _as_float_array(value, name, (None,))
    except ShapeError as exc:
        raise ParameterError(
            f"{name}: expected a number or a per-element array of shape (n_tets,): {exc}", name
        ) from None
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name}: expected finite values, got {arr[~np.isfinite(arr)][0]}", name)
    arr.setflags(write=False)
    return arr


def _check(condition: Any, name: str, message: str, value: Any) -> None:
    if not np.all(condition):
        shown = value if np.ndim(value) == 0 else f"{np.asarray(value)[~np.asarray(condition)][0]} (per-element)"
        raise ParameterError(f"{name}: {message}, got {shown}", name)


class NeoHookean:
    """Compressible Neo-Hookean material.

    Strain energy per unit rest volume (``I1 = tr(F^T F)``, ``J = det F``)::

        W = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2

    with ``c(J) = ln J`` (default) or ``J - 1``, chosen per body (``Body(volumetric=...)``).

    Give exactly one of the pairs (``youngs_modulus``, ``poisson_ratio``) or
    (``shear_modulus``, ``lame_lambda``). Each value is a scalar or a per-element
    array of shape ``(n_tets,)`` (checked against the mesh when the material is used by a
    :class:`Body`).

    Parameters
    ----------
    youngs_modulus
        E in Pa, > 0.
    poisson_ratio
        nu, with 0 <= nu < 0.5: lambda = E nu / ((1 + nu)(1 - 2 nu)) must be finite and
        >= 0 (> 0 in the mixed formulation, which divides by it). Nearly incompressible
        silicone: nu = 0.499 or 0.4999 with ``Body(..., formulation="mixed")``.
    shear_modulus
        mu = E / (2 (1 + nu)) in Pa, > 0.
    lame_lambda
        lambda in Pa, >= 0 (> 0 for the mixed formulation).
    density
        kg/m^3, >= 0 (only matters under gravity).

    Examples
    --------
    >>> import sorofem as sf
    >>> silicone = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)
    >>> round(silicone.shear_modulus), round(silicone.lame_lambda)
    (22759, 204828)
    """

    def __init__(
        self,
        youngs_modulus: ArrayLike | None = None,
        poisson_ratio: ArrayLike | None = None,
        *,
        shear_modulus: ArrayLike | None = None,
        lame_lambda: ArrayLike | None = None,
        density: ArrayLike = 0.0,
    ) -> None:
        e_nu = (youngs_modulus is not None, poisson_ratio is not None)
        lame = (shear_modulus is not None, lame_lambda is not None)
        if not ((all(e_nu) and not any(lame)) or (all(lame) and not any(e_nu))):
            given = [
                n
                for n, v in (
                    ("youngs_modulus", youngs_modulus),
                    ("poisson_ratio", poisson_ratio),
                    ("shear_modulus", shear_modulus),
                    ("lame_lambda", lame_lambda),
                )
                if v is not None
            ]
            raise ParameterError(
                "NeoHookean: give exactly one pair, (youngs_modulus, poisson_ratio) or "
                f"(shear_modulus, lame_lambda); got {', '.join(given) or 'none'}",
                "youngs_modulus" if not given else given[0],
            )
        self._given = "E_nu" if all(e_nu) else "lame"
        if self._given == "E_nu":
            E = _material_value(youngs_modulus, "youngs_modulus")
            nu = _material_value(poisson_ratio, "poisson_ratio")
            _check(np.greater(E, 0), "youngs_modulus", "expected > 0 Pa", E)
            _check(np.greater(nu, -1), "poisson_ratio", "expected > -1", nu)
            _check(
                np.less(nu, 0.5),
                "poisson_ratio",
                "expected nu < 0.5 (nu = 0.5 means lame_lambda = inf; both formulations need a "
                "finite lambda, the mixed one because its P1-P1 pressure modes are controlled only "
                "by the compliance M_p / lambda; model silicone with e.g. nu = 0.4999 and "
                "formulation='mixed')",
                nu,
            )
            _check(
                np.greater_equal(nu, 0),
                "poisson_ratio",
                "expected >= 0 (this compressible Neo-Hookean needs lame_lambda >= 0, i.e. nu >= 0)",
                nu,
            )
            self._E, self._nu = E, nu
            self._mu = np.divide(E, 2 * (1 + np.asarray(nu)))
            self._lam = np.divide(np.multiply(E, nu), (1 + np.asarray(nu)) * (1 - 2 * np.asarray(nu)))
        else:
            mu = _material_value(shear_modulus, "shear_modulus")
            lam = _material_value(lame_lambda, "lame_lambda")
            _check(np.greater(mu, 0), "shear_modulus", "expected > 0 Pa", mu)
            _check(
                np.greater_equal(lam, 0),
                "lame_lambda",
                "expected >= 0 Pa (compressible Neo-Hookean needs lambda >= 0)",
                lam,
            )
            self._mu, self._lam = mu, lam
            mu_a, lam_a = np.asarray(mu), np.asarray(lam)
            self._E = mu_a * (3 * lam_a + 2 * mu_a) / (lam_a + mu_a)
            self._nu = lam_a / (2 * (lam_a + mu_a))
        rho = _material_value(density, "density")
        _check(np.greater_equal(rho, 0), "density", "expected >= 0 kg/m^3", rho)
        self._rho = rho
        # Keep scalars as floats so repr and to_dict stay readable.
        for attr in ("_E", "_nu", "_mu", "_lam"):
            value = getattr(self, attr)
            if np.ndim(value) == 0:
                setattr(self, attr, float(value))

    @property
    def youngs_modulus(self) -> float | NDArray[np.float64]:
        """E, Pa."""
        return self._E

    @property
    def poisson_ratio(self) -> float | NDArray[np.float64]:
        """nu, dimensionless."""
        return self._nu

    @property
    def shear_modulus(self) -> float | NDArray[np.float64]:
        """mu, Pa."""
        return self._mu

    @property
    def lame_lambda(self) -> float | NDArray[np.float64]:
        """lambda, Pa."""
        return self._lam

    @property
    def density(self) -> float | NDArray[np.float64]:
        """rho, kg/m^3."""
        return self._rho

    def per_element(self, n_tets: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``(mu, lam, rho)``, each ``(n_tets,)`` float64, for the extension.

        Raises
        ------
        ParameterError
            A per-element array does not have length ``n_tets``.
        """
        names = {
            "_mu": "shear_modulus" if self._given == "lame" else "youngs_modulus/poisson_ratio",
            "_lam": "lame_lambda" if self._given == "lame" else "youngs_modulus/poisson_ratio",
            "_rho": "density",
        }
        out = []
        for attr in ("_mu", "_lam", "_rho"):
            value = np.asarray(getattr(self, attr), dtype=np.float64)
            if value.ndim == 0:
                value = np.full(n_tets, float(value))
            elif value.shape != (n_tets,):
                name = names[attr]
                raise ParameterError(
                    f"{name}: per-element values must have shape ({n_tets},) (one per tet), got shape {value.shape}",
                    name.split("/")[0],
                )
            out.append(np.ascontiguousarray(value))
        return out[0], out[1], out[2]

    def to_dict(self) -> dict[str, Any]:
        """Plain summary (per-element arrays as their min and max)."""

        def plain(v: Any) -> Any:
            if np.ndim(v) == 0:
                return float(v)
            return {"min": float(np.min(v)), "max": float(np.max(v)), "per_element": True}

        return {
            "model": "neo-hookean",
            "youngs_modulus": plain(self._E),
            "poisson_ratio": plain(self._nu),
            "shear_modulus": plain(self._mu),
            "lame_lambda": plain(self._lam),
            "density": plain(self._rho),
        }

    def __repr__(self) -> str:
        def fmt(v: Any) -> str:
            return f"{float(v):.6g}" if np.ndim(v) == 0 else f"<{np.size(v)} values>"

        if self._given == "E_nu":
            args = f"youngs_modulus={fmt(self._E)}, poisson_ratio={fmt(self._nu)}"
        else:
            args = f"shear_modulus={fmt(self._mu)}, lame_lambda={fmt(self._lam)}"
        return f"NeoHookean({args}, density={fmt(self._rho)})"


# ---------------------------------------------------------------------------
# Body


class Body:
    """A mesh, a material, boundary conditions and nodal loads.

    Parameters
    ----------
    mesh
        The rest configuration.
    material
        A :class:`NeoHookean` (scalar or per-element parameters).
    formulation
        ``"standard"``: displacement-only linear tetrahedra; they lock (come out far too
        stiff) as nu -> 0.5. ``"mixed"``: linear displacement plus a continuous linear nodal
        pressure ``p`` (Pa), a perturbed-Lagrangian saddle point that does not lock; the
        volumetric energy ``lambda/2 c(J)^2`` becomes ``p c(J) - p^2 / (2 lambda)``, so
        ``p ~ lambda c(J)`` is positive in tension. See :data:`FORMULATIONS`.
    volumetric
        ``"log"`` (default): ``c(J) = ln J``; ``"linear"``: ``c(J) = J - 1``, which makes the
        nearly incompressible limit preserve volume (rather than mean ``ln J``) exactly.
        Used by both formulations.
    pressure_mass
        Mixed only (ignored by ``"standard"``): the pressure mass matrix ``M_p`` of the
        compliance ``C = M_p / lambda``, ``"consistent"`` (default, exact P1) or
        ``"lumped"`` (diagonal).

    Raises
    ------
    InputError
        Unknown formulation, volumetric measure or pressure mass.
    ParameterError
        ``formulation="mixed"`` with ``lame_lambda = 0`` (``poisson_ratio = 0``) anywhere:
        the mixed form divides by lambda.

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
    >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45))
    >>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    >>> body.add_force(mesh.nodes_on_plane((1, 0, 0), (1, 0, 0)), (0, 0, -0.01))
    >>> body.fixed_nodes.size
    9

    Nearly incompressible silicone, without locking:

    >>> silicone = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.4999, density=1080)
    >>> body = sf.Body(mesh, silicone, formulation="mixed", volumetric="log", pressure_mass="consistent")
    >>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    >>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
    >>> result.pressure.shape, abs(result.mean_log_j) < 1e-4
    ((81,), True)
    """

    def __init__(
        self,
        mesh: Mesh,
        material: NeoHookean,
        formulation: str = "standard",
        *,
        volumetric: str = "log",
        pressure_mass: str = "consistent",
    ) -> None:
        if not isinstance(mesh, Mesh):
            raise InputError(f"mesh: expected a sorofem.Mesh, got {_describe(mesh)}")
        if not isinstance(material, NeoHookean):
            raise InputError(f"material: expected a sorofem.NeoHookean, got {_describe(material)}")
        for name, value, allowed in (
            ("formulation", formulation, FORMULATIONS),
            ("volumetric", volumetric, VOLUMETRIC_MEASURES),
            ("pressure_mass", pressure_mass, PRESSURE_MASSES),
        ):
            if not isinstance(value, str) or value not in allowed:
                raise InputError(f"{name}: expected one of {list(allowed)}, got {value!r}")
        # Fail now rather than at solve time if per-element arrays do not fit the mesh.
        _, lam, _ = material.per_element(mesh.n_tets)
        if formulation == "mixed" and not np.all(lam > 0):
            name = "lame_lambda" if material._given == "lame" else "poisson_ratio"
            raise ParameterError(
                f"{name}: formulation='mixed' needs lame_lambda > 0 (poisson_ratio > 0), got "
                f"lame_lambda = {float(lam[~(lam > 0)][0])} Pa; it divides by lambda (compliance "
                "C = M_p / lambda). Use formulation='standard' for nu = 0",
                name,
            )
        self.mesh = mesh
        self.material = material
        self.formulation = formulation
        self.volumetric = volumetric
        self.pressure_mass = pressure_mass
        self._fixed = np.zeros(0, dtype=np.int64)
        self._prescribed = np.zeros((0, 3), dtype=np.float64)
        self._forces = np.zeros((mesh.n_nodes, 3), dtype=np.float64)
        self._model: Any = None
        self._model_fixed: NDArray[np.int64] | None = None
        self._cables: list[Any] = []  # sorofem.Cable
        self._actuations: list[float] = []
        self._model_n_cables = 0

    def fix(self, nodes: ArrayLike, displacement: ArrayLike | None = None) -> None:
        """Fix nodes, optionally at a prescribed displacement.

        Repeated calls accumulate; fixing a node again replaces its prescribed displacement.

        Parameters
        ----------
        nodes
            Node indices (1-D integers) or a boolean mask of shape ``(n_nodes,)``.
        displacement
            ``None`` (held in place), one ``(3,)`` vector for all nodes or ``(k, 3)``
            per node, in metres.
        """
        idx = _as_index_array(nodes, "nodes", self.mesh.n_nodes)
        if displacement is None:
            disp = np.zeros((idx.size, 3))
        else:
            disp = _vector_per_node(displacement, "displacement", idx.size)
        all_idx = np.concatenate([self._fixed, idx])
        all_disp = np.concatenate([self._prescribed, disp])
        # Last occurrence wins: unique() on the reversed arrays returns first hits.
        uniq, first = np.unique(all_idx[::-1], return_index=True)
        self._fixed = uniq
        self._prescribed = all_disp[::-1][first]

    def add_force(self, nodes: ArrayLike, force: ArrayLike) -> None:
        """Add point forces, in newtons per node; repeated calls accumulate.

        Parameters
        ----------
        nodes
            Node indices (1-D integers, repeats add up) or a boolean mask.
        force
            One ``(3,)`` vector applied to every node, or ``(k, 3)`` per node.
        """
        idx = _as_index_array(nodes, "nodes", self.mesh.n_nodes)
        f = _vector_per_node(force, "force", idx.size)
        np.add.at(self._forces, idx, f)

    def add_cable(self, cable: Any) -> int:
        """Add a :class:`sorofem.Cable`; returns its index. The model is rebuilt at the next
        solve (points are located in the mesh then; see :meth:`cable_placements`).

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
        >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45))
        >>> body.add_cable(sf.Cable.line((0, 0.05, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5))
        0
        """
        from .cables import Cable

        if not isinstance(cable, Cable):
            raise InputError(f"cable: expected a sorofem.Cable, got {_describe(cable)}")
        if any(c is cable for c in self._cables):
            raise InputError("cable: this Cable has already been added to the body")
        self._cables.append(cable)
        self._actuations.append(cable.actuation)
        return len(self._cables) - 1

    def set_actuation(self, cable: Any, alpha: float) -> None:
        """Set the actuation alpha (> 0; 1 = rest length, < 1 = pulled) of a cable, given as
        the :class:`sorofem.Cable` or its index. Takes effect at the next solve without
        rebuilding the model."""
        from .cables import cable_index, check_actuation

        index = cable_index(self, cable)
        alpha = check_actuation(alpha, "alpha")
        self._actuations[index] = alpha
        if self._model is not None and self._model_n_cables == len(self._cables):
            self._model.set_actuation(index, alpha)

    @property
    def cables(self) -> tuple[Any, ...]:
        """The cables added to the body, in index order."""
        return tuple(self._cables)

    @property
    def actuations(self) -> list[float]:
        """Current actuation alpha of each cable."""
        return list(self._actuations)

    def cable_placements(self) -> list[list[Any]]:
        """Where each cable point ended up: per cable, one :class:`sorofem.cables.CablePlacement`
        per point (``kind`` "embedded", "snapped", "free" or "anchor").

        Raises
        ------
        ParameterError
            A point lies outside the mesh and its cable has ``outside="error"``.
        """
        from .cables import CablePlacement

        return [[CablePlacement.from_core(p) for p in cable] for cable in self._core_model().cable_placements()]

    @property
    def fixed_nodes(self) -> NDArray[np.int64]:
        """Sorted indices of the fixed nodes, ``(k,)``."""
        return self._fixed.copy()

    @property
    def prescribed_displacement(self) -> NDArray[np.float64]:
        """Prescribed displacement of each fixed node, ``(k, 3)``, aligned with :attr:`fixed_nodes`."""
        return self._prescribed.copy()

    @property
    def forces(self) -> NDArray[np.float64]:
        """Accumulated nodal forces, ``(n_nodes, 3)``, N."""
        return self._forces.copy()

    @property
    def formulation_options(self) -> dict[str, str]:
        """The options that apply to :attr:`formulation`: ``volumetric``, and
        ``pressure_mass`` when mixed."""
        options = {"volumetric": self.volumetric}
        if self.formulation == "mixed":
            options["pressure_mass"] = self.pressure_mass
        return options

    def _core_model(self) -> Any:
        """The extension's Model, rebuilt only when the fixed set changes: building it
        analyses the sparsity pattern, which is worth reusing across solves."""
        if (
            self._model is None
            or not np.array_equal(self._model_fixed, self._fixed)
            or self._model_n_cables != len(self._cables)
        ):
            core = _core_module()
            cables = [c.to_core(alpha) for c, alpha in zip(self._cables, self._actuations)]
            self._model = core.Model(
                self.mesh.points, self.mesh.tets, self._fixed.copy(), self.formulation, self.formulation_options,
                cables=cables or None,
            )
            self._model_fixed = self._fixed.copy()
            self._model_n_cables = len(self._cables)
        return self._model

    def __repr__(self) -> str:
        options = "".join(f", {k}={v!r}" for k, v in self.formulation_options.items())
        return (
            f"Body({self.mesh!r}, {self.material!r}, formulation={self.formulation!r}{options}, "
            f"fixed={self._fixed.size} nodes)"
        )


# ---------------------------------------------------------------------------
# Results


@dataclass
class SolveReport:
    """What the nonlinear solver did.

    Attributes
    ----------
    converged
        Whether the relative residual reached the tolerance.
    iterations
        Newton iterations over all load steps.
    residual_history
        Relative residual norm after each iteration.
    energy_history
        Total potential energy after each iteration, J.
    load_steps
        Accepted load steps (including those added by cutbacks).
    cutbacks
        How many times a load step failed and was halved.
    projected_steps
        Newton iterations that used the projected (positive semi-definite) Hessian.
    factorizations
        Numeric factorisations of the Hessian (one per iteration, plus one for every exact
        Hessian that turned out indefinite).
    failed_factorizations
        Those of them that gave no usable direction (matrix not positive definite).
    timings
        Seconds per phase: ``assembly``, ``factorization`` (of which ``failed_factorization``
        in the failed ones), ``solve``, ``line_search``, ``total``.
    absolute_residual_norm
        Final residual (gradient) norm, N.
    reference_norm
        The norm the residual is divided by to make it relative, N.
    message
        The solver's own one-line account (empty if none).
    """

    converged: bool = False
    iterations: int = 0
    residual_history: list[float] = field(default_factory=list)
    energy_history: list[float] = field(default_factory=list)
    load_steps: int = 0
    cutbacks: int = 0
    projected_steps: int = 0
    factorizations: int = 0
    failed_factorizations: int = 0
    step_lengths: list[float] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    absolute_residual_norm: float = math.nan
    reference_norm: float = math.nan
    message: str = ""

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "SolveReport":
        """Build from the extension's report dict (unknown keys ignored)."""
        return cls(
            converged=bool(data.get("converged", False)),
            iterations=int(data.get("iterations", 0)),
            residual_history=[float(r) for r in data.get("residual_history", [])],
            energy_history=[float(e) for e in data.get("energy_history", [])],
            load_steps=int(data.get("load_steps", 0)),
            cutbacks=int(data.get("cutbacks", 0)),
            projected_steps=int(data.get("projected_steps", 0)),
            factorizations=int(data.get("factorizations", 0)),
            failed_factorizations=int(data.get("failed_factorizations", 0)),
            step_lengths=[float(t) for t in data.get("step_lengths", [])],
            timings={str(k): float(v) for k, v in dict(data.get("timings", {})).items()},
            # The extension's "residual_norm" is absolute; ours (a property) is relative.
            absolute_residual_norm=float(data.get("residual_norm", math.nan)),
            reference_norm=float(data.get("reference_norm", math.nan)),
            message=str(data.get("message", "")),
        )

    @property
    def residual_norm(self) -> float:
        """Final **relative** residual norm (NaN if no iterate was recorded)."""
        return self.residual_history[-1] if self.residual_history else math.nan

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def summary(self) -> str:
        """A few human-readable lines."""
        status = "converged" if self.converged else "did NOT converge"
        lines = [
            f"Newton {status} in {self.iterations} iterations "
            f"({self.load_steps} load steps, {self.cutbacks} cutbacks), "
            f"relative residual {self.residual_norm:.3e}"
        ]
        if self.timings:
            parts = ", ".join(f"{k} {v:.3f}" for k, v in self.timings.items())
            lines.append(f"time [s]: {parts}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


class StaticResult:
    """Equilibrium of a body, returned by :func:`solve_static`.

    Attributes
    ----------
    mesh
        The body's mesh (rest configuration).
    positions
        Deformed node positions, ``(n_nodes, 3)``, m.
    displacement
        ``positions - mesh.points``, ``(n_nodes, 3)``, m.
    pressure
        Nodal pressure ``(n_nodes,)`` in Pa for mixed formulations, ``None`` for ``"standard"``.
        It is the multiplier of the volume constraint, ``p ~ lambda c(J)``: positive where
        the material is stretched in volume (the mean Cauchy stress is ``p / J``).
        Equal-order P1-P1 is not inf-sup stable: as nu -> 0.5 the nodal pressure can
        oscillate (on coarse meshes even flip sign across a bent beam) while the
        displacement stays accurate; judge pressures on refined meshes.
    report
        The :class:`SolveReport`.

    Volume bookkeeping (both formulations): :attr:`J` per tetrahedron,
    :attr:`deformed_volumes`, :attr:`volume_change` and :attr:`mean_log_j`.
    """

    def __init__(
        self,
        body: Body,
        positions: NDArray[np.float64],
        pressure: NDArray[np.float64] | None,
        report: SolveReport,
        reactions: NDArray[np.float64] | None = None,
        cable_points: Sequence[ArrayLike] | None = None,
        cable_tensions: Sequence[ArrayLike] | None = None,
    ) -> None:
        self.body = body
        #: Current position of every cable point, one ``(k, 3)`` array per cable (m).
        self.cable_points = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in cable_points or []]
        #: Tension of every cable segment, one ``(k - 1,)`` array per cable (N, >= 0).
        self.cable_tensions = [np.asarray(t, dtype=np.float64).reshape(-1) for t in cable_tensions or []]
        #: The actuation alpha of each cable at this solve.
        self.actuations = body.actuations
        #: Support reactions ``(n_fixed, 3)`` in N, one row per entry of ``body.fixed_nodes``:
        #: the force each support exerts on the body (they balance the applied loads).
        self.reactions = None if reactions is None else np.asarray(reactions, dtype=np.float64)
        self.mesh = body.mesh
        self.positions = np.asarray(positions, dtype=np.float64)
        self.displacement = self.positions - self.mesh.points
        self.pressure = None if pressure is None else np.asarray(pressure, dtype=np.float64)
        self.report = report
        self._model = body._core_model()
        self._material = body.material.per_element(self.mesh.n_tets)
        self._fields: dict[str, NDArray[np.float64]] | None = None

    def _element_fields(self) -> dict[str, NDArray[np.float64]]:
        if self._fields is None:
            # The model may have been given another material since this solve.
            self._model.set_material(*self._material)
            fields = self._model.element_fields(self.positions)
            self._fields = {k: np.asarray(v, dtype=np.float64) for k, v in fields.items()}
        return self._fields

    @property
    def J(self) -> NDArray[np.float64]:  # noqa: N802 - the standard symbol
        """Volume ratio ``det F`` per tetrahedron, ``(n_tets,)``."""
        return self._element_fields()["J"]

    @property
    def von_mises(self) -> NDArray[np.float64]:
        """Von Mises equivalent of the Cauchy stress per tetrahedron, ``(n_tets,)``, Pa."""
        return self._element_fields()["von_mises"]

    @cached_property
    def deformed_volumes(self) -> NDArray[np.float64]:
        """Signed volume of each deformed tetrahedron, ``(n_tets,)``, m^3 (from the positions)."""
        x = self.positions[self.mesh.tets]
        edges = x[:, 1:] - x[:, :1]
        return np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2])) / 6.0

    @property
    def volume_change(self) -> float:
        """Relative change of the total volume, ``(V_deformed - V_rest) / V_rest``."""
        rest = self.mesh.volumes
        return float((self.deformed_volumes - rest).sum() / rest.sum())

    @property
    def mean_log_j(self) -> float:
        """Volume-weighted mean of ``ln J``, ``sum_e V_e ln J_e / V`` (rest volumes): the
        quantity the ``"log"`` volumetric measure keeps near 0 as nu -> 0.5."""
        rest = self.mesh.volumes
        with np.errstate(divide="ignore", invalid="ignore"):
            log_j = np.log(self.deformed_volumes / rest)
        return float((rest * log_j).sum() / rest.sum())

    @property
    def anchor_reactions(self) -> list[NDArray[np.float64] | None]:
        """Per cable, the force ``(3,)`` in N that its world anchor (``anchor_first=True``: the
        motor) exerts on the cable, ``-T_0 (y_1 - y_0) / |y_1 - y_0|`` with ``T_0`` the first
        segment's tension; ``None`` for a cable without an anchor. With the support
        ``reactions`` and the applied loads it closes the body's force balance."""
        out: list[NDArray[np.float64] | None] = []
        for cable, points, tensions in zip(self.body.cables, self.cable_points, self.cable_tensions):
            if not cable.anchor_first:
                out.append(None)
                continue
            direction = points[1] - points[0]
            length = float(np.linalg.norm(direction))
            out.append(-tensions[0] * direction / length if length > 0 else np.zeros(3))
        return out

    @property
    def max_displacement(self) -> float:
        """Largest nodal displacement magnitude, m."""
        return float(np.linalg.norm(self.displacement, axis=1).max(initial=0.0))

    def to_dict(self) -> dict[str, Any]:
        """Summary for ``summary.json``: plain JSON types only."""
        return {
            "converged": self.report.converged,
            "newton_iterations": self.report.iterations,
            "residual_norm": self.report.residual_norm,
            "max_displacement": self.max_displacement,
            "timings": dict(self.report.timings),
            "n_nodes": self.mesh.n_nodes,
            "n_tets": self.mesh.n_tets,
            "formulation": self.body.formulation,
            "formulation_options": self.body.formulation_options,
            "material": self.body.material.to_dict(),
            "min_J": float(self.J.min()),
            "max_J": float(self.J.max()),
            "volume_change": self.volume_change,
            "mean_log_j": self.mean_log_j,
            "min_pressure": None if self.pressure is None else float(self.pressure.min()),
            "max_pressure": None if self.pressure is None else float(self.pressure.max()),
            "max_von_mises": float(self.von_mises.max()),
            **self._cables_dict(),
            "report": self.report.to_dict(),
        }

    def _cables_dict(self) -> dict[str, Any]:
        """``{"cables": [...]}`` (tensions, actuation, point placements) when the body has cables."""
        if not self.body.cables:
            return {}
        from .cables import placement_counts

        placements = self.body.cable_placements()
        anchors = self.anchor_reactions + [None] * len(self.body.cables)
        return {
            "cables": [
                {
                    "actuation": alpha,
                    "stiffness": cable.stiffness,
                    "rest_length": cable.length,
                    "tensions": self.cable_tensions[c].tolist() if c < len(self.cable_tensions) else None,
                    "max_tension": float(self.cable_tensions[c].max()) if c < len(self.cable_tensions) else None,
                    "anchor_reaction": None if anchors[c] is None else anchors[c].tolist(),
                    "placements": [p.kind for p in placements[c]],
                    "placement_counts": placement_counts(placements[c]),
                }
                for c, (cable, alpha) in enumerate(zip(self.body.cables, self.actuations))
            ]
        }

    def __repr__(self) -> str:
        return (
            f"StaticResult(converged={self.report.converged}, iterations={self.report.iterations}, "
            f"max_displacement={self.max_displacement:.4g})"
        )


def solve_static(
    body: Body,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    *,
    tolerance: float = 1e-8,
    max_iterations: int = 50,
    load_steps: int = 1,
    initial: ArrayLike | StaticResult | None = None,
    progress: bool | None = None,
) -> StaticResult:
    """Static equilibrium of a body under gravity, nodal forces and prescribed displacements.

    Newton's method with a line search minimises the total potential energy; loads are
    applied in ``load_steps`` equal increments (the solver may cut a step back).

    Parameters
    ----------
    body
        The body, with its boundary conditions and forces.
    gravity
        Acceleration ``(3,)``, m/s^2.
    tolerance
        Relative residual norm at which Newton stops.
    max_iterations
        Newton iterations allowed per load step.
    load_steps
        Number of load increments.
    initial
        Initial guess of the deformed **positions** ``(n_nodes, 3)`` (or a previous
        :class:`StaticResult`); default: the rest shape.
    progress
        A line on stderr with the elapsed time while the solve runs (``None``: only on a
        terminal and only for solves longer than half a second; see :mod:`sorofem.progress`),
        then the iterations and load steps it took.

    Returns
    -------
    StaticResult

    Raises
    ------
    ConvergenceError
        Newton did not converge; ``err.report`` is a :class:`SolveReport`.

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
    >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    >>> body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
    >>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
    >>> bool(result.displacement[:, 2].min() < 0)
    True
    """
    if not isinstance(body, Body):
        raise InputError(f"body: expected a sorofem.Body, got {_describe(body)}")
    g = _as_finite(gravity, "gravity", (3,))
    tol = _positive_scalar(tolerance, "tolerance")
    iters = _positive_int(max_iterations, "max_iterations")
    steps = _positive_int(load_steps, "load_steps")
    n = body.mesh.n_nodes
    if isinstance(initial, StaticResult):
        initial = initial.positions
    x0 = None if initial is None else _as_finite(initial, "initial", (n, 3))

    from .progress import Progress

    model = body._core_model()
    model.set_material(*body.material.per_element(body.mesh.n_tets))
    # The core solves in one call (the GIL released): the line can only show the elapsed time.
    with Progress(total=1, desc="static solve", unit="solve", enabled=progress) as bar:
        try:
            out = model.solve(g, body._forces.copy(), body._prescribed.copy(), x0, tol, iters, steps)
        except ConvergenceError as err:
            if isinstance(err.report, dict):
                err.report = SolveReport.from_dict(err.report)
            raise
        report = SolveReport.from_dict(out)
        bar.set(1, postfix=f"{report.iterations} Newton iterations, {report.load_steps} load step(s), "
                           f"{report.cutbacks} cut-back(s)")
    cable_points, cable_tensions = out.get("cable_points"), out.get("cable_tensions")
    return StaticResult(
        body, out["positions"], out.get("pressure"), report, reactions=out.get("reactions"),
        cable_points=cable_points, cable_tensions=cable_tensions,
    )

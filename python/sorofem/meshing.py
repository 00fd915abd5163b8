"""From a closed triangle surface (STL, OBJ, PLY, OFF from CAD) to a tetrahedral mesh.

Users often have only the surface of a moulded robot: the CAD model of the mould cavity
exported as STL. :func:`tetrahedralize` checks that surface (closed, manifold, consistently
oriented, no degenerate triangle), fills it with linear tetrahedra and returns a
:class:`sorofem.Mesh`. :func:`read_surface` (that of :mod:`sorofem.io`), :func:`check_surface`
and :func:`surface_volume` are the pieces it is built from.

The mesher
----------
The tetrahedralisation is done by fTetWild (Hu et al., "Fast Tetrahedral Meshing in the
Wild", SIGGRAPH 2020; github.com/wildmeshing/fTetWild) through its PyPI wrapper
``pytetwild``, an **optional** dependency: ``pip install ".[mesh]"`` from a checkout of sorofem
(README, "Install"). Nothing else in
sorofem needs it, and it is imported only when :func:`tetrahedralize` runs. Why this one:

* **Licence.** fTetWild and ``pytetwild`` are MPL-2.0 (file-level copyleft: using the
  unmodified library from a BSD-3-Clause project is fine; the libgmp in its wheel is LGPL
  and dynamically linked). The ``tetgen`` wheel (an MIT wrapper) and ``meshpy`` both bundle
  TetGen, which is AGPL-3.0 (or commercial); Gmsh is GPL-2.0-or-later and a large SDK. As
  the recommended extra, either would put copyleft obligations on applications built on a
  BSD-3-Clause project.
* **Wheels.** ``pytetwild`` ships manylinux x86_64 wheels (cp311, and an abi3 wheel for
  CPython >= 3.12) whose only dependency is NumPy; the ``[mesh]`` extra installs it without
  a compiler.
* **Robustness.** fTetWild meshes *within an envelope* of the input (exact rational
  predicates, then quality optimisation) instead of conforming exactly to it as TetGen
  does, so the sliver triangles of real CAD exports neither make it fail nor leave sliver
  tetrahedra. The price: the mesh boundary may lie up to ``envelope`` (relative to the
  bounding-box diagonal) away from the input surface, so the enclosed volume can differ by
  up to about ``2 * envelope * diagonal * area`` (the volume of that envelope); this
  function checks it (``check_volume``). fTetWild also targets an *edge length*, not a
  maximum tetrahedron volume (so :func:`tetrahedralize` takes ``edge_length``, not TetGen's
  ``max_volume``), and its output differs slightly between runs.

``pytetwild`` 0.3 to 0.4.2 import PyVista (and so VTK, over 100 MB) when imported; the
``[mesh]`` extra therefore asks for ``pytetwild>=0.2.3,<0.3``, which needs only NumPy (and
is what the tests run). A newer ``pytetwild`` takes the same keyword arguments and should
work where PyVista is installed; without PyVista, :func:`require_mesher` says what to do.

Examples
--------
>>> import numpy as np, sorofem as sf
>>> points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
...                    [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]) * 0.02
>>> triangles = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
...                       [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
>>> round(sf.meshing.surface_volume(points, triangles) * 1e6, 6)   # cm^3
8.0
>>> mesh = sf.tetrahedralize((points, triangles), edge_length=0.005)   # doctest: +SKIP
>>> abs(mesh.volumes.sum() - 8e-6) < 1e-9                             # doctest: +SKIP
True
"""

from __future__ import annotations

import contextlib
import importlib
import numbers
import os
import tempfile
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import boolean, describe, positive_scalar
from .errors import InputError, MeshError, ParameterError, ShapeError
from .io import read_surface
from .mesh import Mesh

__all__ = [
    "MESHER",
    "INSTALL_HINT",
    "mesher_available",
    "require_mesher",
    "read_surface",
    "check_surface",
    "surface_volume",
    "surface_area",
    "tetrahedralize",
]

#: The Python package that does the tetrahedralisation (fTetWild's wrapper).
MESHER = "pytetwild"
#: How to install it.
INSTALL_HINT = "pip install \".[mesh]\" from a checkout of sorofem (or pip install 'pytetwild>=0.2.3,<0.3')"
#: A triangle is degenerate when its area is below this times its longest edge squared
#: (an equilateral triangle has 0.43); rounding leaves ~1e-16 on collinear points.
DEGENERATE_AREA = 1e-12

PathLike = str | os.PathLike[str]


# ---------------------------------------------------------------------------
# The mesher


def require_mesher() -> Any:
    """The mesher module (``pytetwild``), imported.

    Raises
    ------
    ImportError
        It is not installed (or cannot be imported); the message says how to install it.

    Examples
    --------
    >>> import sorofem as sf
    >>> sf.meshing.require_mesher()  # doctest: +SKIP
    <module 'pytetwild' from '...'>
    """
    try:
        return importlib.import_module(MESHER)
    except ModuleNotFoundError as exc:
        if exc.name == MESHER:
            raise ImportError(
                f"sorofem.tetrahedralize needs the optional mesher {MESHER} (fTetWild, MPL-2.0), "
                f"which is not installed: {INSTALL_HINT}"
            ) from exc
        if exc.name and exc.name.split(".")[0] == "pyvista":
            raise ImportError(
                f"the installed {MESHER} imports PyVista, which is not installed; install the "
                f"version sorofem asks for ({INSTALL_HINT}) or "
                f"PyVista (pip install pyvista)"
            ) from exc
        raise


def mesher_available() -> bool:
    """True when the optional mesher (``pytetwild``) can be imported.

    Examples
    --------
    >>> import sorofem as sf
    >>> isinstance(sf.meshing.mesher_available(), bool)
    True
    """
    try:
        require_mesher()
    except ImportError:
        return False
    return True


# ---------------------------------------------------------------------------
# Surfaces


def _surface_arrays(points: ArrayLike, triangles: ArrayLike, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Shapes, dtypes, finiteness and index range of a surface given as arrays."""
    try:
        pts = np.asarray(points)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name} points: expected an (n, 3) array of numbers, got {describe(points)} ({exc})") from None
    if pts.dtype == object or pts.dtype == np.bool_ or not (
        np.issubdtype(pts.dtype, np.floating) or np.issubdtype(pts.dtype, np.integer)
    ):
        raise ShapeError(f"{name} points: expected real numbers, got {describe(pts)}")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ShapeError(f"{name} points: expected shape (n, 3), got shape {pts.shape}")
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    if not np.all(np.isfinite(pts)):
        row = int(np.argwhere(~np.isfinite(pts))[0, 0])
        raise MeshError(f"{name} points: expected finite coordinates, got {pts[row].tolist()} at point {row}")
    try:
        tri = np.asarray(triangles)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name} triangles: expected an (m, 3) integer array, got {describe(triangles)} ({exc})") from None
    if tri.dtype == np.bool_ or not np.issubdtype(tri.dtype, np.integer):
        raise ShapeError(f"{name} triangles: expected integer point indices, got {describe(tri)}")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ShapeError(f"{name} triangles: expected shape (m, 3), got shape {tri.shape}")
    if len(tri) < 4:
        raise MeshError(f"{name} triangles: a closed surface needs at least 4 triangles, got {len(tri)}")
    tri = np.ascontiguousarray(tri, dtype=np.int64)
    if tri.min() < 0 or tri.max() >= len(pts):
        bad = int(np.argwhere((tri < 0) | (tri >= len(pts)))[0, 0])
        raise MeshError(
            f"{name} triangles: point indices must be in [0, {len(pts)}), got {tri[bad].tolist()} in triangle {bad}"
        )
    return pts, tri


def check_surface(
    points: ArrayLike, triangles: ArrayLike, name: str = "surface"
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Check that a triangle surface bounds a solid, and tidy it.

    Coincident points are merged and unused points dropped; a surface whose triangles all
    face inwards is turned outwards (CAD exports differ). What is an error:

    * wrong shapes or dtypes (:class:`~sorofem.ShapeError`), non-finite coordinates,
      indices out of range;
    * a **degenerate** triangle: two corners at the same point, or zero area (below
      :data:`DEGENERATE_AREA` times its longest edge squared);
    * a surface that is **not closed**: an edge that belongs to one triangle only (a hole);
    * a **non-manifold** edge, shared by more than two triangles;
    * **inconsistent orientation**: two triangles that share an edge and run along it in
      the same direction (one of them faces the wrong way);
    * a surface that encloses no volume.

    Self-intersections are not detected (fTetWild tolerates them, and the volume check of
    :func:`tetrahedralize` catches their effect).

    Parameters
    ----------
    points
        ``(n, 3)`` coordinates, m.
    triangles
        ``(m, 3)`` point indices (0-based), ``m >= 4``.
    name
        How the surface is called in error messages.

    Returns
    -------
    points, triangles
        The tidied surface, outward oriented: ``(n', 3)`` float64 and ``(m, 3)`` int64.

    Raises
    ------
    ShapeError, MeshError
        As listed above; the message names the offending triangle, edge or point.

    Examples
    --------
    >>> import numpy as np, sorofem as sf
    >>> tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> points, triangles = sf.meshing.check_surface(tet, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    >>> triangles.shape
    (4, 3)
    >>> sf.meshing.check_surface(tet, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 2, 3]])
    Traceback (most recent call last):
    ...
    sorofem.errors.MeshError: surface: inconsistent orientation: triangles 0 and 3 ...
    """
    pts, tri = _surface_arrays(points, triangles, name)
    # Merge coincident points (an STL repeats every corner) and drop unused ones.
    unique, inverse = np.unique(pts, axis=0, return_inverse=True)
    tri = inverse.reshape(-1)[tri]
    used, tri = np.unique(tri, return_inverse=True)
    tri = tri.reshape(-1, 3)
    pts = unique[used]

    # Degenerate triangles.
    repeated = (tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 2] == tri[:, 0])
    if np.any(repeated):
        k = int(np.argmax(repeated))
        raise MeshError(
            f"{name}: triangle {k} is degenerate: two of its corners are the same point "
            f"{pts[tri[k]].tolist()} (expected three distinct points)"
        )
    corners = pts[tri]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    longest2 = np.max(
        [np.sum((corners[:, a] - corners[:, b]) ** 2, axis=1) for a, b in ((0, 1), (1, 2), (2, 0))], axis=0
    )
    flat = 0.5 * area2 <= DEGENERATE_AREA * longest2
    if np.any(flat):
        k = int(np.argmax(flat))
        raise MeshError(
            f"{name}: triangle {k} is degenerate: zero area (its corners {corners[k].tolist()} are collinear; "
            f"expected area > {DEGENERATE_AREA:g} x longest edge^2, got {0.5 * area2[k]:.3e} m^2)"
        )

    # Closed and manifold: every edge is shared by exactly two triangles.
    directed = tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # edge e of triangle e // 3
    undirected = np.sort(directed, axis=1)
    edges, inverse, counts = np.unique(undirected, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    for bad, what in ((counts == 1, "not closed"), (counts > 2, "not manifold")):
        if np.any(bad):
            e = int(np.argmax(bad))
            owners = (np.flatnonzero(inverse == e) // 3).tolist()
            a, b = edges[e]
            detail = (
                f"{int(bad.sum())} edge(s) belong to one triangle only (a hole), e.g. the edge of triangle "
                f"{owners[0]}"
                if what == "not closed"
                else f"{int(bad.sum())} edge(s) are shared by more than two triangles, e.g. triangles {owners}"
            )
            raise MeshError(
                f"{name}: the surface is {what}: every edge must be shared by exactly two triangles, but "
                f"{detail} between points {pts[a].tolist()} and {pts[b].tolist()}"
            )
    # Consistent orientation: the two triangles of an edge run along it in opposite directions.
    _, dinverse, dcounts = np.unique(directed, axis=0, return_inverse=True, return_counts=True)
    dinverse = dinverse.reshape(-1)
    if np.any(dcounts > 1):
        d = int(np.argmax(dcounts > 1))
        owners = (np.flatnonzero(dinverse == d) // 3).tolist()
        a, b = directed[np.flatnonzero(dinverse == d)[0]]
        raise MeshError(
            f"{name}: inconsistent orientation: triangles {owners[0]} and {owners[1]} share the edge from "
            f"{pts[a].tolist()} to {pts[b].tolist()} in the same direction (expected opposite directions; "
            f"flip one of them). {int((dcounts > 1).sum())} edge(s) are affected"
        )
    volume = surface_volume(pts, tri)
    scale = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    if not abs(volume) > 1e-12 * scale**3:
        raise MeshError(f"{name}: the surface encloses no volume (expected > 0, got {volume:.3e} m^3)")
    if volume < 0:  # all triangles face inwards
        tri = tri[:, [0, 2, 1]]
    return pts, np.ascontiguousarray(tri)


def surface_volume(points: ArrayLike, triangles: ArrayLike) -> float:
    """Volume enclosed by a closed triangle surface (m^3), by the divergence theorem:
    ``V = 1/6 sum_t a . (b x c)`` over the triangles ``(a, b, c)``; positive when the
    triangles face outwards. Exact (up to rounding) for the polyhedron.

    Examples
    --------
    >>> import numpy as np, sorofem as sf
    >>> tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> round(sf.meshing.surface_volume(tet, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]), 12)
    0.166666666667
    """
    corners = np.asarray(points, dtype=np.float64)[np.asarray(triangles, dtype=np.int64)]
    # Relative to the centroid, for rounding (the sum is translation invariant on a closed surface).
    corners = corners - corners.reshape(-1, 3).mean(axis=0)
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


def surface_area(points: ArrayLike, triangles: ArrayLike) -> float:
    """Total area of a triangle surface, m^2.

    Examples
    --------
    >>> import numpy as np, sorofem as sf
    >>> tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    >>> round(sf.meshing.surface_area(tet, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]), 6)
    2.366025
    """
    corners = np.asarray(points, dtype=np.float64)[np.asarray(triangles, dtype=np.int64)]
    return float(0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1).sum())


# ---------------------------------------------------------------------------
# Tetrahedralisation


def _as_surface(surface: Any, scale: float) -> tuple[np.ndarray, np.ndarray, Path | None]:
    if isinstance(surface, (str, os.PathLike)):
        path = Path(surface)
        points, triangles = read_surface(path, scale=scale)
        return points, triangles, path
    if isinstance(surface, np.ndarray) or not isinstance(surface, Sequence) or len(surface) != 2:
        raise InputError(
            f"surface: expected a file path (.stl, .obj, .ply, .off, ...) or a (points, triangles) pair, "
            f"got {describe(surface)}"
        )
    points, triangles = surface
    points, triangles = _surface_arrays(points, triangles, "surface")
    return points * scale, triangles, None


def tetrahedralize(
    surface: PathLike | tuple[ArrayLike, ArrayLike],
    edge_length: float | None = None,
    *,
    envelope: float = 1e-3,
    scale: float = 1.0,
    simplify: bool = False,
    coarsen: bool = True,
    check_volume: bool = True,
    threads: int = 0,
) -> Mesh:
    """Fill a closed triangle surface with linear tetrahedra (fTetWild, optional extra).

    Needs the optional mesher: ``pip install ".[mesh]"`` from a checkout (see the module docstring
    for the choice of fTetWild). The surface is checked first (:func:`check_surface`), then
    meshed; the mesh is oriented and validated by :class:`sorofem.Mesh`, and its volume is
    compared with the volume the surface encloses (divergence theorem).

    Parameters
    ----------
    surface
        A surface file meshio reads (``.stl``, ``.obj``, ``.ply``, ``.off``, ...) or a pair
        ``(points (n, 3), triangles (m, 3))``.
    edge_length
        Target tetrahedron edge length, m (after ``scale``); default: 1/20 of the
        bounding-box diagonal. A target, not a bound: with ``coarsen`` the edges typically
        come out 1 to 1.5 times as long, a few up to 3 times. fTetWild has no maximum
        tetrahedron volume (TetGen's ``-a``); the regular tetrahedron of edge ``h`` has the
        volume ``h^3 / (6 sqrt(2))``, so halving ``edge_length`` gives about 8 times as many
        tetrahedra.
    envelope
        How far the mesh boundary may lie from the input surface, relative to the
        bounding-box diagonal (fTetWild's epsilon), in (0, 0.1]. Smaller is more faithful
        and slower.
    scale
        Factor applied to the coordinates first (``1e-3`` for a surface in millimetres).
    simplify
        Let fTetWild first coarsen the input surface within the envelope (worth it for
        dense scans; off by default so a CAD surface is kept as it is, which is also faster
        for moderate triangle counts).
    coarsen
        Let fTetWild coarsen its mesh as far as quality allows. fTetWild refines where it
        cannot reach its quality target, so without coarsening a large ``edge_length`` can
        give *more* tetrahedra than a smaller one; with it (default) the count falls as
        ``edge_length`` grows.
    check_volume
        Raise :class:`~sorofem.MeshError` when the mesh volume differs from the enclosed
        volume by more than the envelope's volume, ``2 * envelope * diagonal * area``: then
        the mesher dropped part of the body (features thinner than the envelope, or a
        self-intersecting surface).
    threads
        Threads fTetWild may use; 0: all cores.

    Returns
    -------
    Mesh
        Positively oriented tetrahedra; ``mesh.source`` is the surface file, if one was given.

    Notes
    -----
    fTetWild writes a debug file into the working directory; the call therefore runs it in
    a temporary directory (``os.chdir`` for its duration, so do not rely on the working
    directory in other threads meanwhile). Its output varies slightly from run to run.

    Raises
    ------
    ImportError
        The mesher is not installed (the message says how to install it: :data:`INSTALL_HINT`).
    FileNotFoundError
        No such surface file.
    ShapeError, MeshError
        The surface is malformed (see :func:`check_surface`), or the mesher failed.
    ParameterError
        A size or option out of range.

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.tetrahedralize("finger.stl", edge_length=4e-3, scale=1e-3)  # doctest: +SKIP
    >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=150e3, poisson_ratio=0.49, density=1070),
    ...                formulation="mixed")                                   # doctest: +SKIP
    """
    scale = positive_scalar(scale, "scale")
    if edge_length is not None:
        edge_length = positive_scalar(edge_length, "edge_length")
    envelope = positive_scalar(envelope, "envelope")
    if envelope > 0.1:
        raise ParameterError(f"envelope: expected a fraction of the bounding-box diagonal in (0, 0.1], got {envelope}", "envelope")
    for flag, name in ((simplify, "simplify"), (coarsen, "coarsen"), (check_volume, "check_volume")):
        boolean(flag, name)
    if isinstance(threads, bool) or not isinstance(threads, numbers.Integral) or threads < 0:
        raise ParameterError(f"threads: expected an integer >= 0 (0: all cores), got {describe(threads)}", "threads")

    points, triangles, path = _as_surface(surface, scale)
    name = f"surface {path}" if path is not None else "surface"
    points, triangles = check_surface(points, triangles, name)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    if edge_length is not None and edge_length > diagonal:
        raise ParameterError(
            f"edge_length: expected at most the surface's bounding-box diagonal {diagonal:.4g} m, got {edge_length:.4g} m",
            "edge_length",
        )

    mesher = require_mesher()
    # fTetWild reads the index array as uint32.
    if len(points) >= 2**31:
        raise MeshError(f"{name}: too many points for the mesher ({len(points)})")
    # fTetWild writes a debug file (__tracked_surface.stl) into the working directory: give it
    # a scratch one, so the user's folder is left alone.
    with tempfile.TemporaryDirectory(prefix="sorofem-mesh-") as scratch, contextlib.chdir(scratch):
        vertices, tets = mesher.tetrahedralize(
            points,
            triangles.astype(np.int32),
            edge_length_abs=edge_length,
            epsilon=envelope,
            simplify=bool(simplify),
            optimize=True,
            coarsen=bool(coarsen),
            num_threads=int(threads),
            quiet=True,
        )
    vertices = np.asarray(vertices, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    if tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise MeshError(f"{name}: the mesher returned no tetrahedra (array of shape {tets.shape})")
    used, tets = np.unique(tets, return_inverse=True)
    tets, vertices = tets.reshape(-1, 4), vertices[used]
    # fTetWild's tets are negatively oriented (by sorofem's convention): swap two nodes of each
    # inverted one here, so that mesh.reoriented keeps meaning "fixed in the input".
    corners = vertices[tets]
    signed = np.einsum("ij,ij->i", corners[:, 1] - corners[:, 0],
                       np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0]))
    tets[signed < 0] = tets[signed < 0][:, [0, 1, 3, 2]]
    try:
        mesh = Mesh(vertices, tets)
    except MeshError as exc:
        raise MeshError(f"{name}: the mesher returned an invalid mesh: {exc}") from None
    if path is not None:
        mesh.source = path

    if check_volume:
        enclosed = surface_volume(points, triangles)
        meshed = float(mesh.volumes.sum())
        bound = 2.0 * envelope * diagonal * surface_area(points, triangles)
        if abs(meshed - enclosed) > bound:
            raise MeshError(
                f"{name}: the tetrahedra fill {meshed:.6g} m^3 but the surface encloses {enclosed:.6g} m^3; the "
                f"difference {abs(meshed - enclosed):.3g} m^3 exceeds the envelope's volume 2 x envelope x diagonal "
                f"x area = {bound:.3g} m^3 (expected less): the surface may intersect itself or have features "
                f"thinner than the envelope; repair it or pass a smaller envelope"
            )
    return mesh

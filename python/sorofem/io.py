"""Reading and writing meshes and results.

Formats
-------
``.tet``
    A plain text format, one entry per line, 0-based indices::

        # comment
        v 0.0 0.0 0.0        # a vertex: x y z
        t 0 1 2 3            # a tetrahedron: four vertex indices

    Blank lines and ``#`` comments (whole-line or trailing) are allowed.
anything else
    Through meshio (``.vtu``, ``.msh``, ``.mesh``, ``.xdmf``, ...). Only linear
    tetrahedra (``tetra`` cells) are used: lower-dimensional cells beside them (surface
    triangles, lines, points of physical groups) are skipped, and nodes used by no
    tetrahedron are dropped, because a node without stiffness makes the problem singular.
    Other volume cells (second-order ``tetra10``, hexahedra, wedges, pyramids) are an
    error rather than silently left out of the body.
Gmsh ``.msh``
    Versions 2.2 and 4.0/4.1, ASCII or binary (what Gmsh and fTetWild write); node tags may
    start at 1 and have gaps.
TetGen ``.node`` + ``.ele``
    Name either file; the other one (same stem) must be next to it. Indices may be 0- or
    1-based (the first node's number sets the base); boundary markers and attributes are
    allowed.

**Cell tags.** When the file gives each tetrahedron an integer tag (a Gmsh physical group,
``gmsh:physical``; a TetGen region attribute, the first element attribute of the ``.ele``
file, ``tetgen -A``; a Medit reference), it is kept as :attr:`sorofem.Mesh.cell_tags`,
``(n_tets,)`` int64 in the order of ``mesh.tets``; otherwise ``cell_tags`` is None. Gmsh
files without physical groups have no tags (the elementary entity numbers are not used).

Writers never overwrite the file a mesh was read from.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> sf.io.write_mesh("/tmp/beam.tet", mesh)
>>> sf.io.read_mesh("/tmp/beam.tet").n_tets
192
"""

from __future__ import annotations

import numbers
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError, MeshError, ParameterError

if TYPE_CHECKING:
    from .model import Mesh, StaticResult

__all__ = ["read_mesh", "write_mesh", "write_result", "CELL_TAG_KEYS"]

PathLike = str | os.PathLike[str]

#: meshio cell-data names of per-tetrahedron integer tags, in the order they are looked for:
#: the first one present becomes :attr:`sorofem.Mesh.cell_tags`.
CELL_TAG_KEYS = ("gmsh:physical", "tetgen:ref", "medit:ref")
#: Volume cells meshio may report besides ``tetra`` (used when meshio does not say).
_VOLUME_CELLS = ("tetra10", "hexahedron", "hexahedron20", "hexahedron24", "hexahedron27", "wedge", "wedge12",
                 "wedge15", "wedge18", "pyramid", "pyramid13", "pyramid14")


def _same_file(a: Path, b: Path | None) -> bool:
    if b is None:
        return False
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _refuse_overwrite(path: Path, source: Path | None) -> None:
    if _same_file(path, source):
        raise InputError(
            f"refusing to overwrite the input mesh file {source}; write to another path"
        )


def read_mesh(path: PathLike, scale: float = 1.0) -> "Mesh":
    """Read a tetrahedral mesh.

    Parameters
    ----------
    path
        A ``.tet`` file, a Gmsh ``.msh`` (2.2 or 4.x, ASCII or binary; what fTetWild writes
        too), a TetGen ``.node`` or ``.ele`` file (the pair is read; 0- or 1-based), or any
        other volume mesh meshio reads (``.vtu``, ``.mesh``, ...).
    scale
        Factor applied to the coordinates (e.g. ``1e-3`` for a mesh in millimetres).

    Returns
    -------
    Mesh
        With ``mesh.source`` set to ``path``. Only the linear tetrahedra are kept: triangles,
        lines and points that many files carry beside them (Gmsh physical surfaces, say) are
        skipped, and nodes no tetrahedron uses are dropped (the remaining nodes keep their
        order). ``mesh.cell_tags`` holds the file's per-tetrahedron integer tag (Gmsh physical
        group, TetGen region attribute, Medit reference), or None; see the module docstring.

    Raises
    ------
    FileNotFoundError
        No such file (for TetGen: either file of the pair).
    MeshError
        A malformed ``.tet`` line (the message gives file and line), no tetrahedra, volume
        cells other than linear tetrahedra (``tetra10``, hexahedra, ...), or an invalid mesh.

    Examples
    --------
    >>> mesh = sf.io.read_mesh("box2.tet", scale=1.0)  # doctest: +SKIP
    """
    from .model import Mesh

    path = Path(path)
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not (0 < scale < float("inf")):
        raise ParameterError(f"scale: expected a finite positive number, got {scale!r}", "scale")
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    tags = None
    if path.suffix.lower() == ".tet":
        points, tets = _read_tet(path)
    else:
        if path.suffix in (".node", ".ele"):  # meshio reads the TetGen pair from either name
            other = path.with_suffix(".ele" if path.suffix == ".node" else ".node")
            if not other.is_file():
                raise FileNotFoundError(f"mesh file not found: {other} (the TetGen companion of {path})")
        points, tets, tags = _read_meshio(path)
    try:
        mesh = Mesh(points * float(scale), tets)
    except MeshError as exc:
        raise MeshError(f"{path}: {exc}") from None
    mesh.source = path
    if tags is not None:
        tags.setflags(write=False)
        mesh.cell_tags = tags
    return mesh


def _read_tet(path: Path) -> tuple[np.ndarray, np.ndarray]:
    points: list[list[float]] = []
    tets: list[list[int]] = []
    with path.open("r", encoding="utf-8", errors="replace") as fh:
        for lineno, raw in enumerate(fh, start=1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            tag = parts[0]
            try:
                if tag == "v" and len(parts) == 4:
                    points.append([float(p) for p in parts[1:]])
                    continue
                if tag == "t" and len(parts) == 5:
                    tets.append([int(p) for p in parts[1:]])
                    continue
            except ValueError:
                pass
            raise MeshError(
                f"{path}, line {lineno}: expected 'v x y z' (three numbers) or 't i j k l' "
                f"(four integer indices), got {raw.strip()!r}"
            )
    if not tets:
        raise MeshError(f"{path}: no tetrahedra ('t i j k l' lines) found")
    return np.array(points, dtype=np.float64).reshape(-1, 3), np.array(tets, dtype=np.int64)


def _volume_types(types: set[str]) -> list[str]:
    """The cell types among ``types`` that are 3-D but not linear tetrahedra."""
    try:
        from meshio._mesh import topological_dimension as dims
    except ImportError:  # a meshio without the table: the common ones
        dims = {t: 3 for t in _VOLUME_CELLS}
    return sorted(t for t in types if t != "tetra" and dims.get(t) == 3)


def meshio_read(path: str | os.PathLike[str], what: str) -> Any:
    """``meshio.read(path)``, with any failure as a :class:`MeshError` naming the file and
    ``what`` it should hold ("mesh", "surface"). meshio prints the error of every reader it
    tries (for .msh: ANSYS before Gmsh) to stdout, which would corrupt `sorofem info --json`;
    that text goes into the error message instead."""
    import contextlib
    import io as _io

    import meshio

    tried = _io.StringIO()
    try:
        with contextlib.redirect_stdout(tried):
            return meshio.read(path)
    except Exception as exc:  # meshio raises many types (ReadError, KeyError, ...)
        detail = " ".join(tried.getvalue().split())
        raise MeshError(
            f"{path}: could not read the {what} with meshio: {exc}" + (f" ({detail})" if detail else "")
        ) from None


def _read_meshio(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Points, tets and per-tet tags (or None) of a file meshio reads."""
    m = meshio_read(path, "mesh")
    volume = _volume_types({c.type for c in m.cells})
    if volume:
        counts = ", ".join(f"{sum(len(c.data) for c in m.cells if c.type == t)} {t}" for t in volume)
        hint = (" (second-order tetrahedra: mesh with element order 1, e.g. `gmsh -3 -order 1`)"
                if "tetra10" in volume else " (mesh the volume with tetrahedra only)")
        raise MeshError(
            f"{path}: the mesh has volume cells that are not linear tetrahedra ({counts}); sorofem uses linear "
            f"tetrahedra ('tetra') only and will not leave part of the body out{hint}"
        )
    tetra = [i for i, c in enumerate(m.cells) if c.type == "tetra"]
    blocks = [np.asarray(m.cells[i].data, dtype=np.int64) for i in tetra]
    if not blocks:
        found = sorted({c.type for c in m.cells}) or ["none"]
        raise MeshError(
            f"{path}: no linear tetrahedra ('tetra' cells) found; cell types in the file: {', '.join(found)}"
        )
    tets = np.concatenate(blocks)
    points = np.asarray(m.points, dtype=np.float64)
    if points.ndim == 2 and points.shape[1] == 2:
        raise MeshError(f"{path}: the mesh is 2-D; sorofem needs 3-D coordinates")
    if tets.size and (tets.min() < 0 or tets.max() >= len(points)):
        raise MeshError(f"{path}: tetra node indices out of range [0, {len(points)})")
    used = np.unique(tets)
    if used.size != len(points):
        remap = np.full(len(points), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        points, tets = points[used], remap[tets]
    return points, tets, _cell_tags(m, tetra, len(tets))


def _cell_tags(m: object, tetra: list[int], n_tets: int) -> np.ndarray | None:
    """The first of CELL_TAG_KEYS that gives every tetrahedron an integer, as int64."""
    cell_data = getattr(m, "cell_data", {})
    for key in CELL_TAG_KEYS:
        data = cell_data.get(key)
        if data is None or len(data) <= max(tetra):
            continue
        try:
            values = np.concatenate([np.asarray(data[i], dtype=np.float64).reshape(-1) for i in tetra])
        except (TypeError, ValueError):
            continue
        if values.size == n_tets and np.all(np.isfinite(values)) and np.all(values == np.round(values)):
            return values.astype(np.int64)
    return None


def write_mesh(path: PathLike, mesh: "Mesh") -> None:
    """Write a mesh as ``.tet`` (full float precision) or through meshio.

    Raises
    ------
    InputError
        ``path`` is the file the mesh was read from.
    """
    path = Path(path)
    _refuse_overwrite(path, mesh.source)
    if path.suffix.lower() == ".tet":
        with path.open("w", encoding="utf-8") as fh:
            fh.write(f"# sorofem mesh: {mesh.n_nodes} vertices, {mesh.n_tets} tetrahedra\n")
            fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in mesh.points.tolist())
            fh.writelines(f"t {a} {b} {c} {d}\n" for a, b, c, d in mesh.tets.tolist())
        return
    import meshio

    meshio.write_points_cells(path, mesh.points, [("tetra", mesh.tets)])


def write_result(
    path: PathLike,
    result: "StaticResult",
    extra_point_data: Mapping[str, ArrayLike] | None = None,
) -> None:
    """Write a result (normally ``.vtu``) for ParaView.

    The points are the **deformed** positions. Point data: ``displacement`` (m),
    ``pressure`` (Pa, mixed formulations only) and ``extra_point_data``; cell data:
    ``J`` (volume ratio) and ``von_mises`` (Pa). Use ParaView's "Warp By Vector" with
    scale -1 on ``displacement`` to see the rest shape.

    Raises
    ------
    InputError
        ``path`` is the input mesh file, or ``extra_point_data`` has a wrong length.
    """
    import meshio

    path = Path(path)
    mesh = result.mesh
    _refuse_overwrite(path, mesh.source)
    point_data: dict[str, np.ndarray] = {"displacement": result.displacement}
    if result.pressure is not None:
        point_data["pressure"] = result.pressure
    for name, values in (extra_point_data or {}).items():
        arr = np.asarray(values)
        if arr.shape[:1] != (mesh.n_nodes,):
            raise InputError(
                f"extra_point_data[{name!r}]: expected {mesh.n_nodes} rows (one per node), got shape {arr.shape}"
            )
        point_data[str(name)] = arr
    cell_data = {"J": [result.J], "von_mises": [result.von_mises]}
    meshio.write(
        path,
        meshio.Mesh(result.positions, [("tetra", mesh.tets)], point_data=point_data, cell_data=cell_data),
    )

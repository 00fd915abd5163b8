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
    tetrahedra (``tetra`` cells) are used; nodes used by no tetrahedron (e.g. by surface
    triangles only) are dropped, because a node without stiffness makes the problem singular.

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
from typing import TYPE_CHECKING, Mapping

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError, MeshError, ParameterError

if TYPE_CHECKING:
    from .model import Mesh, StaticResult

__all__ = ["read_mesh", "write_mesh", "write_result"]

PathLike = str | os.PathLike[str]


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
        A ``.tet`` file or any volume mesh meshio reads.
    scale
        Factor applied to the coordinates (e.g. ``1e-3`` for a mesh in millimetres).

    Returns
    -------
    Mesh
        With ``mesh.source`` set to ``path``.

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshError
        A malformed ``.tet`` line (the message gives file and line), no tetrahedra,
        or an invalid mesh.

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
    if path.suffix.lower() == ".tet":
        points, tets = _read_tet(path)
    else:
        points, tets = _read_meshio(path)
    try:
        mesh = Mesh(points * float(scale), tets)
    except MeshError as exc:
        raise MeshError(f"{path}: {exc}") from None
    mesh.source = path
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


def _read_meshio(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import contextlib
    import io as _io

    import meshio

    # meshio prints the error of every reader it tries (for .msh: ANSYS before Gmsh) to stdout,
    # which would corrupt `sorofem info --json`; keep that text for the error message instead.
    tried = _io.StringIO()
    try:
        with contextlib.redirect_stdout(tried):
            m = meshio.read(path)
    except Exception as exc:  # meshio raises many types (ReadError, KeyError, ...)
        detail = " ".join(tried.getvalue().split())
        raise MeshError(
            f"{path}: could not read the mesh with meshio: {exc}" + (f" ({detail})" if detail else "")
        ) from None
    blocks = [np.asarray(c.data, dtype=np.int64) for c in m.cells if c.type == "tetra"]
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
    return points, tets


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

"""Mesh and surface file formats at the level of arrays: the ``.tet`` text format, Wavefront OBJ,
and everything else through meshio.

Internal: :class:`sorofem.Mesh` (``Mesh.read``, ``Mesh.write``) and :mod:`sorofem.io` build on
these; they know nothing of meshes beyond points and cells, so that the mesh class can sit
above them.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any, Iterator, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._files import atomic_path, check_path
from ._validate import positive_scalar
from .errors import InputError, MeshError

__all__ = [
    "CELL_TAG_KEYS",
    "Surface",
    "same_file",
    "refuse_overwrite",
    "meshio_read",
    "meshio_format",
    "meshio_write",
    "read_volume",
    "write_volume",
    "read_surface",
]

PathLike = str | os.PathLike[str]

#: meshio cell-data names of per-tetrahedron integer tags, in the order they are looked for:
#: the first one present becomes :attr:`sorofem.Mesh.cell_tags`.
CELL_TAG_KEYS = ("gmsh:physical", "tetgen:ref", "medit:ref")
#: Volume cells besides ``tetra``, for a meshio cell block that does not state its dimension.
_VOLUME_CELLS = ("tetra10", "hexahedron", "hexahedron20", "hexahedron24", "hexahedron27", "wedge", "wedge12",
                 "wedge15", "wedge18", "pyramid", "pyramid13", "pyramid14")


def same_file(a: Path, b: Path | None) -> bool:
    """Whether ``a`` and ``b`` name the same file (``b`` None: no)."""
    if b is None:
        return False
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def refuse_overwrite(path: Path, source: Path | None) -> None:
    """An :class:`InputError` when writing ``path`` would overwrite ``source``, the input file."""
    if same_file(path, source):
        raise InputError(f"refusing to overwrite the input mesh file {source}; write to another path")


def meshio_read(path: PathLike, what: str) -> Any:
    """``meshio.read(path)``, with any failure as a :class:`MeshError` naming the file and
    ``what`` it should hold ("mesh", "surface"). meshio prints the error of every reader it
    tries (for .msh: ANSYS before Gmsh) to stdout and stderr, which would corrupt `sorofem info
    --json` and the one-line error of the command line; that text goes into the error message
    instead. A read that does not end within :data:`READ_SECONDS` (plus a second per
    :data:`READ_BYTES_PER_SECOND` bytes) is stopped: some of meshio's readers loop forever on a
    truncated file."""
    import meshio

    path = Path(path)
    _check_headers(path)
    tried = io.StringIO()
    seconds = READ_SECONDS + path.stat().st_size / READ_BYTES_PER_SECOND
    try:
        with contextlib.redirect_stdout(tried), contextlib.redirect_stderr(tried), _deadline(seconds):
            return meshio.read(path, file_format=_gmsh_format(path))
    except _ReadTimeout:
        raise MeshError(
            f"{path}: meshio did not finish reading the {what} within {seconds:.0f} s; the file is damaged (some "
            "of meshio's readers loop forever on a truncated file)"
        ) from None
    except (Exception, SystemExit) as exc:  # meshio raises many types (ReadError, KeyError, ...), even SystemExit
        detail = " ".join(tried.getvalue().split())
        raise MeshError(
            f"{path}: could not read the {what} with meshio: {exc}" + (f" ({detail})" if detail else "")
        ) from None


#: A meshio read may take this long, s, plus one second per READ_BYTES_PER_SECOND bytes of the
#: file, before it is stopped (main thread only: Python runs signal handlers there).
READ_SECONDS = 10.0
READ_BYTES_PER_SECOND = 2e6


class _ReadTimeout(Exception):
    pass


@contextlib.contextmanager
def _deadline(seconds: float) -> Iterator[None]:
    """Raise :class:`_ReadTimeout` in the block after ``seconds`` (SIGALRM; the caller's own
    alarm handler and timer are put back)."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        yield
        return

    def expire(signum: int, frame: Any) -> None:
        raise _ReadTimeout()

    handler = signal.signal(signal.SIGALRM, expire)
    started = time.monotonic()
    previous, interval = signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, handler)
        if previous > 0:
            signal.setitimer(signal.ITIMER_REAL, max(previous - (time.monotonic() - started), 1e-3), interval)


def _first_line(path: Path) -> bytes | None:
    """The first line that is neither blank nor a ``#`` comment (None: there is none)."""
    with path.open("rb") as fh:
        for raw in fh:
            line = raw.strip()
            if line and not line.startswith(b"#"):
                return line
    return None


def _check_headers(path: Path) -> None:
    """Refuse the files on which meshio's readers never return: a TetGen pair with an empty
    file, a PLY without ``end_header``."""
    suffix = path.suffix.lower()
    if suffix in (".node", ".ele"):
        for file in (path.with_suffix(".node"), path.with_suffix(".ele")):
            if file.is_file() and _first_line(file) is None:
                raise MeshError(f"{path}: the TetGen file {file} has no header line")
    if suffix == ".ply":
        with path.open("rb") as fh:
            head = fh.read(1 << 16)
        if b"end_header" not in head:
            raise MeshError(f"{path}: not a PLY file (no 'end_header' line)")


def _gmsh_format(path: Path) -> str | None:
    """``"gmsh"`` for a ``.msh`` that is Gmsh's (it starts with ``$MeshFormat``), so that meshio
    does not try ANSYS's reader first; None otherwise (meshio picks by the suffix)."""
    if path.suffix.lower() != ".msh":
        return None
    line = _first_line(path)
    return "gmsh" if line is not None and line.startswith(b"$MeshFormat") else None


#: meshio formats that write more than the named file (TetGen's .node + .ele, XDMF's .h5): they
#: are written in place, not through a temporary file.
_MULTI_FILE_FORMATS = ("tetgen", "xdmf")


def meshio_format(path: Path) -> str:
    """The meshio format that ``path``'s suffix selects.

    Raises
    ------
    InputError
        No suffix, or one meshio does not know (the message lists those it does).
    """
    import meshio

    suffixes = [s.lower() for s in path.suffixes]
    for k in range(len(suffixes)):
        formats = meshio.extension_to_filetypes.get("".join(suffixes[k:]))
        if formats:
            return str(formats[0])
    known = ", ".join(sorted(meshio.extension_to_filetypes))
    raise InputError(f"{path}: cannot tell the file format from the suffix {path.suffix!r}; expected one of {known}")


def meshio_write(path: Path, mesh: Any, *, run_id: int | None = None, **kwargs: Any) -> None:
    """``meshio.write`` to ``path`` through a temporary file renamed over it
    (:func:`sorofem._files.atomic_path`), for a format checked before anything is written;
    meshio's own failures become an :class:`InputError` naming ``path``. ``run_id`` marks a
    ``.vtu`` file with the field data ``sorofem_run_id`` (one Int64)."""
    import meshio

    file_format = kwargs.pop("file_format", None) or meshio_format(path)
    try:
        if file_format in _MULTI_FILE_FORMATS:
            meshio.write(path, mesh, file_format=file_format, **kwargs)
            return
        with atomic_path(path) as temporary:
            meshio.write(temporary, mesh, file_format=file_format, **kwargs)
            if run_id is not None and file_format == "vtu":
                _mark_vtu(temporary, run_id)
    except OSError:
        raise
    except (meshio.ReadError, meshio.WriteError, KeyError, ValueError, TypeError, ModuleNotFoundError) as exc:
        raise InputError(f"{path}: meshio cannot write this mesh as {file_format}: {exc}") from None


def _mark_vtu(path: Path, run_id: int) -> None:
    """Add the field data ``sorofem_run_id`` to a VTU file meshio wrote (its writer has none):
    a ``FieldData`` element at the head of the ``UnstructuredGrid``, where VTK and meshio read it."""
    data = path.read_bytes()
    tag = b"<UnstructuredGrid>"
    at = data.find(tag)
    if at < 0:
        raise InputError(f"{path}: not a VTU file as meshio writes it; cannot mark it with the run id")
    at += len(tag)
    field = (
        '\n<FieldData>\n<DataArray type="Int64" Name="sorofem_run_id" NumberOfTuples="1" format="ascii">'
        f"{int(run_id)}</DataArray>\n</FieldData>"
    ).encode("ascii")
    path.write_bytes(data[:at] + field + data[at:])


def _is_volume(cells: Any) -> bool:
    """Whether a meshio cell block holds 3-D cells."""
    dim = getattr(cells, "dim", None)
    return dim == 3 if dim is not None else cells.type == "tetra" or cells.type in _VOLUME_CELLS


# ---------------------------------------------------------------------------
# Volume meshes


def read_volume(path: Path) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64] | None]:
    """Points ``(n, 3)``, linear tetrahedra ``(m, 4)`` and per-tet integer tags ``(m,)`` (or
    None) of a mesh file: ``.tet``, or anything meshio reads (a TetGen pair by either name).

    Only the tetrahedra are kept, and the nodes they use (in their order).

    Raises
    ------
    FileNotFoundError
        No such file (for TetGen: either file of the pair).
    MeshError
        A malformed file, no tetrahedra, or volume cells other than linear tetrahedra.
    """
    path = check_path(path, "path")
    if not path.is_file():
        raise FileNotFoundError(f"mesh file not found: {path}")
    if path.suffix.lower() == ".tet":
        points, tets = _read_tet(path)
        return points, tets, None
    if path.suffix in (".node", ".ele"):  # meshio reads the TetGen pair from either name
        other = path.with_suffix(".ele" if path.suffix == ".node" else ".node")
        if not other.is_file():
            raise FileNotFoundError(f"mesh file not found: {other} (the TetGen companion of {path})")
    if path.suffix.lower() in SURFACE_FORMATS:
        raise MeshError(f"{path}: a {path.suffix.lower()} file holds a triangle surface, not tetrahedra; "
                        f"{_fill_hint(path)}")
    try:
        return _read_meshio_volume(path)
    except MeshError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, AttributeError, OverflowError, MemoryError) as exc:
        # What meshio hands back from a damaged file can be anything: ragged or non-numeric
        # arrays, cells without points, indices beyond int64.
        raise MeshError(f"{path}: malformed mesh data ({type(exc).__name__}: {exc})") from None


#: Suffixes of triangle-surface formats (no volume cells): a volume mesh is made from them by
#: sf.tetrahedralize.
SURFACE_FORMATS = (".stl", ".obj", ".ply", ".off")


def _fill_hint(path: Path) -> str:
    return (f"fill it with tetrahedra by sf.tetrahedralize({path.name!r}, edge_length=...) (the optional extra "
            f"'mesh'), or in a scene with [mesh] surface = \"{path.name}\" and edge_length")


def _read_tet(path: Path) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
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
    try:
        tet_array = np.array(tets, dtype=np.int64)
    except OverflowError:
        raise MeshError(f"{path}: a node index does not fit in a 64-bit integer") from None
    return np.array(points, dtype=np.float64).reshape(-1, 3), tet_array


def _read_meshio_volume(path: Path) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64] | None]:
    m = meshio_read(path, "mesh")
    volume = sorted({c.type for c in m.cells if c.type != "tetra" and _is_volume(c)})
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
        surface = f": a surface; {_fill_hint(path)}" if "triangle" in found else ""
        raise MeshError(
            f"{path}: no linear tetrahedra ('tetra' cells) found; cell types in the file: {', '.join(found)}{surface}"
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


def _cell_tags(m: Any, tetra: list[int], n_tets: int) -> NDArray[np.int64] | None:
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


def write_volume(path: Path, points: NDArray[np.float64], tets: NDArray[np.int64]) -> None:
    """Write tetrahedra as ``.tet`` (full float precision) or through meshio (by suffix), through
    a temporary file renamed over ``path``.

    Raises
    ------
    InputError
        A suffix no writer knows.
    OutputError
        The file cannot be written.
    """
    path = check_path(path, "path")
    if path.suffix.lower() == ".tet":
        with atomic_path(path) as temporary, temporary.open("w", encoding="utf-8") as fh:
            fh.write(f"# sorofem mesh: {len(points)} vertices, {len(tets)} tetrahedra\n")
            fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in points.tolist())
            fh.writelines(f"t {a} {b} {c} {d}\n" for a, b, c, d in tets.tolist())
        return
    import meshio

    meshio_write(path, meshio.Mesh(points, [("tetra", tets)]))


# ---------------------------------------------------------------------------
# Triangle surfaces


class Surface(NamedTuple):
    """A triangle surface: ``vertices`` ``(v, 3)`` (m) and ``faces`` ``(f, 3)`` (0-based; ``f``
    may be 0 for a point cloud). Unpacks as ``vertices, faces``."""

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]

    def same_topology(self, other: "Surface") -> bool:
        """Whether both have the same vertex count and the same faces, vertex for vertex
        (orientation and face order ignored)."""
        if len(self.vertices) != len(other.vertices) or len(self.faces) != len(other.faces):
            return False
        a = np.unique(np.sort(self.faces, axis=1), axis=0)
        b = np.unique(np.sort(other.faces, axis=1), axis=0)
        return a.shape == b.shape and bool(np.all(a == b))


def read_surface(path: PathLike, scale: float = 1.0) -> Surface:
    """Read a triangle surface: Wavefront OBJ with its own reader (polygons fanned into
    triangles, negative indices), anything else through meshio (triangles kept, quadrilaterals
    split in two; points, lines and vertex cells ignored). The surface is **not** checked for
    closedness or orientation (see :func:`sorofem.meshing.check_surface`); a file with points
    only gives a point cloud (no faces).

    Parameters
    ----------
    path
        The file (``.obj``, ``.stl``, ``.ply``, ``.off``, ...).
    scale
        Factor applied to the coordinates (e.g. ``1e-3`` for a CAD export in millimetres).

    Returns
    -------
    Surface
        ``vertices (v, 3)`` float64 (m) and ``faces (f, 3)`` int64.

    Raises
    ------
    FileNotFoundError
        No such file.
    MeshError
        The file cannot be parsed, holds volume cells or non-triangular cells, has no vertices,
        or face indices out of range.
    ParameterError
        ``scale`` is not a finite number > 0.
    """
    scale = positive_scalar(scale, "scale")
    path = check_path(path, "path")
    if not path.is_file():
        raise FileNotFoundError(f"surface file not found: {path}")
    try:
        if path.suffix.lower() == ".obj":
            vertices, faces = _read_obj(path)
        else:
            vertices, faces = _read_meshio_surface(path)
    except MeshError:
        raise
    except (ValueError, TypeError, IndexError, KeyError, AttributeError, OverflowError, MemoryError) as exc:
        raise MeshError(f"{path}: malformed surface data ({type(exc).__name__}: {exc})") from None
    if not np.all(np.isfinite(vertices)):
        raise MeshError(f"{path}: the surface has non-finite coordinates")
    if len(vertices) == 0:
        raise MeshError(f"{path}: the surface has no vertices")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise MeshError(f"{path}: face indices outside [0, {len(vertices)})")
    return Surface(vertices * scale, faces)


def _read_obj(path: Path) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Vertices and triangles of a Wavefront OBJ (polygons fanned into triangles)."""
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    with path.open(encoding="utf-8", errors="replace") as fh:
        for line_no, line in enumerate(fh, 1):
            parts = line.split()
            if not parts:
                continue
            try:
                if parts[0] == "v":
                    vertices.append([float(v) for v in parts[1:4]])
                elif parts[0] == "f":
                    idx = [int(p.split("/")[0]) for p in parts[1:]]
                    idx = [i - 1 if i > 0 else len(vertices) + i for i in idx]
                    faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
            except (ValueError, IndexError):
                raise MeshError(f"{path}:{line_no}: cannot parse OBJ line {line.strip()!r}") from None
    return np.asarray(vertices, dtype=np.float64).reshape(-1, 3), np.asarray(faces, dtype=np.int64).reshape(-1, 3)


def _read_meshio_surface(path: Path) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    m = meshio_read(path, "surface")
    kinds = sorted({c.type for c in m.cells})
    if any(_is_volume(c) for c in m.cells):
        raise MeshError(
            f"{path}: this is a volume mesh (cells: {', '.join(kinds)}), not a surface; read it with "
            f"sorofem.Mesh.read(path)"
        )
    others = [k for k in kinds if k not in ("triangle", "quad", "line", "vertex")]
    if others:
        raise MeshError(
            f"{path}: surface cells must be triangles (or quads); found {', '.join(others)}: triangulate "
            f"the surface first"
        )
    blocks: list[NDArray[np.int64]] = [np.zeros((0, 3), dtype=np.int64)]
    for cells in m.cells:
        data = np.asarray(cells.data, dtype=np.int64)
        if cells.type == "triangle":
            blocks.append(data.reshape(-1, 3))
        elif cells.type == "quad":
            data = data.reshape(-1, 4)
            blocks += [data[:, [0, 1, 2]], data[:, [0, 2, 3]]]
    points = np.asarray(m.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise MeshError(f"{path}: expected 3-D points, got an array of shape {points.shape}")
    return points, np.concatenate(blocks)

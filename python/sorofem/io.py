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

**Surfaces.** :func:`read_surface` reads triangle surfaces (OBJ with its own reader, ``.stl``,
``.ply``, ``.off`` and the rest through meshio) for :meth:`sorofem.Target.surface` and
:func:`sorofem.tetrahedralize`.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> sf.io.write_mesh("/tmp/beam.tet", mesh)
>>> sf.io.read_mesh("/tmp/beam.tet").n_tets
192
"""

from __future__ import annotations

import json
import math
import os
import re
import secrets
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._files import MAX_NAME_BYTES, MAX_PATH_BYTES, append_line, atomic_path, check_path, write_text
from ._formats import CELL_TAG_KEYS, Surface, meshio_read, meshio_write, read_surface, refuse_overwrite
from .errors import InputError
from .mesh import Mesh

__all__ = ["read_mesh", "write_mesh", "write_result", "result_mesh", "read_points", "read_surface", "Surface",
           "CELL_TAG_KEYS", "meshio_read", "atomic_path", "write_text", "append_line", "check_path", "MAX_NAME_BYTES",
           "MAX_PATH_BYTES", "json_text", "new_run_id", "RunFolder"]

PathLike = str | os.PathLike[str]


class ResultLike(Protocol):
    """What :func:`write_result` reads of a result (a :class:`sorofem.StaticResult`)."""

    mesh: Mesh
    positions: NDArray[np.float64]
    displacement: NDArray[np.float64]
    pressure: NDArray[np.float64] | None

    @property
    def J(self) -> NDArray[np.float64]: ...  # noqa: N802, D102

    @property
    def von_mises(self) -> NDArray[np.float64]: ...  # noqa: D102


def read_mesh(path: PathLike, scale: float = 1.0) -> Mesh:
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
    return Mesh.read(path, scale=scale)


def write_mesh(path: PathLike, mesh: Mesh) -> None:
    """Write a mesh as ``.tet`` (full float precision) or through meshio (:meth:`Mesh.write`).

    Raises
    ------
    InputError
        ``path`` is the file the mesh was read from.
    """
    mesh.write(path)


def read_points(path: PathLike) -> NDArray[np.float64]:
    """Points ``(k, 3)`` from a file: NumPy's ``.npy`` (an array of shape ``(k, 3)``) or a text
    table (``.csv``, ``.txt``, ``.dat``: three columns x, y, z separated by commas or
    whitespace, ``#`` comments, at most one header line of column names).

    Raises
    ------
    FileNotFoundError
        No such file.
    InputError
        Not three finite columns, or a format other than these.

    Examples
    --------
    >>> import numpy as np, sorofem as sf
    >>> _ = open("/tmp/markers.csv", "w").write("x,y,z\n0.1,0,0.02\n0.2,0,0.02\n")
    >>> sf.io.read_points("/tmp/markers.csv").shape
    (2, 3)
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"points file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise InputError(f"{path}: not a NumPy .npy array ({exc})") from None
    elif suffix in (".csv", ".txt", ".dat"):
        lines = [line.split("#", 1)[0].strip() for line in path.read_text(encoding="utf-8").splitlines()]
        rows = [line.replace(",", " ").split() for line in lines if line]
        try:
            float(rows[0][0]) if rows else None
        except ValueError:
            rows = rows[1:]  # a header of column names
        try:
            arr = np.array([[float(v) for v in row] for row in rows], dtype=np.float64)
        except ValueError as exc:
            raise InputError(f"{path}: expected numbers in three columns x, y, z ({exc})") from None
        if arr.size == 0 or any(len(row) != 3 for row in rows):
            counts = sorted({len(row) for row in rows})
            raise InputError(f"{path}: expected three columns x, y, z on every line, got {counts or 'no rows'}")
    else:
        raise InputError(f"{path}: expected a .npy array or a .csv/.txt table of points, got a {suffix or 'file without suffix'}")
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.dtype.kind not in "fiu":
        raise InputError(f"{path}: expected an array of shape (k, 3), got shape {arr.shape} ({arr.dtype})")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{path}: expected finite coordinates")
    return arr


def result_mesh(
    result: ResultLike,
    extra_point_data: Mapping[str, ArrayLike] | None = None,
    *,
    points: str = "rest",
) -> Any:
    """A result as a :class:`meshio.Mesh`: linear tetrahedra with point data ``displacement``
    (m), ``pressure`` (Pa, mixed formulation only), ``contact_force`` (N, the obstacles' force
    on each node, bodies with obstacles only) and ``extra_point_data``, cell data ``J`` (volume
    ratio) and ``von_mises`` (Pa).

    Parameters
    ----------
    points
        ``"rest"`` (default, the finite-element convention): the rest positions, so that
        ParaView's "Warp By Vector" on ``displacement`` (scale 1) shows the deformed body;
        ``"deformed"``: the deformed positions (then warping would deform it twice).

    Raises
    ------
    InputError
        ``points`` is neither, or ``extra_point_data`` has a wrong length.
    """
    import meshio

    if not isinstance(points, str) or points not in ("rest", "deformed"):
        raise InputError(f"points: expected 'rest' or 'deformed', got {points!r}")
    mesh = result.mesh
    point_data: dict[str, np.ndarray] = {"displacement": result.displacement}
    if result.pressure is not None:
        point_data["pressure"] = result.pressure
    if getattr(result, "contact", None) is not None:
        point_data["contact_force"] = np.asarray(result.contact_forces)
    for name, values in (extra_point_data or {}).items():
        arr = np.asarray(values)
        if arr.shape[:1] != (mesh.n_nodes,):
            raise InputError(
                f"extra_point_data[{name!r}]: expected {mesh.n_nodes} rows (one per node), got shape {arr.shape}"
            )
        point_data[str(name)] = arr
    cell_data = {"J": [result.J], "von_mises": [result.von_mises]}
    xyz = mesh.points if points == "rest" else result.positions
    return meshio.Mesh(np.array(xyz), [("tetra", mesh.tets)], point_data=point_data, cell_data=cell_data)


def write_result(
    path: PathLike,
    result: ResultLike,
    extra_point_data: Mapping[str, ArrayLike] | None = None,
    *,
    points: str = "rest",
    run_id: int | None = None,
) -> None:
    """Write a result (normally ``.vtu``) for ParaView: :func:`result_mesh` written by meshio,
    to a temporary name renamed over ``path`` (:func:`atomic_path`).

    The points are the **rest** positions and the point data ``displacement`` carries the
    motion (the finite-element convention): in ParaView, "Warp By Vector" on ``displacement``
    with scale 1 shows the deformed body, once. ``points="deformed"`` writes the deformed
    positions instead (e.g. a second file ``deformed.vtu`` to open without a filter). ``run_id``
    (an integer, as ``sorofem run`` gives each run) marks a ``.vtu`` with the field data
    ``sorofem_run_id``.

    Raises
    ------
    InputError
        ``path`` is the input mesh file, ``points`` is unknown, ``extra_point_data`` has a
        wrong length, the format is unknown, or a field is not finite (nothing is written).
    OutputError
        The file cannot be written.
    """
    path = check_path(path, "path")
    refuse_overwrite(path, result.mesh.source)
    mesh = result_mesh(result, extra_point_data, points=points)
    arrays = [("positions", result.positions), *mesh.point_data.items(),
              *((name, blocks[0]) for name, blocks in mesh.cell_data.items())]
    for name, values in arrays:
        arr = np.asarray(values)
        if np.issubdtype(arr.dtype, np.number) and not np.all(np.isfinite(arr)):
            raise InputError(f"result: {name} has non-finite values; refusing to write them to {path}")
    meshio_write(path, mesh, run_id=run_id)


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON types (NumPy scalars and arrays converted); a non-finite float,
    which JSON cannot hold, becomes ``None`` (``null``)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def json_text(value: Any, indent: int | None = 2) -> str:
    """Valid JSON text of ``value`` (:func:`jsonable`: never NaN or Infinity), ending with a
    newline when indented.

    Examples
    --------
    >>> sf.io.json_text({"loss": float("nan"), "n": np.int64(3)}, indent=None)  # doctest: +SKIP
    '{"loss": null, "n": 3}'
    """
    text = json.dumps(jsonable(value), indent=indent, allow_nan=False)
    return text + "\n" if indent is not None else text


def new_run_id() -> int:
    """A random 48-bit integer that marks the files of one run (``summary.json``'s ``run_id``,
    the ``sorofem_run_id`` field data of its ``.vtu`` files)."""
    return secrets.randbits(48)


_FRAME = re.compile(r"frame_\d+\.vtu")
#: The temporary name atomic_path writes to: .STEM.tmp-XXXXXXXX.SUFFIX
_TEMPORARY = re.compile(r"\..+\.tmp-[0-9a-f]{8}(\.[^.]+)?")


class RunFolder:
    """The output folder of one run of ``sorofem run``, ``estimate`` or ``control``: its run id,
    the ``summary.json`` that marks it, and what an earlier run left there.

    The rule: a command owns a fixed set of names in its folder (``owned``; for ``run`` the
    files it writes for static and dynamic scenes). When a run starts, it

    * draws a :attr:`run_id` that every file it writes carries (``summary.json``'s
      ``run_id``, the ``.vtu`` files' field data ``sorofem_run_id``, ``trajectory.pvd``'s
      attribute);
    * writes ``summary.json`` at once with ``"complete": false`` and ``"status": "running"``,
      so a run killed at any point (even by SIGKILL) leaves a summary that says so;
    * removes the frames ``frame_NNNNN.vtu`` of an earlier run from the frames folder
      (``trajectory/``, which is sorofem's own) when it will write frames, and the hidden
      temporary files (``.NAME.tmp-XXXXXXXX.SUFFIX``) of owned names that a killed run left;
    * lists the other owned names present that it will not write in ``stale_outputs`` (in
      ``summary.json``, and a warning on stderr): they are an earlier run's, and are left
      alone.

    Every file is written to a temporary name and renamed (:func:`atomic_path`);
    ``summary.json`` is written last, with ``"complete": true`` only once every other output
    is on the disk.
    """

    def __init__(self, folder: Path, outputs: Mapping[str, Path], owned: tuple[str, ...], frames: str | None = None) -> None:
        self.folder = Path(folder)
        self.outputs = dict(outputs)
        self.owned = owned
        self.frames = frames
        self.run_id = new_run_id()
        self.started = _now()
        self.stale: list[str] = []
        #: The last summary written and its status ("running" until the run ends).
        self.summary: dict[str, Any] = {}
        self.status = "running"

    def start(self, summary: Mapping[str, Any]) -> None:
        """Create the folder, find stale outputs, clear old frames, write the first summary."""
        if self.outputs:
            self.folder.mkdir(parents=True, exist_ok=True)
        self.stale = sorted(
            name for name in self.owned if name not in self.outputs and (self.folder / name).exists()
        )
        if self.frames is not None and self.frames in self.outputs and (self.folder / self.frames).is_dir():
            for old in (self.folder / self.frames).iterdir():
                if _FRAME.fullmatch(old.name) or _TEMPORARY.fullmatch(old.name):
                    old.unlink()
        if self.folder.is_dir():
            for old in self.folder.iterdir():
                # What a killed run (SIGKILL, power loss) left while writing one of these names.
                if _TEMPORARY.fullmatch(old.name) and old.name.split(".tmp-")[0][1:] in self._stems():
                    old.unlink()
        self.write_summary(summary, complete=False, status="running")

    def _stems(self) -> set[str]:
        return {Path(name).stem for name in self.owned}

    def write_summary(self, summary: Mapping[str, Any], *, complete: bool, status: str) -> str:
        """The summary marked with the run (id, start and end times, ``complete``, ``status``,
        stale outputs) as JSON text, written to ``summary.json`` if it is an output."""
        marked = {
            **summary,
            "run_id": self.run_id,
            "started": self.started,
            "finished": _now() if status != "running" else None,
            "complete": complete,
            "status": status,
            "stale_outputs": self.stale,
        }
        text = json_text(marked)
        self.summary, self.status = dict(summary), status
        if "summary.json" in self.outputs:
            write_text(self.outputs["summary.json"], text)
        return text

    def stopped(self, status: str) -> None:
        """Mark a run that stopped before it wrote its final summary (Ctrl-C, SIGTERM, a full
        disk): the last summary again, with ``"complete": false`` and ``status`` (best effort:
        a full disk may refuse this too)."""
        if self.status != "running":
            return
        try:
            self.write_summary(self.summary, complete=False, status=status)
        except OSError:
            pass


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")

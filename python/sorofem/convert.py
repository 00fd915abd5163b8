"""Convert tetrahedral meshes between file formats (``sorofem convert IN OUT [--scale S]``).

Reads anything :func:`sorofem.io.read_mesh` reads and writes:

``.tet``
    sorofem's text format (full float precision).
``.msh``
    Gmsh 4.1, ASCII (physical and geometrical tags 0).
``.node`` / ``.ele``
    TetGen: both ``STEM.node`` and ``STEM.ele`` are written, whichever one is named.
``.stl``, ``.obj``, ``.ply``, ``.off``
    Surface formats: the outward-oriented boundary triangles (only their nodes).
anything else meshio writes
    ``.vtu``, ``.vtk``, ``.mesh`` (Medit), ``.inp`` (Abaqus), ...: the tetrahedra.

Reading goes through :func:`sorofem.io.read_mesh`, so a converted mesh is exactly what a
scene would see: tets only, nodes used by no tet dropped, inverted tets reoriented, coordinates
multiplied by ``scale``. The input is never overwritten: for TetGen the ``.node`` and
``.ele`` companions of the input and of the output are compared too.

Examples
--------
>>> import sorofem as sf
>>> from sorofem.convert import convert
>>> sf.Mesh.box(size=(400, 100, 100), cells=(4, 1, 1)).write("/tmp/beam_mm.tet")
>>> mesh = convert("/tmp/beam_mm.tet", "/tmp/beam.msh", scale=1e-3)
>>> sf.Mesh.read("/tmp/beam.msh").bounds[1].tolist()
[0.4, 0.1, 0.1]
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ._formats import same_file
from .errors import InputError
from .io import read_mesh, write_mesh
from .mesh import Mesh

__all__ = ["convert", "SURFACE_SUFFIXES", "TETGEN_SUFFIXES"]

#: Formats that hold triangles only: the boundary surface is written.
SURFACE_SUFFIXES = (".stl", ".obj", ".ply", ".off")
#: TetGen's pair of files; naming either one means both.
TETGEN_SUFFIXES = (".node", ".ele")

PathLike = str | os.PathLike[str]


def _files_of(path: Path) -> list[Path]:
    """The files a mesh path stands for (both halves of a TetGen pair)."""
    if path.suffix.lower() in TETGEN_SUFFIXES:
        return [path.with_suffix(suffix) for suffix in TETGEN_SUFFIXES]
    return [path]


def convert(source: PathLike, target: PathLike, scale: float = 1.0) -> Mesh:
    """Read the mesh ``source`` and write it to ``target`` in the format of its suffix.

    Parameters
    ----------
    source
        Input mesh: ``.tet`` or any volume format meshio reads (``.msh``, ``.node``/``.ele``,
        ``.vtu``, ...).
    target
        Output path; its suffix picks the format (see the module docstring).
    scale
        Factor applied to the coordinates (e.g. ``1e-3`` from millimetres to metres).

    Returns
    -------
    Mesh
        The mesh that was written (before surface extraction), with ``source`` set.

    Raises
    ------
    FileNotFoundError
        ``source`` does not exist.
    InputError
        ``target`` is (or, for TetGen, shares a file with) ``source``, or meshio cannot write
        the format.
    MeshError
        ``source`` holds no valid tetrahedral mesh.

    Examples
    --------
    >>> convert("part.msh", "part.tet", scale=1e-3)  # doctest: +SKIP
    """
    source, target = Path(source), Path(target)
    for written in _files_of(target):
        for read in _files_of(source):
            if same_file(written, read):
                raise InputError(
                    f"refusing to overwrite the input file {read} (converting {source} to {target}); "
                    "choose another output name"
                )
    mesh = read_mesh(source, scale=scale)
    suffix = target.suffix.lower()
    if not suffix:
        raise InputError(f"{target}: the output needs a file suffix (.tet, .msh, .vtu, .node, ...) to pick the format")
    if suffix == ".tet":
        write_mesh(target, mesh)
        return mesh

    import meshio

    points, cells = mesh.points, [("tetra", mesh.tets)]
    kwargs: dict[str, object] = {}
    if suffix in SURFACE_SUFFIXES:
        faces = mesh.boundary_faces()
        used = np.unique(faces)
        remap = np.full(mesh.n_nodes, -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        points, cells = points[used], [("triangle", remap[faces])]
    cell_data = {}
    if suffix == ".msh":
        # ASCII Gmsh 4.1; explicit zero tags (meshio would otherwise print a warning for each).
        kwargs = {"file_format": "gmsh", "binary": False}
        zeros = np.zeros(mesh.n_tets, dtype=np.int64)
        cell_data = {"gmsh:physical": [zeros], "gmsh:geometrical": [zeros]}
    try:
        meshio.write(target, meshio.Mesh(points, cells, cell_data=cell_data), **kwargs)
    except (meshio.ReadError, meshio.WriteError, KeyError, ValueError, ModuleNotFoundError) as exc:
        # ReadError: meshio's "could not deduce file format" for an unknown suffix.
        raise InputError(f"{target}: meshio cannot write this format: {exc}") from None
    return mesh


def run_command(source: Path, target: Path, scale: float, quiet: bool = False) -> int:
    """``sorofem convert``: convert and print what was written; returns the exit code 0 (errors
    propagate to :func:`sorofem.cli.main`)."""
    mesh = convert(source, target, scale=scale)
    if not quiet:
        written = ", ".join(str(p) for p in _files_of(target))
        what = "boundary surface of " if target.suffix.lower() in SURFACE_SUFFIXES else ""
        print(f"wrote {written}: {what}{mesh.n_nodes} nodes, {mesh.n_tets} tets (scale {scale:g})")
    return 0


#: Old private name of :func:`run_command`.
_cli = run_command

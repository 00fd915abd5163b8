"""Property-based: mesh and surface files of any content. A reader either returns a valid mesh
(finite coordinates, indices in range, positive volumes) or raises a :class:`sorofem.MeshError`
naming the file; ``sorofem info`` exits 0 or 2, never with a traceback.

The bytes are random, or a valid file of each format damaged (cut, bytes flipped, numbers
replaced by extreme ones). ``make fuzz`` runs the same checks with many more examples
(tests/fuzz_mesh_readers.py).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import sorofem as sf
from sorofem.cli import main

SUFFIXES = [".tet", ".vtu", ".msh", ".mesh", ".vtk", ".xml", ".obj", ".stl", ".ply", ".off", ".node", ".unknownext", ""]
EXTREMES = [b"nan", b"inf", b"-1", b"1e308", b"99999999999999999999999", b"0", b"", b"\x00", b"1e-320", b"-0"]


def _valid_files(folder: Path) -> dict[str, bytes]:
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(2, 1, 1))
    out = {}
    for suffix in (".tet", ".vtu", ".msh", ".mesh", ".vtk"):
        path = folder / f"valid{suffix}"
        if suffix == ".msh":
            sf.convert.convert(folder / "valid.tet", path)
        elif suffix == ".vtu":
            import meshio

            meshio.write(path, meshio.Mesh(mesh.points, [("tetra", mesh.tets)]), binary=False)
        else:
            sf.io.write_mesh(path, mesh)
        out[suffix] = path.read_bytes()
    out[".obj"] = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n"
    return out


_FOLDER = Path(__import__("tempfile").mkdtemp(prefix="sorofem-valid-"))
VALID = _valid_files(_FOLDER)


@st.composite
def damaged(draw) -> tuple[str, bytes]:
    """A valid file cut short, with bytes flipped, or with numbers made extreme."""
    suffix = draw(st.sampled_from(sorted(VALID)))
    data = bytearray(VALID[suffix])
    kind = draw(st.sampled_from(["cut", "flip", "extreme", "lines"]))
    if kind == "cut":
        data = data[: draw(st.integers(0, len(data)))]
    elif kind == "flip":
        for _ in range(draw(st.integers(1, 8))):
            data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    elif kind == "extreme":
        tokens = bytes(data).split(b" ")
        for _ in range(draw(st.integers(1, 4))):
            tokens[draw(st.integers(0, len(tokens) - 1))] = draw(st.sampled_from(EXTREMES))
        data = bytearray(b" ".join(tokens))
    else:
        lines = bytes(data).split(b"\n")
        order = draw(st.permutations(range(len(lines))))
        data = bytearray(b"\n".join(lines[i] for i in order[: draw(st.integers(0, len(lines)))]))
    return draw(st.sampled_from([suffix, *SUFFIXES])), bytes(data)


FILES = st.one_of(damaged(), st.tuples(st.sampled_from(SUFFIXES), st.binary(max_size=400)))


def read_volume_checked(path: Path) -> None:
    try:
        mesh = sf.Mesh.read(path)
    except sf.MeshError as exc:
        assert str(path) in str(exc), str(exc)
        return
    except FileNotFoundError as exc:  # a TetGen file without its companion
        assert str(path.with_suffix("")) in str(exc)
        return
    assert np.all(np.isfinite(mesh.points))
    assert mesh.tets.min() >= 0 and mesh.tets.max() < mesh.n_nodes
    assert np.all(mesh.volumes > 0)


def read_surface_checked(path: Path) -> None:
    try:
        surface = sf.io.read_surface(path)
    except sf.MeshError as exc:
        assert str(path) in str(exc), str(exc)
        return
    assert np.all(np.isfinite(surface.vertices))
    assert surface.faces.size == 0 or (surface.faces.min() >= 0 and surface.faces.max() < len(surface.vertices))


@settings(max_examples=150)
@given(file=FILES)
def test_any_mesh_file_is_read_or_refused_with_a_mesh_error(tmp_path_factory, file):
    suffix, data = file
    path = tmp_path_factory.mktemp("mesh") / f"m{suffix}"
    path.write_bytes(data)
    read_volume_checked(path)
    read_surface_checked(path)


@settings(max_examples=40)
@given(file=FILES)
def test_sorofem_info_answers_any_mesh_file_cleanly(tmp_path_factory, file):
    suffix, data = file
    path = tmp_path_factory.mktemp("info") / f"m{suffix}"
    path.write_bytes(data)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        code = main(["info", str(path), "--json"])
    assert code in (0, 2) and "Traceback" not in err.getvalue(), err.getvalue()
    if code == 0:
        __import__("json").loads(out.getvalue(), parse_constant=lambda c: (_ for _ in ()).throw(AssertionError(c)))

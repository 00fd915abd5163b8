"""Reading and writing meshes and results."""

from __future__ import annotations

import sys
import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.io import read_mesh, write_mesh, write_result


@pytest.fixture
def beam() -> sf.Mesh:
    return sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(4, 1, 1))


def test_tet_round_trip(tmp_path, beam):
    path = tmp_path / "beam.tet"
    write_mesh(path, beam)
    back = read_mesh(path)
    assert np.array_equal(back.points, beam.points)
    assert np.array_equal(back.tets, beam.tets)
    assert back.source == path


def test_tet_comments_blank_lines_and_scale(tmp_path):
    path = tmp_path / "one.tet"
    path.write_text(
        "# a single tet\n\nv 0 0 0\nv 1 0 0  # trailing comment\nv 0 1 0\nv 0 0 1\n\nt 0 1 2 3\n"
    )
    mesh = read_mesh(path, scale=1e-3)
    assert mesh.n_tets == 1
    assert mesh.volumes.sum() == pytest.approx(1e-9 / 6)


@pytest.mark.parametrize(
    "bad_line",
    ["v 0 0", "t 0 1 2", "v 0 0 x", "t 0 1 2 3.5", "q 1 2 3"],
)
def test_malformed_tet_line_names_file_and_line(tmp_path, bad_line):
    path = tmp_path / "bad.tet"
    path.write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\n{bad_line}\nv 0 0 1\nt 0 1 2 3\n")
    with pytest.raises(sf.MeshError) as info:
        read_mesh(path)
    message = str(info.value)
    assert "bad.tet" in message and "line 4" in message and bad_line in message


def test_tet_without_tets(tmp_path):
    path = tmp_path / "empty.tet"
    path.write_text("v 0 0 0\n")
    with pytest.raises(sf.MeshError, match="no tetrahedra"):
        read_mesh(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_mesh(tmp_path / "nope.vtu")


def test_vtu_round_trip(tmp_path, beam):
    path = tmp_path / "beam.vtu"
    beam.write(path)
    back = sf.Mesh.read(path)
    assert np.allclose(back.points, beam.points)
    assert np.array_equal(back.tets, beam.tets)


def test_meshio_drops_unused_nodes_and_needs_tetra(tmp_path):
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5]], dtype=float)
    path = tmp_path / "extra.vtu"
    meshio.write_points_cells(path, points, [("tetra", np.array([[0, 1, 2, 3]])), ("vertex", np.array([[4]]))])
    mesh = read_mesh(path)
    assert mesh.n_nodes == 4
    tri = tmp_path / "surface.vtu"
    meshio.write_points_cells(tri, points[:3], [("triangle", np.array([[0, 1, 2]]))])
    with pytest.raises(sf.MeshError, match="triangle"):
        read_mesh(tri)


def test_shared_box2(shared_data):
    mesh = sf.Mesh.read(shared_data / "box2.tet", scale=1.0)
    assert (mesh.n_nodes, mesh.n_tets) == (81, 192)
    assert mesh.volumes.sum() == pytest.approx(0.4 * 0.1 * 0.1)


def test_refuses_to_overwrite_input(tmp_path, beam):
    src = tmp_path / "robot.tet"
    write_mesh(src, beam)
    before = src.read_bytes()
    mesh = read_mesh(src)
    with pytest.raises(sf.InputError, match="overwrite"):
        mesh.write(src)
    with pytest.raises(sf.InputError, match="overwrite"):
        write_mesh(tmp_path / "." / "robot.tet", mesh)
    assert src.read_bytes() == before
    mesh.write(tmp_path / "copy.tet")  # another path is fine


def _solved(mesh: sf.Mesh) -> sf.StaticResult:
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return sf.solve_static(body, gravity=(0, 0, -9.81))


def test_write_result(tmp_path, beam):
    result = _solved(beam)
    path = tmp_path / "result.vtu"
    write_result(path, result, extra_point_data={"marker": np.arange(beam.n_nodes, dtype=float)})
    back = meshio.read(path)
    # The finite-element convention: rest points, and the motion as point data, so that
    # ParaView's Warp By Vector (scale 1) gives the deformed body once.
    assert np.allclose(back.points, beam.points)
    assert np.allclose(back.points + back.point_data["displacement"], result.positions)
    assert "pressure" not in back.point_data
    assert "marker" in back.point_data
    assert np.allclose(back.cell_data["J"][0], result.J)
    assert np.allclose(back.cell_data["von_mises"][0], result.von_mises)
    with pytest.raises(sf.InputError, match="marker"):
        write_result(path, result, extra_point_data={"marker": np.zeros(3)})


def test_write_result_deformed_and_the_result_as_meshio_and_pyvista(tmp_path, beam, monkeypatch):
    result = _solved(beam)
    write_result(tmp_path / "deformed.vtu", result, points="deformed")
    deformed = meshio.read(tmp_path / "deformed.vtu")
    assert np.allclose(deformed.points, result.positions)
    with pytest.raises(sf.InputError, match="points: expected 'rest' or 'deformed'"):
        write_result(tmp_path / "x.vtu", result, points="current")
    mesh = result.to_meshio()
    assert np.array_equal(mesh.points, beam.points) and np.array_equal(mesh.cells_dict["tetra"], beam.tets)
    assert np.array_equal(mesh.point_data["displacement"], result.displacement)
    assert np.array_equal(mesh.cell_data["von_mises"][0], result.von_mises)
    assert np.array_equal(result.to_meshio("deformed").points, result.positions)
    monkeypatch.setitem(sys.modules, "pyvista", None)  # as if PyVista were not installed
    with pytest.raises(ImportError, match="pip install pyvista"):
        result.to_pyvista()


def test_write_result_refuses_input_mesh(tmp_path, beam):
    src = tmp_path / "robot.vtu"
    beam.write(src)
    result = _solved(sf.Mesh.read(src))
    with pytest.raises(sf.InputError, match="overwrite"):
        write_result(src, result)


def test_plots(tmp_path, beam):
    result = _solved(beam)
    fig = sf.plot.plot_rest_and_deformed(result, tmp_path / "shape.png", title="beam")
    assert fig.axes[0].get_title() == "beam"
    sf.plot.plot_convergence(result.report, tmp_path / "conv.png", tolerance=1e-8)
    for name in ("shape.png", "conv.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plots_follow_the_matplotlib_convention(tmp_path, beam):
    """Each plot function draws into ``ax=`` when given (a notebook's figure) and returns the
    Figure; without ``path`` nothing is written."""
    from matplotlib.figure import Figure

    result = _solved(beam)
    fig = Figure()
    ax = fig.add_subplot()
    assert sf.plot.plot_convergence(result.report, ax=ax) is fig
    assert list(tmp_path.iterdir()) == []
    # Iteration 0 is the initial residual: "converged after n iterations" ends at n.
    x = ax.lines[0].get_xdata()
    assert x[0] == 0 and x[-1] == result.report.iterations == len(result.report.residual_history) - 1
    assert ax.get_title() == f"Newton: converged after {result.report.iterations} iterations"
    fig3d = Figure()
    ax3d = fig3d.add_subplot(projection="3d")
    assert sf.plot.plot_rest_and_deformed(result, ax=ax3d) is fig3d
    with pytest.raises(sf.InputError, match="3-D matplotlib Axes"):
        sf.plot.plot_rest_and_deformed(result, ax=ax)
    own = sf.plot.plot_convergence(result.report)
    assert isinstance(own, Figure) and own is not fig


def test_shape_tick_labels_do_not_meet_at_the_corners(beam):
    """Seen from azimuth -60 the y axis starts where x ends and z rises where y ends: no tick
    label at y's ends, nor at z's lower end."""
    cube = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    for result in (_solved(beam), _solved(cube)):  # a slender body (short y and z) and a compact one
        ax = sf.plot.plot_rest_and_deformed(result).axes[0]
        for axis, (lo, hi), ends in ((ax.yaxis, ax.get_ylim(), (True, True)), (ax.zaxis, ax.get_zlim(), (True, False))):
            ticks = axis.get_major_locator()()
            margin = 0.1 * (hi - lo)
            assert len(ticks) >= 1
            if ends[0]:
                assert min(ticks) > lo + margin
            if ends[1]:
                assert max(ticks) < hi - margin


# ---------------------------------------------------------------------------
# Gmsh (2.2, 4.1; ASCII, binary) and TetGen files, with the extra cells and tags they carry

#: Two tets (0-based node indices) of total volume 1/6 + 1/3, and a sixth point no tet uses.
POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [9, 9, 9]], dtype=float)
TETS = np.array([[0, 1, 2, 3], [1, 2, 4, 3]])
VOLUME = 1 / 6 + 1 / 3


def _check_two_tets(mesh: sf.Mesh, scale: float = 1.0, tags: list[int] | None = None) -> None:
    assert (mesh.n_nodes, mesh.n_tets) == (5, 2)  # the unused point is dropped
    assert mesh.volumes.sum() == pytest.approx(VOLUME * scale**3)
    np.testing.assert_allclose(mesh.points, POINTS[:5] * scale)
    assert (mesh.cell_tags is None) if tags is None else (mesh.cell_tags.tolist() == tags)


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_gmsh22_with_points_lines_triangles_and_physical_groups(tmp_path, binary):
    path = tmp_path / "part.msh"
    cells = [("vertex", np.array([[5]])), ("line", np.array([[0, 1]])), ("triangle", np.array([[0, 1, 2]])),
             ("tetra", TETS)]
    physical = [np.array([1]), np.array([2]), np.array([3]), np.array([7, 8])]
    meshio.write(path, meshio.Mesh(POINTS, cells, cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical}),
                 file_format="gmsh22", binary=binary)
    _check_two_tets(sf.Mesh.read(path, scale=1e-3), 1e-3, tags=[7, 8])


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_gmsh41_written_by_meshio(tmp_path, binary):
    path = tmp_path / "part.msh"
    meshio.write(path, meshio.Mesh(POINTS[:5], [("tetra", TETS)]), file_format="gmsh", binary=binary)
    assert path.read_bytes().startswith(b"$MeshFormat\n4.1")
    _check_two_tets(sf.Mesh.read(path))  # no physical groups: no tags


# Gmsh 4.1 ASCII as Gmsh writes it: physical names, entities (a point, a surface and two volumes
# in physical groups 1, 3, 7 and 8), nodes by entity block with tags starting at 1, a point
# element, a surface triangle and one tet in each volume.
GMSH41 = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
4
0 1 "tip"
2 3 "base"
3 7 "soft"
3 8 "stiff"
$EndPhysicalNames
$Entities
1 0 1 2
1 9 9 9 1 1
1 0 0 0 1 1 0 1 3 0
1 0 0 0 1 1 1 1 7 0
2 0 0 0 1 1 1 1 8 0
$EndEntities
$Nodes
3 6 1 6
0 1 0 1
6
9 9 9
2 1 0 3
1
2
3
0 0 0
1 0 0
0 1 0
3 1 0 2
4
5
0 0 1
1 1 1
$EndNodes
$Elements
4 4 1 4
0 1 15 1
1 6
2 1 2 1
2 1 2 3
3 1 4 1
3 1 2 3 4
3 2 4 1
4 2 3 5 4
$EndElements
"""


def test_gmsh41_as_gmsh_writes_it(tmp_path, capsys):
    path = tmp_path / "finger.msh"
    path.write_text(GMSH41)
    mesh = sf.Mesh.read(path, scale=2.0)
    _check_two_tets(mesh, 2.0, tags=[7, 8])
    # Tags follow the mesh through scaled() and transformed(), and `sorofem info` lists them.
    assert mesh.scaled(0.5).cell_tags.tolist() == [7, 8]
    assert mesh.transformed(["x", "-z", "y"]).cell_tags.tolist() == [7, 8]
    from sorofem.cli import main

    assert main(["info", str(path), "--json"]) == 0
    info = __import__("json").loads(capsys.readouterr().out)
    assert (info["n_nodes"], info["n_tets"], info["cell_tags"]) == (5, 2, {"7": 1, "8": 1})
    assert info["volume"] == pytest.approx(VOLUME)


# TetGen as `tetgen -pqA` writes it: 1-based indices, a boundary-marker column, a region attribute
# per tet, a comment at the end.
TETGEN_NODE = """6  3  0  1
   1    0.0  0.0  0.0    1
   2    1.0  0.0  0.0    1
   3    0.0  1.0  0.0    1
   4    0.0  0.0  1.0    1
   5    1.0  1.0  1.0    1
   6    9.0  9.0  9.0    0
# Generated by tetgen -pqA part.poly
"""
TETGEN_ELE = """2  4  1
    1     1    2    3    4    1
    2     2    3    5    4    2
# Generated by tetgen -pqA part.poly
"""


def test_tetgen_one_based_with_region_attributes(tmp_path, capsys):
    (tmp_path / "part.1.node").write_text(TETGEN_NODE)
    (tmp_path / "part.1.ele").write_text(TETGEN_ELE)
    for name in ("part.1.node", "part.1.ele"):
        _check_two_tets(sf.Mesh.read(tmp_path / name, scale=1e-3), 1e-3, tags=[1, 2])
    from sorofem.cli import main

    assert main(["convert", str(tmp_path / "part.1.ele"), str(tmp_path / "part.tet"), "--quiet"]) == 0
    _check_two_tets(sf.Mesh.read(tmp_path / "part.tet"))
    (tmp_path / "lonely.node").write_text(TETGEN_NODE)
    with pytest.raises(FileNotFoundError, match="lonely.ele"):
        sf.Mesh.read(tmp_path / "lonely.node")


def test_tetgen_zero_based_written_by_meshio(tmp_path):
    meshio.write(tmp_path / "part.node", meshio.Mesh(POINTS, [("tetra", TETS)]), file_format="tetgen")
    assert (tmp_path / "part.ele").is_file()
    _check_two_tets(sf.Mesh.read(tmp_path / "part.ele"))


@pytest.mark.parametrize("kind, cell, words", [
    ("tetra10", np.array([[0, 1, 2, 3, 6, 7, 8, 9, 10, 11]]), ["1 tetra10", "order 1"]),
    ("hexahedron", np.array([[0, 1, 2, 3, 4, 5, 6, 7]]), ["1 hexahedron", "tetrahedra only"]),
])
def test_other_volume_cells_are_an_error(tmp_path, kind, cell, words):
    points = np.random.default_rng(0).random((12, 3))
    path = tmp_path / "part.vtu"
    meshio.write_points_cells(path, points, [("tetra", np.array([[0, 1, 2, 3]])), (kind, cell)])
    with pytest.raises(sf.MeshError) as info:
        sf.Mesh.read(path)
    for word in words:
        assert word in str(info.value)

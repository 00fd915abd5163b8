"""Reading and writing meshes and results."""

from __future__ import annotations

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
    assert np.allclose(back.points, result.positions)
    assert np.allclose(back.point_data["displacement"], result.displacement)
    assert "pressure" not in back.point_data
    assert "marker" in back.point_data
    assert np.allclose(back.cell_data["J"][0], result.J)
    assert np.allclose(back.cell_data["von_mises"][0], result.von_mises)
    with pytest.raises(sf.InputError, match="marker"):
        write_result(path, result, extra_point_data={"marker": np.zeros(3)})


def test_write_result_refuses_input_mesh(tmp_path, beam):
    src = tmp_path / "robot.vtu"
    beam.write(src)
    result = _solved(sf.Mesh.read(src))
    with pytest.raises(sf.InputError, match="overwrite"):
        write_result(src, result)


def test_plots(tmp_path, beam):
    result = _solved(beam)
    sf.plot.plot_rest_and_deformed(result, tmp_path / "shape.png", title="beam")
    sf.plot.plot_convergence(result.report, tmp_path / "conv.png", tolerance=1e-8)
    for name in ("shape.png", "conv.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

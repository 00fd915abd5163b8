"""Scenes from a surface: ``[mesh] surface`` (filled with tetrahedra by sf.tetrahedralize), a
surface given as ``mesh.file`` (a clear error, no warning from meshio), and targets read from
files (``[target] positions_file``)."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main

DATA = Path(__file__).resolve().parent.parent / "examples" / "data"


def _scene_text(mesh: str) -> str:
    """A scene standing on z = 0, its [mesh] table ``mesh``."""
    return f"""\
[mesh]
{mesh}

[material]
youngs_modulus = 50e3
poisson_ratio = 0.45
density = 1070

[[fixed]]
box = {{ min = [-1, -1, -1], max = [1, 1, 1e-4] }}

[loads]
gravity = [0, 0, -9.81]
"""


def _write(tmp_path: Path, mesh: str, extra: str = "") -> Path:
    for name in ("h_robot.stl", "finger.stl"):
        (tmp_path / name).write_bytes((DATA / name).read_bytes())
    path = tmp_path / "scene.toml"
    path.write_text(_scene_text(mesh) + extra, encoding="utf-8")
    return path


@pytest.mark.parametrize("suffix", [".stl", ".obj"])
def test_a_surface_as_mesh_file_names_the_way_out_and_warns_nothing(tmp_path, capsys, suffix):
    points, triangles = sf.io.read_surface(DATA / "h_robot.stl")
    meshio.write(tmp_path / f"robot{suffix}", meshio.Mesh(points, [("triangle", triangles)]))
    scene = _write(tmp_path, f'file = "robot{suffix}"\nscale = 1e-3')
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # meshio's overflow warning once leaked through here
        assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.splitlines()) == 1
    err = captured.err
    assert "key 'mesh.file'" in err and f"a {suffix} file holds a triangle surface" in err
    assert "sf.tetrahedralize(" in err and '[mesh] surface = "robot' in err
    with pytest.raises(sf.MeshError, match=r"sf\.tetrahedralize"):
        sf.Mesh.read(tmp_path / f"robot{suffix}")


def test_triangles_only_in_a_volume_format_name_the_way_out_too(tmp_path):
    points, triangles = sf.io.read_surface(DATA / "h_robot.stl")
    meshio.write(tmp_path / "robot.vtu", meshio.Mesh(points, [("triangle", triangles)]))
    with pytest.raises(sf.MeshError, match=r"cell types in the file: triangle: a surface; fill it with tetrahedra by "
                                           r"sf\.tetrahedralize"):
        sf.Mesh.read(tmp_path / "robot.vtu")


def test_surface_key_fills_the_surface_with_tetrahedra(tmp_path):
    pytest.importorskip(sf.meshing.MESHER, reason="[mesh] surface needs the optional mesher")
    scene = sf.Scene.load(_write(tmp_path, 'surface = "h_robot.stl"\nscale = 1e-3\nedge_length = 0.008'))
    points, triangles = sf.io.read_surface(tmp_path / "h_robot.stl", scale=1e-3)
    enclosed = sf.meshing.surface_volume(points, triangles)
    assert scene.mesh.volumes.sum() == pytest.approx(enclosed, rel=0.02)
    assert np.ptp(scene.mesh.points, axis=0) == pytest.approx([0.08, 0.02, 0.06], rel=0.01)
    assert scene.mesh.source == tmp_path / "h_robot.stl" and scene.mesh.source in scene.input_files
    finer = sf.Scene.load(_write(tmp_path, 'surface = "h_robot.stl"\nscale = 1e-3\nedge_length = 0.004'))
    assert finer.mesh.n_tets > 2 * scene.mesh.n_tets  # edge_length is passed on


def test_surface_key_errors(tmp_path, monkeypatch):
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(_write(tmp_path, 'surface = "missing.stl"'))
    assert info.value.key == "mesh.surface" and "surface file not found" in str(info.value)
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(_write(tmp_path, 'file = "h_robot.stl"\nedge_length = 0.01'))
    assert info.value.key == "mesh.edge_length" and "only allowed with" in str(info.value)
    monkeypatch.setitem(sys.modules, sf.meshing.MESHER, None)  # as if the mesher were not installed
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(_write(tmp_path, 'surface = "h_robot.stl"\nscale = 1e-3'))
    assert info.value.key == "mesh.surface" and sf.meshing.INSTALL_HINT in str(info.value)


def test_surface_key_edge_length_out_of_range(tmp_path):
    pytest.importorskip(sf.meshing.MESHER, reason="[mesh] surface needs the optional mesher")
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(_write(tmp_path, 'surface = "h_robot.stl"\nscale = 1e-3\nedge_length = 1.0'))
    assert info.value.key == "mesh.edge_length" and "bounding-box diagonal" in str(info.value)


TARGET_SCENE = """\
[mesh]
box = { size = [0.4, 0.1, 0.1], cells = [4, 2, 2] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]
"""


@pytest.mark.parametrize("suffix", [".csv", ".npy", ".txt"])
def test_target_positions_from_a_file(tmp_path, suffix):
    goal = np.array([[0.4, 0.05, -0.1], [0.4, 0.0, -0.12]])
    path = tmp_path / f"goal{suffix}"
    if suffix == ".npy":
        np.save(path, goal)
    else:
        sep = "," if suffix == ".csv" else " "
        path.write_text("# measured\nx,y,z\n" + "".join(sep.join(map(repr, row)) + "\n" for row in goal.tolist()))
    text = TARGET_SCENE + f'\n[target]\npoints = [[0.4, 0.05, 0.05], [0.4, 0.0, 0.0]]\npositions_file = "{path.name}"\n'
    scene = sf.Scene.from_toml(text, tmp_path / "scene.toml")
    bound = scene.target.bind(scene.mesh)
    np.testing.assert_array_equal(bound.goal, goal)
    assert path in scene.input_files  # never overwritten by an output
    text = TARGET_SCENE + f'\n[target]\nnodes = [0]\npositions_file = "{path.name}"\n'
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.from_toml(text, tmp_path / "scene.toml")
    assert info.value.key == "target.positions_file" and "expected 1 positions, one per entry of 'nodes', got 2" in str(info.value)


@pytest.mark.parametrize("content, message", [
    ("1,2\n3,4\n", "expected three columns x, y, z on every line, got [2]"),
    ("x,y,z\n1,2,three\n", "expected numbers in three columns"),
])
def test_target_positions_file_errors(tmp_path, content, message):
    (tmp_path / "goal.csv").write_text(content)
    text = TARGET_SCENE + '\n[target]\nnodes = [0, 1]\npositions_file = "goal.csv"\n'
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.from_toml(text, tmp_path / "scene.toml")
    assert info.value.key == "target.positions_file" and message in str(info.value)
    for extra, key, what in (
        ('positions_file = "absent.csv"', "target.positions_file", "points file not found"),
        ("", "target.positions", "missing: expected the goal of each of 'nodes'"),
        ('positions = [[0, 0, 0], [0, 0, 0]]\npositions_file = "goal.csv"', "target",
         "expected at most one of 'positions', 'positions_file', 'tracks' or 'tracks_file'"),
    ):
        text = TARGET_SCENE + f"\n[target]\nnodes = [0, 1]\n{extra}\n"
        with pytest.raises(sf.SceneError) as info:
            sf.Scene.from_toml(text, tmp_path / "scene.toml")
        assert info.value.key == key and what in str(info.value), (extra, info.value.key, str(info.value))

"""Scene files: a valid scene builds; every kind of mistake is a SceneError naming the key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sorofem as sf
from conftest import BOX_SCENE


def write(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_valid_box_scene(box_scene):
    scene = sf.Scene.load(box_scene)
    assert (scene.mesh.n_nodes, scene.mesh.n_tets) == (20, 24)
    assert scene.formulation == "standard"
    assert scene.gravity.tolist() == [0, 0, -9.81]
    assert scene.body.fixed_nodes.size == 4
    assert scene.solver == {"tolerance": 1e-8, "max_iterations": 50, "load_steps": 1}
    assert scene.material.density == 1080
    result = scene.solve()
    assert result.report.converged


def test_file_scene_relative_path_scale_forces_and_defaults(tmp_path, shared_data):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "box2.tet").write_bytes((shared_data / "box2.tet").read_bytes())
    path = write(
        tmp_path,
        """
[mesh]
file = "meshes/box2.tet"
scale = 10.0

[material]
shear_modulus = 2e4
lame_lambda = 2e5

[[fixed]]
nodes = [0, 1, 2, 3, 4, 5, 6, 7, 8]

[[fixed]]
box = { min = [3.99, -1, -1], max = [4.01, 2, 2] }
displacement = [0.1, 0, 0]

[loads]
forces = [{ nodes = [40], force = [0, 0, -1.0] }]
""",
    )
    scene = sf.Scene.load(path)
    assert scene.mesh.bounds()[1] == pytest.approx([4.0, 1.0, 1.0])
    assert scene.mesh.source == tmp_path / "meshes" / "box2.tet"
    assert scene.body.fixed_nodes.size == 18
    assert scene.body.prescribed_displacement[:, 0].max() == pytest.approx(0.1)
    assert scene.body.forces[40].tolist() == [0, 0, -1.0]
    assert scene.gravity.tolist() == [0, 0, 0]
    assert scene.material.density == 0.0
    assert scene.solver["max_iterations"] == 50


def replace(old: str, new: str) -> str:
    assert old in BOX_SCENE, old
    return BOX_SCENE.replace(old, new)


BAD_SCENES = [
    # (scene text, key named in the error)
    (BOX_SCENE + "\n[extra]\nfoo = 1\n", "extra"),
    (replace("density = 1080", "density = 1080\ncolour = 'red'"), "material.colour"),
    (replace("poisson_ratio = 0.45", "poisson_ratio = 0.5"), "material.poisson_ratio"),
    (replace("poisson_ratio = 0.45", 'poisson_ratio = "0.45"'), "material.poisson_ratio"),
    (replace("youngs_modulus = 66e3", "youngs_modulus = -66e3"), "material.youngs_modulus"),
    (replace("density = 1080", "density = -1"), "material.density"),
    (replace("poisson_ratio = 0.45\n", ""), "material.youngs_modulus"),
    (replace('kind = "standard"', 'kind = "hybrid"'), "formulation.kind"),
    (replace("cells = [4, 1, 1]", "cells = [4, 1]"), "mesh.box.cells"),
    (replace("cells = [4, 1, 1]", "cells = [4, 0, 1]"), "mesh.box.cells"),
    (replace("size = [0.1, 0.02, 0.02]", "size = [0.1, 0.02, -0.02]"), "mesh.box.size"),
    (replace("box = { size", 'file = "beam.vtu"\nbox = { size'), "mesh"),
    (replace("[mesh]\nbox = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }", '[mesh]\nfile = "missing.vtu"'), "mesh.file"),
    (replace("[mesh]\n", "[mesh]\nscale = 0\n"), "mesh.scale"),
    (replace("[[fixed]]\nbox = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }\n", ""), "fixed"),
    (replace("[[fixed]]", "[fixed]"), "fixed"),
    (replace("min = [-1e-9, -1, -1]", "min = [5, -1, -1]"), "fixed[0].box"),
    (replace("max = [1e-9, 1, 1] }", "max = [1e-9, 1, 1], maxx = 1 }"), "fixed[0].box.maxx"),
    (replace("box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }", "nodes = [0, 1, 99]"), "fixed[0].nodes"),
    (replace("box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }", "nodes = []"), "fixed[0].nodes"),
    (replace("max = [1e-9, 1, 1] }", "max = [1e-9, 1, 1] }\ndisplacement = [0, 0]"), "fixed[0].displacement"),
    (replace("gravity = [0, 0, -9.81]", "gravity = [0, 0, true]"), "loads.gravity"),
    (replace("gravity = [0, 0, -9.81]", "gravity = [0, 0, -9.81]\nforces = [{ nodes = [1] }]"), "loads.forces[0].force"),
    (replace("tolerance = 1e-8", "tolerance = 0"), "solver.tolerance"),
    (replace("max_iterations = 50", "max_iterations = 2.5"), "solver.max_iterations"),
    (replace("load_steps = 1", "load_steps = 0"), "solver.load_steps"),
    (replace("load_steps = 1", "line_search = true"), "solver.line_search"),
]


@pytest.mark.parametrize("text, key", BAD_SCENES, ids=[key for _, key in BAD_SCENES])
def test_bad_scene_names_key(tmp_path, text, key):
    path = write(tmp_path, text)
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(path)
    err = info.value
    assert err.key == key
    assert f"'{key}'" in str(err)
    assert str(path) in str(err)


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("poisson_ratio = 0.45", "poisson_ratio = 0.7", "material.poisson_ratio"),
        ("load_steps = 1", "load_steps = 0", "solver.load_steps"),
        ("max = [1e-9, 1, 1] }", "max = [1e-9, 1, 1], maxx = 1 }", "fixed[0].box.maxx"),
    ],
)
def test_scene_error_line_numbers(tmp_path, old, new, key):
    text = replace(old, new)
    line = next(i for i, content in enumerate(text.splitlines(), start=1) if new in content)
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(write(tmp_path, text))
    assert (info.value.key, info.value.line) == (key, line)
    assert f":{line}" in str(info.value)


def test_second_fixed_entry_line(tmp_path):
    text = BOX_SCENE.replace("[loads]", "[[fixed]]\nnodes = [1000]\n\n[loads]")
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(write(tmp_path, text))
    assert info.value.key == "fixed[1].nodes"
    assert text.splitlines()[info.value.line - 1] == "nodes = [1000]"


def test_invalid_toml_reports_line(tmp_path):
    path = write(tmp_path, "[mesh]\nfile = \n")
    with pytest.raises(sf.SceneError, match="invalid TOML") as info:
        sf.Scene.load(path)
    assert info.value.line == 2


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        sf.Scene.load(tmp_path / "nope.toml")


def test_malformed_mesh_file_is_scene_error(tmp_path):
    (tmp_path / "bad.tet").write_text("v 0 0 0\nv oops\n")
    text = replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }", 'file = "bad.tet"')
    with pytest.raises(sf.SceneError, match="line 2") as info:
        sf.Scene.load(write(tmp_path, text))
    assert info.value.key == "mesh.file"


def test_box_origin_and_array_of_tables_forces(tmp_path):
    text = replace("cells = [4, 1, 1] }", "cells = [4, 1, 1], origin = [1, 2, 3] }")
    text = text.replace("min = [-1e-9, -1, -1], max = [1e-9, 1, 1]", "min = [0.999, 0, 0], max = [1.001, 5, 5]")
    text += "\n[[loads.forces]]\nbox = { min = [1.099, 0, 0], max = [1.101, 5, 5] }\nforce = [0, 0, -0.5]\n"
    text = text.replace("[loads]\ngravity = [0, 0, -9.81]\n", "")
    scene = sf.Scene.load(write(tmp_path, text))
    assert scene.mesh.bounds()[0].tolist() == [1, 2, 3]
    loaded = np.flatnonzero(np.any(scene.body.forces != 0, axis=1))
    assert loaded.size == 4

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
    assert scene.solver == {"tolerance": 1e-8, "max_iterations": 50, "load_steps": 1, "max_cutbacks": 8}
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
    assert scene.mesh.bounds[1] == pytest.approx([4.0, 1.0, 1.0])
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
    (replace("poisson_ratio = 0.45\n", ""), "material.poisson_ratio"),  # the missing half of the pair
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
    assert scene.mesh.bounds[0].tolist() == [1, 2, 3]
    loaded = np.flatnonzero(np.any(scene.body.forces != 0, axis=1))
    assert loaded.size == 4


def test_single_table_must_be_array_of_tables(tmp_path):
    text = replace("density = 1080", "density = 1080\n\n[material.region]\ncells = [0]\nyoungs_modulus = 1e5")
    with pytest.raises(sf.SceneError, match=r"write \[\[material.region\]\], not \[material.region\]") as info:
        sf.Scene.load(write(tmp_path, text))
    assert info.value.key == "material.region" and info.value.line is not None


# -- [[material.region]]: per-element materials ---------------------------------------------

# Two halves in series along x (nu = 0: uniaxial stress, no lateral coupling): the right half
# twice as stiff; clamped at x = 0, pulled by a prescribed displacement at x = 0.1.
BAR_SCENE = """\
[mesh]
box = { size = [0.1, 0.01, 0.01], cells = [10, 1, 1] }

[material]
youngs_modulus = 60e3
poisson_ratio = 0.0
density = 1000

[[material.region]]
name = "stiff"
box = { min = [0.05, -1, -1], max = [1, 1, 1] }
youngs_modulus = 120e3

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[[fixed]]
box = { min = [0.1, -1, -1], max = [1, 1, 1] }
displacement = [1e-5, 0, 0]

[solver]
tolerance = 1e-12
"""


def bar(old: str = "", new: str = "") -> str:
    assert old in BAR_SCENE, old
    return BAR_SCENE.replace(old, new, 1) if old else BAR_SCENE


def test_region_series_bar_matches_springs_in_series(tmp_path):
    """Small strain (1e-4): interface displacement and end force of two springs in series."""
    scene = sf.Scene.load(write(tmp_path, BAR_SCENE))
    x = scene.mesh.points[:, 0]
    centroids = scene.mesh.points[scene.mesh.tets].mean(axis=1)[:, 0]
    np.testing.assert_array_equal(scene.regions["stiff"], np.flatnonzero(centroids >= 0.05))
    np.testing.assert_array_equal(scene.material_region, np.where(centroids >= 0.05, 0, -1))
    np.testing.assert_allclose(scene.material.youngs_modulus, np.where(centroids >= 0.05, 120e3, 60e3))
    result = scene.solve()
    delta, length, area, e1, e2 = 1e-5, 0.05, 1e-4, 60e3, 120e3
    compliance = length / (e1 * area) + length / (e2 * area)
    interface = result.displacement[np.isclose(x, 0.05), 0]
    np.testing.assert_allclose(interface, delta * (length / (e1 * area)) / compliance, rtol=1e-3)
    # The stiff half stretches half as much as the soft one.
    strain_soft = interface.mean() / length
    strain_stiff = (delta - interface.mean()) / length
    assert strain_stiff / strain_soft == pytest.approx(0.5, rel=1e-3)
    # The support at x = 0.1 pulls with the force of the series spring.
    tip = np.isclose(x[scene.body.fixed_nodes], 0.1)
    assert result.reactions[tip, 0].sum() == pytest.approx(delta / compliance, rel=1e-3)


def test_region_cells_inheritance_overrides_and_density(tmp_path):
    text = bar("[[fixed]]", """[[material.region]]
cells = [0, 1, 2, 3, 4, 5, 59]
shear_modulus = 50e3
density = 2000

[[fixed]]""")
    scene = sf.Scene.load(write(tmp_path, text))
    owner = scene.material_region
    assert owner[:6].tolist() == [1] * 6 and owner[59] == 1            # the later entry wins ...
    assert set(owner[6:30]) == {-1} and set(owner[30:59]) == {0}       # ... where they overlap
    assert scene.regions["stiff"].tolist() == list(range(30, 59))       # what the named entry kept
    mu, lam, rho = scene.material.per_element(scene.mesh.n_tets)
    assert mu[0] == mu[59] == 50e3 and lam[0] == 0.0                    # lambda inherited (nu = 0)
    assert mu[6] == pytest.approx(30e3) and mu[30] == pytest.approx(60e3)
    assert rho[0] == 2000 and rho[6] == rho[30] == 1000                 # density inherited
    # Inheritance across pairs: E from the entry, nu from [material] (given as mu, lambda).
    text = BOX_SCENE.replace("youngs_modulus = 66e3\npoisson_ratio = 0.45",
                             "shear_modulus = 20e3\nlame_lambda = 80e3")
    text += "\n[[material.region]]\ncells = [0]\nyoungs_modulus = 100e3\n"
    material = sf.Scene.load(write(tmp_path, text)).material
    base = sf.NeoHookean(shear_modulus=20e3, lame_lambda=80e3)
    assert material.youngs_modulus[0] == pytest.approx(100e3)
    assert material.poisson_ratio[0] == pytest.approx(base.poisson_ratio)
    assert material.shear_modulus[1] == pytest.approx(20e3)


def test_region_box_and_cells_select_the_same(tmp_path):
    stiff = sf.Scene.load(write(tmp_path, BAR_SCENE)).regions["stiff"]
    text = bar('box = { min = [0.05, -1, -1], max = [1, 1, 1] }', f"cells = {stiff.tolist()}")
    scene = sf.Scene.load(write(tmp_path, text, "cells.toml"))
    np.testing.assert_array_equal(scene.regions["stiff"], stiff)


BAD_REGIONS = [
    # (old, new, key, words in the message)
    ("min = [0.05, -1, -1]", "min = [0.5, -1, -1]", "material.region[0].box", ["selects no elements", "spans"]),
    ("min = [0.05, -1, -1]", "min = [0.05, 2, -1]", "material.region[0].box", ["min <= max"]),
    ('box = { min = [0.05, -1, -1], max = [1, 1, 1] }', "cells = [3, 60]", "material.region[0].cells",
     ["60 out of range", "60 tets"]),
    ('box = { min = [0.05, -1, -1], max = [1, 1, 1] }', "cells = [-1]", "material.region[0].cells", [">= 0", "-1"]),
    ('box = { min = [0.05, -1, -1], max = [1, 1, 1] }', "cells = []", "material.region[0].cells", ["non-empty"]),
    ("youngs_modulus = 120e3", "youngs_modulus = 120e3\npoisson_ratio = 0.5", "material.region[0].poisson_ratio",
     ["< 0.5", "got 0.5"]),
    ("youngs_modulus = 120e3", "shear_modulus = -1", "material.region[0].shear_modulus", ["> 0", "got -1"]),
    ("youngs_modulus = 120e3", "youngs_modulus = 120e3\nlame_lambda = 1e5", "material.region[0]",
     ["at most one of 'youngs_modulus' + 'poisson_ratio', 'shear_modulus' + 'lame_lambda', 'c10' + 'c01' + 'd1'",
      "'lame_lambda'"]),
    ('box = { min = [0.05, -1, -1], max = [1, 1, 1] }', "", "material.region[0]", ["exactly one of 'box' or 'cells'"]),
    ("youngs_modulus = 120e3", "youngs_modulus = 120e3\ncells = [1]", "material.region[0]",
     ["exactly one of 'box' or 'cells'", "'box', 'cells'"]),
    ("youngs_modulus = 120e3", "youngs_modulus = 120e3\ncolour = 1", "material.region[0].colour", ["unknown key"]),
    ('name = "stiff"', 'name = "stiff part"', "material.region[0].name", ["'stiff part'"]),
    ('name = "stiff"\nbox = { min = [0.05, -1, -1], max = [1, 1, 1] }\nyoungs_modulus = 120e3',
     "cells = [0]", "material.region[0]", ["no material value and no name"]),
    ("[[fixed]]", "[[material.region]]\nname = \"stiff\"\ncells = [1]\n\n[[fixed]]", "material.region[1].name",
     ["already the name of material.region[0]"]),
    ("[[fixed]]", "[[material.region]]\nbox = { min = [0, -1, -1], max = [1, 1, 1] }\ndensity = 1\n\n[[fixed]]",
     "material.region[0]", ["overridden by later"]),
]


@pytest.mark.parametrize("old, new, key, words", BAD_REGIONS, ids=[f"{k}:{w[0][:20]}" for _, _, k, w in BAD_REGIONS])
def test_bad_region_entries_name_the_entry(tmp_path, old, new, key, words):
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(write(tmp_path, bar(old, new)))
    assert info.value.key == key, str(info.value)
    for word in words:
        assert word in info.value.message, (word, str(info.value))
    assert info.value.line is not None


def test_region_error_line_of_second_entry(tmp_path):
    text = bar("[[fixed]]", "[[material.region]]\ncells = [0, 99]\ndensity = 5\n\n[[fixed]]")
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(write(tmp_path, text))
    assert info.value.key == "material.region[1].cells"
    assert text.splitlines()[info.value.line - 1] == "cells = [0, 99]"


def test_region_mixed_formulation_needs_lambda_in_every_element(tmp_path):
    text = bar("poisson_ratio = 0.0", "poisson_ratio = 0.3").replace(
        "youngs_modulus = 120e3", "youngs_modulus = 120e3\npoisson_ratio = 0.0") + '\n[formulation]\nkind = "mixed"\n'
    with pytest.raises(sf.SceneError, match="lame_lambda > 0") as info:
        sf.Scene.load(write(tmp_path, text))
    assert info.value.key == "material.region[0].poisson_ratio"


def test_estimate_a_named_region(tmp_path, capsys):
    """`sorofem estimate` fits the shear modulus of one named region (the rest kept)."""
    from sorofem.cli import main

    beam = BOX_SCENE + '\n[[material.region]]\nname = "tip"\nbox = { min = [0.05, -1, -1], max = [1, 1, 1] }\nyoungs_modulus = 132e3\n'
    truth = sf.Scene.load(write(tmp_path, beam, "truth.toml"))
    tip_mu = float(truth.material.shear_modulus[truth.regions["tip"][0]])
    goal = sf.solve_static(truth.body, truth.gravity, tolerance=1e-12).positions
    nodes = np.arange(truth.mesh.n_nodes)
    fit = beam + (f"\n[target]\nnodes = {nodes.tolist()}\npositions = {goal.tolist()}\n"
                  f'\n[estimate]\nparams = ["shear_modulus:tip"]\nx0 = [{tip_mu * 0.6}]\n')
    out = tmp_path / "out"
    assert sf.Scene.load(write(tmp_path, fit, "fit.toml")).estimate["params"] == ["shear_modulus:tip"]
    assert main(["estimate", str(tmp_path / "fit.toml"), "--out", str(out), "--quiet"]) == 0
    import json

    summary = json.loads((out / "summary.json").read_text())
    mu = np.asarray(summary["shear_modulus"])
    assert mu[truth.regions["tip"]] == pytest.approx(tip_mu, rel=1e-5)
    outside = np.setdiff1d(np.arange(truth.mesh.n_tets), truth.regions["tip"])
    assert mu[outside] == pytest.approx(float(truth.material.shear_modulus[outside[0]]), rel=1e-12)
    # An unknown region name is a scene error naming [estimate].params.
    with pytest.raises(sf.SceneError, match="not the name of a") as info:
        sf.Scene.from_toml(fit.replace("shear_modulus:tip", "shear_modulus:base"), tmp_path / "s.toml")
    assert info.value.key == "estimate.params"


# -- [mesh] axes -----------------------------------------------------------------------------


def test_axes_rotate_the_mesh_and_the_solution(tmp_path):
    """y-up to z-up, ["x", "-z", "y"]: the same beam, rotated, gives the rotated solution."""
    plain = sf.Scene.load(write(tmp_path, BOX_SCENE))
    text = replace("[mesh]\n", '[mesh]\naxes = ["x", "-z", "y"]\n').replace("gravity = [0, 0, -9.81]", "gravity = [0, 9.81, 0]")
    rotated = sf.Scene.load(write(tmp_path, text, "rotated.toml"))
    p, q = plain.mesh.points, rotated.mesh.points
    np.testing.assert_array_equal(q, np.column_stack([p[:, 0], -p[:, 2], p[:, 1]]) + 0.0)
    np.testing.assert_array_equal(rotated.mesh.tets, plain.mesh.tets)  # a rotation keeps the orientation
    u, v = plain.solve().displacement, rotated.solve().displacement
    np.testing.assert_allclose(v, np.column_stack([u[:, 0], -u[:, 2], u[:, 1]]), atol=1e-12)


def test_axes_reflection_keeps_tets_positive(tmp_path):
    """A reflection would invert every tet: they are flipped back, and the solution is mirrored."""
    plain = sf.Scene.load(write(tmp_path, BOX_SCENE))
    text = replace("[mesh]\n", '[mesh]\naxes = ["x", "y", "-z"]\n').replace("gravity = [0, 0, -9.81]", "gravity = [0, 0, 9.81]")
    mirrored = sf.Scene.load(write(tmp_path, text, "mirrored.toml"))
    mesh = mirrored.mesh
    np.testing.assert_allclose(mesh.volumes, plain.mesh.volumes, rtol=1e-14)
    assert np.all(mesh.volumes > 0) and mesh.reoriented.size == 0
    # Without the flip, the Mesh constructor itself would have reoriented every tet.
    assert sf.Mesh(mesh.points, plain.mesh.tets).reoriented.size == plain.mesh.n_tets
    u, v = plain.solve().displacement, mirrored.solve().displacement
    np.testing.assert_allclose(v, u * [1, 1, -1], atol=1e-12)


def test_axes_apply_after_scale_to_a_mesh_file(tmp_path):
    sf.Mesh.box(size=(4.0, 2.0, 1.0), cells=(2, 1, 1)).write(tmp_path / "part.tet")
    text = replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }",
                   'file = "part.tet"\nscale = 0.01\naxes = ["+z", "x", "-y"]')
    scene = sf.Scene.load(write(tmp_path, text))
    lo, hi = scene.mesh.bounds
    np.testing.assert_allclose(lo, [0, 0, -0.02], atol=1e-15)
    np.testing.assert_allclose(hi, [0.01, 0.04, 0], atol=1e-15)
    assert scene.mesh.source == tmp_path / "part.tet"


@pytest.mark.parametrize("axes, words", [
    ('["x", "x", "y"]', ["signed permutation", "['x', 'x', 'y']"]),
    ('["x", "-x", "z"]', ["signed permutation"]),
    ('["x", "y"]', ["an array of 3", "length 2"]),
    ('["x", "y", "w"]', ["one of 'x'", "'w'", "item [2]"]),
    ('"xyz"', ["an array of 3", "a string 'xyz'"]),
])
def test_bad_axes(tmp_path, axes, words):
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(write(tmp_path, replace("[mesh]\n", f"[mesh]\naxes = {axes}\n")))
    assert info.value.key == "mesh.axes" and info.value.line == 3
    for word in words:
        assert word in info.value.message, (word, str(info.value))


def test_mesh_transformed_checks_its_axes():
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.02), cells=(2, 1, 1))
    with pytest.raises(sf.ParameterError, match="signed permutation") as info:
        mesh.transformed(["x", "y"])
    assert info.value.parameter == "axes"
    assert mesh.transformed(("+x", "y", "z")).points.tolist() == mesh.points.tolist()


def soft_beam_scene(max_cutbacks: object) -> str:
    """A slender soft beam under its weight: too far from the rest shape for 8 Newton iterations
    in one load step; 7 halvings of the step are needed."""
    return f"""\
[mesh]
box = {{ size = [0.4, 0.05, 0.05], cells = [16, 2, 2] }}

[material]
youngs_modulus = 1e4
poisson_ratio = 0.3
density = 1000

[[fixed]]
box = {{ min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }}

[loads]
gravity = [0, 0, -9.81]

[solver]
max_iterations = 8
max_cutbacks = {max_cutbacks}
"""


def test_solver_max_cutbacks_limits_the_halvings_of_a_load_step(tmp_path):
    solved = sf.Scene.load(write(tmp_path, soft_beam_scene(8))).solve()
    assert solved.report.converged and solved.report.cutbacks == 7
    for limit in (0, 6):
        scene = sf.Scene.load(write(tmp_path, soft_beam_scene(limit)))
        assert scene.solve_options.max_cutbacks == limit
        with pytest.raises(sf.errors.ConvergenceError, match=f"after {limit} cut-backs"):
            scene.solve()


def test_solver_max_cutbacks_must_be_a_non_negative_integer(tmp_path):
    for bad in ("-1", "1.5", "true"):
        path = write(tmp_path, soft_beam_scene(bad))
        with pytest.raises(sf.errors.SceneError, match="max_cutbacks"):
            sf.Scene.load(path)

"""The cases of a sweep (keys, values, grids, Latin hypercubes, tables) and solving them where
they run (sorofem.sweeps._solve), without a cluster."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf
from sorofem.errors import InputError
from sorofem.sweeps import Cases, parse_key
from sorofem.sweeps._cases import parse_values
from sorofem.sweeps._solve import Batch, clear_cache, solve_batch

SCENE = """\
[mesh]
box = { size = [0.4, 0.1, 0.1], cells = [4, 1, 1] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]

[[cable]]
start = [0, 0.05, 0.09]
direction = [1, 0, 0]
length = 0.4
divisions = 4
stiffness = 1e5
actuation = 0.9
"""


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "beam.toml"
    path.write_text(SCENE, encoding="utf-8")
    return path


def test_keys_follow_the_scene_spec():
    assert parse_key("material.youngs_modulus").column_type() == "float"
    assert parse_key("loads.gravity").column_type() == "list"
    assert parse_key("mesh.file").column_type() == "str"
    assert parse_key("solver.max_iterations").column_type() == "int"
    assert parse_key("mesh.box").column_type() == "json"
    assert parse_key("cable[0].actuation").per_solve and parse_key("material.region[1].shear_modulus").per_solve
    assert not parse_key("cable[0].transition").per_solve and not parse_key("mesh.box.cells").per_solve
    assert not parse_key("material.model").per_solve
    with pytest.raises(InputError, match="unknown key 'pulley' under 'cable\\[0\\]'"):
        parse_key("cable[0].pulley")
    with pytest.raises(InputError, match="is not a dotted scene key"):
        parse_key("material..youngs_modulus")
    with pytest.raises(InputError, match="'material' is not an array of tables"):
        parse_key("material[0].youngs_modulus")


def test_values_are_read_by_the_key_type():
    assert parse_values(parse_key("material.youngs_modulus"), "5e4, 66e3", "--grid") == [5e4, 66e3]
    assert parse_values(parse_key("mesh.file"), "a.vtu,b.msh", "--grid") == ["a.vtu", "b.msh"]
    assert parse_values(parse_key("loads.gravity"), "[0,0,-9.81],[0,0,0]", "--grid") == [[0, 0, -9.81], [0, 0, 0]]
    assert parse_values(parse_key("cable[0].anchor_first"), "true,false", "--grid") == [True, False]
    with pytest.raises(InputError, match="expected an integer, got '2.5'"):
        parse_values(parse_key("solver.max_iterations"), "2.5", "--grid")


def test_grid_is_a_cartesian_product_first_key_slowest(scene):
    cases = Cases.build(scene, grid={"material.youngs_modulus": [1e4, 2e4], "cable[0].actuation": [0.8, 0.9, 1.0]})
    assert cases.n == 6
    assert [cases.row(i) for i in range(6)] == [(1e4, 0.8), (1e4, 0.9), (1e4, 1.0), (2e4, 0.8), (2e4, 0.9),
                                                (2e4, 1.0)]
    # Every case shares one model: only per-solve values change.
    assert len({cases.group(i) for i in range(6)}) == 1
    mesh = Cases.build(scene, grid={"mesh.box.cells": [[4, 1, 1], [8, 2, 2]], "material.youngs_modulus": [1e4, 2e4]})
    assert [mesh.group(i) for i in range(4)] == [mesh.group(0)] * 2 + [mesh.group(2)] * 2
    assert mesh.group(0) != mesh.group(2)


def test_latin_hypercube_has_one_sample_per_stratum_and_is_seeded(scene):
    n = 20
    cases = Cases.build(scene, sample={"material.youngs_modulus": (1e4, 3e4), "cable[0].actuation": (0.5, 1.0)},
                        samples=n, seed=7)
    e, a = (np.array(v) for v in cases.values)
    assert sorted(((e - 1e4) / 2e4 * n).astype(int)) == list(range(n))
    assert sorted(((a - 0.5) / 0.5 * n).astype(int)) == list(range(n))
    again = Cases.build(scene, sample={"material.youngs_modulus": (1e4, 3e4), "cable[0].actuation": (0.5, 1.0)},
                        samples=n, seed=7)
    assert again.digest() == cases.digest()
    other = Cases.build(scene, sample={"material.youngs_modulus": (1e4, 3e4), "cable[0].actuation": (0.5, 1.0)},
                        samples=n, seed=8)
    assert other.digest() != cases.digest()
    # With a grid: every grid point gets every sample.
    both = Cases.build(scene, grid={"solver.max_iterations": [20, 30]}, sample={"cable[0].actuation": (0.5, 1.0)},
                       samples=3)
    assert both.n == 6 and both.values[1][:3] == both.values[1][3:]


def test_a_csv_table_of_cases(scene, tmp_path):
    table = tmp_path / "cases.csv"
    table.write_text('material.youngs_modulus,loads.gravity,mesh.file\n5e4,"[0, 0, -9.81]",a.vtu\n'
                     '6e4,"[0, -9.81, 0]",b.vtu\n', encoding="utf-8")
    cases = Cases.build(scene, table=table)
    assert cases.n == 2
    assert cases.columns() == {"material.youngs_modulus": [5e4, 6e4], "loads.gravity": [[0, 0, -9.81], [0, -9.81, 0]],
                               "mesh.file": ["a.vtu", "b.vtu"]}
    table.write_text("material.poisson_ratio\n0.3\n0.7\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"material.poisson_ratio \(.*cases.csv row 1\): expected a number"):
        Cases.build(scene, table=table)
    with pytest.raises(InputError, match="cannot be combined"):
        Cases.build(scene, table=table, grid={"material.youngs_modulus": [1e4]})


def test_a_column_of_numbers_is_checked_at_once_as_one_by_one(scene):
    key = parse_key("material.poisson_ratio")
    values = [0, 0.1, 0.25, 0.45, 0.499]
    checked = key.check_column(values, scene, lambda i: f"value {i}")
    assert checked == [key.check(v, scene, "one") for v in values] == [0.0, 0.1, 0.25, 0.45, 0.499]
    assert all(type(v) is float for v in checked)
    # A bad value is named by its place, as the check of that value alone names it.
    for bad, message in ((0.5, "expected a number >= 0 and < 0.5, got 0.5"), (-0.1, "got -0.1"),
                         (float("nan"), "expected a finite number, got nan"),
                         (float("inf"), "expected a finite number, got inf"), (True, "got a boolean true"), ("0.3", "got .*0.3")):
        with pytest.raises(InputError, match=rf"material.poisson_ratio \(value 3\): .*{message}"):
            key.check_column([0.1, 0.2, 0.3, bad, 0.6], scene, lambda i: f"value {i}")
    gravity = parse_key("loads.gravity")
    assert gravity.check_column([[0, 0, -9.81], [0, -1, 0]], scene, str) == [[0.0, 0.0, -9.81], [0.0, -1.0, 0.0]]
    with pytest.raises(InputError, match=r"\(grid value 2\): expected a number >= 0 and < 0.5, got 0.7"):
        Cases.build(scene, grid={"material.poisson_ratio": np.array([0.3, 0.4, 0.7])})


def test_an_integer_beyond_float64_is_named_not_a_traceback(scene, tmp_path):
    """10**400 as a number: the scene's check and the column's name the key and the value's
    size (before, a bare OverflowError from float())."""
    huge = 10**400
    key = parse_key("material.youngs_modulus")
    with pytest.raises(InputError, match=r"material.youngs_modulus \(value 1\): expected a finite number, got an "
                                         r"integer of 401 digits"):
        key.check_column([5e4, huge], scene, lambda i: f"value {i}")
    path = tmp_path / "huge.toml"
    path.write_text(SCENE.replace("youngs_modulus = 66e3", f"youngs_modulus = {huge}"), encoding="utf-8")
    with pytest.raises(sf.SceneError, match="material.youngs_modulus.*integer of 401 digits") as info:
        sf.Scene.load(path)
    assert info.value.key == "material.youngs_modulus"



def test_python_arguments_of_other_types_are_named_errors_or_taken_as_meant(scene, tmp_path):
    """What the command line cannot pass but Python can: a key that is not a string, a NumPy
    count, a negative or huge seed (before, an AttributeError, a TypeError from the sweep's JSON
    record and a ValueError from NumPy), and one field name given as a string."""
    with pytest.raises(InputError, match="grid: expected a dotted scene key .* got int 3"):
        Cases.build(scene, grid={3: [1.0]})
    cases = Cases.build(scene, sample={"material.youngs_modulus": (1e4, 3e4)}, samples=np.int64(4))
    assert cases.n == 4 and type(cases.origin["samples"]) is int
    for seed in (-1, 2**64, 1.5):
        with pytest.raises(sf.ParameterError, match="seed: expected an integer from 0 to 9223372036854775807"):
            Cases.build(scene, sample={"material.youngs_modulus": (1e4, 3e4)}, samples=2, seed=seed)
    # One name as a string is that name (not its letters); the check still runs before any cluster.
    with pytest.raises(InputError, match="save: unknown field 'velocity'"):
        sf.sweep(scene, tmp_path / "out", grid={"material.youngs_modulus": [5e4]}, save="velocity")
    assert not (tmp_path / "out").exists()

def _batch(scene, keys, rows, **extra):
    return Batch(str(scene), scene.read_text(), tuple(keys), tuple(enumerate(rows)), **extra)


def test_cases_that_share_a_structure_share_one_compiled_model(scene):
    clear_cache()
    keys = ("material.youngs_modulus", "cable[0].actuation")
    rows = [(4e4, 0.8), (8e4, 0.95), (6e4, 1.0)]
    outcomes = solve_batch(_batch(scene, keys, rows, n_cables=1, save=("displacement",)))
    from sorofem.sweeps import _solve

    assert len(_solve._CACHE) == 1
    kept = next(iter(_solve._CACHE.values())).scene
    # Each case equals its scene built and solved from scratch, bit for bit.
    for (e, alpha), outcome in zip(rows, outcomes):
        text = SCENE.replace("youngs_modulus = 66e3", f"youngs_modulus = {e!r}").replace(
            "actuation = 0.9", f"actuation = {alpha!r}")
        fresh = sf.Scene.from_toml(text, scene).solve()
        assert np.array_equal(outcome.fields["displacement"], fresh.displacement)
        assert outcome.row["newton_iterations"] == fresh.report.iterations
        assert outcome.row["cable[0].tensions"] == fresh.cable_tensions[0].tolist()
        like = sf.Scene.from_data(__import__("tomllib").loads(text), scene, like=kept)
        assert like.body.core_model() is kept.body.core_model()
    # Another mesh is another structure: another model.
    solve_batch(_batch(scene, ("mesh.box.cells",), [([3, 1, 1],)], n_cables=1))
    assert len(_solve._CACHE) == 2
    clear_cache()


def test_a_dynamic_case_collects_the_last_frame(scene):
    scene.write_text(SCENE + "\n[dynamics]\ndt = 0.01\nsteps = 5\n", encoding="utf-8")
    (outcome,) = solve_batch(_batch(scene, ("material.youngs_modulus",), [(5e4,)], n_cables=1,
                                    markers=((0.4, 0.05, 0.05),), save=("displacement",)))
    row = outcome.row
    text = scene.read_text().replace("youngs_modulus = 66e3", "youngs_modulus = 50000.0")
    trajectory = sf.Scene.from_toml(text, scene).simulate(progress=False)
    assert row["converged"] and row["steps"] == 5 and row["final_time"] == pytest.approx(0.05)
    assert np.array_equal(outcome.fields["displacement"], trajectory.displacement[-1])
    assert row["newton_iterations"] == int(trajectory.iterations.sum())
    # The marker at the centre of the free end, interpolated in its tetrahedron as a target's points are.
    bound = sf.Target.points([[0.4, 0.05, 0.05]], [[0, 0, 0]]).bind(trajectory.mesh)
    expected = bound.points(trajectory.final_positions)[0]
    np.testing.assert_allclose([row["marker[0].x"], row["marker[0].y"], row["marker[0].z"]], expected, atol=1e-15)
    # After 0.05 s, the end face has moved (the cable lifts it, gravity pulls it down).
    assert abs(row["marker[0].z"] - 0.05) > 1e-3


def test_a_value_the_builder_rejects_is_a_failed_row(scene):
    # A region box that selects nothing is only known once the mesh is there.
    scene.write_text(SCENE.replace("density = 1080", 'density = 1080\n[[material.region]]\nbox = { min = [0, 0, 0], '
                                   'max = [0.1, 1, 1] }\nyoungs_modulus = 1e5'), encoding="utf-8")
    (outcome,) = solve_batch(_batch(scene, ("material.region[0].box.max",), [([-1.0, -1.0, -1.0],)], n_cables=1))
    assert outcome.row["converged"] is False and outcome.row["error"].startswith("bad input:")
    assert "expected min <= max" in outcome.row["error"]


#: The beam of SCENE with a tendon along the top pulled 10 mm, a tendon along the bottom at
#: 0.5 N, and the spring chain of SCENE.
TENDONS = SCENE.replace("[[cable]]", """[[cable]]
model = "tendon"
start = [0.01, 0.05, 0.09]
direction = [1, 0, 0]
length = 0.38
divisions = 4
pull = 0.01

[[cable]]
model = "tendon"
start = [0.01, 0.05, 0.01]
direction = [1, 0, 0]
length = 0.38
divisions = 4
tension = 0.5

[[cable]]""")


def _override(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def test_tendon_commands_are_per_solve_values_that_share_one_model(tmp_path):
    """A tendon's pull and tension, like a spring chain's alpha, are values the compiled model
    takes at each solve: the cases of a grid over them share one model, and each equals its
    scene built and solved from scratch, bit for bit."""
    scene = tmp_path / "tendons.toml"
    scene.write_text(TENDONS, encoding="utf-8")
    assert parse_key("cable[0].pull").per_solve and parse_key("cable[1].tension").per_solve
    keys = ("cable[0].pull", "cable[1].tension", "cable[2].actuation")
    cases = Cases.build(scene, grid={k: v for k, v in zip(keys, ([0.005, 0.02], [0.0, 2.0], [0.9, 1.0]))})
    assert cases.n == 8 and len({cases.group(i) for i in range(cases.n)}) == 1
    clear_cache()
    rows = [cases.row(i) for i in range(cases.n)]
    outcomes = solve_batch(_batch(scene, keys, rows, n_cables=3, save=("displacement",)))
    from sorofem.sweeps import _solve

    assert len(_solve._CACHE) == 1
    kept = next(iter(_solve._CACHE.values())).scene
    for (pull, tension, alpha), outcome in zip(rows, outcomes):
        assert outcome.row["converged"], outcome.row["error"]
        text = _override(_override(_override(TENDONS, "pull = 0.01", f"pull = {pull!r}"), "tension = 0.5",
                                   f"tension = {tension!r}"), "actuation = 0.9", f"actuation = {alpha!r}")
        fresh = sf.Scene.from_toml(text, scene)
        result = fresh.solve()
        assert np.array_equal(outcome.fields["displacement"], result.displacement)
        assert outcome.row["newton_iterations"] == result.report.iterations
        # The top tendon holds its pull with the tension it takes, or is slack where the spring
        # chain beside it curls the beam further; the bottom one carries its command.
        taut = result.cable_pull[0] == pytest.approx(pull, rel=1e-9)
        assert (taut and result.cable_tension[0] > 0) or (result.cable_pull[0] > pull and result.cable_tension[0] == 0)
        assert taut or alpha < 1.0
        assert outcome.row["cable[0].max_tension"] == result.cable_tension[0]
        assert outcome.row["cable[1].max_tension"] == result.cable_tension[1] == tension
        like = sf.Scene.from_data(__import__("tomllib").loads(text), scene, like=kept)
        assert like.body.core_model() is kept.body.core_model() and like.body.commands == fresh.body.commands
    # A harder pull of the top tendon lifts the free end higher.
    by = {row: outcome.row for row, outcome in zip(rows, outcomes)}
    assert by[(0.02, 0.0, 1.0)]["tip.z"] > by[(0.005, 0.0, 1.0)]["tip.z"]
    clear_cache()


def test_a_tendon_command_the_builder_rejects_is_a_failed_row(tmp_path):
    """Pull and tension are checked per case, also on a scene built like a kept one."""
    scene = tmp_path / "tendons.toml"
    scene.write_text(TENDONS, encoding="utf-8")
    clear_cache()
    ok, too_long = solve_batch(_batch(scene, ("cable[0].pull",), [(0.02,), (0.5,)], n_cables=3))
    (both,) = solve_batch(_batch(scene, ("cable[1].pull",), [(0.01,)], n_cables=3))
    assert ok.row["converged"] and too_long.row["converged"] is False and both.row["converged"] is False
    assert too_long.row["error"].startswith("bad input:") and "cable[0].pull" in too_long.row["error"]
    assert "rest length" in too_long.row["error"]
    assert "cable[1].pull" in both.row["error"] and "exactly one of pull (m) and tension (N)" in both.row["error"]
    clear_cache()


@pytest.mark.parametrize(("material", "key", "values"), [
    ('model = "yeoh"\nc10 = 11e3\nc20 = -400.0\nc30 = 40.0\nd1 = 2e-6', "material.c10", [8e3, 16e3]),
    ('model = "ogden"\n"mu:0" = 1.9e3\n"alpha:0" = -3.8\n"mu:1" = 2.2e4\n"alpha:1" = 1.7\nd1 = 2e-6', "material.mu:1",
     [1.5e4, 3e4]),
])
def test_material_coefficient_keys_are_swept(tmp_path, material, key, values):
    """Coefficients of the other material models by their names (Yeoh's ``c10``, Ogden's
    ``mu:1``) are sweep keys, per-solve values like Young's modulus."""
    text = SCENE.replace("youngs_modulus = 66e3\npoisson_ratio = 0.45", material)
    scene = tmp_path / "material.toml"
    scene.write_text(text, encoding="utf-8")
    parsed = parse_key(key)
    assert parsed.per_solve and parsed.column_type() == "float"
    cases = Cases.build(scene, grid={key: values})
    assert cases.columns() == {key: values} and cases.group(0) == cases.group(1)
    clear_cache()
    outcomes = solve_batch(_batch(scene, (key,), [(v,) for v in values], n_cables=1, save=("displacement",)))
    name = key.split(".")[1]
    for value, outcome in zip(values, outcomes):
        assert outcome.row["converged"], outcome.row["error"]
        line = next(line for line in material.splitlines() if line.split("=")[0].strip().strip('"') == name)
        fresh = sf.Scene.from_toml(text.replace(line, f'"{name}" = {value!r}'), scene).solve()
        assert np.array_equal(outcome.fields["displacement"], fresh.displacement)
    # The stiffer case sags less under gravity.
    assert outcomes[1].row["max_displacement"] < outcomes[0].row["max_displacement"]
    clear_cache()

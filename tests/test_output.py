"""The scene's [output] table: the folder (and --out over it), each file's switch, the PNG's
colouring field, and the rule that nothing the scene reads is overwritten."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main
from sorofem.plot import COLOR_FIELDS, _face_owners, _surface_field, plot_rest_and_deformed
from conftest import BOX_SCENE

STATIC = ("result.vtu", "summary.json", "shape.png", "convergence.png")
CABLE = """
[[cable]]
start = [0.0, 0.01, 0.018]
direction = [1, 0, 0]
length = 0.1
divisions = 4
stiffness = 1e3
actuation = 0.97
"""
DYNAMICS = "\n[dynamics]\ndt = 0.01\nsteps = 2\n"


def _scene(tmp_path: Path, extra: str = "", name: str = "scene.toml", base: str = BOX_SCENE) -> Path:
    folder = tmp_path / "scenes"
    folder.mkdir(exist_ok=True)
    path = folder / name
    path.write_text(base + extra, encoding="utf-8")
    return path


def _files(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()} if folder.exists() else set()


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_directory_is_relative_to_the_scene_file(tmp_path, monkeypatch, capsys):
    scene = _scene(tmp_path, '\n[output]\ndirectory = "results/beam"\n')
    monkeypatch.chdir(tmp_path)  # not the scene's folder
    assert main(["run", str(scene)]) == 0
    out = tmp_path / "scenes" / "results" / "beam"
    assert _files(out) == set(STATIC)
    assert str(out) in capsys.readouterr().out
    assert sf.Scene.load(scene).output["directory"] == scene.parent / "results" / "beam"


def test_out_wins_over_the_directory(tmp_path, capsys):
    scene = _scene(tmp_path, '\n[output]\ndirectory = "results"\n')
    out = tmp_path / "elsewhere"
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0
    assert _files(out) == set(STATIC)
    assert not (scene.parent / "results").exists()


def test_no_folder_at_all_is_an_input_error(tmp_path, capsys):
    scene = _scene(tmp_path)
    assert main(["run", str(scene)]) == 2
    line = _one_error(capsys)
    assert "--out DIR" in line and "[output] directory" in line
    assert _files(scene.parent) == {"scene.toml"}


def test_directory_that_is_a_file(tmp_path, capsys):
    scene = _scene(tmp_path, '\n[output]\ndirectory = "taken"\n')
    (scene.parent / "taken").write_text("mine")
    assert main(["run", str(scene)]) == 2
    line = _one_error(capsys)
    assert "[output] directory" in line and "not a folder" in line
    assert (scene.parent / "taken").read_text() == "mine"


@pytest.mark.parametrize("switch, files", [
    ("summary", {"result.vtu", "shape.png", "convergence.png", "cables.vtu"}),
    ("vtu", {"summary.json", "shape.png", "convergence.png", "cables.vtu"}),
    ("png", {"result.vtu", "summary.json", "cables.vtu"}),
    ("cables", set(STATIC)),
])
def test_static_switches(tmp_path, capsys, switch, files):
    scene = _scene(tmp_path, CABLE + f'\n[output]\ndirectory = "out"\n{switch} = false\n')
    assert main(["run", str(scene), "--json"]) == 0
    assert _files(scene.parent / "out") == files
    assert json.loads(capsys.readouterr().out)["converged"] is True  # --json prints it either way


@pytest.mark.parametrize("switch, files", [
    (None, {"trajectory.pvd", "trajectory", "summary.json", "trajectory.png"}),
    ("pvd", {"summary.json", "trajectory.png"}),
    ("png", {"trajectory.pvd", "trajectory", "summary.json"}),
    ("summary", {"trajectory.pvd", "trajectory", "trajectory.png"}),
    ("vtu", {"trajectory.pvd", "trajectory", "summary.json", "trajectory.png"}),  # no result.vtu to skip
])
def test_dynamics_switches(tmp_path, capsys, switch, files):
    off = f"{switch} = false\n" if switch else ""
    scene = _scene(tmp_path, DYNAMICS + f'\n[output]\ndirectory = "out"\n{off}')
    assert main(["run", str(scene), "--quiet"]) == 0
    assert _files(scene.parent / "out") == files


def test_everything_off_writes_nothing(tmp_path, capsys):
    scene = _scene(tmp_path, '\n[output]\ndirectory = "out"\nsummary = false\nvtu = false\npng = false\n')
    assert main(["run", str(scene)]) == 0
    assert "wrote nothing" in capsys.readouterr().out
    assert not (scene.parent / "out").exists()


def test_not_converged_without_summary(tmp_path, capsys):
    text = BOX_SCENE.replace("gravity = [0, 0, -9.81]", "gravity = [0, 0, -500.0]").replace(
        "max_iterations = 50", "max_iterations = 2")
    scene = _scene(tmp_path, '\n[output]\ndirectory = "out"\nsummary = false\n', base=text)
    assert main(["run", str(scene)]) == 3
    assert "report in" not in capsys.readouterr().err
    assert _files(scene.parent / "out") == {"convergence.png"}


def test_control_follows_directory_and_switches(tmp_path, capsys):
    base = BOX_SCENE + CABLE.replace("actuation = 0.97", "actuation = 1.0")
    probe = sf.Scene.from_toml(base, tmp_path / "probe.toml")
    probe.body.set_actuation(0, 0.9)
    tip = np.flatnonzero(np.isclose(probe.mesh.points[:, 0], 0.1))
    goal = sf.solve_static(probe.body, probe.gravity, tolerance=1e-12).positions[tip]
    extra = (f"\n[target]\nnodes = {tip.tolist()}\npositions = {goal.tolist()}\n[control]\nbounds = [[0.5, 1.0]]\n"
             '\n[output]\ndirectory = "fit"\nvtu = false\n')
    scene = _scene(tmp_path, extra, base=base)
    assert main(["control", str(scene), "--quiet"]) == 0
    assert _files(scene.parent / "fit") == {"summary.json", "fit.png"}  # [output] png = true by default


def test_directory_never_overwrites_the_scene_inputs(tmp_path, capsys):
    """directory = "." puts the outputs next to the scene: a mesh named result.vtu is refused."""
    folder = tmp_path / "scenes"
    folder.mkdir()
    sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(4, 1, 1)).write(folder / "result.vtu")
    before = (folder / "result.vtu").read_bytes()
    text = BOX_SCENE.replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }", 'file = "result.vtu"')
    scene = _scene(tmp_path, '\n[output]\ndirectory = "."\n', base=text)
    assert main(["run", str(scene)]) == 2
    line = _one_error(capsys)
    assert "[output] directory" in line and "overwrite the input file" in line
    assert (folder / "result.vtu").read_bytes() == before and _files(folder) == {"result.vtu", "scene.toml"}
    # With the file switched off there is nothing to protect: the run goes ahead.
    scene.write_text(text + '\n[output]\ndirectory = "."\nvtu = false\n', encoding="utf-8")
    assert main(["run", str(scene), "--quiet"]) == 0
    assert (folder / "result.vtu").read_bytes() == before


def test_frames_never_overwrite_an_input(tmp_path, capsys):
    folder = tmp_path / "scenes" / "trajectory"
    folder.mkdir(parents=True)
    sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(4, 1, 1)).write(folder / "frame_00000.vtu")
    text = BOX_SCENE.replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }",
                             'file = "trajectory/frame_00000.vtu"')
    scene = _scene(tmp_path, DYNAMICS + '\n[output]\ndirectory = "."\n', base=text)
    assert main(["run", str(scene)]) == 2
    assert "trajectory" in _one_error(capsys)


# ---------------------------------------------------------------------------
# color_by


@pytest.mark.parametrize("value, formulation, key, words", [
    ('"pressure"', "standard", "output.color_by", ["'pressure'", "mixed", "'von_mises'"]),
    ('"stress"', "standard", "output.color_by", ["'von_mises'", "'stress'"]),
    ('""', "standard", "output.directory", ["empty"]),
])
def test_bad_output_values_name_the_key(tmp_path, value, formulation, key, words):
    name = "directory" if key.endswith("directory") else "color_by"
    text = BOX_SCENE.replace('kind = "standard"', f'kind = "{formulation}"') + f"\n[output]\n{name} = {value}\n"
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.from_toml(text, tmp_path / "s.toml")
    assert info.value.key == key and info.value.line == text.splitlines().index(f"{name} = {value}") + 1
    for word in words:
        assert word in str(info.value)


def test_pressure_colouring_of_a_mixed_scene(tmp_path, capsys):
    text = BOX_SCENE.replace('kind = "standard"', 'kind = "mixed"')
    scene = _scene(tmp_path, '\n[output]\ndirectory = "out"\ncolor_by = "pressure"\nvtu = false\n', base=text)
    assert main(["run", str(scene), "--quiet"]) == 0
    assert (scene.parent / "out" / "shape.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The standard scene with the same table is a scene error (exit 2), before anything runs.
    scene.write_text(BOX_SCENE + '\n[output]\ndirectory = "out2"\ncolor_by = "pressure"\n', encoding="utf-8")
    assert main(["run", str(scene)]) == 2
    assert "output.color_by" in _one_error(capsys) and not (scene.parent / "out2").exists()


@pytest.fixture(scope="module")
def mixed_result() -> sf.StaticResult:
    text = BOX_SCENE.replace('kind = "standard"', 'kind = "mixed"')
    return sf.Scene.from_toml(text, Path("beam.toml")).solve()


def test_surface_fields(mixed_result):
    result = mixed_result
    faces = result.mesh.boundary_faces()
    owners = _face_owners(result.mesh.tets, faces)
    for face, tet in zip(faces, owners):
        assert set(face) <= set(result.mesh.tets[tet])
    values = {name: _surface_field(result, faces, name)[0] for name in COLOR_FIELDS}
    np.testing.assert_allclose(values["displacement"], np.linalg.norm(result.displacement, axis=1)[faces].mean(axis=1))
    np.testing.assert_array_equal(values["von_mises"], result.von_mises[owners])
    np.testing.assert_array_equal(values["J"], result.J[owners])
    np.testing.assert_allclose(values["pressure"], result.pressure[faces].mean(axis=1))


def test_each_colouring_draws_a_different_png(tmp_path, mixed_result):
    images = {}
    for name in COLOR_FIELDS:
        plot_rest_and_deformed(mixed_result, tmp_path / f"{name}.png", color_by=name)
        images[name] = (tmp_path / f"{name}.png").read_bytes()
    assert len(set(images.values())) == len(COLOR_FIELDS)
    standard = sf.Scene.from_toml(BOX_SCENE, Path("beam.toml")).solve()
    with pytest.raises(sf.InputError, match="mixed formulation"):
        plot_rest_and_deformed(standard, tmp_path / "p.png", color_by="pressure")
    with pytest.raises(sf.InputError, match="color_by"):
        plot_rest_and_deformed(standard, tmp_path / "p.png", color_by="strain")

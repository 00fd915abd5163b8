"""The `sorofem` command: run, info, --version and exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import sorofem as sf
from sorofem.cli import main
from conftest import BOX_SCENE

OUTPUTS = ("result.vtu", "summary.json", "shape.png", "convergence.png")


def test_run_writes_outputs(box_scene, tmp_path, capsys):
    out = tmp_path / "out" / "nested"
    assert main(["run", str(box_scene), "--out", str(out)]) == 0
    for name in OUTPUTS:
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "converged",
        "newton_iterations",
        "residual_norm",
        "max_displacement",
        "timings",
        "n_nodes",
        "n_tets",
        "formulation",
        "material",
    ):
        assert key in summary, key
    assert summary["converged"] is True
    assert (summary["n_nodes"], summary["n_tets"]) == (20, 24)
    assert summary["formulation"] == "standard"
    assert summary["max_displacement"] > 0
    captured = capsys.readouterr()
    assert "converged" in captured.out and captured.err == ""


def test_run_json_and_quiet(box_scene, tmp_path, capsys):
    assert main(["run", str(box_scene), "--out", str(tmp_path / "a"), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["converged"] is True
    assert main(["run", str(box_scene), "--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert capsys.readouterr().out == ""


def test_run_never_deletes_other_files(box_scene, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["run", str(box_scene), "--out", str(out), "--quiet"]) == 0
    assert (out / "notes.txt").read_text() == "mine"


def _expect_input_error(argv, capsys, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0]


def test_run_bad_scene_exits_2(tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text(BOX_SCENE.replace("poisson_ratio = 0.45", "poisson_ratio = 0.5"))
    _expect_input_error(["run", str(scene), "--out", str(tmp_path / "out")], capsys, "material.poisson_ratio")
    assert not (tmp_path / "out").exists()


def test_run_missing_scene_exits_2(tmp_path, capsys):
    _expect_input_error(["run", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "out")], capsys, "nope.toml")


def test_run_missing_mesh_file_exits_2(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        BOX_SCENE.replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }", 'file = "robot.vtu"')
    )
    _expect_input_error(["run", str(scene), "--out", str(tmp_path / "out")], capsys, "mesh.file", "robot.vtu")


def test_run_empty_fixed_exits_2(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE.replace("[[fixed]]\nbox = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }\n", ""))
    _expect_input_error(["run", str(scene), "--out", str(tmp_path / "out")], capsys, "fixed")


def test_run_out_is_a_file_exits_2(box_scene, tmp_path, capsys):
    target = tmp_path / "file"
    target.write_text("x")
    _expect_input_error(["run", str(box_scene), "--out", str(target)], capsys, "--out")


def test_run_refuses_to_overwrite_input_mesh(tmp_path, capsys):
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(4, 1, 1))
    mesh.write(tmp_path / "result.vtu")
    before = (tmp_path / "result.vtu").read_bytes()
    scene = tmp_path / "scene.toml"
    scene.write_text(
        BOX_SCENE.replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }", 'file = "result.vtu"')
    )
    _expect_input_error(["run", str(scene), "--out", str(tmp_path)], capsys, "overwrite")
    assert (tmp_path / "result.vtu").read_bytes() == before


@pytest.mark.parametrize("argv", [["run"], ["frobnicate"], [], ["run", "x.toml"], ["info"]])
def test_usage_errors_exit_2(argv, capsys):
    _expect_input_error(argv, capsys)


def test_not_converged_exits_3_and_writes_summary(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    text = BOX_SCENE.replace("gravity = [0, 0, -9.81]", "gravity = [0, 0, -500.0]")
    text = text.replace("max_iterations = 50", "max_iterations = 1").replace("tolerance = 1e-8", "tolerance = 1e-14")
    scene.write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is False
    assert "report" in summary and "newton_iterations" in summary
    assert not (out / "result.vtu").exists()
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err


def test_info(shared_data, capsys):
    assert main(["info", str(shared_data / "box2.tet")]) == 0
    out = capsys.readouterr().out
    assert "81" in out and "192" in out and "radius ratio" in out


def test_info_json_and_scale(tmp_path, capsys):
    path = tmp_path / "beam.tet"
    sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2)).write(path)
    assert main(["info", str(path), "--scale", "0.5", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["n_nodes"], data["n_tets"]) == (81, 192)
    assert data["volume"] == pytest.approx(0.01 / 8)
    assert data["bounds_max"] == pytest.approx([0.5, 0.05, 0.05])
    assert 0 < data["min_quality"] <= 1 and data["bad_tets"] == 0


def test_info_missing_and_malformed(tmp_path, capsys):
    _expect_input_error(["info", str(tmp_path / "nope.tet")], capsys, "nope.tet")
    bad = tmp_path / "bad.tet"
    bad.write_text("v 0 0 0\nt 0 1\n")
    _expect_input_error(["info", str(bad)], capsys, "line 2")


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("sorofem ")


def test_quality_of_regular_tet():
    import numpy as np

    from sorofem.mesh_info import tet_quality

    regular = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    assert tet_quality(regular, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(1.0)


def test_quiet_switches_the_progress_line_off(box_scene, tmp_path, monkeypatch):
    """`--quiet` makes the automatic progress choice "never" for the whole command."""
    from sorofem import progress

    seen = []
    real_run = __import__("sorofem.cli", fromlist=["_run"])._run

    def spy(args):
        seen.append(progress._DEFAULT.get())
        return real_run(args)

    monkeypatch.setattr("sorofem.cli._run", spy)
    assert main(["run", str(box_scene), "--out", str(tmp_path / "a"), "--quiet"]) == 0
    assert main(["run", str(box_scene), "--out", str(tmp_path / "b")]) == 0
    assert seen == [False, None]

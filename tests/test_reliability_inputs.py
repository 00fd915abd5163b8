"""Issue 20, bad input: every class of malformed input the issue found gets a clean error (the
parameter named, exit 2 on the command line), never a silent wrong answer, a traceback, a panic
or a runaway run. One test per class, named after it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import EXIT_INPUT, EXIT_SOLVER, main
from tests.conftest import BOX_SCENE

TIP = (0.1, 0, 0)


def beam(cells=(4, 1, 1)) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=cells)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def run_scene(tmp_path: Path, text: str, capsys, *command: str) -> tuple[int, str]:
    scene = tmp_path / "scene.toml"
    scene.write_text(text, encoding="utf-8")
    code = main([command[0] if command else "run", str(scene), "--out", str(tmp_path / "out"), "--quiet",
                 *command[1:]])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, err


def replaced(old: str, new: str, text: str = BOX_SCENE) -> str:
    assert old in text, old
    return text.replace(old, new)


# -- item 1: overflowing loads are errors, never a converged zero -----------------------------


@pytest.mark.parametrize(
    "setup, name",
    [
        (lambda b: sf.solve_static(b, gravity=(0, 0, -1e300)), "gravity"),
        (lambda b: (b.add_force(b.mesh.nodes_on_plane(TIP, (1, 0, 0)), (0, 0, 1e308)), sf.solve_static(b)), "forces"),
        (lambda b: (b.add_cable(sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.1, 4, stiffness=1e308, actuation=0.8)),
                    sf.solve_static(b)), "stiffness"),
        (lambda b: (setattr(b, "material", sf.NeoHookean(shear_modulus=22e3, lame_lambda=1e308)),
                    sf.solve_static(b, gravity=(0, 0, -9.81))), "lame_lambda"),
        (lambda b: (b.fix([5], (0, 0, 1e300)), sf.solve_static(b)), "displacement"),
        (lambda b: sf.simulate(b, 0.01, 2, gravity=(0, 0, -1e300)), "gravity"),
    ],
)
def test_issue_20_overflowing_load_is_an_input_error(setup, name):
    with pytest.raises(sf.ParameterError) as info:
        setup(beam())
    assert info.value.parameter == name and "1e+150" in str(info.value)


def test_issue_20_overflowing_load_exits_2_with_the_key(tmp_path, capsys):
    code, err = run_scene(tmp_path, replaced("gravity = [0, 0, -9.81]", "gravity = [0, 0, -1e300]"), capsys)
    assert code == EXIT_INPUT and "gravity" in err and not (tmp_path / "out" / "result.vtu").exists()


class _NonFiniteModel:
    """A model whose solve returns NaN positions (what a core producing non-finite values
    would hand back): the Python side must refuse it."""

    def __init__(self, model):
        self._model = model

    def solve(self, *args, **kwargs):
        out = self._model.solve(*args, **kwargs)
        out["positions"] = np.full_like(np.asarray(out["positions"]), np.nan)
        return out

    def __getattr__(self, name):
        return getattr(self._model, name)


def test_issue_20_non_finite_solution_is_a_solver_error_exit_3(tmp_path, capsys, monkeypatch):
    body = beam()
    real = sf.Body.core_model
    monkeypatch.setattr(sf.Body, "core_model", lambda self: _NonFiniteModel(real(self)))
    with pytest.raises(sf.SolverError, match="non-finite positions"):
        sf.solve_static(body, gravity=(0, 0, -9.81))
    code, err = run_scene(tmp_path, BOX_SCENE, capsys)
    assert code == EXIT_SOLVER and "non-finite" in err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["converged"] is False and summary["complete"] is True and summary["status"] == "failed"
    assert not (tmp_path / "out" / "result.vtu").exists()


def test_issue_20_check_finite_solution_refuses_an_overflowed_residual():
    from sorofem.static import check_finite_solution

    report = sf.SolveReport(converged=True, residual_history=[math.nan], reference_norm=math.inf)
    with pytest.raises(sf.InputError, match="overflow"):
        check_finite_solution({"positions": np.zeros((2, 3))}, report)


# -- item 2: summary.json never carries NaN; "not identifiable" said explicitly ---------------


def test_issue_20_unidentifiable_parameter_is_said_in_json(tmp_path, capsys):
    # A target on clamped nodes only: the fit cannot see the modulus.
    scene = replaced("[solver]", """[target]
nodes = [0, 5]
positions = [[0, 0, 0], [0, 0.02, 0]]

[estimate]
params = ["shear_modulus"]
x0 = [20e3]

[solver]""")
    code, _ = run_scene(tmp_path, scene, capsys, "estimate")
    text = (tmp_path / "out" / "summary.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    summary = json.loads(text)
    assert summary["uncertainty"]["std"]["shear_modulus"] == "not identifiable"
    assert summary["uncertainty"]["identifiable"]["shear_modulus"] is False
    assert code in (0, EXIT_SOLVER)


def test_issue_20_nelder_mead_history_has_no_nan():
    body = beam()
    goal = sf.solve_static(body, gravity=(0, 0, -9.81)).positions
    tip = body.mesh.nodes_on_plane(TIP, (1, 0, 0))
    fit = sf.estimate(beam(), sf.Target.nodes(tip, goal[tip]), ["shear_modulus"], x0=[15e3], gravity=(0, 0, -9.81),
                      method="nelder-mead", max_evaluations=40)
    losses = [h["loss"] for h in fit.history] + [s["loss"] for s in fit.starts]
    assert losses and all(math.isfinite(v) for v in losses)


# -- item 3: invalid arguments rejected --------------------------------------------------------


def test_issue_20_invalid_arguments_are_rejected(tmp_path):
    surface = tmp_path / "goal.obj"
    surface.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(sf.ParameterError, match="scale"):
        sf.Target.surface(surface, scale=-1)
    with pytest.raises(sf.ParameterError, match="scale"):
        sf.Target.surface(sf.io.read_surface(surface), scale=-1)  # not only when a file is read
    body = beam()
    target = sf.Target.nodes([9], [[0.1, 0, 0]])
    with pytest.raises(sf.InputError, match="lame_lambda"):
        sf.estimate(body, target, ["shear_modulus"], x0={"lame_lambda": 1e5})
    with pytest.raises(sf.ParameterError, match="starts"):
        sf.estimate(body, target, ["shear_modulus"], starts=-2)
    with pytest.raises(sf.ParameterError, match="max_evaluations"):
        sf.estimate(body, target, ["shear_modulus"], max_evaluations=0)
    with pytest.raises(sf.InputError, match="scalar parameter"):
        sf.estimate(body, target, ["shear_modulus"], x0=[[1e4, 2e4]])


# -- item 4: no panic, no abort: memory estimated before allocating ----------------------------


@pytest.mark.parametrize("cells", [(10**6, 10**6, 10**6), (2**62, 2**62, 1), (2000, 2000, 2000)])
def test_issue_20_huge_box_is_refused_before_allocating(cells):
    with pytest.raises(sf.ParameterError, match="memory|2147483647") as info:
        sf.Mesh.box(cells=cells)
    assert info.value.parameter == "cells"


def test_issue_20_huge_box_scene_exits_2(tmp_path, capsys):
    code, err = run_scene(tmp_path, replaced("cells = [4, 1, 1]", "cells = [100000, 100000, 100]"), capsys)
    assert code == EXIT_INPUT and "memory" in err and "mesh" in err


# -- item 5: every mesh-reader failure is a MeshError naming the file -------------------------

_VTU_HEAD = '<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="0.1">\n<UnstructuredGrid>\n'
MALFORMED = {
    "empty.vtu": b"",
    "truncated.vtu": (_VTU_HEAD + '<Piece NumberOfPoints="4" NumberOfCells="1">\n<Points>\n').encode(),
    "random.vtu": bytes(np.random.default_rng(0).integers(0, 256, 2000, dtype=np.uint8)),
    "nocells.vtu": (_VTU_HEAD + '<Piece NumberOfPoints="1" NumberOfCells="0">\n<Points>\n<DataArray type="Float64" '
                    'NumberOfComponents="3" format="ascii">0 0 0</DataArray>\n</Points>\n<Cells>\n</Cells>\n</Piece>\n'
                    '</UnstructuredGrid>\n</VTKFile>\n').encode(),
    "dolfin.xml": b'<?xml version="1.0"?>\n<dolfin><mesh celltype="tetrahedron" dim="3"><vertices size="1">'
                  b'<vertex index="0" x="0" y="0" z="0"/></vertices></mesh></dolfin>\n',
    "huge_index.tet": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nt 0 1 2 99999999999999999999999\n",
    "garbage.msh": b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\nnonsense\n",
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_issue_20_malformed_mesh_is_a_mesh_error(tmp_path, capsys, name):
    path = tmp_path / name
    path.write_bytes(MALFORMED[name])
    with pytest.raises(sf.MeshError) as info:
        sf.Mesh.read(path)
    assert str(path) in str(info.value)
    assert main(["info", str(path)]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(path) in err


# -- item 6: out-of-range numbers and names, checked before any work --------------------------


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("max_iterations = 50", "max_iterations = 9223372036854775807", "solver.max_iterations"),
        ("load_steps = 1", "load_steps = 2147483648", "solver.load_steps"),
        ("load_steps = 1", "load_steps = 1099511627776", "solver.load_steps"),
        ("box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }", "nodes = [9223372036854775807]", "fixed[0].nodes"),
        ("[solver]", "[dynamics]\ndt = 1e308\nsteps = 10\n\n[solver]", "dynamics.dt"),
        ("[solver]", "[dynamics]\ndt = 0.01\nsteps = 9223372036854775807\n\n[solver]", "dynamics.steps"),
        ("[solver]", "[dynamics]\ndt = 0.01\nsteps = 2\nsave_every = 4294967296\n\n[solver]", "dynamics.save_every"),
        ("[solver]", "[[cable]]\nstart = [0, 0.01, 0.01]\ndirection = [1, 0, 0]\nlength = 0.1\ndivisions = 2147483648\n"
         "stiffness = 1e3\n\n[solver]", "cable[0].divisions"),
        ("[mesh]\n", "[mesh]\nscale = 1e-105\n", "mesh"),
        ("cells = [4, 1, 1] }", "cells = [4, 1, 1] }\nfile = \"a\\u0000b.vtu\"", "mesh"),
    ],
)
def test_issue_20_out_of_range_scene_numbers_exit_2(tmp_path, capsys, old, new, key):
    text = replaced(old, new)
    if "file =" in new:
        text = text.replace('box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }\n', "")
    code, err = run_scene(tmp_path, text, capsys)
    assert code == EXIT_INPUT, err
    assert key in err


def test_issue_20_deep_toml_nesting_exits_2(tmp_path, capsys):
    code, err = run_scene(tmp_path, BOX_SCENE + "deep = " + "[" * 5000 + "]" * 5000 + "\n", capsys)
    assert code == EXIT_INPUT and "nested too deeply" in err


@pytest.mark.parametrize("name", ["a\0b.toml", "x" * 300 + ".toml", "d/" * 2100 + "s.toml"])
def test_issue_20_bad_file_names_exit_2(tmp_path, capsys, name):
    assert main(["run", str(tmp_path / name), "--out", str(tmp_path / "out")]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "Traceback" not in err and ("NUL" in err or "bytes long" in err)


def test_issue_20_long_mesh_file_component_exits_2(tmp_path, capsys):
    text = BOX_SCENE.replace("box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }", f'file = "{"m" * 300}.vtu"')
    code, err = run_scene(tmp_path, text, capsys)
    assert code == EXIT_INPUT and "mesh.file" in err and "255" in err


def test_issue_20_huge_integers_in_the_api_name_the_limit():
    body = beam()
    for call, name in [
        (lambda: sf.solve_static(body, max_iterations=2**64), "max_iterations"),
        (lambda: sf.solve_static(body, load_steps=2**31), "load_steps"),
        (lambda: sf.simulate(body, 0.01, 2**40), "steps"),
        (lambda: sf.simulate(body, 1e308, 2), "dt"),
        (lambda: sf.Cable.line((0, 0, 0), (1, 0, 0), 0.1, 2**31, stiffness=1.0), "divisions"),
        (lambda: sf.estimate(body, sf.Target.nodes([9], [[0.1, 0, 0]]), ["shear_modulus"], starts=2**31), "starts"),
    ]:
        with pytest.raises(sf.ParameterError) as info:
            call()
        assert info.value.parameter == name, str(info.value)


def test_issue_20_subnormal_mesh_scale_is_refused():
    with pytest.raises(sf.MeshError, match="bounding-box diagonal"):
        sf.Mesh.box(cells=(1, 1, 1)).scaled(1e-105)
    with pytest.raises(sf.MeshError, match="bounding-box diagonal"):
        sf.Mesh.box(size=(1e300, 1e300, 1e300))


# -- item 7: library exceptions wrapped, the argument named ------------------------------------


def test_issue_20_exception_in_actuation_callable_names_the_schedule():
    body = beam()
    body.add_cable(sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.1, 4, stiffness=1e3))
    with pytest.raises(sf.ParameterError, match=r"actuation: the schedule raised ZeroDivisionError at t = 0.01 s"):
        sf.simulate(body, 0.01, 2, actuation=lambda t: 1 / 0)
    with pytest.raises(sf.ParameterError, match=r"actuation\[0\]: the schedule raised KeyError"):
        sf.simulate(body, 0.01, 2, actuation=[lambda t: {}["x"]])


@pytest.mark.parametrize("content", ["[1, 2, 3]\n", "not json at all\n{}\n", '{"params": [1]}\n', '"text"\n{}\n'])
def test_issue_20_garbage_history_names_the_file_and_line(tmp_path, content):
    path = tmp_path / "history.jsonl"
    path.write_text(content)
    with pytest.raises(sf.InputError, match="history_path") as info:
        sf.estimate(beam(), sf.Target.nodes([9], [[0.1, 0, 0]]), ["shear_modulus"], history_path=path, resume=True)
    assert str(path) in str(info.value)


def test_issue_20_history_path_that_is_a_folder(tmp_path):
    with pytest.raises(sf.InputError, match="is a folder"):
        sf.estimate(beam(), sf.Target.nodes([9], [[0.1, 0, 0]]), ["shear_modulus"], history_path=tmp_path)


@pytest.mark.parametrize(
    "objective, words",
    [
        (lambda x: (0.0, np.zeros((3, 1))), "shape (3, 1)"),
        (lambda x: 1.0, "expected the callable to return"),
        (lambda x: (math.nan, np.zeros_like(x)), "finite number"),
        (lambda x: 1 / 0, "ZeroDivisionError"),
    ],
)
def test_issue_20_callable_objective_errors_name_the_objective(objective, words):
    with pytest.raises(sf.InputError, match="objective") as info:
        sf.gradient(beam(), objective, ["shear_modulus"], gravity=(0, 0, -9.81))
    assert words in str(info.value)


def test_issue_20_unknown_output_extension_is_an_input_error(tmp_path):
    with pytest.raises(sf.InputError, match="unknownext"):
        sf.io.write_mesh(tmp_path / "x.unknownext", sf.Mesh.box())
    assert list(tmp_path.iterdir()) == []


# -- item 8: runaway runs capped by documented limits ------------------------------------------


def test_issue_20_runaway_counts_are_capped_by_the_documented_limits():
    from sorofem._validate import LIMITS

    body = beam()
    for name, call in [
        ("load_steps", lambda v: sf.solve_static(body, load_steps=v)),
        ("max_iterations", lambda v: sf.solve_static(body, max_iterations=v)),
        ("steps", lambda v: sf.simulate(body, 1e-3, v)),
        ("starts", lambda v: sf.estimate(body, sf.Target.nodes([9], [[0.1, 0, 0]]), ["shear_modulus"], starts=v)),
        ("max_evaluations", lambda v: sf.estimate(body, sf.Target.nodes([9], [[0.1, 0, 0]]), ["shear_modulus"],
                                                  max_evaluations=v)),
    ]:
        with pytest.raises(sf.ParameterError, match=str(int(LIMITS[name].value))):
            call(int(LIMITS[name].value) + 1)


def test_the_guarantees_page_lists_every_limit_with_its_value():
    from sorofem._validate import LIMITS

    page = (Path(__file__).resolve().parent.parent / "docs" / "guarantees.md").read_text()
    rows = {line.split("|")[1].strip().strip("`"): line.split("|")[2].strip() for line in page.splitlines()
            if line.startswith("| `")}
    assert set(rows) >= set(LIMITS)
    for name, limit in LIMITS.items():
        assert float(rows[name]) == limit.value, name


def test_issue_20_a_model_beyond_the_memory_is_refused_before_it_is_built(monkeypatch):
    from sorofem import _validate

    body = beam()
    monkeypatch.setattr(_validate, "machine_memory", lambda: 100_000)  # 100 kB: less than 20 nodes need
    with pytest.raises(sf.ParameterError, match="memory") as info:
        sf.solve_static(body)
    assert info.value.parameter == "mesh"

"""What `sorofem --help` and `sorofem convert --help` tell a newcomer, and the plurals of the
reports."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

import sorofem as sf
from sorofem.cli import EXIT_INPUT, EXIT_OK, EXIT_SOLVER, EXIT_UNEXPECTED, main

ROOT = Path(__file__).resolve().parent.parent


def _help(capsys, *argv: str) -> str:
    assert main([*argv, "--help"]) == 0
    return capsys.readouterr().out


def test_top_level_help_has_examples_and_exit_codes(capsys):
    text = _help(capsys)
    assert "examples:" in text and "exit codes:" in text
    for code in (EXIT_OK, EXIT_INPUT, EXIT_SOLVER, EXIT_UNEXPECTED, 130):
        assert re.search(rf"^\s+{code}\s+\S", text, flags=re.M), code
    # Every example names a command that exists and, where it names a scene, one that exists.
    examples = [line.split("#")[0].strip() for line in text.split("examples:")[1].split("exit codes:")[0].splitlines()]
    commands = {"run", "estimate", "control", "info", "convert", "view", "schema"}
    assert {"run", "estimate", "control"} <= {shlex.split(e)[1] for e in examples if e}
    for example in filter(None, examples):
        words = shlex.split(example)
        assert words[0] == "sorofem" and words[1] in commands, example
        for word in words:
            if word.startswith("examples/"):
                assert (ROOT / word).is_file(), word


def test_convert_help_lists_the_formats(capsys):
    text = _help(capsys, "convert")
    assert "(see sorofem.convert)" not in text
    for suffix in (".tet", ".msh", ".node", ".ele", ".stl", ".obj", ".vtu"):
        assert suffix in text, suffix
    assert "sf.tetrahedralize" in text  # what to do with a surface


def test_reports_count_with_the_right_plural():
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(2, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    report = sf.solve_static(body, (0, 0, -9.81), load_steps=1).report
    assert "(1 load step, 0 cutbacks)" in report.summary() and "1 load steps" not in report.summary()
    assert "(2 load steps," in sf.solve_static(body, (0, 0, -9.81), load_steps=2).report.summary()


@pytest.mark.parametrize("n, noun, text", [(0, "cutback", "0 cutbacks"), (1, "cutback", "1 cutback"),
                                           (2, "Newton iteration", "2 Newton iterations")])
def test_plural(n, noun, text):
    from sorofem._text import plural

    assert plural(n, noun) == text


def test_mesh_bounds_is_a_property_and_the_call_warns():
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(2, 1, 1))
    lo, hi = mesh.bounds
    assert lo.tolist() == [0, 0, 0] and hi.tolist() == pytest.approx([0.4, 0.1, 0.1])
    with pytest.warns(DeprecationWarning, match=r"Mesh\.bounds\(\) is deprecated.*mesh\.bounds"):
        called = mesh.bounds()
    assert called.min.tolist() == lo.tolist() and called.max.tolist() == hi.tolist()
    assert mesh.size == pytest.approx(float(((hi - lo) ** 2).sum() ** 0.5))

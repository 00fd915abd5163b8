"""`sorofem estimate` and `sorofem control`: [target], [estimate] and [control] scenes."""

from __future__ import annotations

import json

import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main

BASE = """\
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]
"""

CABLE = """
[[cable]]
start = [0.0, 0.01, 0.018]
direction = [1, 0, 0]
length = 0.1
divisions = 4
stiffness = 1e4
"""


def _free_end(text: str, tmp_path, alpha: float | None = None):
    """Free-end node indices and their equilibrium positions (cable 0 at ``alpha`` if given)."""
    scene = sf.Scene.from_toml(text, tmp_path / "goal.toml")
    if alpha is not None:
        scene.body.set_actuation(0, alpha)
    result = sf.solve_static(scene.body, scene.gravity, tolerance=1e-12)
    nodes = np.flatnonzero(np.isclose(scene.mesh.points[:, 0], 0.1))
    return nodes, result.positions[nodes]


def _target(nodes, positions) -> str:
    return f"\n[target]\nnodes = {nodes.tolist()}\npositions = {positions.tolist()}\n"


def test_estimate_recovers_mu_lambda(tmp_path, capsys):
    nodes, goal = _free_end(BASE, tmp_path)
    scene = tmp_path / "fit.toml"
    scene.write_text(
        BASE + _target(nodes, goal)
        + '\n[estimate]\nparams = ["shear_modulus", "lame_lambda"]\nx0 = [15e3, 0.15e6]\n'
    )
    out = tmp_path / "out"
    assert main(["estimate", str(scene), "--out", str(out)]) == 0
    assert "mu" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    truth = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45)
    assert summary["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-4)
    assert summary["lame_lambda"] == pytest.approx(truth.lame_lambda, rel=1e-4)
    assert summary["youngs_modulus"] == pytest.approx(66e3, rel=1e-4)
    assert summary["poisson_ratio"] == pytest.approx(0.45, rel=1e-4)
    for key in ("residual", "forward_solves", "history"):
        assert key in summary
    assert (out / "result.vtu").is_file()


def test_control_recovers_alpha(tmp_path, capsys):
    text = BASE + CABLE
    nodes, goal = _free_end(text, tmp_path, alpha=0.9)
    scene = tmp_path / "ctl.toml"
    scene.write_text(text + _target(nodes, goal) + "\n[control]\ncables = [0]\nbounds = [[0.5, 1.0]]\n")
    out = tmp_path / "out"
    assert main(["control", str(scene), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["actuation"][0] == pytest.approx(0.9, abs=1e-4)
    assert printed["reachable"] is True
    for key in ("distance", "forward_solves", "history"):
        assert key in printed
    assert (out / "result.vtu").is_file() and (out / "summary.json").is_file()


BAD_TARGETS = [
    ("[target]\nnodes = [19]\n", "target.positions"),
    ("[target]\nnodes = [999]\npositions = [[0, 0, 0]]\n", "target.nodes"),
    ("[target]\nnodes = [1, 2]\npositions = [[0, 0, 0]]\n", "target.positions"),
    ("[target]\nnodes = [1]\npoints = [[0, 0, 0]]\npositions = [[0, 0, 0]]\n", "target"),
    ("[target]\nnodes = [1]\npositions = [[0, 0, 0]]\ncolour = 1\n", "target.colour"),
    ("[target]\nnodes = [1]\npositions = [[0, 0]]\n", "target.positions"),
    ("[target]\nnodes = [\"a\"]\npositions = [[0, 0, 0]]\n", "target.nodes"),
    ("[target]\npoints = [[5, 5, 5]]\npositions = [[0, 0, 0]]\n", "target.points"),
    ('[target]\nsurface = "missing.obj"\n', "target.surface"),
    ('[target]\nsurface = 3\n', "target.surface"),
    ("[target]\nnodes = [1]\npositions = [[0, 0, 0]]\nscale = 2\n", "target.scale"),
]


@pytest.mark.parametrize("section, key", BAD_TARGETS)
@pytest.mark.parametrize("command", ["estimate", "control"])
def test_bad_target_exits_2(tmp_path, capsys, section, key, command):
    scene = tmp_path / "bad.toml"
    tail = '[estimate]\nparams = ["shear_modulus"]\nx0 = [20e3]\n' if command == "estimate" else "[control]\n"
    scene.write_text(BASE + CABLE + "\n" + section + "\n" + tail)
    assert main([command, str(scene), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and key in lines[0], err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "section, key",
    [
        ('[estimate]\nparams = ["shear_modulus"]\n', "estimate.x0"),
        ('[estimate]\nparams = ["bogus"]\nx0 = [1]\n', "estimate.params"),
        ('[estimate]\nparams = ["shear_modulus"]\nx0 = [1]\nmethod = "magic"\n', "estimate.method"),
        ('[estimate]\nparams = ["shear_modulus"]\nx0 = [1]\nbounds = [1, 2]\n', "estimate.bounds"),
        ('[estimate]\nparams = ["shear_modulus"]\nx0 = [1]\nstarts = "x"\n', "estimate.starts"),
        ('[control]\ncables = [3]\n', "control.cables"),
        ('[control]\nbounds = [[0.5]]\n', "control.bounds"),
        ('[control]\nspeed = 1\n', "control.speed"),
    ],
)
def test_bad_estimate_control_sections(tmp_path, section, key):
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.from_toml(BASE + CABLE + "\n" + section, tmp_path / "s.toml")
    assert key in str(info.value)


def test_missing_sections_exit_2(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(BASE)
    assert main(["estimate", str(scene), "--out", str(tmp_path / "o")]) == 2
    assert "[target]" in capsys.readouterr().err


TENDON = """
[[cable]]
start = [0.005, 0.01, 0.018]
direction = [1, 0, 0]
length = 0.09
divisions = 4
model = "tendon"
pull = 0.001
"""


def test_control_recovers_a_tendon_pull_in_metres(tmp_path, capsys):
    """Issue 16 item 4: `sorofem control` optimises a tendon's pull in metres, bounds in metres."""
    text = BASE + TENDON
    scene = sf.Scene.from_toml(text, tmp_path / "goal.toml")
    scene.body.pull(0, displacement=0.004)
    result = sf.solve_static(scene.body, scene.gravity, tolerance=1e-12)
    nodes = np.flatnonzero(np.isclose(scene.mesh.points[:, 0], 0.1))
    path = tmp_path / "ctl.toml"
    path.write_text(text + _target(nodes, result.positions[nodes]) + "\n[control]\ncables = [0]\nbounds = [[0.0, 0.008]]\n")
    out = tmp_path / "out"
    assert main(["control", str(path), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["actuation"][0] == pytest.approx(0.004, abs=1e-7)
    assert printed["reachable"] is True


# ---------------------------------------------------------------------------
# [target] contact_force (issue 17)

FINGER = """\
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [10, 2, 2] }

[material]
youngs_modulus = 100e3
poisson_ratio = 0.3

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[[cable]]
start = [0.0, 0.01, 0.003]
direction = [1, 0, 0]
length = 0.095
divisions = 9
model = "tendon"
pull = 0.003

[[obstacle]]
name = "wall"
plane = { point = [0.2, 0, 0], normal = [-1, 0, 0] }

[[obstacle]]
name = "table"
plane = { point = [0, 0, -0.004], normal = [0, 0, 1] }

[contact]
stiffness = 1e9
"""


def _table_force(text: str, tmp_path, pull: float | None = None) -> float:
    """|F| of the table on the finger of scene ``text`` (its tendon pulled to ``pull`` if given)."""
    scene = sf.Scene.from_toml(text, tmp_path / "check.toml")
    if pull is not None:
        scene.body.pull(0, displacement=pull)
    return float(np.linalg.norm(sf.solve_static(scene.body, scene.gravity, tolerance=1e-12).obstacle_forces[1]))


@pytest.mark.parametrize("obstacle", ['"table"', "1"])
def test_control_presses_the_table_with_a_target_force(tmp_path, capsys, obstacle):
    """The tendon pull that makes the table (named, or by index) push back with 0.05 N: checked
    by a plain solve at the pull found."""
    assert _table_force(FINGER, tmp_path) > 0.055, "the commanded pull should press harder than the goal"
    path = tmp_path / "ctl.toml"
    path.write_text(FINGER + f"\n[target]\ncontact_force = {{ obstacle = {obstacle}, force = 0.05 }}\n"
                    "\n[control]\ncables = [0]\nbounds = [[0.002, 0.006]]\n")
    out = tmp_path / "out"
    assert main(["control", str(path), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["reachable"] is True
    assert _table_force(FINGER, tmp_path, printed["actuation"][0]) == pytest.approx(0.05, rel=1e-6)
    assert (out / "fit.png").is_file() and (out / "result.vtu").is_file()


def test_estimate_fits_the_modulus_to_a_force_vector(tmp_path, capsys):
    """E from the force vector the table exerts, the finger's tendon held at its pull; both scenes
    share the barrier stiffness ([contact] stiffness), so the fit is exact."""
    scene = sf.Scene.from_toml(FINGER, tmp_path / "truth.toml")
    force = sf.solve_static(scene.body, tolerance=1e-12).obstacle_forces[1]
    path = tmp_path / "fit.toml"
    path.write_text(FINGER.replace("youngs_modulus = 100e3", "youngs_modulus = 60e3")
                    + f"\n[target]\ncontact_force = {{ obstacle = \"table\", force = {force.tolist()} }}\n"
                    "\n[estimate]\nparams = [\"youngs_modulus\"]\nx0 = [60e3]\n")
    out = tmp_path / "out"
    assert main(["estimate", str(path), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["youngs_modulus"] == pytest.approx(100e3, rel=1e-6)


BAD_CONTACT_TARGETS = [
    ('contact_force = { obstacle = "cup", force = 0.1 }', "target.contact_force.obstacle", "'cup'"),
    ("contact_force = { obstacle = 2, force = 0.1 }", "target.contact_force.obstacle", "2"),
    ('contact_force = { obstacle = "table", force = [0.1, 0.2] }', "target.contact_force.force", "[0.1, 0.2]"),
    ('contact_force = { obstacle = "table", force = -0.1 }', "target.contact_force.force", "-0.1"),
    ('contact_force = { obstacle = "table" }', "target.contact_force.force", "missing"),
    ('contact_force = { obstacle = "table", force = 0.1 }\nnodes = [1]\npositions = [[0, 0, 0]]', "target",
     "contact_force"),
]


@pytest.mark.parametrize("section, key, shown", BAD_CONTACT_TARGETS)
@pytest.mark.parametrize("command", ["estimate", "control"])
def test_a_bad_contact_force_target_exits_2_naming_the_key(tmp_path, capsys, section, key, shown, command):
    scene = tmp_path / "bad.toml"
    tail = '[estimate]\nparams = ["shear_modulus"]\nx0 = [20e3]\n' if command == "estimate" else "[control]\n"
    scene.write_text(FINGER + "\n[target]\n" + section + "\n\n" + tail)
    assert main([command, str(scene), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and key in lines[0] and shown in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_obstacle_names_are_unique(tmp_path):
    text = FINGER.replace('name = "wall"', 'name = "table"')
    with pytest.raises(sf.SceneError, match=r"obstacle\[1\]\.name"):
        sf.Scene.from_toml(text, tmp_path / "s.toml")

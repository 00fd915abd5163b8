"""Contact through the Python API: obstacles and contact settings checked with errors that name
what is wrong, a block resting on a table reported in the result and its files, the command
line's exit codes."""

from __future__ import annotations

import json
import warnings

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main
from sorofem.obstacles import OpenSurfaceWarning

SIZE = 0.1  # m
DENSITY = 1080.0  # kg/m^3
GRAVITY = (0.0, 0.0, -9.81)


def block(lift: float = 1e-4, cells: int = 2) -> sf.Body:
    mesh = sf.Mesh.box(size=(SIZE, SIZE, SIZE), cells=(cells, cells, cells), origin=(0.0, 0.0, lift))
    return sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=DENSITY))


def tetrahedron(offset: float) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) * 0.05 + offset
    return vertices, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


@pytest.mark.parametrize(("make", "error", "names"), [
    (lambda: sf.Plane((0, 0, 0), (0, 0, 0)), sf.InputError, "normal"),
    (lambda: sf.Sphere((0, 0, 0), -1.0), sf.ParameterError, "radius"),
    (lambda: sf.Box((0, 0, 0), (1, -1, 1)), sf.InputError, "max > min"),
    (lambda: sf.Obstacle.mesh((np.eye(3), np.array([[0, 1, 2]]))), sf.MeshError, "open"),
    (lambda: sf.Obstacle.mesh((np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 1.0]]),
                               np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]))), sf.MeshError, "area"),
    (lambda: sf.Obstacle.mesh((np.eye(3), np.array([[0, 1, 5]])), one_sided=True), sf.MeshError, "5"),
])
def test_bad_obstacles_are_named(make, error, names):
    with pytest.raises(error, match=names):
        make()


def test_an_open_surface_is_a_one_sided_sheet_with_a_warning():
    with pytest.warns(OpenSurfaceWarning, match="orientation"):
        sheet = sf.Obstacle.mesh((np.eye(3), np.array([[0, 1, 2]])), one_sided=True)
    assert not sheet.is_closed
    closed = sf.Obstacle.mesh(tetrahedron(1.0))
    assert closed.is_closed


def test_bad_contact_settings_are_named():
    body = block()
    with pytest.raises(sf.ParameterError, match="friction") as info:
        body.add_obstacle(sf.Plane((0, 0, 0), (0, 0, 1)), friction=-0.1)
    assert info.value.parameter == "friction"
    for dhat in (0.0, -1e-3, float("nan")):
        with pytest.raises(sf.ParameterError, match="dhat"):
            body.set_contact(dhat=dhat)
    with pytest.raises(sf.InputError, match="unknown setting 'd_hat'"):
        body.set_contact(d_hat=1e-3)
    assert body.contact_settings["adaptive_stiffness"] is True
    with pytest.raises(sf.ParameterError, match="adaptive_stiffness: expected True or False, got 'no'") as info:
        body.set_contact(adaptive_stiffness="no")
    assert info.value.parameter == "adaptive_stiffness"
    body.set_contact(adaptive_stiffness=False)
    assert body.contact_settings["adaptive_stiffness"] is False
    body.set_contact(adaptive_stiffness=None)
    assert body.contact_settings["adaptive_stiffness"] is True
    with pytest.raises(sf.InputError, match="obstacle"):
        body.add_obstacle("a table")  # type: ignore[arg-type]
    assert body.obstacles == () and body.dhat is None


@pytest.mark.parametrize(("obstacle", "names"), [
    # A table cutting the block: its lowest node 4.99 cm below the plane.
    (sf.Plane((0, 0, 0.05), (0, 0, 1)), r"body node 0 at signed distance -4\.990e-2 m"),
    # A ball dipping 4.1 mm into the top face (z = 0.1001) between its nodes: the triangle it meets.
    (sf.Sphere((0.025, 0.025, 0.111), 0.015), r"body triangle \[\d+, \d+, \d+\] at signed distance -4\.100e-3 m"),
    # A box inside the block: none of its vertices is outside.
    (sf.Box((0.02, 0.02, 0.02), (0.03, 0.03, 0.03)), "inside the body"),
])
def test_an_obstacle_intersecting_the_body_at_rest_is_named(obstacle, names):
    body = block()
    body.add_obstacle(sf.Plane((0, 0, 0), (0, 0, 1)))
    with pytest.raises(sf.ParameterError, match=names) as info:
        body.add_obstacle(obstacle)
    assert "obstacles[1]" in str(info.value)
    assert len(body.obstacles) == 1  # the rejected one is not kept


def test_a_block_on_a_table_reports_its_contact(tmp_path):
    """The table carries the weight: its force is -weight (1e-6), spread over the bottom nodes
    only, every node above the table; the files carry the contact forces."""
    body = block()
    body.add_obstacle(sf.Plane((0, 0, 0), (0, 0, 1)), friction=0.5)
    result = sf.solve_static(body, gravity=GRAVITY, tolerance=1e-10)
    weight = DENSITY * SIZE**3 * np.asarray(GRAVITY)
    assert result.contact_forces.shape == (body.mesh.n_nodes, 3)
    np.testing.assert_allclose(result.obstacle_forces[0], -weight, atol=1e-6 * np.linalg.norm(weight))
    bottom = np.abs(body.mesh.points[:, 2] - 1e-4) < 1e-12
    assert np.all(result.contact_forces[~bottom] == 0.0)
    assert 0 < result.min_distance < body.dhat
    assert result.positions[:, 2].min() > 0
    assert result.active_contacts >= bottom.sum()
    assert np.all(np.asarray(result.contact.iterate_min_distances) > 0)

    sf.io.write_result(tmp_path / "result.vtu", result)
    written = meshio.read(tmp_path / "result.vtu")
    np.testing.assert_allclose(written.point_data["contact_force"], result.contact_forces)


def _scene(obstacle: str, contact: str = "") -> str:
    return f"""
[mesh]
box = {{ size = [0.1, 0.1, 0.1], cells = [2, 2, 2], origin = [0, 0, 1e-4] }}

[material]
model = "neo-hookean"
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[loads]
gravity = [0, 0, -9.81]

[[obstacle]]
{obstacle}
friction = 0.5
{contact}
"""


def test_a_scene_resting_on_a_table_runs_and_reports_the_contact(tmp_path):
    scene = tmp_path / "table.toml"
    scene.write_text(_scene("plane = { point = [0, 0, 0], normal = [0, 0, 1] }"), encoding="utf-8")
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    weight = 1080 * 0.1**3 * 9.81
    assert summary["contact"]["obstacles"][0]["force"][2] == pytest.approx(weight, rel=1e-6)
    assert summary["contact"]["obstacles"][0]["kind"] == "plane"


@pytest.mark.parametrize(("obstacle", "contact", "names"), [
    ("plane = { point = [0, 0, 0.05], normal = [0, 0, 1] }", "", "obstacle"),
    ("plane = { point = [0, 0, 0], normal = [0, 0, 1] }", "[contact]\ndhat = 0.0", "dhat"),
    ("plane = { point = [0, 0, 0], normal = [0, 0, 1] }", "[contact]\nadaptive_stiffness = 1", "adaptive_stiffness"),
    ("sphere = { center = [0, 0, -1], radius = -0.5 }", "", "radius"),
])
def test_a_bad_scene_exits_2_naming_the_key(tmp_path, capsys, obstacle, contact, names):
    scene = tmp_path / "bad.toml"
    scene.write_text(_scene(obstacle, contact), encoding="utf-8")
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert names in err and "Traceback" not in err


def test_a_friction_relag_from_a_converged_state_is_judged_against_the_first_solves_reference():
    """A tendon pull (no external load: the first solve's reference is its own start residual)
    with a frictional obstacle out of reach: the friction re-lags start at the converged state,
    whose leftover residual (round-off) must not become their reference. They took 224 extra
    Newton iterations wandering at that round-off before the re-lags kept the first reference."""
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=DENSITY))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    x = np.linspace(0.0, 0.095, 6)
    points = np.vstack([[-0.01, 0.01, 0.018], np.c_[x, np.full_like(x, 0.01), np.full_like(x, 0.018)]])
    cable = sf.Cable(points, model="tendon", anchor_first=True)
    body.add_cable(cable)
    body.add_obstacle(sf.Plane((0, 0, -0.05), (0, 0, 1)), friction=0.5)
    rest = sf.solve_static(body, tolerance=1e-10)
    body.pull(cable, displacement=1e-3)
    pulled = sf.solve_static(body, tolerance=1e-10, initial=rest)
    assert pulled.report.converged and pulled.active_contacts == 0
    assert pulled.cable_pull[0] == pytest.approx(1e-3, rel=1e-9)
    assert pulled.report.iterations <= 6, pulled.report.residual_history

"""The viewer's tendons and contact: a tendon's slider is its command (pull in mm or tension in N),
its solved tension and pull are shown after each solve (slack ones as such); obstacles are drawn
and contact forces shown as arrows with their scale and the total force per obstacle; a playback
draws the obstacles and moves those on a path frame by frame.

The slider and arrow logic (sorofem.viewer.commands, sorofem.viewer.contact) is tested without a
server; the views against a real viser server on a free loopback port (skipped without viser).
The real-browser checks are in tests/test_viewer.py (`make test-viewer`).
"""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import pytest

import sorofem as sf
from sorofem.viewer.commands import cable_lines, command_slider, is_slack, nice_ceiling, tension_scale
from sorofem.viewer.contact import contact_arrows, obstacle_lines, obstacle_meshes, obstacle_offsets
from sorofem.viewer.style import ARROW_LENGTH, ARROW_THRESHOLD, PULL_RANGE_FRACTION

#: The 0.4 m silicone cantilever (8 x 2 x 2 cells) with three cables: a tendon along the top
#: pulled 10 mm, a tendon along the bottom at tension 0.5 N and a spring chain at alpha 0.95.
TENDON_SCENE = """\
[mesh]
box = { size = [0.4, 0.1, 0.1], cells = [8, 2, 2] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]

[[cable]]
model = "tendon"
start = [0.01, 0.05, 0.09]
direction = [1, 0, 0]
length = 0.38
divisions = 8
pull = 0.01

[[cable]]
model = "tendon"
start = [0.01, 0.05, 0.01]
direction = [1, 0, 0]
length = 0.38
divisions = 8
tension = 0.5

[[cable]]
start = [0, 0.03, 0.05]
direction = [1, 0, 0]
length = 0.4
divisions = 8
stiffness = 1e5
actuation = 0.95
"""

#: A 0.1 m block resting on a table under gravity, a ball, a crate and a tetrahedron (a closed
#: triangle surface) beside it.
CONTACT_SCENE = """\
[mesh]
box = { size = [0.1, 0.1, 0.1], cells = [2, 2, 2], origin = [0, 0, 1e-4] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[loads]
gravity = [0, 0, -9.81]

[[obstacle]]
plane = { point = [0, 0, 0], normal = [0, 0, 1] }
friction = 0.5

[[obstacle]]
sphere = { center = [0.3, 0.05, 0.05], radius = 0.04 }

[[obstacle]]
box = { min = [-0.3, 0, 0], max = [-0.2, 0.1, 0.1] }
"""
TETRAHEDRON = (np.array([[0.0, 0.3, 0.0], [0.1, 0.3, 0.0], [0.0, 0.4, 0.0], [0.0, 0.3, 0.1]]),
               np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))


@pytest.fixture
def tendon_scene(tmp_path: Path) -> Path:
    path = tmp_path / "tendons.toml"
    path.write_text(TENDON_SCENE, encoding="utf-8")
    return path


@pytest.fixture
def contact_scene(tmp_path: Path) -> Path:
    path = tmp_path / "table.toml"
    path.write_text(CONTACT_SCENE, encoding="utf-8")
    return path


# ---------------------------------------------------------------------------
# Sliders and cable lines, without a server


def test_nice_ceiling() -> None:
    assert [nice_ceiling(v) for v in (0.7, 1.0, 1.2, 3.0, 7.5, 95.0, 0.0042)] == pytest.approx(
        [1.0, 1.0, 2.0, 5.0, 10.0, 100.0, 0.005])


def test_each_cable_gets_the_slider_of_its_command(tendon_scene) -> None:
    body = sf.Scene.load(tendon_scene).body
    pull, tension, spring = (command_slider(body, c) for c in range(3))
    # A pull in mm from 0 to a quarter of the rest length (rounded up), in steps that give at
    # least 100 positions; the slider position is turned into metres.
    length = body.cables[0].length
    assert pull.kind == "pull" and pull.label == "cable 0 pull [mm]" and pull.initial == pytest.approx(10.0)
    assert pull.min == 0.0 and PULL_RANGE_FRACTION * length * 1e3 <= pull.max < 2 * PULL_RANGE_FRACTION * length * 1e3
    assert (pull.max - pull.min) / pull.step >= 100 and pull.command(12.5) == pytest.approx(0.0125)
    # A tension in N, from 0 to the scale of the body (here well above twice the command).
    assert tension.kind == "tension" and tension.label == "cable 1 tension [N]" and tension.initial == 0.5
    mu = 66e3 / (2 * 1.45)
    assert tension.max == tension_scale(body) == nice_ceiling(0.2 * mu * 0.1 * 0.1) == 50.0
    assert tension.min == 0.0 and tension.command(3.0) == 3.0
    # A spring chain keeps its alpha slider.
    assert spring.kind == "actuation" and spring.label == "cable 2 alpha" and spring.initial == 0.95
    assert spring.command(0.8) == 0.8
    # A range widens to hold a command beyond it: a pull of half the tendon, a tension of 80 N,
    # a tendon paid out (a negative pull).
    body.pull(0, displacement=0.19)
    body.pull(1, tension=80.0)
    assert command_slider(body, 0).max == pytest.approx(190.0) and command_slider(body, 1).max == 200.0
    body.pull(0, displacement=-0.005)
    assert command_slider(body, 0).min == pytest.approx(-5.0)


def test_cable_lines_report_tension_pull_and_slack(tendon_scene) -> None:
    scene = sf.Scene.load(tendon_scene)
    scene.body.pull(1, displacement=0.0)  # the bottom tendon, not pulled: gravity shortens the bottom
    result = scene.solve()
    assert result.cable_tension[0] > 0 and result.cable_tension[1] == 0.0 and result.cable_tension[2] is None
    assert not is_slack(result, 0) and is_slack(result, 1) and not is_slack(result, 2)
    top, bottom, spring = cable_lines(result)
    assert top.startswith("cable 0 (tendon, pull 10 mm): taut")
    assert f"tension {result.cable_tension[0]:.4g} N" in top and "pull 10 mm" in top
    assert bottom.startswith("cable 1 (tendon, pull 0 mm): **slack**") and "tension 0 N" in bottom
    assert spring.startswith("cable 2: alpha 0.950, tension ")


# ---------------------------------------------------------------------------
# Obstacles and contact arrows, without a server


def test_obstacle_meshes_draw_each_kind_where_it_is(contact_scene) -> None:
    body = sf.Scene.load(contact_scene).body
    body.add_obstacle(sf.Obstacle.mesh(TETRAHEDRON))
    plane, ball, crate, tetrahedron = obstacle_meshes(body)
    # The table: a quad in the plane z = 0 around the block, larger than its footprint.
    vertices, triangles = plane
    assert triangles.shape == (2, 3) and np.all(vertices[:, 2] == 0.0)
    lo, hi = body.mesh.bounds
    assert np.all(vertices[:, :2].min(axis=0) < lo[:2]) and np.all(vertices[:, :2].max(axis=0) > hi[:2])
    vertices, triangles = ball
    np.testing.assert_allclose(np.linalg.norm(vertices - [0.3, 0.05, 0.05], axis=1), 0.04, rtol=1e-12)
    assert triangles.max() < len(vertices)
    vertices, triangles = crate
    assert triangles.shape == (12, 3) and np.array_equal(vertices.min(axis=0), [-0.3, 0, 0])
    vertices, triangles = tetrahedron
    np.testing.assert_array_equal(vertices, TETRAHEDRON[0]) and np.testing.assert_array_equal(triangles, TETRAHEDRON[1])
    # A moving obstacle is drawn where it is at t = 0, where static solves hold it.
    moving = sf.Scene.load(contact_scene).body
    moving.add_obstacle(sf.Sphere((0.05, 0.05, 0.4), 0.05), path=[[0.0, 0.0, 0.0, 0.1], [1.0, 0.0, 0.0, 0.0]])
    vertices = obstacle_meshes(moving)[-1][0]
    np.testing.assert_allclose(np.linalg.norm(vertices - [0.05, 0.05, 0.5], axis=1), 0.05, rtol=1e-12)


def test_contact_arrows_carry_the_weight(contact_scene) -> None:
    scene = sf.Scene.load(contact_scene)
    result = scene.solve()
    weight = 1080 * 0.1**3 * 9.81
    lo, hi = scene.mesh.bounds
    size = float(np.linalg.norm(hi - lo))
    arrows = contact_arrows(result, size)
    forces = result.contact_forces
    # Each arrow ends at its node and, divided by the scale, is the node's contact force; the
    # nodes left out carry less than the threshold, and the arrows carry the block's weight.
    np.testing.assert_allclose(arrows.segments[:, 1], result.positions[arrows.nodes], rtol=0, atol=0)
    vectors = (arrows.segments[:, 1] - arrows.segments[:, 0]) / arrows.scale
    np.testing.assert_allclose(vectors, forces[arrows.nodes], rtol=1e-12, atol=1e-12 * weight)
    left_out = np.setdiff1d(np.arange(len(forces)), arrows.nodes)
    assert np.all(np.linalg.norm(forces[left_out], axis=1) <= ARROW_THRESHOLD * arrows.largest)
    assert vectors.sum(axis=0)[2] == pytest.approx(weight, rel=1e-6)
    # The longest arrow is at most ARROW_LENGTH of the body's size, and 1 N is a round length.
    longest = np.linalg.norm(arrows.segments[:, 1] - arrows.segments[:, 0], axis=1).max()
    assert ARROW_LENGTH * size / 10 < longest <= ARROW_LENGTH * size * (1 + 1e-12)
    assert nice_ceiling(1e-3 / arrows.scale) == pytest.approx(1e-3 / arrows.scale)
    assert f"1 N = {arrows.scale * 1e3:.3g} mm" in arrows.legend
    # The side panel: each obstacle with its total force; the table carries the weight.
    table, ball, crate = obstacle_lines(result)
    assert table.startswith("obstacle 0 (plane): force (") and f"|F| = {weight:.4g} N" in table
    assert "min distance" in table and "nothing near" in ball and crate.startswith("obstacle 2 (box)")
    # Without obstacles: no arrows, no lines.
    free = sf.solve_static(_cantilever())
    assert contact_arrows(free, 1.0).nodes.size == 0 and obstacle_lines(free) == []
    assert contact_arrows(free, 1.0).legend == "contact forces: none"


def _pressed_block() -> tuple[sf.Body, sf.Trajectory]:
    """The block of CONTACT_SCENE on its table, pressed by a plate coming down from 20 mm above
    its top to 2 mm into it over 0.1 s (a path), in 10 steps; the ball and the crate stay put."""
    body = sf.Scene.from_toml(CONTACT_SCENE, Path("pressed.toml")).body
    body.add_obstacle(sf.Box((-0.05, -0.05, 0.1021), (0.15, 0.15, 0.15)), path=[[0.0, 0, 0, 0.02], [0.1, 0, 0, -0.004]])
    return body, sf.simulate(body, 0.01, 10, gravity=(0, 0, -9.81), progress=False)


def test_obstacle_offsets_follow_the_path_as_the_solver_moved_it() -> None:
    body, trajectory = _pressed_block()
    offsets = obstacle_offsets(body, trajectory.times)
    assert offsets.shape == (11, 4, 3)
    np.testing.assert_allclose(offsets, trajectory.obstacle_translations, rtol=0, atol=1e-15)
    np.testing.assert_allclose(offsets[:, 3, 2], 0.02 - 0.024 * trajectory.times / 0.1, atol=1e-15)
    assert np.all(offsets[:, :3] == 0.0)
    # Unmoved, the plate is its box; moved (where static solves hold it), it is 20 mm higher.
    plate, moved = obstacle_meshes(body, moved=False)[3][0], obstacle_meshes(body)[3][0]
    assert plate[:, 2].min() == pytest.approx(0.1021) and moved[:, 2].min() == pytest.approx(0.1221)
    # The plate pressed on the block at the end: the path reached it.
    assert trajectory.obstacle_forces[-1, 3, 2] < 0


def _cantilever() -> sf.Body:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


# ---------------------------------------------------------------------------
# The views, on a viser server

viser = pytest.importorskip("viser", reason="the optional extra viewer (viser) is not installed")

from sorofem.viewer import build_trajectory_view, build_view, rebuild_body  # noqa: E402
from sorofem.viewer.style import CABLE_COLOUR, SLACK_COLOUR  # noqa: E402


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    yield srv
    srv.stop()


def _colour(handle) -> tuple[int, ...]:
    return tuple(int(v) for v in np.asarray(handle.colors).reshape(-1, 3)[0])


def test_tendon_sliders_drive_pull_and_tension(server, tendon_scene) -> None:
    scene = sf.Scene.load(tendon_scene)
    view = build_view(scene, server)
    assert [s.label for s in view.sliders] == ["cable 0 pull [mm]", "cable 1 tension [N]", "cable 2 alpha"]
    assert view.sliders[0].value == pytest.approx(10.0) and view.sliders[1].value == 0.5
    assert "cable 0 (tendon, pull 10 mm): taut" in view.status.content
    tip = np.isclose(scene.mesh.points[:, 0], 0.4)
    tip_before = view.result.positions[tip, 2].mean()

    view.sliders[0].value = 20.0  # mm, as a browser drag would: the callback re-solves
    assert view.body.commands[0] == ("pull", pytest.approx(0.02)) and view.move_steps == 1
    assert view.result.cable_pull[0] == pytest.approx(0.02, rel=1e-9) and view.result.cable_tension[0] > 0
    assert view.result.positions[tip, 2].mean() > tip_before + 0.01  # the top tendon lifts the free end
    assert "pull 20 mm" in view.status.content and f"tension {view.result.cable_tension[0]:.4g} N" in view.status.content
    view.sliders[1].value = 3.0  # N
    assert view.body.commands[1] == ("tension", 3.0) and view.result.cable_tension[1] == pytest.approx(3.0)
    # The same equilibrium as a solve from rest with those commands.
    reference = sf.solve_static(rebuild_body(view.body, "standard"), scene.gravity, options=scene.solve_options)
    np.testing.assert_allclose(view.result.positions, reference.positions, atol=1e-7)
    np.testing.assert_allclose(view.result.cable_tension[0], reference.cable_tension[0], rtol=1e-6)

    # A tendon that goes slack is drawn grey and said to be slack; pulled again, red.
    assert _colour(view.cables[1]) == CABLE_COLOUR
    view.sliders[1].value = 0.0
    assert view.result.cable_tension[1] == 0.0 and _colour(view.cables[1]) == SLACK_COLOUR
    assert "cable 1 (tendon, tension 0 N): **slack**" in view.status.content
    view.sliders[1].value = 1.0
    assert _colour(view.cables[1]) == CABLE_COLOUR and "cable 1 (tendon, tension 1 N): taut" in view.status.content


def test_a_tendon_pull_in_the_mixed_formulation_goes_by_continuation(server, tendon_scene) -> None:
    scene = sf.Scene.load(tendon_scene)
    view = build_view(scene, server)
    view.formulation.value = "mixed"
    view.sliders[0].value = 40.0  # 30 mm further, in steps of at most 5 % of the 0.38 m tendon
    assert view.move_steps == 2 and view.result.cable_pull[0] == pytest.approx(0.04, rel=1e-9)
    assert view.result.pressure is not None and "last slider move: 2 step(s)" in view.status.content
    reference = sf.solve_static(rebuild_body(view.body, "mixed"), scene.gravity, options=scene.solve_options)
    np.testing.assert_allclose(view.result.positions, reference.positions, atol=1e-7)


def test_sorofem_view_opens_a_tendon_scene(tendon_scene, monkeypatch, capsys) -> None:
    """``sorofem view`` on a scene with tendons (the serving loop replaced by a check and a stop)."""
    import sorofem.viewer as viewer

    served = []

    def serve_once(server, on_stop):
        served.append(server)
        on_stop()
        server.stop()

    monkeypatch.setattr(viewer.serving, "wait_until_interrupted", serve_once)
    assert viewer.serve(tendon_scene, port=_free_port()) == 0
    assert "tendons.toml at http://127.0.0.1:" in capsys.readouterr().out and len(served) == 1


def test_obstacles_and_contact_arrows_in_the_view(server, contact_scene) -> None:
    scene = sf.Scene.load(contact_scene)
    view = build_view(scene, server)
    assert len(view.obstacles) == 3 and "3 obstacle(s)" in view._static_controls[0].content
    for handle, (vertices, triangles) in zip(view.obstacles, obstacle_meshes(scene.body)):
        np.testing.assert_allclose(handle.vertices, vertices, atol=1e-6)
        assert np.array_equal(handle.faces, triangles) and handle.opacity < 1
    lo, hi = scene.mesh.bounds
    arrows = contact_arrows(view.result, float(np.linalg.norm(hi - lo)))
    assert view.arrows.visible and arrows.nodes.size > 0
    np.testing.assert_allclose(view.arrows.points, arrows.segments, atol=1e-7)
    weight = 1080 * 0.1**3 * 9.81
    assert arrows.legend in view.contact_panel.content and f"|F| = {weight:.4g} N" in view.contact_panel.content
    # Another solve (the formulation dropdown rebuilds the body) redraws the arrows.
    view.formulation.value = "mixed"
    assert view.solves == 2
    arrows = contact_arrows(view.result, float(np.linalg.norm(hi - lo)))
    np.testing.assert_allclose(view.arrows.points, arrows.segments, atol=1e-7)


def test_the_playback_shows_a_tendon_s_tension_and_pull(server) -> None:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    body.add_cable(sf.Cable.line((0.01, 0.05, 0.09), (1, 0, 0), 0.38, 8, model="tendon", pull=0.01))
    trajectory = sf.simulate(body, 0.02, 4, gravity=(0, 0, -9.81), progress=False)
    view = build_trajectory_view(trajectory, server)
    try:
        assert "cable 0 (tendon): **slack**, tension 0 N, pull 0 mm" in view.status.content  # at rest
        view.slider.value = 3
        tension, pulled = trajectory.cable_tension[3][0], trajectory.cable_pull[3][0]
        assert tension > 0 and pulled == pytest.approx(0.01, rel=1e-9)
        assert f"cable 0 (tendon): tension {tension:.4g} N, pull 10 mm" in view.status.content
    finally:
        view.close()


def test_the_playback_draws_the_obstacles_and_moves_those_on_a_path(server, monkeypatch, tmp_path) -> None:
    body, trajectory = _pressed_block()
    view = build_trajectory_view(trajectory, server)
    try:
        assert len(view.obstacles) == 4
        for handle, (vertices, triangles) in zip(view.obstacles, obstacle_meshes(body, moved=False)):
            np.testing.assert_allclose(handle.vertices, vertices, atol=1e-6)
            assert np.array_equal(handle.faces, triangles) and handle.opacity < 1
        np.testing.assert_allclose(view.obstacles[3].position, [0, 0, 0.02], atol=1e-7)
        for add in ("add_mesh_simple", "add_glb", "add_point_cloud", "add_line_segments"):
            monkeypatch.setattr(server.scene, add, lambda *a, **k: pytest.fail("a frame re-created a scene node"))
        for k in (5, 10, 0):
            view.slider.value = k
            for handle, offset in zip(view.obstacles, trajectory.obstacle_translations[k]):
                np.testing.assert_allclose(handle.position, offset, atol=1e-7)
    finally:
        view.close()
    # A motion read from a .pvd has no obstacles recorded: none drawn.
    monkeypatch.undo()
    from_file = build_trajectory_view(trajectory.write_pvd(tmp_path), server)
    try:
        assert from_file.frames.n_frames == 11 and from_file.obstacles == []
    finally:
        from_file.close()

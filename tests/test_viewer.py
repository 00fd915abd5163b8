"""The browser viewer: `build_view` against a real viser server on a free loopback port.

Skipped when the optional extra (viser) is not installed. The real-browser test drives
Debian's `chromium` through Playwright's Python package (never `playwright install`); it runs
only with SOROFEM_BROWSER_TEST=1 (`make test-viewer` sets it) and skips when either is missing.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import sorofem as sf

viser = pytest.importorskip("viser", reason="the optional extra viewer (viser) is not installed: pip install \".[viewer]\"")
trimesh = pytest.importorskip("trimesh")

from sorofem.dynamics import Keyframes  # noqa: E402
from sorofem.viewer.colours import colour_range  # noqa: E402
from sorofem.viewer import (  # noqa: E402
    build_trajectory_view,
    build_view,
    colour_by_magnitude,
    colour_field,
    load_frames,
    nodal_field,
    per_client,
    playback,
    rebuild_body,
    simulate_in_chunks,
)

SCENES = Path(__file__).resolve().parent.parent / "examples" / "scenes"


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _glb_vertices(glb: bytes) -> np.ndarray:
    loaded = trimesh.load(io.BytesIO(glb), file_type="glb", process=False)
    geometry = loaded.geometry if hasattr(loaded, "geometry") else {"mesh": loaded}
    return np.concatenate([g.vertices for g in geometry.values()])


@pytest.fixture()
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    yield srv
    srv.stop()


def test_slider_resolves_warm_started_and_moves_the_surface(server) -> None:
    scene = sf.Scene.load(SCENES / "cable_cantilever.toml")
    view = build_view(scene, server)
    assert len(view.sliders) == 1 and view.sliders[0].value == pytest.approx(0.8)
    glb0 = view.surface.glb_data
    shown0 = _glb_vertices(glb0)
    np.testing.assert_allclose(np.sort(shown0, axis=0), np.sort(view.surface_vertices, axis=0), rtol=0, atol=1e-6)
    cable0 = np.array(view.cables[0].points)
    iterations_cold = view.result.report.iterations

    view.sliders[0].value = 0.7  # as a browser drag would: the callback re-solves
    assert view.move_steps == 1 and view.solves == 2  # standard formulation: one step
    assert view.result.actuations == [pytest.approx(0.7)]
    assert view.result.report.converged
    shown1 = _glb_vertices(view.surface.glb_data)
    assert shown1.shape == shown0.shape
    assert np.abs(shown1 - shown0).max() > 1e-3  # the deformed surface sent to the client moved
    assert np.abs(np.array(view.cables[0].points) - cable0).max() > 1e-3
    # Warm start: a small change of alpha needs fewer Newton iterations than the cold solve.
    assert view.result.report.iterations < iterations_cold

    # Same as a direct warm-started solve at that actuation.
    body = rebuild_body(view.body, "standard")
    reference = sf.solve_static(body, scene.gravity, options=scene.solve_options)
    np.testing.assert_allclose(view.result.positions, reference.positions, atol=1e-7)


def test_formulation_dropdown_rebuilds_the_body(server) -> None:
    scene = sf.Scene.load(SCENES / "cable_cantilever.toml")
    view = build_view(scene, server)
    view.sliders[0].value = 0.75
    view.formulation.value = "mixed"
    assert view.body.formulation == "mixed" and view.result.pressure is not None
    assert view.body.actuations == [pytest.approx(0.75)]
    assert np.array_equal(view.body.fixed_nodes, scene.body.fixed_nodes)
    assert "mixed" in view.status.content


def test_scene_without_cables(server) -> None:
    view = build_view(sf.Scene.load(SCENES / "cantilever.toml"), server)
    assert view.sliders == [] and view.cables == []
    assert view.result.max_displacement > 0


def test_colour_map() -> None:
    colours = colour_by_magnitude(np.array([0.0, 0.5, 1.0]))
    assert colours.shape == (3, 4) and colours.dtype == np.uint8
    assert not np.array_equal(colours[0], colours[2])
    assert np.array_equal(colour_by_magnitude(np.zeros(2))[0], colour_by_magnitude(np.zeros(2))[1])


def _glb_colours(glb: bytes) -> np.ndarray:
    loaded = trimesh.load(io.BytesIO(glb), file_type="glb", process=False)
    geometry = loaded.geometry if hasattr(loaded, "geometry") else {"mesh": loaded}
    return np.concatenate([g.visual.vertex_colors for g in geometry.values()])


def test_colour_by_dropdown_shows_stress_and_pressure(server) -> None:
    scene = sf.Scene.load(SCENES / "cable_cantilever.toml")
    view = build_view(scene, server)
    by_displacement = _glb_colours(view.surface.glb_data)
    view.colour_dropdown.value = "von_mises"  # as a browser selection would
    assert view.colour_by == "von_mises" and "von Mises stress [kPa]" in view.colour_bar.content
    assert not np.array_equal(_glb_colours(view.surface.glb_data), by_displacement)
    solves = view.solves
    view.colour_dropdown.value = "pressure"  # standard formulation: refused, colouring kept
    assert view.colour_by == "von_mises" and "mixed" in view.status.content and view.solves == solves
    view.formulation.value = "mixed"
    view.colour_dropdown.value = "pressure"
    assert view.colour_by == "pressure" and "pressure p [kPa]" in view.colour_bar.content
    view.formulation.value = "standard"  # no pressure any more: back to displacement
    assert view.colour_by == "displacement" and view.colour_dropdown.value == "displacement"


def test_nodal_fields_of_a_homogeneous_stretch() -> None:
    """Element fields averaged to the nodes: a homogeneous state gives every node its value."""
    mesh = sf.Mesh.box(size=(0.1, 0.05, 0.05), cells=(4, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=1e5, poisson_ratio=0.3), formulation="mixed")
    stretch = 0.02 * mesh.points[:, 0:1] * np.array([[1.0, 0.0, 0.0]])
    boundary = np.unique(mesh.boundary_faces())
    body.fix(boundary, stretch[boundary])
    result = sf.solve_static(body)
    for name in ("von_mises", "J"):
        values, _ = nodal_field(result, name)
        element = result.von_mises if name == "von_mises" else result.J
        np.testing.assert_allclose(values, element.mean(), rtol=1e-6)
    pressure, label = nodal_field(result, "pressure")
    np.testing.assert_allclose(pressure, result.pressure) and label.startswith("pressure")
    colours, scale = colour_field(np.array([0.9, 1.0, 1.1]), "J")  # diverging, centred on 1
    assert np.array_equal(colours[1], colour_field(np.array([1.0]), "J")[0][0]) and scale.startswith("0.9")
    with pytest.raises(sf.InputError, match="colour field"):
        nodal_field(result, "temperature")


def test_wireframe_keeps_the_field_colours_and_the_colour_bar_has_units(server) -> None:
    view = build_view(sf.Scene.load(SCENES / "cable_cantilever.toml"), server)
    u = nodal_field(view.result, "displacement")[0][view.surface_nodes]
    assert "|u| [mm]" in view.colour_bar.content and f"{u.max() * 1e3:.3g}" in view.colour_bar.content
    edges = view.surface_edges
    assert edges.shape == (3 * len(view.surface_faces) // 2, 2)  # a closed surface: each edge in two triangles
    view.wireframe_checkbox.value = True  # as a click would
    assert view.wireframe.visible and not view.surface.visible
    for field_name, title in (("displacement", "|u| [mm]"), ("von_mises", "von Mises stress [kPa]")):
        view.colour_dropdown.value = field_name
        assert title in view.colour_bar.content
        surface_colours = _glb_colours(view.surface.glb_data)[:, :3]
        assert len(np.unique(surface_colours, axis=0)) > 10  # a field, not one colour
        np.testing.assert_array_equal(view.wireframe.colors, surface_colours[edges])
        np.testing.assert_allclose(view.wireframe.points, view.surface_vertices[edges], atol=1e-6)
    view.sliders[0].value = 0.75  # the wireframe follows the solves
    np.testing.assert_allclose(view.wireframe.points, view.surface_vertices[edges], atol=1e-6)
    view.formulation.value = "mixed"
    view.colour_dropdown.value = "J"
    low, high = colour_range(nodal_field(view.result, "J")[0][view.surface_nodes], "J")
    assert "J = det F" in view.colour_bar.content and low < 1 < high and high - 1 == pytest.approx(1 - low)


def test_mixed_slider_moves_by_continuation(server) -> None:
    """Issue 19: mixed-formulation slider moves were slow (alpha 0.3 -> 0.7 in one jump). The
    view now continues from the equilibrium shown in steps of DEFAULT_ALPHA_STEP; it reaches
    the same equilibrium as a solve from rest, in fewer Newton iterations than one jump."""
    scene = sf.Scene.load(SCENES / "cable_cantilever.toml")
    view = build_view(scene, server)
    view.formulation.value = "mixed"
    view.sliders[0].value = 0.3
    assert view.body.actuations == [pytest.approx(0.3)] and view.move_steps >= 10  # 0.8 -> 0.3
    view.sliders[0].value = 0.7
    assert view.move_steps >= 8 and view.result.actuations == [pytest.approx(0.7)]
    assert f"{view.move_iterations} Newton iterations" in view.status.content
    reference = sf.solve_static(rebuild_body(view.body, "mixed"), scene.gravity, options=scene.solve_options)
    np.testing.assert_allclose(view.result.positions, reference.positions, atol=1e-7)

    # One jump from the same state, on a body of its own (the compiled model keeps the last
    # pressure as the next warm start: a model shared with the view would start from 0.7's).
    other = sf.Scene.load(SCENES / "cable_cantilever.toml")
    body = other.body.replace(formulation="mixed")
    start = sf.actuate(body, 0, 0.3, scene.gravity, tolerance=scene.solve_options.tolerance,
                       max_iterations=scene.solve_options.max_iterations)[-1]
    body.set_actuation(0, 0.7)
    jump = sf.solve_static(body, scene.gravity, initial=start, options=scene.solve_options).report.iterations
    assert view.move_iterations < jump


def test_a_drag_redirects_the_move_under_way(server) -> None:
    """Slider positions that arrive while a move runs (a drag) redirect it: the last one wins."""
    view = build_view(sf.Scene.load(SCENES / "cable_cantilever.toml"), server)
    moving = threading.Thread(target=view.set_actuation, args=(0, 0.3))
    moving.start()
    assert _wait(lambda: view.solves > 1)  # the first step is shown
    view.set_actuation(0, 0.75)  # returns at once if the move is still under way
    moving.join()
    assert view.body.actuations == [pytest.approx(0.75)] and view.result.actuations == [pytest.approx(0.75)]
    assert not view._moving and view._targets == {}


def test_a_node_pulled_with_a_spring(server) -> None:
    """Shift + drag: the grabbed node carries the spring force k (anchor - x) at equilibrium."""
    scene = sf.Scene.load(SCENES / "cable_cantilever.toml")
    view = build_view(scene, server)
    before = view.result.positions.copy()
    tip = int(np.argmax(before[:, 0] + before[:, 2]))  # the free end's upper edge
    assert view.grab(before[tip] + 1e-4) == tip and view.dragged == tip
    # Reciprocity (Maxwell-Betti): the measured compliance is symmetric and positive definite.
    compliance = view._compliance
    np.testing.assert_allclose(compliance, compliance.T, atol=2e-3 * np.abs(compliance).max())
    assert np.all(np.linalg.eigvalsh(0.5 * (compliance + compliance.T)) > 0)
    anchor = before[tip] + np.array([-0.05, 0.0, 0.15])
    view.drag_to(anchor)
    x = view.result.positions[tip]
    k = view.drag_stiffness
    np.testing.assert_allclose(view.drag_force, k * (anchor - x), rtol=1e-5, atol=1e-9 * k)
    assert x[2] > before[tip][2] + 0.02 and np.linalg.norm(view.drag_force) > 1.0  # lifted, by a real force
    assert f"pulling node {tip}" in view.status.content and view.drag_line.visible
    # The equilibrium of the body with that force, solved independently.
    reference = sf.solve_static(rebuild_body(view.body, "standard"), scene.gravity, options=scene.solve_options)
    np.testing.assert_allclose(view.result.positions, reference.positions, atol=1e-7)
    view.release()
    assert view.dragged is None and not view.drag_line.visible
    np.testing.assert_allclose(view.body.forces, 0.0, atol=1e-12)
    np.testing.assert_allclose(view.result.positions, before, atol=1e-7)


# ---------------------------------------------------------------------------
# Playback of a trajectory


def _pulled_cantilever(steps: int = 30, save_every: int = 3) -> sf.Trajectory:
    """The cable cantilever pulled to alpha = 0.8 over 0.3 s: 11 frames, 0 .. 0.6 s."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    body.add_cable(sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5))
    return sf.simulate(body, 0.02, steps, actuation=Keyframes([[0, 1], [0.3, 0.8]]), gravity=(0, 0, -9.81),
                       damping=(5.0, 0.01), save_every=save_every, progress=False)


def _wait(condition, timeout: float = 10.0) -> bool:
    deadline = time.time() + timeout
    while not condition():
        if time.time() > deadline:
            return False
        time.sleep(0.01)
    return True


def _segments(points: np.ndarray) -> np.ndarray:
    return np.stack([points[:-1], points[1:]], axis=1)


@pytest.fixture()
def trajectory() -> sf.Trajectory:
    return _pulled_cantilever()


def test_frame_slider_moves_the_vertices_of_the_one_surface(server, trajectory, monkeypatch) -> None:
    view = build_trajectory_view(trajectory, server)
    try:
        surface = view.surface
        nodes = view.surface_nodes
        assert view.frames.n_frames == 11 and view.slider.max == 10 and view.frame == 0
        np.testing.assert_allclose(_glb_vertices(surface.glb_data), trajectory.positions[0][nodes], atol=1e-6)
        # Frames must move the existing handles, never add scene nodes.
        for add in ("add_mesh_simple", "add_glb", "add_point_cloud", "add_line_segments"):
            monkeypatch.setattr(server.scene, add, lambda *a, **k: pytest.fail("a frame re-created a scene node"))
        for k in (4, 10, 1):
            view.slider.value = k  # as a browser drag would
            assert view.frame == k and view.time == pytest.approx(trajectory.times[k])
            assert view.surface is surface
            np.testing.assert_allclose(_glb_vertices(surface.glb_data), trajectory.positions[k][nodes], atol=1e-6)
            np.testing.assert_allclose(view.cables[0].points, _segments(trajectory.cable_points[k][0]), atol=1e-6)
            assert f"t = {trajectory.times[k]:.4g} s" in view.status.content
        # The surface is coloured (not only its nodes): one scale over the whole motion, shown
        # by the colour bar in mm.
        u = np.linalg.norm(trajectory.displacement[:, nodes], axis=2)
        assert view.vmax == pytest.approx(u.max())
        np.testing.assert_array_equal(_glb_colours(surface.glb_data), colour_by_magnitude(u[1], u.max()))
        assert "|u| [mm]" in view.colour_bar.content and f"{u.max() * 1e3:.3g}" in view.colour_bar.content
        assert "alpha 0.9" in view.status.content and "tension" in view.status.content  # frame 1: t = 0.06 s
        # The wireframe keeps the colours: each edge's ends coloured as their nodes.
        view.wireframe_checkbox.value = True
        assert view.wireframe.visible and not view.surface.visible
        edges = view.surface_edges
        np.testing.assert_allclose(view.wireframe.points, trajectory.positions[1][nodes][edges], atol=1e-6)
        np.testing.assert_array_equal(view.wireframe.colors, colour_by_magnitude(u[1], u.max())[:, :3][edges])
        view.slider.value = 4
        np.testing.assert_allclose(view.wireframe.points, trajectory.positions[4][nodes][edges], atol=1e-6)
        view.wireframe_checkbox.value = False
        np.testing.assert_allclose(_glb_vertices(surface.glb_data), trajectory.positions[4][nodes], atol=1e-6)
    finally:
        view.close()


def test_play_pause_speed_and_loop(server, trajectory) -> None:
    view = build_trajectory_view(trajectory, server, loop=False)
    try:
        last = view.frames.n_frames - 1
        assert view.play_button.label == "play" and not view.playing
        view.speed_dropdown.value = "2x"  # the 0.6 s motion in 0.3 s: about 10 ticks at 30 fps
        assert view.speed == 2.0
        view.play_button.value = True  # a click
        assert view.playing and view.play_button.label == "pause"
        assert _wait(lambda: not view.playing), "the playback did not stop at the end"
        assert view.frame == last and view.slider.value == last and view.play_button.label == "play"
        np.testing.assert_allclose(_glb_vertices(view.surface.glb_data), trajectory.positions[last][view.surface_nodes],
                                   atol=1e-6)
        assert view.frames_shown > 3  # intermediate frames were shown on the way

        # From the last frame, play starts again at the beginning; looping keeps it going.
        view.loop_checkbox.value = True
        view.set_speed(0.1)  # slow: frame 1 (t = 0.06 s) after 0.6 s
        view.play()
        assert view.frame == 0 and view.playing
        view.slider.value = 8  # jump while playing: the clock follows the slider
        assert _wait(lambda: view.frame >= 9 or view.frame < 8, 5.0)
        view.pause()
        frame = view.frame
        time.sleep(0.2)
        assert view.frame == frame and not view.playing
        view.set_speed(5.0)  # a 0.66 s cycle (the last frame held one frame spacing) in 0.13 s
        shown = view.frames_shown
        seen: list[int] = []
        view.play()
        assert _wait(lambda: seen.append(view.frame) or view.frames_shown > shown + 2 * last, 10.0), "no loop"
        assert sum(b < a for a, b in zip(seen, seen[1:])) >= 2  # went back to the start at least twice
        assert view.playing  # looped instead of stopping
        view.pause()
        with pytest.raises(sf.InputError, match="speed"):
            view.set_speed(0)
    finally:
        view.close()
    assert view._thread is None


def test_playback_of_a_written_pvd(server, trajectory, tmp_path) -> None:
    trajectory.write_pvd(tmp_path / "run")
    for source in (tmp_path / "run", tmp_path / "run" / "trajectory.pvd"):
        frames = load_frames(source)
        np.testing.assert_allclose(frames.times, trajectory.times)
        np.testing.assert_allclose(frames.positions, trajectory.positions, atol=1e-12)
        np.testing.assert_allclose(frames.mesh.points, trajectory.mesh.points, atol=1e-12)
        assert frames.n_cables == 1 and frames.kinetic_energy is None
    view = build_trajectory_view(tmp_path / "run", server, speed=3.0)
    try:
        assert "3x" in view.speed_dropdown.options and view.speed == 3.0
        view.slider.value = 7
        np.testing.assert_allclose(_glb_vertices(view.surface.glb_data), trajectory.positions[7][view.surface_nodes],
                                   atol=1e-6)
        np.testing.assert_allclose(view.cables[0].points, _segments(trajectory.cable_points[7][0]), atol=1e-6)
    finally:
        view.close()


def test_nothing_to_play(tmp_path) -> None:
    with pytest.raises(sf.InputError, match="no such file"):
        load_frames(tmp_path / "missing")
    with pytest.raises(sf.InputError, match="trajectory.pvd"):
        load_frames(tmp_path)
    (tmp_path / "scene.toml").write_text("", encoding="utf-8")
    with pytest.raises(sf.InputError, match=r"\.pvd"):
        load_frames(tmp_path / "scene.toml")
    (tmp_path / "broken.pvd").write_text("<VTKFile><Collection></Collection></VTKFile>", encoding="utf-8")
    with pytest.raises(sf.InputError, match="no <DataSet>"):
        load_frames(tmp_path / "broken.pvd")


def test_single_frame_trajectory_does_not_play(server) -> None:
    traj = _pulled_cantilever(steps=1, save_every=5)
    assert traj.n_frames == 2
    single = load_frames(traj)
    single.times, single.positions, single.cable_points = single.times[:1], single.positions[:1], single.cable_points[:1]
    view = build_trajectory_view(single, server)
    view.play()
    assert not view.playing and view.slider.disabled
    view.slider.value = 1  # clamped
    assert view.frame == 0


def test_cli_plays_a_run_folder_and_a_dynamic_scene(tmp_path, trajectory, monkeypatch, capsys) -> None:
    """``sorofem view`` (viewer.serve) with the serving loop replaced by two tabs that connect,
    then an immediate stop."""
    import sorofem.viewer as viewer

    served = []

    def serve_once(server, on_stop):
        tabs = on_stop.__self__  # PerClient.close: one view per tab
        with _tabs(server, 2):
            first, second = tabs.wait_for(2)
            assert first is not second and first.server is not second.server
            served.append(type(first).__name__)
        on_stop()
        server.stop()

    monkeypatch.setattr(viewer.serving, "wait_until_interrupted", serve_once)
    trajectory.write_pvd(tmp_path / "run")
    assert viewer.serve(tmp_path / "run", port=_free_port()) == 0
    assert "(11 frames)" in capsys.readouterr().out
    dynamic = tmp_path / "pull.toml"
    dynamic.write_text((SCENES / "cable_cantilever.toml").read_text(encoding="utf-8")
                       + "\n[dynamics]\ndt = 0.02\nsteps = 6\nsave_every = 2\nmass_damping = 5.0\n", encoding="utf-8")
    assert viewer.serve(dynamic, port=_free_port(), trajectory=True) == 0
    assert "(4 frames)" in capsys.readouterr().out
    assert viewer.serve(dynamic, port=_free_port()) == 0  # without --trajectory: the static view
    assert "frames" not in capsys.readouterr().out
    with pytest.raises(sf.InputError, match=r"\[dynamics\]"):
        viewer.serve(SCENES / "cantilever.toml", port=_free_port(), trajectory=True)
    assert served == ["TrajectoryView", "TrajectoryView", "View"]


# ---------------------------------------------------------------------------
# The scene view's "simulate [dynamics]" button: the motion played in the same page

PULL = "\n[dynamics]\ndt = 0.02\nsteps = 6\nsave_every = 2\nmass_damping = 5.0\n"
#: A motion long enough to be cancelled (a minute or more of steps).
LONG_PULL = "\n[dynamics]\ndt = 0.02\nsteps = 200000\nsave_every = 1000\nmass_damping = 5.0\n"


def _dynamic_scene(tmp_path: Path, extra: str = PULL) -> Path:
    path = tmp_path / "pull.toml"
    path.write_text((SCENES / "cable_cantilever.toml").read_text(encoding="utf-8") + extra, encoding="utf-8")
    return path


def test_simulate_button_plays_the_dynamics_in_the_page(server, tmp_path) -> None:
    path = _dynamic_scene(tmp_path)
    view = build_view(sf.Scene.load(path), server)
    assert view.simulate_button.label == "simulate [dynamics]" and not view.simulate_button.disabled
    assert "6 steps of 0.02 s" in view.simulate_button.hint
    view.sliders[0].value = 0.75  # the motion holds the actuation set in the page
    view.simulate_button.value = True  # a click: simulates, then plays
    motion = view.motion
    try:
        assert motion is not None and view.simulations == 1 and motion.playing
        motion.pause()
        assert _wait(lambda: motion._thread is None)
        # The static view is hidden, the playback shows the simulated frames.
        assert not view.surface.visible and not view.sliders[0].visible and not view.simulate_button.visible
        reference = sf.Scene.load(path)
        reference.body.set_actuation(0, 0.75)
        expected = reference.simulate(progress=False)
        assert motion.frames.n_frames == expected.n_frames == 4
        np.testing.assert_allclose(motion.frames.positions, expected.positions, rtol=0, atol=1e-10)
        for k in (3, 1):
            motion.slider.value = k  # as a browser drag would
            np.testing.assert_allclose(_glb_vertices(motion.surface.glb_data),
                                       motion.frames.positions[k][motion.surface_nodes], atol=1e-6)
            np.testing.assert_allclose(motion.cables[0].points, _segments(expected.cable_points[k][0]), atol=1e-6)
        assert "alpha 0.750" in motion.status.content
        # Back to static: the playback and its controls are gone, the static view is back as it was.
        view.back_button.value = True
        assert view.motion is None and view.back_button is None and motion._closed
        assert all(h._impl.removed for h in (motion.surface, motion.slider, motion.play_button, motion.header))
        assert view.surface.visible and not view.wireframe.visible and view.sliders[0].visible
        assert view.sliders[0].value == pytest.approx(0.75) and "alpha 0.750" in view.status.content
        # A second run after a formulation switch simulates the mixed body.
        view.formulation.value = "mixed"
        second = view.simulate(play=False)
        assert second is view.motion and view.simulations == 2 and not second.playing
        assert second.frames.trajectory.body.formulation == "mixed"
        view.show_static()
    finally:
        if view.motion is not None:
            view.motion.close()


def test_simulate_button_without_dynamics(server) -> None:
    view = build_view(sf.Scene.load(SCENES / "cable_cantilever.toml"), server)
    assert view.simulate_button.disabled and "no [dynamics] table" in view.simulate_button.hint
    with pytest.raises(sf.InputError, match=r"\[dynamics\]"):
        view.simulate()
    assert view.motion is None


def test_failed_simulation_keeps_the_static_view(server, tmp_path, monkeypatch) -> None:
    view = build_view(sf.Scene.load(_dynamic_scene(tmp_path)), server)

    def fail(*_, **__):
        raise sf.ConvergenceError("time step 3 did not converge")

    monkeypatch.setattr(playback, "simulate", fail)  # what simulate_in_chunks calls
    view.simulate_button.value = True
    assert view.motion is None and view.simulations == 0
    assert "simulation failed" in view.status.content and "steps 1 .. 2" in view.status.content
    assert "time step 3 did not converge" in view.status.content
    assert view.surface.visible and not view.simulate_button.disabled and not view.sliders[0].disabled
    assert view.simulate_button.label == "simulate [dynamics]"


def test_simulation_in_pieces_matches_one_run(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(playback, "CHUNK_SECONDS", 0.0)  # one save interval per piece
    scene = sf.Scene.load(_dynamic_scene(tmp_path, PULL.replace("steps = 6", "steps = 7")))  # 7: a short last piece
    seen: list[tuple[int, int, float]] = []
    pieces = simulate_in_chunks(scene, scene.body, on_progress=lambda *state: seen.append(state))
    whole = scene.simulate(progress=False)
    assert [done for done, _, _ in seen] == [2, 4, 6, 7] and seen[-1][1:] == (7, pytest.approx(0.14))
    np.testing.assert_allclose(pieces.times, whole.times, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pieces.positions, whole.positions, rtol=0, atol=1e-10)
    np.testing.assert_allclose(pieces.kinetic_energy, whole.kinetic_energy, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(pieces.velocities, whole.velocities, rtol=0, atol=1e-8)
    assert np.array_equal(pieces.iterations, whole.iterations) and np.array_equal(pieces.actuation, whole.actuation)
    for mine, theirs in zip(pieces.cable_points, whole.cable_points, strict=True):
        np.testing.assert_allclose(mine[0], theirs[0], rtol=0, atol=1e-10)
    cancel = threading.Event()
    cancel.set()
    assert simulate_in_chunks(scene, scene.body, cancel=cancel) is None


def test_simulate_shows_progress_and_can_be_cancelled(server, tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(playback, "CHUNK_SECONDS", 0.0)
    view = build_view(sf.Scene.load(_dynamic_scene(tmp_path, LONG_PULL)), server)
    assert not view.progress_bar.visible and not view.cancel_button.visible
    running = threading.Thread(target=view.simulate)
    running.start()
    try:
        assert _wait(lambda: view.progress_bar.visible and view.progress_bar.value > 0, 20.0), "no progress shown"
        assert view.cancel_button.visible and view.simulate_button.disabled and view.sliders[0].disabled
        assert re.search(r"step \d+ of 200000, t = ", view.status.content)
        view.cancel_button.value = True  # a click
    finally:
        view.cancel()
        running.join(60.0)
    assert view.motion is None and view.simulations == 0
    assert re.search(r"cancelled.*after \d+ of 200000 steps", view.status.content)
    assert not view.progress_bar.visible and not view.cancel_button.visible
    assert not view.simulate_button.disabled and not view.sliders[0].disabled and view.surface.visible


# ---------------------------------------------------------------------------
# One view per browser tab. A tab is stood in for by a websocket speaking viser's protocol
# (what the page's script opens); the real-browser test below opens two pages.


@contextlib.contextmanager
def _tabs(server, count: int):
    """``count`` connected tabs: viser counts a client once it has sent its camera. The camera
    message is written as the page's script sends it (msgpack on the websocket), not built
    from viser's private message classes."""
    import msgspec
    from websockets.sync.client import connect

    camera = {"type": "ViewerCameraMessage", "wxyz": (1.0, 0.0, 0.0, 0.0), "position": (0.0, -1.0, 0.5),
              "fov": 1.0, "near": 0.01, "far": 100.0, "image_height": 480, "image_width": 640,
              "look_at": (0.0, 0.0, 0.0), "up_direction": (0.0, 0.0, 1.0)}
    sockets = []
    for _ in range(count):
        sockets.append(connect(f"ws://127.0.0.1:{server.get_port()}", subprotocols=[f"viser-v{viser.__version__}"],
                               max_size=None, max_queue=None))
        sockets[-1].send(msgspec.msgpack.encode(camera))
    try:
        yield
    finally:
        for socket_ in sockets:
            socket_.close()


def test_each_tab_has_its_own_view(server, tmp_path) -> None:
    scene = sf.Scene.load(_dynamic_scene(tmp_path))
    equilibrium = scene.solve()
    tabs = per_client(server, lambda client: build_view(scene, client, body=scene.body.replace(),
                                                        equilibrium=equilibrium))
    try:
        with _tabs(server, 2):
            first, second = tabs.wait_for(2)
            assert first.server is not server and first.server.client_id != second.server.client_id
            first.sliders[0].value = 0.7
            first.wireframe_checkbox.value = True
            first.formulation.value = "mixed"
            assert first.body.actuations == [pytest.approx(0.7)] and first.wireframe.visible
            # The other tab, and the scene, are as they were.
            assert second.sliders[0].value == pytest.approx(0.8) and second.body.actuations == [pytest.approx(0.8)]
            assert not second.wireframe_checkbox.value and not second.wireframe.visible and second.surface.visible
            assert second.formulation.value == "standard" and second.result is equilibrium
            assert scene.body.actuations == [pytest.approx(0.8)] and scene.body.formulation == "standard"
            np.testing.assert_allclose(_glb_vertices(second.surface.glb_data),
                                       equilibrium.positions[second.surface_nodes], atol=1e-6)
            # Both tabs solving at once (their bodies share a compiled model): each gets its own answer.
            movers = [threading.Thread(target=tab.set_actuation, args=(0, alpha))
                      for tab, alpha in ((first, 0.5), (second, 0.6))]
            for mover in movers:
                mover.start()
            for mover in movers:
                mover.join()
            for tab, alpha in ((first, 0.5), (second, 0.6)):
                assert tab.result.actuations == [pytest.approx(alpha)] and tab.result.report.converged
                body = rebuild_body(tab.body, tab.body.formulation)
                reference = sf.solve_static(body, scene.gravity, options=scene.solve_options)
                np.testing.assert_allclose(tab.result.positions, reference.positions, atol=1e-7)
            # A tab's simulation plays in that tab only.
            motion = first.simulate(play=False)
            assert motion is not None and motion.server is first.server and second.motion is None
            assert not first.sliders[0].visible and second.sliders[0].visible and second.surface.visible
        assert _wait(lambda: not tabs.views), "closed tabs were not forgotten"
    finally:
        tabs.close()


def test_tabs_of_sorofem_view_warm_start_from_their_own_solves_only(tmp_path, monkeypatch) -> None:
    """The tabs of ``sorofem view`` shared one compiled model, which keeps the last solve's tendon
    tensions (and pressures, barrier stiffness) as the next warm start: a tab's solve started
    from another tab's. Each tab now has a model of its own: a move in one tab gives, bit for
    bit, what the same move gives on a body nobody else touched."""
    import copy

    import sorofem.viewer as viewer

    path = tmp_path / "tendon.toml"
    path.write_text((SCENES / "cable_cantilever.toml").read_text(encoding="utf-8").replace(
        "stiffness = 1e5", 'model = "tendon"\npull = 0.01').replace("actuation = 0.8\n", ""), encoding="utf-8")
    scene = sf.Scene.load(path)
    assert scene.body.commands == [("pull", 0.01)]
    checked = []

    def serve_once(server, on_stop):
        tabs = on_stop.__self__
        with _tabs(server, 2):
            first, second = tabs.wait_for(2)
            assert first.body.core_model() is not second.body.core_model()
            first.sliders[0].value = 60.0  # mm: a hard pull in the first tab
            second.sliders[0].value = 40.0  # taut (the first 20 mm or so take up the sag)
            # The same move on a copy of the scene's body with a model of its own.
            alone = copy.deepcopy(scene.body)
            start = scene.solve(body=copy.deepcopy(scene.body))
            (reference,) = sf.actuate(alone, 0, [0.04], scene.gravity, initial=start,
                                      tolerance=scene.solve_options.tolerance,
                                      max_iterations=scene.solve_options.max_iterations)
            assert second.result.report.iterations == reference.report.iterations
            assert np.array_equal(second.result.positions, reference.positions)
            assert 0 < second.result.cable_tension[0] == reference.cable_tension[0] < first.result.cable_tension[0]
            checked.append(True)
        on_stop()
        server.stop()

    monkeypatch.setattr(viewer.serving, "wait_until_interrupted", serve_once)
    assert viewer.serve(path, port=_free_port()) == 0
    assert checked == [True]


# ---------------------------------------------------------------------------
# A real browser: headless Chromium (Debian package) driven by Playwright's Python package.

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

browser_test = pytest.mark.skipif(
    os.environ.get("SOROFEM_BROWSER_TEST") != "1" or CHROMIUM is None,
    reason="real-browser test (~7 s): run by `make test-viewer` (SOROFEM_BROWSER_TEST=1), needs Debian's chromium",
)


@contextlib.contextmanager
def _browser_pages(server, ready_text: str, count: int = 1):
    """``count`` headless Chromium pages (tabs) on ``server``'s view, opened one after the other,
    each once ``ready_text`` shows and it is connected; yields ``(pages, errors)`` with the pages'
    JavaScript errors."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright Python package not installed")
    errors: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                    args=["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"])
        try:
            pages = []
            for k in range(count):
                page = browser.new_page()
                page.on("pageerror", lambda exc: errors.append(str(exc)))
                page.goto(f"http://127.0.0.1:{server.get_port()}")
                page.wait_for_selector("canvas", timeout=30_000)
                page.get_by_text(ready_text).first.wait_for(timeout=30_000)
                assert _wait(lambda: len(server.get_clients()) > k, 10.0), "the browser did not connect"
                pages.append(page)
            yield pages, errors
        finally:
            browser.close()


@contextlib.contextmanager
def _browser_page(server, ready_text: str):
    """One page of :func:`_browser_pages`: yields ``(page, errors)``."""
    with _browser_pages(server, ready_text) as (pages, errors):
        yield pages[0], errors


@browser_test
def test_browser_loads_the_view(server) -> None:
    view = build_view(sf.Scene.load(SCENES / "cable_cantilever.toml"), server)
    with _browser_page(server, "cable 0 alpha") as (page, errors):
        # A change made on the server reaches the connected client without errors.
        view.sliders[0].value = 0.7
        page.wait_for_timeout(500)
        assert view.solves == 2
    assert not errors, errors


@browser_test
def test_browser_plays_a_trajectory(server, trajectory) -> None:
    view = build_trajectory_view(trajectory, server, speed=0.5)
    try:
        with _browser_page(server, "speed (x real time)") as (page, errors):
            # The play button in the page starts the playback on the server.
            page.get_by_role("button", name="play").first.click()
            assert _wait(lambda: view.playing, 10.0), "clicking play in the browser did nothing"
            assert _wait(lambda: view.frame >= 2, 10.0)
            page.get_by_role("button", name="pause").first.click()
            assert _wait(lambda: not view.playing, 10.0)
            page.wait_for_timeout(300)
    finally:
        view.close()
    assert not errors, errors


@browser_test
def test_browser_simulates_and_plays_a_scene(server, tmp_path) -> None:
    view = build_view(sf.Scene.load(_dynamic_scene(tmp_path)), server)
    try:
        with _browser_page(server, "simulate [dynamics]") as (page, errors):
            page.get_by_role("button", name="simulate [dynamics]").first.click()
            assert _wait(lambda: view.motion is not None, 20.0), "clicking simulate in the browser did nothing"
            motion = view.motion
            page.get_by_text("speed (x real time)").first.wait_for(timeout=30_000)  # the playback controls
            page.get_by_text("cable 0 alpha").first.wait_for(state="hidden", timeout=10_000)  # static ones hidden
            assert _wait(lambda: motion.frames_shown > 1, 10.0)  # it plays
            page.get_by_role("button", name="back to static").first.click()
            assert _wait(lambda: view.motion is None, 10.0), "clicking back to static did nothing"
            page.get_by_text("cable 0 alpha").first.wait_for(state="visible", timeout=10_000)
            page.wait_for_timeout(300)
    finally:
        if view.motion is not None:
            view.motion.close()
    assert not errors, errors


@browser_test
def test_browser_tabs_have_their_own_controls(server) -> None:
    scene = sf.Scene.load(SCENES / "cable_cantilever.toml")
    equilibrium = scene.solve()
    tabs = per_client(server, lambda client: build_view(scene, client, body=scene.body.replace(),
                                                        equilibrium=equilibrium))
    try:
        with _browser_pages(server, "cable 0 alpha", count=2) as (pages, errors):
            first, second = tabs.wait_for(2)  # in the order the pages connected
            assert "|u| [mm]" in pages[0].content()  # the colour bar
            # Each tab's camera looks at the body (the page reports its camera back).
            lo, hi = scene.body.mesh.bounds
            centre, size = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
            for tab in (first, second):
                assert _wait(lambda tab=tab: np.linalg.norm(tab.server.camera.look_at - centre) < 1e-3 * size, 10.0), \
                    f"the camera looks at {tab.server.camera.look_at}, not at the body's centre {centre}"
            pages[0].get_by_text("wireframe (see the cables)").first.click()
            assert _wait(lambda: first.wireframe.visible, 10.0), "the click did not reach the first tab's view"
            first.sliders[0].value = 0.7
            pages[1].wait_for_timeout(500)
            assert not second.wireframe_checkbox.value and second.sliders[0].value == pytest.approx(0.8)
            assert not pages[1].get_by_role("checkbox", name="wireframe (see the cables)").is_checked()
            assert pages[0].get_by_role("checkbox", name="wireframe (see the cables)").is_checked()
    finally:
        tabs.close()
    assert not errors, errors


@browser_test
def test_browser_cancels_a_simulation(server, tmp_path) -> None:
    view = build_view(sf.Scene.load(_dynamic_scene(tmp_path, LONG_PULL)), server)
    try:
        with _browser_page(server, "simulate [dynamics]") as (page, errors):
            page.get_by_role("button", name="simulate [dynamics]").first.click()
            page.get_by_role("button", name="cancel").first.wait_for(state="visible", timeout=20_000)
            assert _wait(lambda: view.progress_bar.value > 0, 20.0)
            page.get_by_text("of 200000").first.wait_for(timeout=10_000)  # the step count in the page
            page.get_by_role("button", name="cancel").first.click()
            page.get_by_text("cancelled").first.wait_for(timeout=30_000)
            assert view.motion is None and not view.simulate_button.disabled
    finally:
        view.close()
    assert not errors, errors


@browser_test
def test_browser_pulls_a_node_with_shift_drag(server) -> None:
    view = build_view(sf.Scene.load(SCENES / "cable_cantilever.toml"), server)
    before = view.result.positions.copy()
    pulled: list[float] = []
    with _browser_page(server, "cable 0 alpha") as (page, errors):
        page.wait_for_timeout(1000)  # the surface drawn
        box = page.locator("canvas").first.bounding_box()
        x, y = box["x"] + 0.485 * box["width"], box["y"] + 0.667 * box["height"]  # on the beam's middle
        page.keyboard.down("Shift")
        page.mouse.move(x, y)
        page.mouse.down()
        for k in range(1, 11):
            page.mouse.move(x, y - 8 * k)  # upwards
            page.wait_for_timeout(60)
        assert _wait(lambda: pulled.append(float(np.linalg.norm(view.drag_force))) or pulled[-1] > 1.0, 10.0), \
            "shift + drag did not pull the node"
        grabbed = view.dragged
        assert grabbed is not None and view.result.positions[grabbed][2] > before[grabbed][2] + 0.005
        page.mouse.up()
        page.keyboard.up("Shift")
        assert _wait(lambda: view.dragged is None, 10.0), "releasing the mouse did not let go"
        np.testing.assert_allclose(view.result.positions, before, atol=1e-7)
    assert not errors, errors


#: The cable cantilever with its cable a tendon along the top, pulled 10 mm, and a table below
#: the free end (which the pull lifts off it, or gravity lays on it).
TENDON_ON_TABLE = """\
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
pull = 0.0

[[obstacle]]
plane = { point = [0, 0, -0.03], normal = [0, 0, 1] }
"""


@browser_test
def test_browser_drives_a_tendon_slider_and_draws_the_obstacles(server, tmp_path) -> None:
    path = tmp_path / "tendon_on_table.toml"
    path.write_text(TENDON_ON_TABLE, encoding="utf-8")
    view = build_view(sf.Scene.load(path), server)
    assert view.result.obstacle_forces[0][2] > 0  # gravity lays the free end on the table
    with _browser_page(server, "cable 0 pull [mm]") as (page, errors):
        page.get_by_text("contact force arrows: 1 N =").first.wait_for(timeout=30_000)
        page.get_by_text("(tendon, pull 0 mm)").first.wait_for(timeout=30_000)
        # The slider in the page: three steps right pull the tendon 3 mm (its step is 1 mm over
        # 0 .. 100 mm, a quarter of its 0.38 m rounded up).
        assert view.slider_specs[0].step == 1.0 and view.slider_specs[0].max == 100.0
        slider = page.get_by_role("slider").first
        slider.focus()
        for _ in range(3):
            slider.press("ArrowRight")
        assert _wait(lambda: view.body.commands[0][1] == pytest.approx(3e-3), 20.0), view.body.commands
        assert _wait(lambda: view.result.cable_pull[0] == pytest.approx(3e-3, rel=1e-9), 20.0)
        page.get_by_text("(tendon, pull 3 mm): taut").first.wait_for(timeout=30_000)
        # The obstacle and the arrows are drawn: hiding them changes the picture.
        canvas = page.locator("canvas").first
        shots = [canvas.screenshot()]
        assert _wait(lambda: shots.append(canvas.screenshot()) or shots[-1] == shots[-2], 20.0), "no still picture"
        drawn = shots[-1]
        for handle in (*view.obstacles, view.arrows):
            handle.visible = False
        assert _wait(lambda: canvas.screenshot() != drawn, 20.0), "hiding the obstacle changed nothing on screen"
    assert not errors, errors

"""The browser viewer: `build_view` against a real viser server on a free loopback port.

Skipped when the optional extra (viser) is not installed. The real-browser test drives
Debian's `chromium` through Playwright's Python package (never `playwright install`); it runs
only with SOROFEM_BROWSER_TEST=1 (`make test-viewer` sets it) and skips when either is missing.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import socket
import time
from pathlib import Path

import numpy as np
import pytest

import sorofem as sf

viser = pytest.importorskip("viser", reason="the optional extra viewer (viser) is not installed: pip install \".[viewer]\"")
trimesh = pytest.importorskip("trimesh")

from sorofem.dynamics import Keyframes  # noqa: E402
from sorofem.viewer import (  # noqa: E402
    build_trajectory_view,
    build_view,
    colour_by_magnitude,
    colour_field,
    load_frames,
    nodal_field,
    rebuild_body,
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
    assert view.solves == 2
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
    reference = sf.solve_static(body, scene.gravity, **scene.solver)
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
    assert view.colour_by == "von_mises" and "von Mises" in view.status.content
    assert not np.array_equal(_glb_colours(view.surface.glb_data), by_displacement)
    solves = view.solves
    view.colour_dropdown.value = "pressure"  # standard formulation: refused, colouring kept
    assert view.colour_by == "von_mises" and "mixed" in view.status.content and view.solves == solves
    view.formulation.value = "mixed"
    view.colour_dropdown.value = "pressure"
    assert view.colour_by == "pressure" and "pressure" in view.status.content
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
        np.testing.assert_array_equal(surface.vertices, trajectory.positions[0][nodes].astype(np.float32))
        # Frames must move the existing handles, never add scene nodes.
        for add in ("add_mesh_simple", "add_glb", "add_point_cloud", "add_line_segments"):
            monkeypatch.setattr(server.scene, add, lambda *a, **k: pytest.fail("a frame re-created a scene node"))
        for k in (4, 10, 1):
            view.slider.value = k  # as a browser drag would
            assert view.frame == k and view.time == pytest.approx(trajectory.times[k])
            assert view.surface is surface
            np.testing.assert_array_equal(surface.vertices, trajectory.positions[k][nodes].astype(np.float32))
            np.testing.assert_array_equal(view.colours.points, trajectory.positions[k][nodes].astype(np.float32))
            np.testing.assert_allclose(view.cables[0].points, _segments(trajectory.cable_points[k][0]), atol=1e-6)
            assert f"t = {trajectory.times[k]:.4g} s" in view.status.content
        # Colours: one scale over the whole motion; the clamped end is the most displaced.
        u = np.linalg.norm(trajectory.displacement[:, nodes], axis=2)
        assert view.vmax == pytest.approx(u.max())
        np.testing.assert_array_equal(view.colours.colors, colour_by_magnitude(u[1], u.max())[:, :3])
        assert "alpha 0.9" in view.status.content and "tension" in view.status.content  # frame 1: t = 0.06 s
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
        np.testing.assert_array_equal(view.surface.vertices, trajectory.positions[last][view.surface_nodes].astype(np.float32))
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
        np.testing.assert_allclose(view.surface.vertices, trajectory.positions[7][view.surface_nodes], atol=1e-6)
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
    """``sorofem view`` (viewer.serve) with the serving loop replaced by an immediate stop."""
    import sorofem.viewer as viewer

    served = []

    def serve_once(server, on_stop=None):
        served.append(server)
        if on_stop is not None:
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
    assert len(served) == 3


# ---------------------------------------------------------------------------
# The scene view's "simulate [dynamics]" button: the motion played in the same page

PULL = "\n[dynamics]\ndt = 0.02\nsteps = 6\nsave_every = 2\nmass_damping = 5.0\n"


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
            np.testing.assert_array_equal(motion.surface.vertices,
                                          motion.frames.positions[k][motion.surface_nodes].astype(np.float32))
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

    def fail(**_):
        raise sf.ConvergenceError("step 3 did not converge")

    monkeypatch.setattr(view.scene, "simulate", fail)
    view.simulate_button.value = True
    assert view.motion is None and view.simulations == 0
    assert "simulation failed" in view.status.content and "step 3" in view.status.content
    assert view.surface.visible and not view.simulate_button.disabled and not view.sliders[0].disabled
    assert view.simulate_button.label == "simulate [dynamics]"


# ---------------------------------------------------------------------------
# A real browser: headless Chromium (Debian package) driven by Playwright's Python package.

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

browser_test = pytest.mark.skipif(
    os.environ.get("SOROFEM_BROWSER_TEST") != "1" or CHROMIUM is None,
    reason="real-browser test (~7 s): run by `make test-viewer` (SOROFEM_BROWSER_TEST=1), needs Debian's chromium",
)


@contextlib.contextmanager
def _browser_page(server, ready_text: str):
    """A headless Chromium page on ``server``'s view, once ``ready_text`` shows and the client is
    connected; yields ``(page, errors)`` with the page's JavaScript errors."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright Python package not installed")
    errors: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                    args=["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"])
        try:
            page = browser.new_page()
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(f"http://127.0.0.1:{server.get_port()}")
            page.wait_for_selector("canvas", timeout=30_000)
            page.get_by_text(ready_text).first.wait_for(timeout=30_000)
            assert _wait(lambda: bool(server.get_clients()), 10.0), "the browser did not connect"
            yield page, errors
        finally:
            browser.close()


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

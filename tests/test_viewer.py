"""The browser viewer: `build_view` against a real viser server on a free loopback port.

Skipped when the optional extra (viser) is not installed. The real-browser test drives
Debian's `chromium` through Playwright's Python package (never `playwright install`); it runs
only with SOROFEM_BROWSER_TEST=1 (`make test-viewer` sets it) and skips when either is missing.
"""

from __future__ import annotations

import io
import os
import shutil
import socket
import time
from pathlib import Path

import numpy as np
import pytest

import sorofem as sf

viser = pytest.importorskip("viser", reason="optional extra sorofem[viewer] (viser) not installed")
trimesh = pytest.importorskip("trimesh")

from sorofem.viewer import build_view, colour_by_magnitude, rebuild_body  # noqa: E402

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


# ---------------------------------------------------------------------------
# A real browser: headless Chromium (Debian package) driven by Playwright's Python package.

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(os.environ.get("SOROFEM_BROWSER_TEST") != "1",
                    reason="real-browser test (~7 s): run by `make test-viewer` (SOROFEM_BROWSER_TEST=1)")
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium executable (apt-get install chromium)")
def test_browser_loads_the_view(server) -> None:
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright Python package not installed")
    view = build_view(sf.Scene.load(SCENES / "cable_cantilever.toml"), server)
    url = f"http://127.0.0.1:{server.get_port()}"
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                    args=["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"])
        try:
            page = browser.new_page()
            page.goto(url)
            page.wait_for_selector("canvas", timeout=30_000)
            page.get_by_text("cable 0 alpha").first.wait_for(timeout=30_000)
            deadline = time.time() + 10
            while not server.get_clients() and time.time() < deadline:
                time.sleep(0.1)
            assert server.get_clients(), "the browser did not connect to the viser server"
            # A change made on the server reaches the connected client without errors.
            view.sliders[0].value = 0.7
            page.wait_for_timeout(500)
            assert view.solves == 2
        finally:
            browser.close()

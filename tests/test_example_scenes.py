"""The physics of the example scenes (examples/scenes/), and their data (examples/data/), which
examples/data/make_data.py generates with sorofem itself."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import ModuleType

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCENES = EXAMPLES / "scenes"
DATA = EXAMPLES / "data"


def _generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location("make_data", DATA / "make_data.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def make_data() -> ModuleType:
    return _generator()


def test_generated_data_are_what_the_generator_writes(make_data, tmp_path):
    """The committed files are the generator's output (the tetrahedral finger aside: fTetWild's
    output varies from run to run; its volume is checked below)."""
    written = make_data.write_all(tmp_path, mesher=False)
    assert {p.name for p in written} == {"beam_markers.csv", "cable_goal.npy", "swing_tracks.csv", "finger.stl",
                                         "h_robot.stl"}
    np.testing.assert_allclose(sf.io.read_points(tmp_path / "beam_markers.csv"), sf.io.read_points(DATA / "beam_markers.csv"),
                               rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(np.loadtxt(tmp_path / "swing_tracks.csv", delimiter=",", skiprows=2),
                               np.loadtxt(DATA / "swing_tracks.csv", delimiter=",", skiprows=2), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(np.load(tmp_path / "cable_goal.npy"), np.load(DATA / "cable_goal.npy"), rtol=1e-9, atol=1e-12)
    for name in ("finger.stl", "h_robot.stl"):
        assert (tmp_path / name).read_bytes() == (DATA / name).read_bytes(), name
    assert sum(p.stat().st_size for p in DATA.iterdir()) < 100_000  # small enough to keep in the repository


def test_surfaces_are_closed_and_the_finger_mesh_fills_its_surface():
    for name, (width, height, depth) in (("finger.stl", (120, 25, 25)), ("h_robot.stl", (80, 20, 60))):
        points, triangles = sf.io.read_surface(DATA / name)
        sf.meshing.check_surface(points, triangles, name)  # closed, manifold, outward
        np.testing.assert_allclose(np.ptp(points, axis=0), (width, height, depth), rtol=1e-6)
    # The H: 80 x 60 outline less the two notches (40 x 25 below, 40 x 15 above the bridge), 20 mm thick.
    points, triangles = sf.io.read_surface(DATA / "h_robot.stl")
    assert sf.meshing.surface_volume(points, triangles) == pytest.approx((80 * 60 - 40 * 25 - 40 * 15) * 20, rel=1e-6)
    surface = sf.io.read_surface(DATA / "finger.stl", scale=1e-3)
    mesh = sf.Mesh.read(DATA / "finger.vtu")
    enclosed = sf.meshing.surface_volume(*surface)
    diagonal = float(np.linalg.norm(np.ptp(surface.vertices, axis=0)))
    envelope = 2 * 1e-3 * diagonal * sf.meshing.surface_area(*surface)  # fTetWild's bound
    assert abs(mesh.volumes.sum() - enclosed) < envelope


def test_regions_scene_splits_the_stretch_two_to_one(tmp_path):
    """Two halves in series, E and 2E, nu = 0: the soft half takes 2/3 of the 10 um stretch, and
    the stress is the same in both."""
    assert main(["run", str(SCENES / "regions.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    result = meshio.read(tmp_path / "result.vtu")
    middle = np.isclose(result.points[:, 0], 0.05)
    np.testing.assert_allclose(result.point_data["displacement"][middle, 0], 2 / 3 * 1e-5, rtol=1e-3)
    stress = result.cell_data["von_mises"][0]
    np.testing.assert_allclose(stress, 60e3 * (2 / 3 * 1e-5) / 0.05, rtol=1e-3)  # E x strain of the soft half


def test_dynamics_scene_settles_at_the_static_equilibrium(tmp_path):
    assert main(["run", str(SCENES / "dynamics.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert summary["steps"] == 100 and summary["final_actuation"] == [pytest.approx(0.8)]
    assert summary["final_kinetic_energy"] < 1e-3 * summary["max_kinetic_energy"]
    scene = sf.Scene.load(SCENES / "dynamics.toml")
    pulled = scene.body.replace()
    pulled.set_actuation(0, 0.8)
    static = sf.solve_static(pulled, scene.gravity)
    frames = sorted((tmp_path / "trajectory").glob("*.vtu"))
    last = meshio.read(frames[-1])
    final = scene.mesh.points + last.point_data["displacement"][: scene.mesh.n_nodes]
    assert np.abs(final - static.positions).max() < 0.01 * static.max_displacement


def test_estimate_scene_recovers_the_generators_material(make_data, tmp_path):
    assert main(["estimate", str(SCENES / "estimate.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    truth = make_data.ESTIMATE_TRUTH
    std = summary["uncertainty"]["std"]
    assert std["youngs_modulus"] < 0.02 * summary["youngs_modulus"]  # 6 markers, 0.2 mm noise: E to ~1 %
    for name in ("youngs_modulus", "poisson_ratio"):
        assert abs(summary["params"][name] - truth[name]) < 3 * std[name], name
    assert summary["uncertainty"]["at_bound"] == {"youngs_modulus": None, "poisson_ratio": None}


def test_control_scene_finds_the_generators_actuation(make_data, tmp_path):
    assert main(["control", str(SCENES / "control.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert summary["reachable"] is True
    assert summary["actuation"] == [pytest.approx(make_data.CONTROL_ALPHA, abs=1e-5)]


def test_swing_estimate_scene_recovers_the_generators_damping(make_data, tmp_path):
    """Rayleigh damping from the noisy, partly hidden swing: each coefficient within three of its
    standard errors of the generator's and determined to 10 %; the fit starts far off (its misfit
    is over 10 times the noise) and ends at the noise (the residual standard deviation is the
    0.1 mm put in, to 20 %): what is left is noise, not model error."""
    assert main(["estimate", str(SCENES / "swing_estimate.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    uncertainty = summary["uncertainty"]
    for name, truth in make_data.SWING_DAMPING.items():
        assert abs(summary["params"][name] - truth) < 3 * uncertainty["std"][name], name
        assert uncertainty["relative_std"][name] < 0.1, name
    assert summary["history"][0]["rms"] > 10 * make_data.SWING_NOISE
    assert abs(uncertainty["sigma"] / make_data.SWING_NOISE - 1) < 0.2


def test_schedule_scene_reaches_the_goal_and_holds_it(make_data, tmp_path):
    """The schedule brings the tip points to the goal at T and holds them (RMS distance under
    1 mm at T and after it, at most 1/10 of the distance a plain step to the goal's command
    swings through after T), and the command held after T is the static one that holds the goal
    (the generator's alpha), since the beam is at rest there."""
    assert main(["control", str(SCENES / "schedule.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert summary["reachable"] is True and max(summary["distance"], summary["swing"]) < 1e-3
    assert summary["actuation"][-1] == [pytest.approx(make_data.CONTROL_ALPHA, abs=1e-3)]
    scene = sf.Scene.load(SCENES / "schedule.toml")
    d = scene.dynamics
    step = sf.simulate(scene.body, d["dt"], d["steps"], actuation={0: make_data.CONTROL_ALPHA}, gravity=scene.gravity,
                       damping=(d["mass_damping"], d["stiffness_damping"]), initial=scene.solve(), progress=False)
    goal = scene.target.bind(scene.mesh)
    reach = round(summary["reach_time"] / d["dt"])
    assert summary["swing"] < 0.1 * max(goal.rms(x) for x in step.positions[reach:])


def _balance(result: sf.StaticResult, gravity: np.ndarray, density: float) -> float:
    """|sum of external forces| over the weight: supports, cable anchors, weight."""
    weight = density * result.mesh.volumes.sum() * gravity
    total = result.reactions.sum(axis=0) + weight
    for anchor in result.anchor_reactions:
        if anchor is not None:
            total += anchor
    return float(np.linalg.norm(total) / np.linalg.norm(weight))


def test_finger_scene_curls_up_and_balances_its_forces():
    scene = sf.Scene.load(SCENES / "finger.toml")
    result = scene.solve()
    tip = scene.mesh.points[:, 0] > 0.119
    assert result.displacement[tip, 2].mean() > 0  # the cable lifts the tip against gravity
    assert _balance(result, scene.gravity, 1070.0) < 1e-6
    assert all(t.min() > 0 for t in result.cable_tensions)  # taut everywhere


def test_h_robot_scene_meshes_its_surface_and_stands_on_its_feet():
    pytest.importorskip(sf.meshing.MESHER, reason="h_robot.toml needs the optional mesher")
    scene = sf.Scene.load(SCENES / "h_robot.toml")
    assert scene.mesh.source.resolve() == (DATA / "h_robot.stl").resolve()
    assert scene.mesh.volumes.sum() == pytest.approx((80 * 60 - 40 * 25 - 40 * 15) * 20e-9, rel=0.02)
    result = scene.solve()
    assert _balance(result, scene.gravity, 1070.0) < 1e-6
    assert result.displacement[:, 2].min() < 0  # it sags

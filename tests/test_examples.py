"""Every example script runs and passes its own physics checks; every example scene runs
through the command line."""

from __future__ import annotations

import importlib.util
import inspect
import json
import tomllib
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from ci import missing_in_ci

import sorofem as sf
from sorofem.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCRIPTS = sorted(EXAMPLES.glob("*.py"))
SCENES = sorted((EXAMPLES / "scenes").glob("*.toml"))


def _load(path: Path) -> ModuleType:
    """Import an example by file path (its name starts with a digit, so no plain import)."""
    spec = importlib.util.spec_from_file_location(f"example_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_examples_exist():
    assert SCRIPTS, f"no example scripts in {EXAMPLES}"
    assert SCENES, f"no example scenes in {EXAMPLES / 'scenes'}"


def _passed(check) -> bool:
    """A check is a bool, or a dict with a ``"passed"`` bool (and its value and limit)."""
    return bool(check["passed"] if isinstance(check, dict) else check)


@pytest.mark.parametrize("path", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_example_checks_pass(path, tmp_path):
    """The contract of an example: ``run(out_dir)`` returns a dict whose ``"checks"`` maps
    each physics check's name to its outcome; all must pass."""
    module = _load(path)
    assert callable(getattr(module, "run", None)), f"{path.name} has no run(out_dir)"
    missing = [str(f) for f in getattr(module, "REQUIRED_FILES", ()) if not Path(f).is_file()]
    if missing:
        missing_in_ci(f"{path.name} needs data that is not here: {', '.join(missing)}")
    for name in getattr(module, "REQUIRED_MODULES", ()):  # optional extras, e.g. the mesher
        pytest.importorskip(name, reason=f"{path.name} needs the optional module {name}")
    # Heavy examples take ``quick`` (fewer cases, same checks); their full runs are benchmarks.
    quick = "quick" in inspect.signature(module.run).parameters
    result = module.run(tmp_path, quick=True) if quick else module.run(tmp_path)
    checks = result["checks"]
    assert checks, f"{path.name} checks nothing"
    failed = {name: check for name, check in checks.items() if not _passed(check)}
    assert not failed, f"{path.name}: failed checks {failed}"


@pytest.fixture(scope="module")
def cantilever_summary(tmp_path_factory) -> dict:
    """The demo run through its command-line entry point (as `make demo` does), read back
    from summary.json."""
    module = _load(EXAMPLES / "01_cantilever_gravity.py")
    out = tmp_path_factory.mktemp("demo")
    assert module.main(["--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    for name in summary["files"]:
        assert (out / name).is_file(), name
    return summary


def test_cantilever_example_numbers(cantilever_summary):
    """Both beams converge in a handful of Newton steps; the short one bends to a little less
    than the elastica, the long one hangs down."""
    assert cantilever_summary["passed"] is True
    assert set(cantilever_summary["checks"]) == {
        "newton_quadratic", "force_balance", "moment_balance", "independent_reactions", "long_beam_hangs",
        "short_beam_range",
    }
    beams = cantilever_summary["beams"]
    short, long_ = beams["cantilever_400mm"], beams["cantilever_1000mm"]
    for beam in (short, long_):
        assert beam["converged"]
        assert beam["newton_iterations"] <= 30
        assert beam["residual_norm"] <= 1e-8
        assert set(beam["timings"]) >= {"setup", "solve", "write"}
    # Weight of a 0.4 x 0.1 x 0.1 m beam at 1080 kg/m^3.
    np.testing.assert_allclose(short["weight"], [0, 0, -0.004 * 1080 * 9.81], rtol=1e-12)
    # Below the elastica (the coarse mesh is stiff in bending), and not far below it.
    assert 0.85 < short["tip_deflection"] / short["elastica_tip_deflection"] < 1.0
    assert long_["tip_deflection_over_length"] > 0.9


@pytest.mark.parametrize("scene", SCENES, ids=[p.stem for p in SCENES])
def test_example_scene_runs(scene, tmp_path):
    """Every scene runs (``sorofem run``: a static solve, or a trajectory with [dynamics]), and
    a scene with [estimate] or [control] also through that command. Their physics checks are
    in test_example_scenes.py."""
    data = tomllib.loads(scene.read_text(encoding="utf-8"))
    if "surface" in data["mesh"]:
        pytest.importorskip(sf.meshing.MESHER, reason=f"{scene.name} needs the optional mesher")
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0
    files = (("trajectory.pvd", "summary.json", "trajectory.png") if "dynamics" in data
             else ("result.vtu", "summary.json", "shape.png", "convergence.png"))
    for name in files:
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["converged"] is True
    for command in ("estimate", "control"):
        if command in data:
            assert main([command, str(scene), "--out", str(tmp_path / command), "--quiet"]) == 0
            # With [dynamics]: a fit to motion or a schedule, whose figure is the run it found.
            names = (("summary.json", "trajectory.png") + (("fit.png",) if command == "estimate" else ())
                     if "dynamics" in data else ("summary.json", "result.vtu", "fit.png"))
            for name in names:
                assert (tmp_path / command / name).is_file(), (command, name)


def test_every_command_has_an_example_scene():
    """run (static and [dynamics]), estimate, control (also in time: tracks, keyframes), material
    regions, a tetrahedral mesh file, a surface to tetrahedralise and a target read from a file:
    each has a scene."""
    found: set[str] = set()
    for scene in SCENES:
        data = tomllib.loads(scene.read_text(encoding="utf-8"))
        found |= {key for key in ("dynamics", "estimate", "control", "cable") if key in data}
        found |= {f"mesh.{key}" for key in ("file", "surface", "box") if key in data["mesh"]}
        found |= {"regions"} if data["material"].get("region") else set()
        found |= {f"target.{key}" for key in ("positions_file", "tracks_file") if key in data.get("target", {})}
        found |= {"control.keyframe_times"} if "keyframe_times" in data.get("control", {}) else set()
    assert found >= {"dynamics", "estimate", "control", "cable", "mesh.file", "mesh.surface", "mesh.box", "regions",
                     "target.positions_file", "target.tracks_file", "control.keyframe_times"}, found


def test_cantilever_scene_matches_example(cantilever_summary, tmp_path):
    """The README's scene and the demo's 0.4 m beam are the same model: same answer."""
    out = tmp_path / "scene"
    assert main(["run", str(EXAMPLES / "scenes" / "cantilever.toml"), "--out", str(out), "--quiet"]) == 0
    scene_summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    short = cantilever_summary["beams"]["cantilever_400mm"]
    assert scene_summary["n_nodes"] == short["n_nodes"]
    assert scene_summary["max_displacement"] == pytest.approx(short["max_displacement"], rel=1e-8)

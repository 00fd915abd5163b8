"""`sorofem estimate` and `sorofem control` of scenes with [dynamics]: damping fitted to a
recorded motion ([target] tracks, tracks_file) and cable schedules ([control] keyframe_times,
reach_time); bad input exits 2 naming the key, a solver or a goal that fails exits 3. The
example scenes' physics is in test_example_scenes.py."""

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

DYNAMICS = "\n[dynamics]\ndt = 0.01\nsteps = 10\nmass_damping = 1.0\n"
MARKERS = "\n[target]\npoints = [[0.1, 0.01, 0.01], [0.05, 0.01, 0.02]]\n"
ESTIMATE = '\n[estimate]\nparams = ["mass_damping"]\nx0 = [1.0]\n'
TRACKS = "tracks = [[0.05, 0, 0.1, 0.01, 0.0], [0.1, 1, 0.05, 0.01, 0.01]]\n"
GOAL = "\n[target]\npoints = [[0.1, 0.01, 0.01]]\npositions = [[0.1, 0.01, 0.0]]\n"
SCHEDULE = "\n[control]\ncables = [0]\nbounds = [[0.5, 1.0]]\nkeyframe_times = [0.02, 0.05]\nreach_time = 0.05\n"


def _run(command: str, text: str, tmp_path, capsys, *extra: str) -> tuple[int, str]:
    scene = tmp_path / "scene.toml"
    scene.write_text(text, encoding="utf-8")
    code = main([command, str(scene), "--out", str(tmp_path / "out"), "--quiet", *extra])
    return code, capsys.readouterr().err


def _one_error(code: int, err: str, key: str, text: str) -> None:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (code, err)
    assert key in lines[0] and text in lines[0], err


def test_inline_tracks_of_nodes_give_back_the_damping_exactly(tmp_path, capsys):
    """Exact tracks of two free-end nodes, written inline with one node hidden in some frames:
    mass_damping comes back to 1e-6 relative (the scene's tracks are the simulated run's
    frames, node for node), with stiffness_damping held at its [dynamics] value."""
    truth, held = 3.0, 1e-3
    text = BASE + "\n[dynamics]\ndt = 0.01\nsteps = 20\nmass_damping = 1.0\nstiffness_damping = 0.001\n"
    scene = sf.Scene.from_toml(text, tmp_path / "truth.toml")
    run = sf.simulate(scene.body, 0.01, 20, gravity=scene.gravity, damping=(truth, held), tolerance=1e-12,
                      method="newton", progress=False)
    nodes = np.flatnonzero(np.isclose(scene.mesh.points[:, 0], 0.1))[:2]
    rows = [[k * 0.01, m, *run.positions[k, node]] for k in range(2, 21, 2) for m, node in enumerate(nodes)
            if not (m == 1 and k in (8, 10))]
    tracks = "\n[target]\nnodes = " + json.dumps(nodes.tolist()) + "\ntracks = " + json.dumps(rows) + "\n"
    code, err = _run("estimate", text + tracks + ESTIMATE, tmp_path, capsys)
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    assert summary["params"]["mass_damping"] == pytest.approx(truth, rel=1e-6)
    assert summary["converged"] is True and summary["dynamics"]["stiffness_damping"] == held
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["fit.png", "summary.json", "trajectory.png"]


def test_tracks_file_columns_in_any_order_with_comments(tmp_path):
    (tmp_path / "tracks.csv").write_text("# recorded\nx, marker, z, time, y\n0.1, 0, 0.0, 0.05, 0.01  # tip\n"
                                         "0.05 1 0.01 0.1 0.01\n", encoding="utf-8")
    scene = sf.Scene.from_toml(BASE + DYNAMICS + MARKERS + 'tracks_file = "tracks.csv"\n', tmp_path / "s.toml")
    assert [t for t, _ in scene.tracks] == [pytest.approx(0.05), pytest.approx(0.1)]
    assert scene.target is None and tmp_path / "tracks.csv" in scene.input_files
    first = scene.tracks[0][1].bind(scene.mesh)
    np.testing.assert_allclose(first.matched_goal(scene.mesh.points), [[0.1, 0.01, 0.0]])
    np.testing.assert_allclose(first.points(scene.mesh.points), [[0.1, 0.01, 0.01]])  # marker 0 at rest


BAD_TRACKS = [
    ("time,marker,x,y\n0.05,0,0.1,0.01\n", "missing column(s) z"),
    ("time,marker,x,y,z,w\n0.05,0,0.1,0.01,0,1\n", "unknown column(s) w"),
    ("time,marker,x,y,z\n0.05,0,0.1,0.01\n", "line 2: expected 5 values"),
    ("time,marker,x,y,z\n0.05,0,0.1,0.01,abc\n", "expected numbers"),
    ("time,marker,x,y,z\n", "no rows after the header"),
    ("0.05,0,0.1,0.01,0\n", "missing column(s) time, marker, x, y, z"),
    ("time,marker,x,y,z\n0.015,0,0.1,0.01,0\n", "is not a frame of [dynamics]"),
    ("time,marker,x,y,z\n0.2,0,0.1,0.01,0\n", "outside the run"),
    ("time,marker,x,y,z\n0.05,2,0.1,0.01,0\n", "expected a marker from 0 to 1"),
    ("time,marker,x,y,z\n0.05,0.5,0.1,0.01,0\n", "expected a marker from 0 to 1"),
    ("time,marker,x,y,z\n0.05,0,0.1,0.01,0\n0.05,0,0.1,0.01,0\n", "marker 0 is already given"),
]


@pytest.mark.parametrize("table, text", BAD_TRACKS)
def test_a_bad_tracks_file_exits_2_naming_the_key(tmp_path, capsys, table, text):
    (tmp_path / "tracks.csv").write_text(table, encoding="utf-8")
    code, err = _run("estimate", BASE + DYNAMICS + MARKERS + 'tracks_file = "tracks.csv"\n' + ESTIMATE, tmp_path,
                     capsys)
    _one_error(code, err, "key 'target.tracks_file'", text)
    assert not (tmp_path / "out").exists()


BAD_SCENES = [
    # tracks
    (BASE + MARKERS + TRACKS + ESTIMATE, "target.tracks", "needs a [dynamics] table"),
    (BASE + DYNAMICS + MARKERS + 'tracks_file = "none.csv"\n' + ESTIMATE, "target.tracks_file", "not found"),
    (BASE + DYNAMICS + MARKERS + "tracks = [[0.05, 0, 0.1, 0.01]]\n" + ESTIMATE, "target.tracks", "[time, marker"),
    (BASE + DYNAMICS + MARKERS + "tracks = [[-0.01, 0, 0.1, 0.01, 0]]\n" + ESTIMATE, "target.tracks", ">= 0"),
    (BASE + DYNAMICS + MARKERS + TRACKS + 'positions = [[0, 0, 0], [0, 0, 0]]\n' + ESTIMATE, "key 'target'",
     "expected at most one of 'positions', 'positions_file', 'tracks' or 'tracks_file'"),
    (BASE + DYNAMICS + "\n[target]\nnodes = [999]\n" + TRACKS + ESTIMATE, "target.nodes", "out of range"),
    (BASE + DYNAMICS + "\n[target]\npoints = [[1.0, 0, 0], [0.05, 0.01, 0.02]]\n" + TRACKS + ESTIMATE,
     "target.points", ""),
    # damping and [estimate]
    (BASE + DYNAMICS.replace("1.0", "-1.0") + MARKERS + TRACKS + ESTIMATE, "dynamics.mass_damping", ">= 0"),
    (BASE + MARKERS + "positions = [[0.1, 0, 0], [0, 0, 0]]\n" + ESTIMATE, "estimate.params", "needs a [dynamics]"),
    (BASE + DYNAMICS + MARKERS + TRACKS + ESTIMATE.replace("[1.0]", "[0.0]"), "estimate.x0", "a start > 0"),
    (BASE + DYNAMICS + MARKERS + TRACKS + ESTIMATE + "bounds = [[-1, 10]]\n", "estimate.bounds", "bounds >= 0"),
    (BASE + DYNAMICS + MARKERS + TRACKS + ESTIMATE + "starts = 2\n", "estimate.starts", "from x0 alone"),
    (BASE + DYNAMICS + GOAL + ESTIMATE, "key 'target'", "expected [target] nodes or points with tracks"),
    (BASE + DYNAMICS + MARKERS + TRACKS + '\n[estimate]\nparams = ["shear_modulus_field"]\nx0 = [[1e4]]\n',
     "estimate.params", "a field"),
    (BASE + DYNAMICS.replace("\nsteps", '\ninitial = "static"\nsteps') + MARKERS + TRACKS
     + '\n[estimate]\nparams = ["youngs_modulus"]\nx0 = [60e3]\n', "dynamics.initial", "starts from rest"),
    # [control] in time
    (BASE + CABLE + DYNAMICS + GOAL + SCHEDULE.replace("[0.02, 0.05]", "[0.05, 0.02]"), "control.keyframe_times",
     "expected increasing times"),
    (BASE + CABLE + DYNAMICS + GOAL + SCHEDULE.replace("[0.02, 0.05]", "[0.02, 0.5]"), "control.keyframe_times",
     "within the run"),
    (BASE + CABLE + DYNAMICS + GOAL + SCHEDULE.replace("reach_time = 0.05", "reach_time = 0.055"),
     "control.reach_time", "a multiple of dt"),
    (BASE + CABLE + DYNAMICS + GOAL + SCHEDULE.replace("reach_time = 0.05", "reach_time = 0.2"),
     "control.reach_time", "within the run"),
    (BASE + CABLE + GOAL + SCHEDULE, "control.keyframe_times", "needs a [dynamics] table"),
    (BASE + CABLE + DYNAMICS + GOAL + "\n[control]\ncables = [0]\n", "control.keyframe_times", "missing"),
    (BASE + CABLE + DYNAMICS + "actuation = [[[0, 1], [0.05, 0.9]]]\n" + GOAL + SCHEDULE, "dynamics.actuation",
     "finds the schedule"),
    (BASE + CABLE + DYNAMICS + GOAL + SCHEDULE + 'method = "nelder-mead"\n', "control.method", "'l-bfgs-b'"),
    (BASE + CABLE + DYNAMICS + MARKERS + TRACKS + SCHEDULE, "key 'target'", "not a recorded motion"),
]


@pytest.mark.parametrize("text, key, message", BAD_SCENES, ids=[f"{i}-{k}" for i, (_, k, _) in enumerate(BAD_SCENES)])
def test_bad_motion_scenes_exit_2_naming_the_key(tmp_path, capsys, text, key, message):
    command = "control" if "[control]" in text else "estimate"
    code, err = _run(command, text, tmp_path, capsys)
    _one_error(code, err, key, message)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("flag", [["--resume"], ["--history", "h.jsonl"]])
def test_history_options_are_refused_for_a_fit_to_motion(tmp_path, capsys, flag):
    code, err = _run("estimate", BASE + DYNAMICS + MARKERS + TRACKS + ESTIMATE, tmp_path, capsys, *flag)
    _one_error(code, err, flag[0], "keeps no history file")


def test_a_scene_without_dynamics_still_fits_the_equilibrium(tmp_path, capsys):
    """No [dynamics]: the static estimate, with its result.vtu and history, as before."""
    scene = sf.Scene.from_toml(BASE, tmp_path / "goal.toml")
    goal = sf.solve_static(scene.body, scene.gravity, tolerance=1e-12).positions[[5, 9]]
    target = f"\n[target]\nnodes = [5, 9]\npositions = {goal.tolist()}\n"
    code, err = _run("estimate", BASE + target + '\n[estimate]\nparams = ["youngs_modulus"]\nx0 = [40e3]\n',
                     tmp_path, capsys)
    assert code == 0, err
    assert {"result.vtu", "fit.png", "history.jsonl", "summary.json"} <= {p.name for p in (tmp_path / "out").iterdir()}
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    assert summary["youngs_modulus"] == pytest.approx(66e3, rel=1e-6) and "dynamics" not in summary


def test_a_solver_failure_in_a_fit_to_motion_exits_3(tmp_path, capsys):
    code, err = _run("estimate", BASE + "\n[solver]\nmax_iterations = 1\n" + DYNAMICS + MARKERS + TRACKS + ESTIMATE,
                     tmp_path, capsys)
    assert code == 3 and err.startswith("error: solver failed"), err


def test_an_unreachable_schedule_exits_3_with_its_summary(tmp_path, capsys):
    """A goal 5 cm above the free end, beyond what the cable can lift it: exit 3, summary.json
    says so (converged false) with the schedule found."""
    far = GOAL.replace("[[0.1, 0.01, 0.0]]", "[[0.1, 0.01, 0.06]]")
    code, err = _run("control", BASE + CABLE + DYNAMICS + far + SCHEDULE, tmp_path, capsys)
    assert code == 3 and "not reachable" in err, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    assert summary["converged"] is False and summary["reachable"] is False
    assert summary["distance"] > 0.03 and len(summary["schedule"]["0"]) == 3  # t = 0 and the two keyframes


def test_a_cable_dashpot_is_fitted_to_motion(tmp_path, capsys):
    """[estimate] params = ["cable_damping"]: the dashpot of the scene's cable, pulled to 0.8 at
    the start, comes back to 1e-6 relative from exact tracks of two free-end nodes."""
    truth = 20.0
    text = BASE + CABLE + "actuation = 0.8\ndamping = 5.0\n" + "\n[dynamics]\ndt = 0.01\nsteps = 12\n"
    scene = sf.Scene.from_toml(text, tmp_path / "truth.toml")
    scene.body.set_cable_damping(0, truth)
    run = sf.simulate(scene.body, 0.01, 12, gravity=scene.gravity, tolerance=1e-12, method="newton", progress=False)
    undamped = scene.body.replace()
    undamped.set_cable_damping(0, 5.0)
    slow = sf.simulate(undamped, 0.01, 12, gravity=scene.gravity, tolerance=1e-12, method="newton", progress=False)
    assert np.abs(run.positions - slow.positions).max() > 1e-5  # the dashpot shows in the data
    nodes = np.flatnonzero(np.isclose(scene.mesh.points[:, 0], 0.1))[:2]
    rows = [[k * 0.01, m, *run.positions[k, node]] for k in range(1, 13) for m, node in enumerate(nodes)]
    tracks = "\n[target]\nnodes = " + json.dumps(nodes.tolist()) + "\ntracks = " + json.dumps(rows) + "\n"
    estimate = '\n[estimate]\nparams = ["cable_damping"]\nx0 = [5.0]\n'
    code, err = _run("estimate", text + tracks + estimate, tmp_path, capsys)
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    assert summary["params"]["cable_damping"] == pytest.approx(truth, rel=1e-6)

"""Tendons through the Python API: sf.Cable(..., model="tendon"), body.pull by displacement or
tension, result.cable_tension / cable_pull, continuation, dynamics, sensitivities against central
differences (tests/fdcheck.py), control in metres and newtons, scenes and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

import sorofem as sf
from fdcheck import check_gradient
from sorofem.cli import main

GRAVITY = np.array([0.0, 0.0, -9.81])
TIGHT = 1e-11


def beam_body() -> sf.Body:
    """The 0.4 m cantilever, 8 x 2 x 2 cells, clamped at x = 0, E = 66 kPa, nu = 0.45."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def top_tendon(**command) -> sf.Cable:
    """1 cm below the upper face, from x = 1 cm to 39 cm, 8 segments."""
    return sf.Cable.line((0.01, 0.05, 0.09), (1, 0, 0), 0.38, 8, model="tendon", **command)


def bottom_tendon(**command) -> sf.Cable:
    return sf.Cable.line((0.01, 0.05, 0.01), (1, 0, 0), 0.38, 8, model="tendon", **command)


# -- construction and bad input ----------------------------------------------------------


def test_a_tendon_has_a_command_and_no_spring_options():
    assert top_tendon().command == ("pull", 0.0)
    assert top_tendon(pull=0.01).command == ("pull", 0.01)
    assert top_tendon(tension=2.0).command == ("tension", 2.0)
    assert "model='tendon'" in repr(top_tendon(tension=2.0))
    assert sf.Cable.line((0, 0, 0), (1, 0, 0), 0.4, 4, stiffness=1e4).model == "springs"


@pytest.mark.parametrize(
    "kwargs, parameter",
    [
        ({"pull": 0.01, "tension": 1.0}, "pull"),
        ({"tension": -1.0}, "tension"),
        ({"pull": float("nan")}, "pull"),
        ({"pull": 0.5}, "pull"),  # longer than the 0.38 m tendon
        ({"stiffness": 1e4}, "stiffness"),
        ({"damping": 1.0}, "damping"),
        ({"outside": "free"}, "outside"),
    ],
)
def test_bad_tendons_name_the_parameter(kwargs, parameter):
    with pytest.raises(sf.ParameterError) as err:
        top_tendon(**kwargs)
    assert err.value.parameter == parameter


def test_bad_tendon_points_are_refused():
    with pytest.raises(sf.ParameterError, match="at least 2 points"):
        sf.Cable([[0.1, 0.05, 0.05]], model="tendon")
    with pytest.raises(sf.InputError, match="coincide|differ"):
        sf.Cable([[0.1, 0.05, 0.05], [0.1, 0.05, 0.05], [0.2, 0.05, 0.05]], model="tendon")
    body = beam_body()
    body.add_cable(sf.Cable([[0.1, 0.05, 0.05], [0.2, 0.05, 0.3]], model="tendon"))
    with pytest.raises(sf.InputError, match=r"points\[1\]"):
        sf.solve_static(body, GRAVITY)


def test_commands_go_to_the_right_kind_of_cable():
    body = beam_body()
    tendon = top_tendon()
    springs = sf.Cable.line((0.0, 0.05, 0.01), (1, 0, 0), 0.4, 8, stiffness=1e4)
    body.add_cable(tendon)
    body.add_cable(springs)
    with pytest.raises(sf.InputError, match="tendon"):
        body.set_actuation(tendon, 0.9)
    with pytest.raises(sf.InputError, match="spring"):
        body.pull(springs, displacement=0.01)
    with pytest.raises(sf.InputError, match="exactly one"):
        body.pull(tendon)
    with pytest.raises(sf.InputError, match="exactly one"):
        body.pull(tendon, displacement=0.01, tension=2.0)
    with pytest.raises(sf.ParameterError):
        body.pull(tendon, tension=-2.0)
    with pytest.raises(sf.ParameterError):
        body.pull(tendon, displacement=0.38)
    body.pull(tendon, tension=3.0)
    assert body.commands == [("tension", 3.0), ("actuation", 1.0)]


# -- displacement and force control --------------------------------------------------------


def test_displacement_control_meets_the_pull_and_reads_the_tension():
    body = beam_body()
    tendon = top_tendon()
    body.add_cable(tendon)
    for pull in (0.005, 0.02):
        body.pull(tendon, displacement=pull)
        result = sf.solve_static(body, GRAVITY, tolerance=1e-10)
        assert result.cable_pull[0] == pytest.approx(pull, rel=1e-9)
        tension = result.cable_tension[0]
        assert tension > 0
        np.testing.assert_array_equal(result.cable_tensions[0], np.full(8, tension))
        cable = result.to_dict()["cables"][0]
        assert cable["model"] == "tendon" and cable["tension"] == tension and cable["pull"] == pytest.approx(pull)


def test_a_push_leaves_the_tendon_slack_and_the_body_as_without_it():
    free = beam_body()
    reference = sf.solve_static(free, GRAVITY, tolerance=TIGHT)
    body = beam_body()
    tendon = bottom_tendon()
    body.add_cable(tendon)
    body.pull(tendon, displacement=-0.01)
    result = sf.solve_static(body, GRAVITY, tolerance=TIGHT)
    assert result.cable_tension[0] == 0.0
    assert result.cable_pull[0] > -0.01
    scale = np.abs(reference.positions - free.mesh.points).max()
    assert np.abs(result.positions - reference.positions).max() <= 1e-10 * scale


def test_tension_and_pull_commands_agree():
    body = beam_body()
    tendon = top_tendon(tension=40.0)
    body.add_cable(tendon)
    by_tension = sf.solve_static(body, GRAVITY, tolerance=TIGHT)
    assert by_tension.cable_tension[0] == 40.0
    pull = by_tension.cable_pull[0]
    assert pull > 0
    body.pull(tendon, displacement=pull)
    by_pull = sf.solve_static(body, GRAVITY, tolerance=TIGHT)
    assert by_pull.cable_tension[0] == pytest.approx(40.0, rel=1e-7)
    scale = np.abs(by_tension.positions - body.mesh.points).max()
    assert np.abs(by_pull.positions - by_tension.positions).max() <= 1e-9 * scale


def test_a_pull_continuation_warm_starts_in_few_iterations():
    body = beam_body()
    tendon = top_tendon()
    body.add_cable(tendon)
    results = sf.actuate(body, tendon, 0.03, gravity=GRAVITY, max_step=0.005)
    pulls = [r.cable_pull[0] for r in results]
    np.testing.assert_allclose(pulls, np.linspace(0.005, 0.03, 6), rtol=1e-9)
    tensions = [r.cable_tension[0] for r in results]
    assert all(b > a for a, b in zip(tensions, tensions[1:]))  # a stiffer pull needs more tension
    assert max(r.report.iterations for r in results[1:]) <= 5


def test_dynamics_holds_the_pulled_length_in_every_step():
    body = beam_body()
    tendon = top_tendon()
    body.add_cable(tendon)
    steps, dt = 8, 0.01
    schedule = np.array([[0.002 * (s + 1)] for s in range(steps)])
    trajectory = sf.simulate(body, dt=dt, steps=steps, gravity=GRAVITY, actuation=schedule, tolerance=1e-9)
    for frame in range(1, trajectory.n_frames):
        tension, pulled = trajectory.cable_tension[frame][0], trajectory.cable_pull[frame][0]
        assert tension is not None and pulled is not None
        assert tension == 0.0 or pulled == pytest.approx(schedule[frame - 1][0], abs=1e-9 * 0.38)
    assert trajectory.cable_tension[-1][0] > 0
    assert body.commands == [("pull", 0.0)]  # the body keeps its own command


# -- sensitivities and control ----------------------------------------------------------------


@pytest.mark.parametrize("command, name", [("pull", "cable_pull"), ("tension", "cable_tension")])
def test_gradient_with_respect_to_the_command_matches_central_differences(command, name):
    body = beam_body()
    value = 0.02 if command == "pull" else 15.0
    tendon = top_tendon(**{command: value})
    body.add_cable(tendon)
    tip = body.mesh.points[:, 0] > 0.399
    weights = np.random.default_rng(3).uniform(-1, 1, (int(tip.sum()), 3))

    def objective(positions):
        return float(np.sum(weights * positions[tip])), _scatter(tip, weights)

    def value_at(theta):
        body.pull(tendon, **{"displacement" if command == "pull" else "tension": float(theta[0])})
        return objective(sf.solve_static(body, GRAVITY, tolerance=TIGHT).positions)[0]

    body.pull(tendon, **{"displacement" if command == "pull" else "tension": value})
    result = sf.gradient(body, objective, [name], GRAVITY, tolerance=TIGHT)
    analytic = np.atleast_1d(result.gradient[name])
    assert abs(analytic[0]) > 1e-8
    check = check_gradient(value_at, np.array([value]), analytic, direction=np.array([1.0]), step=1e-3 * value, rtol=1e-5)
    assert check.passed, check


def _scatter(mask, values):
    out = np.zeros((mask.size, 3))
    out[mask] = values
    return out


def test_control_finds_the_pull_that_reaches_a_target():
    body = beam_body()
    tendon = top_tendon()
    body.add_cable(tendon)
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    body.pull(tendon, displacement=0.015)
    goal = sf.solve_static(body, GRAVITY, tolerance=TIGHT).positions[tip]
    body.pull(tendon, displacement=0.0)
    ctl = sf.control(body, sf.Target.nodes(tip, goal), cables=[tendon], bounds=[(0.0, 0.05)], gravity=GRAVITY)
    assert ctl.reachable and ctl.distance < 1e-6
    assert ctl.actuation[0] == pytest.approx(0.015, rel=1e-4)
    assert body.commands == [("pull", 0.0)]


# -- tendons against obstacles -----------------------------------------------------------------

#: A ceiling 1.5 cm above the beam's top face: the curl of a 1 cm pull (tip 2.5 cm up) hits it.
CEILING = 0.115


def test_a_pulled_tendon_curls_the_beam_against_a_ceiling():
    """The pull is still met exactly; the ceiling stops the tip short of it and pushes down, so
    the tendon needs more tension than in free space; the supports balance the ceiling's force
    (the tendon's forces are internal)."""
    free = beam_body()
    free.add_cable(top_tendon(pull=0.01))
    unobstructed = sf.solve_static(free, tolerance=1e-10)
    assert unobstructed.positions[:, 2].max() > CEILING
    body = beam_body()
    body.add_cable(top_tendon(pull=0.01))
    body.add_obstacle(sf.Plane((0, 0, CEILING), (0, 0, -1)))
    result = sf.solve_static(body, tolerance=1e-10)
    assert result.cable_pull[0] == pytest.approx(0.01, rel=1e-9)
    assert 0 < result.min_distance < body.dhat
    assert result.positions[:, 2].max() < CEILING
    push = result.obstacle_forces[0]
    assert push[2] < 0 and result.active_contacts > 0
    assert result.cable_tension[0] > unobstructed.cable_tension[0]
    balance = np.asarray(result.reactions).sum(axis=0) + result.contact_forces.sum(axis=0)
    np.testing.assert_allclose(balance, 0.0, atol=1e-8 * abs(push[2]))


def test_every_step_method_holds_the_pull_against_a_ceiling():
    """Modified Newton (its kept factorisation refreshed when the taut tendons or the active
    contacts change) reaches the same trajectory as full Newton; no iterate crosses the
    ceiling; the linearly implicit step (one iteration, completed by modified Newton near
    contact only) misses the pull by less than 1 um."""
    steps, dt = 30, 0.01
    schedule = np.array([[min(0.012, 0.0015 * (s + 1))] for s in range(steps)])
    runs = {}
    for method in sf.dynamics.STEP_METHODS:
        body = beam_body()
        body.add_cable(top_tendon())
        body.add_obstacle(sf.Plane((0, 0, CEILING), (0, 0, -1)))
        runs[method] = sf.simulate(body, dt=dt, steps=steps, actuation=schedule, tolerance=1e-9,
                                   damping=(1.0, 0.005), method=method)
    for method, run in runs.items():
        assert run.active_contacts.max() > 0, method
        assert np.all(np.asarray(run.iterate_min_distances) > 0), method
        assert run.positions[:, :, 2].max() < CEILING, method
        errors = [abs(run.cable_pull[f][0] - schedule[f - 1][0]) for f in range(1, run.n_frames)]
        assert max(errors) < (1e-9 * 0.38 if method != "linearly_implicit" else 1e-6), method
    newton, modified = runs["newton"], runs["modified"]
    scale = np.abs(newton.positions[-1] - newton.positions[0]).max()
    assert np.abs(modified.positions - newton.positions).max() < 1e-7 * scale
    assert modified.factorizations.sum() < newton.factorizations.sum()


# -- scenes and the CLI ------------------------------------------------------------------------

SCENE = """
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
start = [0.01, 0.05, 0.09]
direction = [1, 0, 0]
length = 0.38
divisions = 8
model = "tendon"
pull = 0.01
"""


def test_scene_tendon_runs_and_reports_tension_and_pull(tmp_path, capsys):
    scene = tmp_path / "tendon.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 0
    assert "tendon" in capsys.readouterr().out
    cable = json.loads((out / "summary.json").read_text())["cables"][0]
    assert cable["model"] == "tendon"
    assert cable["pull"] == pytest.approx(0.01, rel=1e-8)
    assert cable["tension"] > 0


@pytest.mark.parametrize("command", ["pull = 0.01\ntension = 2.0", "tension = -1.0", "pull = 1.0"])
def test_bad_scene_tendons_exit_2(tmp_path, capsys, command):
    scene = tmp_path / "bad.toml"
    scene.write_text(SCENE.replace("pull = 0.01", command))
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and ("pull" in err or "tension" in err), err


def test_a_spring_cable_keeps_its_alpha_bounds_and_keyframes_positive(tmp_path):
    """alpha <= 0 is no longer a structural mistake (a tendon's pull or tension may be 0) but
    stays an error for a spring cable, named by its key."""
    springs = SCENE.replace('model = "tendon"\npull = 0.01', "stiffness = 1e5")
    tip = "[target]\nnodes = [1]\npositions = [[0.4, 0, 0]]\n"
    for extra, key in [
        (tip + "[control]\nbounds = [[0, 1.0]]\n", "control.bounds"),
        ("[dynamics]\ndt = 0.01\nsteps = 2\nactuation = [[[0.0, 1.0], [0.2, 0.0]]]\n", "dynamics.actuation[0]"),
    ]:
        path = tmp_path / "springs.toml"
        path.write_text(springs + extra)
        with pytest.raises(sf.SceneError) as info:
            sf.Scene.load(path)
        assert info.value.key == key, str(info.value)

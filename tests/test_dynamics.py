"""Dynamics: implicit Euler against its exact recurrence, damped settling, schedules, output."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.dynamics import Keyframes, evaluate_schedule

GRAVITY = np.array([0.0, 0.0, -9.81])


@pytest.fixture
def silicone() -> sf.NeoHookean:
    return sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)


@pytest.fixture
def beam(silicone) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def two_cables(body: sf.Body) -> tuple[sf.Cable, sf.Cable]:
    a = sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.4, 4, stiffness=1e4)
    b = sf.Cable.line((0, 0.09, 0.01), (1, 0, 0), 0.4, 4, stiffness=1e4, actuation=0.9)
    body.add_cable(a)
    body.add_cable(b)
    return a, b


# -- schedules (no extension time stepping needed) ------------------------------------


def test_keyframes_interpolate_and_hold():
    pull = Keyframes([[0.0, 1.0], [1.0, 0.5], [2.0, 0.5]])
    assert pull(-1.0) == 1.0 and pull(0.5) == pytest.approx(0.75) and pull(5.0) == 0.5
    with pytest.raises(sf.ParameterError, match="must not decrease"):
        Keyframes([[1.0, 1.0], [0.0, 0.5]])
    with pytest.raises(sf.ShapeError):
        Keyframes([1.0, 0.5])


def test_schedule_forms(beam):
    a, b = two_cables(beam)
    dt, steps = 0.1, 4
    t = dt * np.arange(1, steps + 1)
    held = evaluate_schedule(beam, None, dt, steps)
    np.testing.assert_array_equal(held, [[1.0, 0.9]] * steps)
    both = evaluate_schedule(beam, lambda time: [1 - time, 1.0], dt, steps)
    np.testing.assert_allclose(both[:, 0], 1 - t)
    per_cable = evaluate_schedule(beam, [Keyframes([[0, 1], [0.4, 0.6]]), None], dt, steps)
    np.testing.assert_allclose(per_cable, np.column_stack([1 - t, np.full(steps, 0.9)]))
    by_cable = evaluate_schedule(beam, {b: 0.8, 0: [0.9, 0.8, 0.7, 0.6]}, dt, steps)
    np.testing.assert_allclose(by_cable, np.column_stack([[0.9, 0.8, 0.7, 0.6], np.full(steps, 0.8)]))
    array = np.full((steps, 2), 0.7)
    np.testing.assert_array_equal(evaluate_schedule(beam, array, dt, steps), array)


def test_schedule_errors(beam):
    two_cables(beam)
    with pytest.raises(sf.InputError, match="needs a body with one cable"):
        evaluate_schedule(beam, lambda t: 0.9, 0.1, 3)
    with pytest.raises(sf.ParameterError, match="cable 1 at step 2"):
        evaluate_schedule(beam, [1.0, lambda t: 0.9 - 3 * t], 0.1, 3)
    with pytest.raises(sf.ShapeError, match=r"\(3, 2\)"):
        evaluate_schedule(beam, np.ones((2, 2)), 0.1, 3)
    with pytest.raises(sf.ShapeError, match="one entry per cable"):
        evaluate_schedule(beam, [1.0], 0.1, 3)
    with pytest.raises(sf.InputError, match="index 5"):
        evaluate_schedule(beam, {5: 1.0}, 0.1, 3)


def test_simulate_argument_errors(beam):
    with pytest.raises(sf.ParameterError, match="dt"):
        sf.simulate(beam, 0.0, 10)
    with pytest.raises(sf.ParameterError, match="steps"):
        sf.simulate(beam, 0.01, 0)
    with pytest.raises(sf.ParameterError, match="alpha_M"):
        sf.simulate(beam, 0.01, 10, damping=(-1.0, 0.0))
    with pytest.raises(sf.ParameterError, match="method: expected one of 'modified', 'newton'") as err:
        sf.simulate(beam, 0.01, 10, method="explicit")
    assert err.value.parameter == "method"
    with pytest.raises(sf.ShapeError, match="initial"):
        sf.simulate(beam, 0.01, 10, initial=np.zeros((3, 3)))
    massless = sf.Body(beam.mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45))
    massless.fix([0])
    with pytest.raises(sf.ParameterError, match="density > 0"):
        sf.simulate(massless, 0.01, 10)


# -- time stepping -----------------------------------------------------------------------


@pytest.mark.parametrize("method", sf.dynamics.STEP_METHODS)
def test_free_fall_matches_the_implicit_euler_recurrence(silicone, method):
    """No supports, gravity only: every node follows v_{n+1} = v_n + dt g,
    x_{n+1} = x_n + dt v_{n+1}, i.e. x_n = x_0 + g dt^2 n (n + 1) / 2 (the body stays undeformed).
    The step's potential is quadratic here, so even the linearly implicit step is exact."""
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    body = sf.Body(mesh, silicone)
    dt, steps = 0.01, 30
    traj = sf.simulate(body, dt, steps, gravity=GRAVITY, method=method)
    n = np.arange(steps + 1)
    np.testing.assert_allclose(traj.times, dt * n, rtol=0, atol=1e-12)
    drop = GRAVITY[2] * dt**2 * n * (n + 1) / 2
    expected = mesh.points[None] + drop[:, None, None] * np.array([0, 0, 1.0])
    assert np.abs(traj.positions - expected).max() < 1e-10
    np.testing.assert_allclose(traj.velocities, np.tile(GRAVITY * dt * steps, (mesh.n_nodes, 1)), atol=1e-10)
    # First order in dt against the exact g t^2 / 2: the lag is g dt t / 2.
    lag = traj.displacement[-1, :, 2] - GRAVITY[2] * traj.times[-1] ** 2 / 2
    np.testing.assert_allclose(lag, GRAVITY[2] * dt * traj.times[-1] / 2, rtol=1e-8)
    mass = 1080 * 1e-3
    np.testing.assert_allclose(traj.kinetic_energy, 0.5 * mass * (GRAVITY[2] * dt * n) ** 2, rtol=1e-9)
    # The first step starts from the inertial prediction x_n + dt v_n (one Newton step); later
    # ones from the parabola through the last three states, exact under constant acceleration
    # (the linearly implicit step always starts from the prediction and takes its one step).
    # Modified Newton's kept factorisation is in single precision: its first step leaves a
    # residual of about 1e-7, and a second iteration brings it below the tolerance.
    extrapolated = [1] + [0] * (steps - 1)
    expected_iterations = {"newton": extrapolated, "modified": [2] + [0] * (steps - 1), "linearly_implicit": [1] * steps}
    assert list(traj.iterations) == expected_iterations[method]
    assert traj.cutbacks == 0 and traj.residuals.max() < 1e-8
    # A free body's Hessian is the constant mass term: one factorisation serves the whole run
    # unless every iteration refactorises.
    assert traj.factorizations.sum() == (1 if method != "newton" else sum(extrapolated))


@pytest.mark.parametrize(("poisson_ratio", "single"), [(0.45, True), (0.49999, False)])
def test_kept_factorisations_are_single_precision_where_accurate_enough(poisson_ratio, single):
    """Modified Newton keeps its factorisations in single precision while their solves are
    accurate to 1e-3 (at nu = 0.45 about 1e-6); the locking standard body at nu = 0.49999 (about
    1e-2) is factored in double precision from its first factorisation on. Either way the steps
    converge to the tolerance, so the trajectory is Newton's to it."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    runs = {}
    for method in ("newton", "modified"):
        body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=poisson_ratio, density=1080))
        body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
        runs[method] = sf.simulate(body, 0.01, 20, gravity=GRAVITY, damping=(1.0, 0.0), method=method)
    kept = runs["modified"]
    assert runs["newton"].single_precision_factorizations == 0
    assert kept.single_precision_factorizations == (kept.factorizations.sum() if single else 0)
    assert kept.factorizations.sum() > 0 and kept.residuals.max() < 1e-8
    scale = np.abs(runs["newton"].displacement).max()
    assert np.abs(kept.positions - runs["newton"].positions).max() < 1e-6 * scale


@pytest.mark.parametrize("method", sf.dynamics.STEP_METHODS)
def test_damped_beam_settles_to_the_static_solution(beam, method):
    static = sf.solve_static(beam, gravity=GRAVITY)
    # Near critical damping of the first bending mode (about 2 Hz).
    traj = sf.simulate(beam, 0.02, 100, gravity=GRAVITY, damping=(10.0, 0.01), save_every=10, method=method)
    assert traj.n_frames == 11 and traj.times[-1] == pytest.approx(2.0)
    error = np.abs(traj.final_positions - static.positions).max() / static.max_displacement
    assert error < 1e-3
    assert traj.kinetic_energy[-1] < 1e-6 * traj.kinetic_energy.max()
    assert traj.iterations.max() <= 10


def test_cable_pull_then_hold_matches_the_static_pull(beam):
    cable = sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5)
    beam.add_cable(cable)
    pull = Keyframes([[0.0, 1.0], [0.5, 0.8]])
    traj = sf.simulate(beam, 0.02, 100, actuation=pull, gravity=GRAVITY, damping=(10.0, 0.01), save_every=25)
    np.testing.assert_allclose(traj.actuation[-1], [0.8])
    assert beam.actuations == [1.0], "simulate changed the body's actuation"
    static = sf.actuate(beam, cable, [0.9, 0.8], gravity=GRAVITY)[-1]
    error = np.abs(traj.final_positions - static.positions).max() / static.max_displacement
    assert error < 2e-3
    np.testing.assert_allclose(traj.cable_points[-1][0], static.cable_points[0], atol=2e-3 * static.max_displacement)


def test_free_node_with_mass_settles_below(silicone):
    """A 0.1 kg free node on a 6 cm cable below a clamped cube swings down and settles where
    the taut spring carries its weight: k (L - l - w/2) = m g."""
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(np.arange(mesh.n_nodes))
    cable = sf.Cable([[0.05, 0.05, 0.01], [0.05, 0.05, -0.05]], 1e3, outside="free", free_node_mass=0.1)
    body.add_cable(cable)
    traj = sf.simulate(body, 0.005, 400, gravity=GRAVITY, damping=(5.0, 0.0), save_every=100)
    hang = 0.06 + 0.1 * 9.81 / 1e3 + cable.transition * 0.06 / 2
    np.testing.assert_allclose(traj.cable_points[-1][0][1], [0.05, 0.05, 0.01 - hang], atol=1e-7)
    assert traj.cable_tensions(-1)[0][0] == pytest.approx(0.1 * 9.81, rel=1e-4)


def test_continue_a_trajectory_and_body_state(beam):
    first = sf.simulate(beam, 0.01, 10, gravity=GRAVITY)
    second = sf.simulate(beam, 0.01, 10, gravity=GRAVITY, initial=first)
    whole = sf.simulate(beam, 0.01, 20, gravity=GRAVITY)
    np.testing.assert_allclose(second.final_positions, whole.final_positions, atol=1e-9)


def test_write_pvd(beam, tmp_path):
    two_cables(beam)
    traj = sf.simulate(beam, 0.01, 4, actuation=[lambda t: 1 - t, None], gravity=GRAVITY, save_every=2)
    pvd = traj.write_pvd(tmp_path / "out")
    assert pvd == tmp_path / "out" / "trajectory.pvd"
    entries = ET.parse(pvd).getroot().findall("./Collection/DataSet")
    assert [float(e.get("timestep")) for e in entries] == pytest.approx([0.0, 0.02, 0.04])
    frame = meshio.read(tmp_path / "out" / entries[-1].get("file"))
    n = beam.mesh.n_nodes
    assert frame.points.shape == (n + 10, 3)
    np.testing.assert_allclose(frame.points[:n], traj.positions[-1])
    assert [c.type for c in frame.cells] == ["tetra", "line"]
    summary = traj.to_dict()
    assert summary["steps"] == 4 and summary["frames"] == 3


# -- scene files and the command line ------------------------------------------------


DYNAMIC_SCENE = """\
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
start = [0, 0.01, 0.01]
direction = [1, 0, 0]
length = 0.4
divisions = 10
stiffness = 1e5

[dynamics]
dt = 0.02
steps = 20
mass_damping = 10.0
stiffness_damping = 0.01
save_every = 5
initial = "static"
actuation = [[[0.0, 1.0], [0.2, 0.9]]]
"""


def test_scene_dynamics_matches_the_api(tmp_path, beam):
    path = tmp_path / "dynamic.toml"
    path.write_text(DYNAMIC_SCENE, encoding="utf-8")
    scene = sf.Scene.load(path)
    assert scene.dynamics["dt"] == 0.02 and scene.dynamics["initial"] == "static"
    assert scene.dynamics["actuation"][0](0.1) == pytest.approx(0.95)
    from_scene = scene.simulate()
    cable = sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5)
    beam.add_cable(cable)
    start = sf.solve_static(beam, gravity=GRAVITY)
    from_api = sf.simulate(beam, 0.02, 20, actuation=Keyframes([[0, 1], [0.2, 0.9]]), gravity=GRAVITY,
                           damping=(10.0, 0.01), initial=start, save_every=5)
    np.testing.assert_allclose(from_scene.positions, from_api.positions, atol=1e-12)
    assert from_scene.cable_tensions(-1)[0].max() > 0
    assert scene.to_dict()["dynamics"]["actuation"] == [[[0.0, 1.0], [0.2, 0.9]]]


def test_run_dynamic_scene(tmp_path):
    import json

    from sorofem.cli import main

    path = tmp_path / "dynamic.toml"
    path.write_text(DYNAMIC_SCENE, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    for name in ("trajectory.pvd", "summary.json", "trajectory.png"):
        assert (out / name).is_file(), name
    assert len(list((out / "trajectory").glob("frame_*.vtu"))) == 5
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["steps"] == 20 and summary["frames"] == 5 and summary["cutbacks"] == 0
    assert len(summary["cables"][0]["final_tensions"]) == 10
    assert summary["dynamics"]["mass_damping"] == 10.0


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("dt = 0.02", "dt = 0", "dynamics.dt"),
        ("steps = 20", "", "dynamics.steps"),
        ("save_every = 5", "save_every = 0", "dynamics.save_every"),
        ("mass_damping = 10.0", "mass_damping = -1.0", "dynamics.mass_damping"),
        ('initial = "static"', 'initial = "moving"', "dynamics.initial"),
        ("actuation = [[[0.0, 1.0], [0.2, 0.9]]]", "actuation = [[[0.0, 1.0]], [[0.0, 1.0]]]", "dynamics.actuation"),
        ("actuation = [[[0.0, 1.0], [0.2, 0.9]]]", "actuation = [[[0.2, 1.0], [0.0, 0.9]]]", "dynamics.actuation[0]"),
        ("actuation = [[[0.0, 1.0], [0.2, 0.9]]]", "actuation = [[[0.0, 1.0], [0.2, 0.0]]]", "dynamics.actuation[0]"),
        ("actuation = [[[0.0, 1.0], [0.2, 0.9]]]", "actuation = [[0.0, 1.0]]", "dynamics.actuation[0]"),
        ("dt = 0.02", "dt = 0.02\ntime_step = 0.01", "dynamics.time_step"),
    ],
)
def test_bad_dynamics_entries_name_the_key(tmp_path, old, new, key):
    path = tmp_path / "bad.toml"
    path.write_text(DYNAMIC_SCENE.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(path)
    assert info.value.key == key, str(info.value)


# -- progress line ---------------------------------------------------------------------


class _FakeTTY:
    """stderr that says it is a terminal."""

    def __init__(self) -> None:
        self.text = ""

    def write(self, text: str) -> int:
        self.text += text
        return len(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return True


def _same_trajectory(a, b, atol=1e-12):
    assert a.n_frames == b.n_frames
    np.testing.assert_allclose(a.times, b.times, rtol=0, atol=atol)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=atol)
    np.testing.assert_allclose(a.velocities, b.velocities, rtol=0, atol=1e3 * atol)
    np.testing.assert_allclose(a.kinetic_energy, b.kinetic_energy, rtol=1e-9, atol=atol)
    np.testing.assert_array_equal(a.iterations, b.iterations)
    np.testing.assert_array_equal(a.factorizations, b.factorizations)
    assert a.cutbacks == b.cutbacks
    assert len(a.cable_points) == len(b.cable_points)
    for fa, fb in zip(a.cable_points, b.cable_points):
        for pa, pb in zip(fa, fb):
            np.testing.assert_allclose(pa, pb, rtol=0, atol=atol)


def test_simulate_with_progress_draws_a_line_and_gives_the_same_trajectory(beam, capsys):
    two_cables(beam)
    kwargs = dict(actuation=[Keyframes([[0, 1], [0.1, 0.8]]), None], gravity=GRAVITY, damping=(5.0, 0.01))
    plain = sf.simulate(beam, 0.01, 10, save_every=3, progress=False, **kwargs)
    assert capsys.readouterr().err == ""
    shown = sf.simulate(beam, 0.01, 10, save_every=3, progress=True, **kwargs)
    err = capsys.readouterr().err
    assert err.endswith("\n") and err.count("\n") == 1 and "\r" not in err  # no terminal: the final state once
    assert err.startswith("simulate ") and "100% 10/10 steps" in err
    assert re.search(r"t=0\.1 s, \d\.\d it/step, 0 cutbacks$", err.rstrip())
    assert [round(t, 12) for t in shown.times] == [0.0, 0.03, 0.06, 0.09, 0.1]
    _same_trajectory(plain, shown)
    assert beam.actuations == [1.0, 0.9]


@pytest.mark.parametrize("save_every, steps", [(1, 7), (3, 10), (4, 12), (50, 9)])
def test_chunked_integration_saves_the_same_frames(beam, monkeypatch, save_every, steps):
    """With the line shown the steps run in chunks (here as small as possible: the first chunk
    is one step, then every chunk is as short as the save points allow)."""
    import sorofem.dynamics as dynamics

    monkeypatch.setattr(dynamics, "CHUNK_SECONDS", 0.0)
    calls = []
    real = dynamics._run_in_chunks

    def spy(run, *args):
        def counted(n, *rest):
            calls.append(n)
            return run(n, *rest)
        return real(counted, *args)

    monkeypatch.setattr(dynamics, "_run_in_chunks", spy)
    plain = sf.simulate(beam, 0.01, steps, gravity=GRAVITY, damping=(5.0, 0.0), save_every=save_every, progress=False)
    chunked = sf.simulate(beam, 0.01, steps, gravity=GRAVITY, damping=(5.0, 0.0), save_every=save_every, progress=True)
    assert sum(calls) == steps and len(calls) > 1
    _same_trajectory(plain, chunked)
    # The core's phase times are summed over the chunks: each call reports its own.
    phases = {"assembly", "factorization", "solve", "line_search", "total"}
    assert phases <= plain.timings.keys() and phases <= chunked.timings.keys()
    assert 0.0 < chunked.timings["factorization"] < chunked.timings["total"] <= chunked.timings["simulate"]


def test_simulate_progress_is_automatic(beam, monkeypatch, capsys):
    import sorofem.progress

    sf.simulate(beam, 0.01, 3, gravity=GRAVITY)  # pytest's stderr is not a terminal
    assert capsys.readouterr().err == ""
    tty = _FakeTTY()
    monkeypatch.setattr("sys.stderr", tty)
    monkeypatch.setattr(sorofem.progress, "DELAY", 0.0)
    sf.simulate(beam, 0.01, 3, gravity=GRAVITY)
    shown = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", tty.text)  # without the terminal's control sequences
    assert "3/3 steps" in shown and shown.endswith("\n")
    quiet = _FakeTTY()
    monkeypatch.setattr("sys.stderr", quiet)
    with sorofem.progress.default(False):  # what a --quiet command line does
        sf.simulate(beam, 0.01, 3, gravity=GRAVITY)
    assert quiet.text == ""


def test_progress_with_free_cable_nodes_runs_in_one_piece(silicone, capsys):
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(np.arange(mesh.n_nodes))
    body.add_cable(sf.Cable([[0.05, 0.05, 0.01], [0.05, 0.05, -0.05]], 1e3, outside="free", free_node_mass=0.1))
    plain = sf.simulate(body, 0.005, 40, gravity=GRAVITY, damping=(5.0, 0.0), save_every=10, progress=False)
    shown = sf.simulate(body, 0.005, 40, gravity=GRAVITY, damping=(5.0, 0.0), save_every=10, progress=True)
    assert "40/40 steps" in capsys.readouterr().err
    _same_trajectory(plain, shown, atol=0.0)  # one call: bit for bit


def test_chunk_errors_name_the_global_step():
    from sorofem._chunks import shift_step_in_message

    err = sf.ConvergenceError("time step 3 (t = 0.0400 s) did not converge even at dt = 1.563e-4 s; ...",
                              {"message": "time step 3 (t = 0.0400 s) did not converge"})
    shift_step_in_message(err, 20, 0.2)
    assert str(err).startswith("time step 23 (t = 0.2400 s) did not converge even at dt = 1.563e-4 s")
    assert err.report["message"] == "time step 23 (t = 0.2400 s) did not converge"


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_step_methods_agree_to_the_tolerance_and_modified_newton_factorises_less(beam, formulation):
    """The converged methods reach the same states (to the Newton tolerance per step); the kept
    factorisation of modified Newton saves most of Newton's; the linearly implicit step stays
    within a few per cent here and never factorises more than once per step."""
    beam.formulation = formulation
    cable = sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5)
    beam.add_cable(cable)
    kwargs = dict(actuation=Keyframes([[0.0, 1.0], [0.3, 0.8]]), gravity=GRAVITY, damping=(2.0, 0.005))
    runs = {m: sf.simulate(beam, 0.01, 60, method=m, tolerance=1e-10, **kwargs) for m in sf.dynamics.STEP_METHODS}
    newton, modified, linear = runs["newton"], runs["modified"], runs["linearly_implicit"]
    swing = np.abs(newton.displacement).max()
    assert np.abs(modified.positions - newton.positions).max() < 1e-6 * swing
    assert modified.factorizations.sum() < 0.6 * newton.factorizations.sum()
    assert newton.residuals.max() < 1e-10 and modified.residuals.max() < 1e-10
    assert linear.factorizations.max() <= 1 and list(linear.iterations) == [1] * 60
    assert np.abs(linear.positions - newton.positions).max() < 0.05 * swing


def test_simulate_cables_of_different_point_counts(beam):
    """Regression: the finiteness check of a trajectory stacked each frame's cable points into
    one array, which failed (ValueError) for a spring chain and a tendon of different lengths."""
    beam.add_cable(sf.Cable.line((0, 0.05, 0.09), (1, 0, 0), 0.4, 10, stiffness=1e5))
    beam.add_cable(sf.Cable.line((0, 0.01, 0.05), (1, 0, 0), 0.38, 8, model="tendon", pull=0.0))
    traj = sf.simulate(beam, 0.01, 3, actuation={1: Keyframes([[0.0, 0.0], [0.03, 0.004]])}, gravity=GRAVITY)
    assert [p.shape for p in traj.cable_points[-1]] == [(11, 3), (9, 3)]
    assert traj.cable_pull[-1][1] == pytest.approx(0.004, rel=1e-6)


def test_a_step_whose_start_inverts_an_element_says_so():
    """The linearly implicit step on a floppy cantilever at a coarse dt: its velocities grow until
    the start of a step (u + h v) inverts an element at every halving; the error says so instead of
    listing an empty residual history."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(16, 4, 4))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080.0))
    body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
    with pytest.raises(sf.ConvergenceError, match=r"start state .* inverts an element") as err:
        sf.simulate(body, 0.05, 20, gravity=(0.0, 0.0, -9.81), damping=(1.0, 0.0), method="linearly_implicit")
    assert "residuals: []" not in str(err.value)

"""sf.trajectory_gradient: the discrete adjoint of implicit Euler against central differences of
re-simulated trajectories (tests/fdcheck.py), for every parameter kind, standard and mixed,
with a spring cable and with tendons; and its bad input."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_gradient

import sorofem as sf
from sorofem.dynamics import Keyframes

G = np.array([0.0, 0.0, -9.81])
TIGHT = 1e-11  # Newton tolerance of every step, in the gradient's run and the re-simulations
DT, STEPS = 0.01, 10


def beam(formulation="standard", E=66e3, rho=1080.0, cable=None, tendon=None):
    """The 0.4 m cantilever on 4 x 1 x 1 cells; ``cable`` = (alpha, stiffness) adds a spring
    cable near the bottom face, ``tendon`` = {"pull": d} or {"tension": T} a tendon near the
    top face."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E, poisson_ratio=0.45, density=rho), formulation)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    if cable is not None:
        alpha, k = cable
        body.add_cable(sf.Cable.line((0.0, 0.05, 0.02), (1, 0, 0), 0.4, 4, stiffness=k, actuation=alpha))
    if tendon is not None:
        body.add_cable(sf.Cable.line((0.01, 0.05, 0.08), (1, 0, 0), 0.38, 4, model="tendon", **tendon))
    return body


def tip_swing(body):
    """J = sum_i w_i 1/2 |x_tip(t_i) - X_tip|^2 (m^2), weights growing along the run."""
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    rest = body.mesh.points[tip]

    def objective(x):
        w = np.linspace(0.5, 1.5, len(x))[:, None, None]
        d = np.zeros_like(x)
        d[:, tip] = w * (x[:, tip] - rest)
        return 0.5 * float(np.sum(w * (x[:, tip] - rest) ** 2)), d

    return objective


def simulated(body, objective, **kwargs):
    kwargs.setdefault("gravity", G)
    traj = sf.simulate(body, DT, STEPS, tolerance=TIGHT, method="newton", **kwargs)
    return objective(traj.positions)[0]


def assert_fd(value, theta, gradient, relative_to=None):
    """Each parameter on its own (a relative perturbation), then all together."""
    theta = np.asarray(theta, dtype=np.float64)
    scale = np.abs(theta) if relative_to is None else relative_to
    for i in range(theta.size):
        d = np.zeros(theta.size)
        d[i] = scale[i] if scale[i] > 0 else 1.0
        fd = check_gradient(value, theta, gradient, direction=d, step=1e-5, rtol=2e-5)
        assert fd.passed, f"parameter {i}: {fd}"
    fd = check_gradient(value, theta, gradient, step=1e-5, rtol=2e-5)
    assert fd.passed, str(fd)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_material_density_and_rayleigh_damping_match_central_differences(formulation):
    body = beam(formulation)
    objective = tip_swing(body)
    damping = (3.0, 0.004)
    names = ["youngs_modulus", "poisson_ratio", "density", "mass_damping", "stiffness_damping"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, tolerance=TIGHT, steps=STEPS, gravity=G, damping=damping,
                               checkpoint_every=3)
    assert g.positions.shape == (STEPS + 1, body.mesh.n_nodes, 3)

    def value(t):
        return simulated(_beam_nu_rho(formulation, t), objective, damping=(t[3], t[4]))

    theta = np.array([66e3, 0.45, 1080.0, *damping])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    assert_fd(value, theta, g.vector)


def _beam_nu_rho(formulation, t):
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=t[0], poisson_ratio=t[1], density=t[2]), formulation)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_steps_halved_after_a_newton_failure_are_differentiated_through_their_sub_steps(formulation):
    """A swing at 6 Newton iterations per step: some steps fail and are halved, as sf.simulate
    halves them (method "modified", the gradient's), and the derivatives follow the sub-steps
    (measured: 1.8e-9 standard, 2.3e-9 mixed)."""
    damping = (1.0, 0.002)
    body = beam(formulation)
    v0 = np.zeros_like(body.mesh.points)
    v0[:, 2] = body.mesh.points[:, 0] / 0.4  # tip up at 1 m/s

    def run(t):
        b = beam(formulation, E=t[0], rho=t[1])
        return sf.simulate(b, DT, STEPS, gravity=G, damping=(t[2], t[3]), initial_velocity=v0, tolerance=TIGHT,
                           max_iterations=6, method="modified")

    theta = np.array([66e3, 1080.0, *damping])
    assert run(theta).cutbacks > 0, "some steps should be halved"
    objective = tip_swing(body)
    g = sf.trajectory_gradient(body, objective, ["youngs_modulus", "density", "mass_damping", "stiffness_damping"],
                               dt=DT, steps=STEPS, gravity=G, damping=damping, initial_velocity=v0, tolerance=TIGHT,
                               max_iterations=6, checkpoint_every=4)
    assert 0 < g.split_steps <= run(theta).cutbacks
    assert g.value == pytest.approx(objective(run(theta).positions)[0], rel=1e-12)
    assert_fd(lambda t: objective(run(t).positions)[0], theta, g.vector)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
@pytest.mark.parametrize("cable", ["spring", "pull"])
def test_scheduled_cables_are_differentiated_through_halved_steps(formulation, cable):
    """The same swing at 6 Newton iterations per step with a scheduled cable: a spring cable with
    a dashpot (keyframes, stiffness, dashpot, stiffness damping) or a pulled tendon (keyframes,
    material); the sub-steps of a halved step share its command (measured: 2e-9 at most for the
    spring cable, 7e-9 for the tendon)."""
    if cable == "spring":
        frames = Keyframes([[0.0, 1.0], [0.04, 0.8], [0.1, 0.85]])
        names = ["keyframes:0", "cable_stiffness", "cable_damping", "stiffness_damping"]
        theta = np.array([*frames.values, 3e3, 20.0, 0.002])
        scale = np.array([0.05, 0.05, 0.05, 3e3, 20.0, 0.002])
    else:
        frames = Keyframes([[0.0, 0.0], [0.05, 0.004], [0.1, 0.006]])
        names = ["keyframes:0", "youngs_modulus", "stiffness_damping"]
        theta = np.array([*frames.values, 66e3, 0.002])
        scale = np.array([1e-3, 1e-3, 1e-3, 66e3, 0.002])

    def body_at(t):
        if cable == "spring":
            b = beam(formulation, cable=(1.0, t[3]))
            b.set_cable_damping(0, t[4])
        else:
            b = beam(formulation, E=t[3], tendon={"pull": 0.0})
        return b

    body = body_at(theta)
    v0 = np.zeros_like(body.mesh.points)
    v0[:, 2] = body.mesh.points[:, 0] / 0.4

    def run(t):
        schedule = {0: Keyframes(np.column_stack([frames.times, t[:3]]))}
        return sf.simulate(body_at(t), DT, STEPS, actuation=schedule, gravity=G, damping=(1.0, t[-1]),
                           initial_velocity=v0, tolerance=TIGHT, max_iterations=6, method="modified")

    assert run(theta).cutbacks > 0, "some steps should be halved"
    objective = tip_swing(body)
    g = sf.trajectory_gradient(body, objective, names, dt=DT, steps=STEPS, actuation={0: frames}, gravity=G,
                               damping=(1.0, theta[-1]), initial_velocity=v0, tolerance=TIGHT, max_iterations=6,
                               checkpoint_every=3)
    assert g.value == pytest.approx(objective(run(theta).positions)[0], rel=1e-12)
    assert_fd(lambda t: objective(run(t).positions)[0], theta, g.vector, relative_to=scale)


def test_the_checkpoint_interval_does_not_change_the_gradient():
    body = beam()
    objective = tip_swing(body)
    runs = [sf.trajectory_gradient(body, objective, ["youngs_modulus", "mass_damping"], dt=DT, steps=STEPS,
                                   gravity=G, damping=(2.0, 0.0), checkpoint_every=k, tolerance=1e-10)
            for k in (1, 4, STEPS)]
    # A recomputed segment starts from its checkpoint with no kept factorisation, so its
    # modified-Newton iterates (not its converged states, to the tolerance 1e-10) differ from
    # the forward pass's.
    for other in runs[1:]:
        np.testing.assert_allclose(other.vector, runs[0].vector, rtol=1e-9)


def test_the_checkpoint_interval_does_not_change_the_gradient_with_a_scheduled_cable():
    """The backward sweep assembles each state's elastic Hessian once, for the step ending there
    and the stiffness damping of the step starting there, also across checkpoint segments; the
    cable, whose command changes between those two steps, is assembled apart for each."""
    body = beam(cable=(1.0, 3e3))
    objective = tip_swing(body)
    frames = Keyframes([[0.0, 1.0], [0.04, 0.8], [0.1, 0.85]])
    names = ["keyframes:0", "youngs_modulus", "density", "mass_damping", "stiffness_damping"]
    runs = [sf.trajectory_gradient(body, objective, names, dt=DT, steps=STEPS, actuation={0: frames},
                                   gravity=G, damping=(1.0, 0.002), checkpoint_every=k, tolerance=1e-10)
            for k in (1, 3, STEPS)]
    for other in runs[1:]:
        np.testing.assert_allclose(other.vector, runs[0].vector, rtol=1e-9)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_the_default_tolerance_differentiates_the_default_simulation(formulation):
    """By default the gradient's forward pass is sf.simulate's default run, frame for frame, and
    its gradient agrees with a tight tolerance's to the residual that tolerance leaves."""
    body = beam(formulation, cable=(0.9, 3e3))
    objective = tip_swing(body)
    names = ["youngs_modulus", "density", "mass_damping", "stiffness_damping", "cable_damping"]
    kwargs = dict(dt=DT, steps=STEPS, gravity=G, damping=(1.0, 0.002))
    body.set_cable_damping(0, 0.5)
    default = sf.trajectory_gradient(body, objective, names, **kwargs)
    simulated_run = sf.simulate(body, DT, STEPS, gravity=G, damping=(1.0, 0.002))
    np.testing.assert_array_equal(default.positions, simulated_run.positions)
    tight = sf.trajectory_gradient(body, objective, names, tolerance=TIGHT, **kwargs)
    assert not np.array_equal(default.vector, tight.vector)
    np.testing.assert_allclose(default.vector, tight.vector, rtol=1e-7)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_spring_cable_schedule_keyframes_and_stiffness(formulation):
    k = 3e3
    body = beam(formulation, cable=(1.0, k))
    objective = tip_swing(body)
    frames = Keyframes([[0.0, 1.0], [0.04, 0.8], [0.1, 0.85]])
    names = ["keyframes:0", "cable_stiffness", "youngs_modulus", "stiffness_damping"]
    damping = (1.0, 0.002)
    g = sf.trajectory_gradient(body, objective, names + ["actuation"], dt=DT, tolerance=TIGHT, steps=STEPS, actuation={0: frames},
                               gravity=G, damping=damping)
    assert g.gradient["keyframes:0"].shape == (3,)
    assert g.gradient["actuation"].shape == (STEPS, 1)

    def value(t):
        b = beam(formulation, E=t[4], cable=(1.0, t[3]))
        return simulated(b, objective, actuation={0: Keyframes(np.column_stack([frames.times, t[:3]]))},
                         damping=(damping[0], t[5]))

    theta = np.array([*frames.values, k, 66e3, damping[1]])
    gradient = np.concatenate([np.ravel(g.gradient[n]) for n in names])
    assert_fd(value, theta, gradient, relative_to=np.array([0.05, 0.05, 0.05, k, 66e3, damping[1]]))

    schedule = np.array([frames(DT * (s + 1)) for s in range(STEPS)])

    def per_step(a):
        return simulated(beam(formulation, cable=(1.0, k)), objective, actuation=a.reshape(STEPS, 1), damping=damping)

    fd = check_gradient(per_step, schedule, g.gradient["actuation"].ravel(), step=1e-5, rtol=2e-5)
    assert fd.passed, str(fd)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
@pytest.mark.parametrize("command", ["pull", "tension"])
def test_tendon_schedule_and_material(formulation, command):
    """A tendon pulled (an exact constraint of every step: the bordered adjoint) or driven by
    its tension, ramped by keyframes; its force is the motor's, which stiffness damping leaves
    undamped."""
    if command == "pull":
        frames = Keyframes([[0.0, 0.0], [0.05, 0.004], [0.1, 0.006]])
    else:
        frames = Keyframes([[0.0, 0.0], [0.05, 1.5], [0.1, 2.0]])
    body = beam(formulation, tendon={command: 0.0})
    objective = tip_swing(body)
    damping = (2.0, 0.003)
    names = ["keyframes:0", "youngs_modulus", "density", "mass_damping", "stiffness_damping"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, tolerance=TIGHT, steps=STEPS, actuation={0: frames}, gravity=G,
                               damping=damping)

    def value(t):
        b = _beam_nu_rho(formulation, [t[3], 0.45, t[4]])
        b.add_cable(sf.Cable.line((0.01, 0.05, 0.08), (1, 0, 0), 0.38, 4, model="tendon", **{command: 0.0}))
        return simulated(b, objective, actuation={0: Keyframes(np.column_stack([frames.times, t[:3]]))},
                         damping=(t[5], t[6]))

    theta = np.array([*frames.values, 66e3, 1080.0, *damping])
    step = 1e-3 if command == "pull" else 0.1
    assert_fd(value, theta, g.vector, relative_to=np.array([step, step, step, 66e3, 1080.0, *damping]))


def test_timed_targets_are_the_sum_of_their_misfits():
    body = beam()
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    goal = body.mesh.points[tip] + [0.0, 0.0, -0.01]
    tracks = [(0.05, sf.Target.nodes(tip, goal)), (0.1, sf.Target.nodes(tip, goal - [0, 0, 0.01]))]
    g = sf.trajectory_gradient(body, tracks, ["density", "mass_damping"], dt=DT, tolerance=TIGHT, steps=STEPS, gravity=G,
                               damping=(1.0, 0.0))
    x = g.positions
    expected = sum(t.bind(body.mesh).misfit(x[round(time / DT)])[0] for time, t in tracks)
    assert g.value == pytest.approx(expected, rel=1e-12)

    def value(t):
        b = beam(rho=t[0])
        traj = sf.simulate(b, DT, STEPS, gravity=G, damping=(t[1], 0.0), tolerance=TIGHT, method="newton")
        return sum(tg.bind(b.mesh).misfit(traj.positions[round(time / DT)])[0] for time, tg in tracks)

    assert_fd(value, np.array([1080.0, 1.0]), g.vector)


# -- bad input -------------------------------------------------------------------------------


def _run(body, objective=None, params=("density",), **kwargs):
    kwargs = {"dt": DT, "steps": 3, "gravity": G, **kwargs}
    return sf.trajectory_gradient(body, objective or tip_swing(body), list(params), **kwargs)


@pytest.mark.parametrize(
    "objective, message",
    [
        (lambda x: (0.0, np.zeros((2, 3))), "shape"),
        (lambda x: (float("nan"), np.zeros_like(x)), "finite number"),
        (lambda x: (0.0, np.full_like(x, np.nan)), "non-finite"),
        (lambda x: 1.0, r"return \(value"),
    ],
)
def test_a_bad_objective_is_named(objective, message):
    with pytest.raises(sf.InputError, match=message) as err:
        _run(beam(), objective)
    assert "objective" in str(err.value)


@pytest.mark.parametrize(
    "params, kwargs, match",
    [
        (["stiffness"], {}, "unknown parameter 'stiffness'"),
        (["keyframes:3"], {}, "keyframes:3"),
        (["keyframes:0"], {"actuation": 0.9}, "Keyframes"),
        (["cable_actuation"], {}, "'actuation'"),
        (["density"], {"dt": 0.0}, "dt"),
        (["density"], {"steps": 0}, "steps"),
        (["density"], {"damping": (-1.0, 0.0)}, "alpha_M"),
        (["density"], {"checkpoint_every": 0}, "checkpoint_every"),
    ],
)
def test_bad_arguments_name_the_parameter(params, kwargs, match):
    body = beam(cable=(1.0, 3e3))
    with pytest.raises((sf.InputError, sf.ParameterError), match=match):
        _run(body, params=params, **kwargs)


@pytest.mark.parametrize("time", [0.015, 1.7e308, -1e300])
def test_a_target_time_off_the_frames_is_refused(time):
    """Between frames, or so far out that time / dt overflows."""
    body = beam()
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    with pytest.raises(sf.ParameterError, match="not one of the frames"):
        _run(body, [(time, sf.Target.nodes(tip, body.mesh.points[tip]))])


def test_friction_is_refused_by_name():
    """Dashpots and frictionless contact are differentiated (tests/test_trajectory_contact.py);
    lagged friction is not."""
    body = beam()
    body.add_obstacle(sf.Plane((0, 0, -0.2), (0, 0, 1)), friction=0.5)
    with pytest.raises(sf.ParameterError, match="friction"):
        _run(body)


def test_a_swing_from_a_static_equilibrium_starts_there():
    """``initial`` takes a StaticResult, as sf.simulate does: released from the equilibrium
    under gravity, with gravity off, the beam swings back up."""
    body = beam()
    start = sf.solve_static(body, G, tolerance=TIGHT)
    g = sf.trajectory_gradient(body, tip_swing(body), ["density"], dt=DT, steps=3, initial=start)
    np.testing.assert_allclose(g.positions[0], start.positions)
    assert g.gradient["density"] != 0.0

"""Trajectory derivatives through cable dashpots and frictionless contact (issue 18): the adjoint
(sf.trajectory_gradient) and the forward sensitivity (``Model::trajectory_sensitivity``) against
central differences of re-simulated trajectories (tests/fdcheck.py), standard and mixed; the
two agree with each other; friction is refused by name.

Contact: the barrier stiffness IPC balances at every step's start (and doubles within it)
changes with the parameters and the states, and the derivatives follow it (the doublings held,
as the halvings are): the cantilever resting on a floor (with a spring cable, a pulled tendon or
a tendon under tension among the forces balanced) and the arm thrown onto the C-body's other
arm, with stiffnesses balanced inside their bounds, are exact, as they are with a stiffness held
fixed (``adaptive_stiffness=False``). The reference stiffness ``kappa_ref`` is fixed at a body's
first solve from its material (a constant of the body, not differentiated): the re-simulations
are given the reference's value.
"""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_gradient, check_jacobian

import sorofem as sf
from sorofem._extension import core
from test_self_contact import CELLS, DENSITY, SIZE, UPPER_BOTTOM, c_shape
from sorofem.dynamics import Keyframes

G = np.array([0.0, 0.0, -9.81])
TIGHT = 1e-11  # Newton tolerance of every step, in the derivatives' run and the re-simulations
DT, STEPS = 0.01, 10
SCHEDULE = Keyframes([[0.0, 1.0], [0.04, 0.7], [0.1, 0.75]])  # the cable pulled taut, then held


def cantilever(formulation="standard", E=66e3, rho=1080.0, cable=None, gap=None, stiffness=None, adaptive=True):
    """The 0.4 m cantilever on 4 x 1 x 1 cells; ``cable`` = (dashpot c, stiffness k) adds a spring
    cable near the bottom face, ``gap`` a floor that far below it (barrier stiffness
    ``stiffness``, J/m^4, adaptive or not)."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E, poisson_ratio=0.45, density=rho), formulation)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    if cable is not None:
        c, k = cable
        body.add_cable(sf.Cable.line((0.0, 0.05, 0.02), (1, 0, 0), 0.4, 4, stiffness=k, actuation=1.0, damping=c))
    if gap is not None:
        body.add_obstacle(sf.Plane((0.0, 0.0, -gap), (0, 0, 1)))
        body.set_contact(stiffness=stiffness, adaptive_stiffness=adaptive)
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


def simulated(body, **kwargs):
    kwargs.setdefault("gravity", G)
    return sf.simulate(body, DT, STEPS, tolerance=TIGHT, method="newton", **kwargs)


def each_and_all(value, theta, gradient, rtol):
    """Each parameter on its own (a relative perturbation), then all together; the worst error."""
    worst = 0.0
    for i in range(theta.size):
        d = np.zeros(theta.size)
        d[i] = abs(theta[i])
        fd = check_gradient(value, theta, gradient, direction=d, step=1e-5, rtol=rtol)
        assert fd.passed, f"parameter {i}: {fd}"
        worst = max(worst, fd.error)
    fd = check_gradient(value, theta, gradient, step=1e-5, rtol=rtol)
    assert fd.passed, str(fd)
    return max(worst, fd.error)


# ---------------------------------------------------------------------------
# Cable dashpots


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_cable_dashpot_gradient_matches_central_differences(formulation):
    """The dashpot couples each step to its start; its coefficient is a parameter."""
    c, k, damping = 0.5, 3e3, (1.0, 0.002)
    body = cantilever(formulation, cable=(c, k))
    objective = tip_swing(body)
    names = ["cable_damping", "cable_stiffness", "youngs_modulus", "density", "stiffness_damping", "keyframes:0"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, tolerance=TIGHT, steps=STEPS, gravity=G, damping=damping,
                               actuation={0: SCHEDULE}, checkpoint_every=3)
    assert g.gradient["cable_damping"].shape == (1,)

    def value(t):
        b = cantilever(formulation, E=t[2], rho=t[3], cable=(t[0], t[1]))
        schedule = Keyframes(np.column_stack([SCHEDULE.times, t[5:]]))
        return objective(simulated(b, damping=(damping[0], t[4]), actuation={0: schedule}).positions)[0]

    theta = np.array([c, k, 66e3, 1080.0, damping[1], *SCHEDULE.values])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    # The dashpot matters: without it the objective differs by more than the checks' tolerance.
    assert abs(value(theta * np.r_[0.0, np.ones(theta.size - 1)]) - g.value) > 1e-3 * g.value
    each_and_all(value, theta, g.vector, rtol=2e-5)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_cable_dashpot_forward_sensitivity_matches_central_differences(formulation):
    """d positions / d c of every frame, and J^T of it against the adjoint."""
    c, k = 0.5, 3e3
    body = cantilever(formulation, cable=(c, k))
    alphas = np.array([[SCHEDULE(DT * (s + 1))] for s in range(STEPS)])

    def run(directions, c_value=c):
        b = cantilever(formulation, cable=(c_value, k))
        model = b.core_model()
        return core().trajectory_sensitivity(model, G, b.forces.copy(), b.prescribed_displacement.copy(), DT,
                                             alphas, directions, 1.0, 0.002, None, None, TIGHT, 50)

    out = run([{"cable_damping": np.array([1.0])}])
    dx = np.asarray(out["dx"])[0]
    assert np.abs(dx).max() > 0

    def positions(t):
        return np.asarray(run([], c_value=float(t[0]))["positions"]).ravel()

    fd = check_jacobian(positions, np.array([c]), dx.reshape(-1, 1), direction=np.array([c]), step=1e-5, rtol=2e-5)
    assert fd.passed, str(fd)
    objective = tip_swing(body)
    g = sf.trajectory_gradient(body, objective, ["cable_damping"], dt=DT, tolerance=TIGHT, steps=STEPS, gravity=G,
                               damping=(1.0, 0.002), actuation={0: SCHEDULE})
    _, dJ = objective(np.asarray(out["positions"]))
    assert float(np.vdot(dJ, dx)) == pytest.approx(g.gradient["cable_damping"][0], rel=1e-8)


# ---------------------------------------------------------------------------
# Contact

GAP = 0.005  # m: the floor below the cantilever, which its tip reaches after 3 steps
STIFF = 1e15  # J/m^4: the barrier stiffness of the finite-difference check


def assert_contact_active(body, **kwargs):
    traj = simulated(body, **kwargs)
    near = traj.min_distances.ravel() < body.dhat
    assert traj.cutbacks == 0
    assert near.sum() >= STEPS // 2, f"contact within dhat in {near.sum()} frames only"


def default_reference_stiffness(formulation):
    """The floor cantilever's default ``kappa_ref`` (J/m^4, from its material at the first solve)."""
    body = cantilever(formulation, gap=GAP)
    sf.simulate(body, DT, 1, gravity=G)
    return body.core_model().contact_settings()["stiffness"]


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_contact_with_a_floor_gradient_matches_central_differences(formulation):
    """The cantilever falls onto a floor and rests on it for most of the run, its barrier
    stiffness adaptive from the default reference and balanced inside its bounds in some of
    those steps: the gradient follows it and is exact (measured: at most 5e-9 standard, 6e-9
    mixed over the parameters; 6.5e-2 with the stiffness held at each step's converged value)."""
    damping = (1.0, 0.002)
    reference = default_reference_stiffness(formulation)
    body = cantilever(formulation, gap=GAP, stiffness=reference)
    assert_contact_active(body, damping=damping)
    objective = tip_swing(body)
    names = ["youngs_modulus", "density", "mass_damping", "stiffness_damping"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, steps=STEPS, gravity=G, damping=damping,
                               checkpoint_every=4, tolerance=TIGHT)
    assert g.balanced_stiffness_steps >= 2, "the stiffness should be balanced inside its bounds"

    def value(t):
        b = cantilever(formulation, E=t[0], rho=t[1], gap=GAP, stiffness=reference)
        return objective(simulated(b, damping=(t[2], t[3])).positions)[0]

    theta = np.array([66e3, 1080.0, *damping])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    each_and_all(value, theta, g.vector, rtol=1e-6)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_contact_with_a_spring_cable_gradient_matches_central_differences(formulation):
    """The damped cable pulled by its schedule while the cantilever rests on the floor: the
    balanced stiffness carries the cable's force, so its stiffness, dashpot and keyframes move
    the balance too (balanced in 8 of 10 steps; measured: at most 6e-9 over the parameters)."""
    c, k, damping = 0.5, 3e3, (1.0, 0.002)
    reference = default_reference_stiffness(formulation)
    body = cantilever(formulation, cable=(c, k), gap=GAP, stiffness=reference)
    objective = tip_swing(body)
    names = ["cable_damping", "cable_stiffness", "youngs_modulus", "density", "stiffness_damping", "keyframes:0"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, tolerance=TIGHT, steps=STEPS, gravity=G, damping=damping,
                               actuation={0: SCHEDULE}, checkpoint_every=3)
    assert g.balanced_stiffness_steps >= 2

    def value(t):
        b = cantilever(formulation, E=t[2], rho=t[3], cable=(t[0], t[1]), gap=GAP, stiffness=reference)
        schedule = Keyframes(np.column_stack([SCHEDULE.times, t[5:]]))
        return objective(simulated(b, damping=(damping[0], t[4]), actuation={0: schedule}).positions)[0]

    theta = np.array([c, k, 66e3, 1080.0, damping[1], *SCHEDULE.values])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    each_and_all(value, theta, g.vector, rtol=1e-6)


#: A fixed barrier stiffness near the floor cantilever's default one (9.3e9 J/m^4).
FIXED_STIFF = 1e10


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_a_fixed_barrier_stiffness_makes_the_floor_gradient_exact(formulation):
    """The same fall onto the floor with ``adaptive_stiffness=False``: every step is then a smooth
    function of the parameters and its start, and the gradient is exact (measured: 4e-9 standard,
    5e-9 mixed; with the adaptive stiffness from this reference, 0.15 and 0.09)."""
    damping = (1.0, 0.002)
    body = cantilever(formulation, gap=GAP, stiffness=FIXED_STIFF, adaptive=False)
    assert_contact_active(body, damping=damping)
    objective = tip_swing(body)
    names = ["youngs_modulus", "density", "mass_damping", "stiffness_damping"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, steps=STEPS, gravity=G, damping=damping,
                               checkpoint_every=4, tolerance=TIGHT)
    assert body.core_model().contact_settings()["stiffness"] == FIXED_STIFF

    def value(t):
        b = cantilever(formulation, E=t[0], rho=t[1], gap=GAP, stiffness=FIXED_STIFF, adaptive=False)
        return objective(simulated(b, damping=(t[2], t[3])).positions)[0]

    theta = np.array([66e3, 1080.0, *damping])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    each_and_all(value, theta, g.vector, rtol=1e-6)


#: A tendon's pull (m) or tension (N) over the run: taut after the first steps, the cantilever
#: then on the floor.
TENDON_SCHEDULES = {"pull": Keyframes([[0.0, 0.0], [0.05, 0.004], [0.1, 0.006]]),
                    "tension": Keyframes([[0.0, 0.0], [0.05, 0.02], [0.1, 0.03]])}


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
@pytest.mark.parametrize("command", ["pull", "tension"])
def test_a_tendon_on_the_floor_gradient_matches_central_differences(formulation, command):
    """A tendon pulled (an exact constraint of every step, its multiplier the tension the next
    step's balance reads) or driven by a tension while the cantilever rests on the floor, the
    barrier stiffness adaptive: exact (measured: at most 5e-8; 9e-3 with the stiffness held at
    each step's converged value)."""
    schedule = TENDON_SCHEDULES[command]

    def body_at(t):
        b = cantilever(formulation, E=t[0], rho=t[1], gap=GAP, stiffness=FIXED_STIFF)
        b.add_cable(sf.Cable.line((0.01, 0.05, 0.08), (1, 0, 0), 0.38, 4, model="tendon", **{command: 0.0}))
        return b

    theta = np.array([66e3, 1080.0, *schedule.values])
    body = body_at(theta)
    assert_contact_active(body, damping=(1.0, 0.002), actuation={0: schedule})
    objective = tip_swing(body)
    g = sf.trajectory_gradient(body, objective, ["youngs_modulus", "density", "keyframes:0"], dt=DT, steps=STEPS,
                               gravity=G, damping=(1.0, 0.002), actuation={0: schedule}, tolerance=TIGHT)
    assert g.balanced_stiffness_steps >= 2

    def value(t):
        changed = Keyframes(np.column_stack([schedule.times, t[2:]]))
        return objective(simulated(body_at(t), damping=(1.0, 0.002), actuation={0: changed}).positions)[0]

    assert g.value == pytest.approx(value(theta), rel=1e-12)
    for i in range(theta.size):
        d = np.zeros(theta.size)
        d[i] = abs(theta[i]) if theta[i] != 0 else schedule.values.max()
        fd = check_gradient(value, theta, g.vector, direction=d, step=1e-5, rtol=1e-6)
        assert fd.passed, f"parameter {i}: {fd}"
    # The forward sensitivity carries the multipliers' changes into the next balance: J^T dx.
    commands = np.array([[schedule(DT * (s + 1))] for s in range(STEPS)])
    out = core().trajectory_sensitivity(body.core_model(), G, body.forces.copy(), body.prescribed_displacement.copy(),
                                        DT, commands, [{"density": np.ones(body.mesh.n_tets)}], 1.0, 0.002, None,
                                        None, TIGHT, 50)
    _, dJ = objective(np.asarray(out["positions"]))
    assert float(np.vdot(dJ, np.asarray(out["dx"])[0])) == pytest.approx(g.gradient["density"], rel=1e-7)


def test_contact_forward_sensitivity_agrees_with_the_adjoint():
    """Both linearise the same steps (the barrier's Hessian at each end, the balanced stiffness's
    change): J^T dx = dJ/dtheta."""
    damping = (1.0, 0.002)
    body = cantilever(gap=GAP)
    assert_contact_active(body, damping=damping)
    objective = tip_swing(body)
    g = sf.trajectory_gradient(body, objective, ["density", "stiffness_damping"], dt=DT, tolerance=TIGHT, steps=STEPS,
                               gravity=G, damping=damping)
    assert g.balanced_stiffness_steps > 0
    model = body.core_model()
    rho = np.full(body.mesh.n_tets, 1.0)
    out = core().trajectory_sensitivity(model, G, body.forces.copy(), body.prescribed_displacement.copy(), DT,
                                        np.zeros((STEPS, 0)), [{"density": rho}, {"stiffness_damping": 1.0}],
                                        *damping, None, None, 1e-10, 50)
    _, dJ = objective(np.asarray(out["positions"]))
    forward = [float(np.vdot(dJ, dx)) for dx in np.asarray(out["dx"])]
    np.testing.assert_allclose(forward, [g.gradient["density"], g.gradient["stiffness_damping"]], rtol=1e-7)


def test_cable_damping_needs_a_spring_cable_and_one_value_per_cable():
    body = cantilever()
    with pytest.raises(sf.InputError, match="'cable_damping' needs spring cables"):
        sf.trajectory_gradient(body, tip_swing(body), ["cable_damping"], dt=DT, steps=2, gravity=G)
    body = cantilever(cable=(0.5, 3e3))
    with pytest.raises(sf.ShapeError, match=r"cable_damping.*expected shape \(1,\), given shape \(2,\)"):
        core().trajectory_sensitivity(body.core_model(), G, body.forces.copy(), body.prescribed_displacement.copy(),
                                      DT, np.ones((2, 1)), [{"cable_damping": np.ones(2)}])


def test_friction_is_refused_by_name():
    body = cantilever()
    body.add_obstacle(sf.Plane((0, 0, -GAP), (0, 0, 1)), friction=0.3)
    with pytest.raises(sf.ParameterError, match="friction"):
        sf.trajectory_gradient(body, tip_swing(body), ["density"], dt=DT, steps=2, gravity=G)


# ---------------------------------------------------------------------------
# Self-contact: the C-body's upper arm thrown onto its lower arm (tests/test_self_contact.py)

THROW_DT, THROW_STEPS = 2e-3, 40
THROW_STIFFNESS = 1e10  # J/m^4: given, so that the re-simulations share it


def thrown(E=30e3, rho=DENSITY, stiffness=THROW_STIFFNESS):
    """The free C-body (no support, no gravity) and its upper arm's initial velocity, 1 m/s down."""
    body = sf.Body(c_shape(), sf.NeoHookean(youngs_modulus=E, poisson_ratio=0.45, density=rho))
    body.set_contact(self_contact=True, stiffness=stiffness)
    rest = body.mesh.points
    arm = (rest[:, 2] >= UPPER_BOTTOM - 1e-12) & (rest[:, 0] > SIZE[0] / CELLS[0] + 1e-12)
    v0 = np.zeros_like(rest)
    v0[arm, 2] = -1.0
    return body, v0, np.flatnonzero(arm)


def arm_at_the_end(body, arm):
    """J = 1/2 |x_arm(T) - X_arm|^2 (m^2)."""
    rest = body.mesh.points[arm]

    def objective(x):
        d = np.zeros_like(x)
        d[-1, arm] = x[-1, arm] - rest
        return 0.5 * float(np.sum((x[-1, arm] - rest) ** 2)), d

    return objective


def test_self_contact_gradient_and_forward_sensitivity_match_central_differences():
    """The arm hits the other one and bounces off; both derivatives are exact (measured: 2e-9)."""
    body, v0, arm = thrown()
    traj = sf.simulate(body, THROW_DT, THROW_STEPS, initial_velocity=v0, tolerance=TIGHT, method="newton")
    assert traj.cutbacks == 0
    assert np.abs(traj.contact_forces).sum(axis=(1, 2)).max() > 0, "the arm should hit the other one"
    objective = arm_at_the_end(body, arm)
    g = sf.trajectory_gradient(body, objective, ["youngs_modulus", "density"], dt=THROW_DT, steps=THROW_STEPS,
                               initial_velocity=v0, tolerance=TIGHT)

    def run(t):
        b, _, _ = thrown(E=t[0], rho=t[1])
        return sf.simulate(b, THROW_DT, THROW_STEPS, initial_velocity=v0, tolerance=TIGHT, method="newton").positions

    theta = np.array([30e3, DENSITY])
    assert g.value == pytest.approx(objective(run(theta))[0], rel=1e-12)
    for i in range(theta.size):
        d = np.zeros(theta.size)
        d[i] = theta[i]
        fd = check_gradient(lambda t: objective(run(t))[0], theta, g.vector, direction=d, step=1e-5, rtol=2e-5)
        assert fd.passed, f"parameter {i}: {fd}"
    out = core().trajectory_sensitivity(body.core_model(), np.zeros(3), body.forces.copy(),
                                        body.prescribed_displacement.copy(), THROW_DT, np.zeros((THROW_STEPS, 0)),
                                        [{"density": np.ones(body.mesh.n_tets)}], 0.0, 0.0, None, v0, TIGHT, 50)
    dx = np.asarray(out["dx"])[0]
    fd = check_jacobian(lambda t: run([30e3, t[0]]).ravel(), np.array([DENSITY]), dx.reshape(-1, 1),
                        direction=np.array([DENSITY]), step=1e-5, rtol=2e-5)
    assert fd.passed, str(fd)


def test_a_balanced_barrier_stiffness_is_differentiated():
    """With a softer barrier the stiffness is balanced inside its bounds where the arm lands: the
    gradient follows it and is exact (measured: 1.5e-8 and 8e-9; 1.5e-2 and 1.1e-2 with the
    stiffness held at each step's converged value)."""
    body, v0, arm = thrown(stiffness=1e9)
    objective = arm_at_the_end(body, arm)
    g = sf.trajectory_gradient(body, objective, ["youngs_modulus", "density"], dt=THROW_DT, steps=THROW_STEPS,
                               initial_velocity=v0, tolerance=TIGHT)
    assert g.balanced_stiffness_steps >= 1

    def value(t):
        b, _, _ = thrown(E=t[0], rho=t[1], stiffness=1e9)
        return objective(sf.simulate(b, THROW_DT, THROW_STEPS, initial_velocity=v0, tolerance=TIGHT,
                                     method="newton").positions)[0]

    theta = np.array([30e3, DENSITY])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    each_and_all(value, theta, g.vector, rtol=1e-6)


def test_a_fixed_barrier_stiffness_makes_the_bounce_gradient_exact():
    """The softer barrier of the test above, held at its value (``adaptive_stiffness=False``):
    the arm still bounces off, no step is balanced, and the gradient is exact (measured: 4e-9;
    0.41 with the adaptive stiffness)."""
    def body_at(rho):
        body, v0, arm = thrown(rho=rho, stiffness=1e9)
        body.set_contact(adaptive_stiffness=False)
        return body, v0, arm

    body, v0, arm = body_at(DENSITY)
    traj = sf.simulate(body, THROW_DT, THROW_STEPS, initial_velocity=v0, tolerance=TIGHT, method="newton")
    assert np.abs(traj.contact_forces).sum(axis=(1, 2)).max() > 0, "the arm should hit the other one"
    objective = arm_at_the_end(body, arm)
    g = sf.trajectory_gradient(body, objective, ["density"], dt=THROW_DT, steps=THROW_STEPS,
                               initial_velocity=v0, tolerance=TIGHT)

    def value(t):
        b, _, _ = body_at(t[0])
        return objective(sf.simulate(b, THROW_DT, THROW_STEPS, initial_velocity=v0, tolerance=TIGHT,
                                     method="newton").positions)[0]

    fd = check_gradient(value, np.array([DENSITY]), g.vector, direction=np.array([DENSITY]), step=1e-5, rtol=2e-5)
    assert fd.passed, str(fd)


def test_mass_damping_recovered_from_a_bounce_through_self_contact():
    """sf.estimate(dynamics=) through self-contact: noiseless tracks of the bouncing arm give the
    damping back (Levenberg-Marquardt on the forward sensitivity, the balanced barrier stiffness
    differentiated)."""
    body, v0, arm = thrown()
    true = 3.0
    traj = sf.simulate(body, THROW_DT, THROW_STEPS, initial_velocity=v0, damping=(true, 0.0), tolerance=TIGHT,
                       method="newton")
    assert np.abs(traj.contact_forces).sum(axis=(1, 2)).max() > 0
    tracks = [(THROW_DT * f, sf.Target.nodes(arm, traj.positions[f][arm])) for f in range(5, THROW_STEPS + 1, 5)]
    fit = sf.estimate(body, tracks, ["mass_damping"], x0=[1.0],
                      dynamics=dict(dt=THROW_DT, steps=THROW_STEPS, initial_velocity=v0, damping=(1.0, 0.0)))
    assert fit.converged
    assert fit.params["mass_damping"] == pytest.approx(true, rel=1e-6)


def rising_floor(formulation="standard", E=66e3, rho=1080.0):
    """The cantilever (no fixed floor) above a floor that rises 4 mm in 20 ms, faster than the
    sagging tip falls: the simulation splits the steps over which it would run into the body.
    Its barrier stiffness is held fixed, so that the derivatives are exact."""
    body = cantilever(formulation, E=E, rho=rho)
    body.add_obstacle(sf.Plane((0.0, 0.0, -GAP), (0, 0, 1)), path=[[0.0, 0, 0, 0], [0.02, 0, 0, 0.004]])
    body.set_contact(stiffness=FIXED_STIFF, adaptive_stiffness=False)
    return body


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_steps_a_moving_obstacle_splits_are_differentiated_through_their_sub_steps(formulation):
    """The derivatives follow the simulation's halved steps (each sub-step an implicit Euler step
    of its own length; measured against central differences: 1e-9 standard, 2e-9 mixed), and the
    forward sensitivity agrees with the adjoint."""
    damping = (1.0, 0.002)
    body = rising_floor(formulation)
    traj = simulated(body, damping=damping)
    assert traj.cutbacks > 0, "the rising floor should split steps"
    assert np.abs(traj.contact_forces).sum(axis=(1, 2)).max() > 0
    objective = tip_swing(body)
    names = ["youngs_modulus", "density", "mass_damping", "stiffness_damping"]
    g = sf.trajectory_gradient(body, objective, names, dt=DT, steps=STEPS, gravity=G, damping=damping,
                               checkpoint_every=3, tolerance=TIGHT)
    assert 0 < g.split_steps <= traj.cutbacks

    def value(t):
        return objective(simulated(rising_floor(formulation, E=t[0], rho=t[1]), damping=(t[2], t[3])).positions)[0]

    theta = np.array([66e3, 1080.0, *damping])
    assert g.value == pytest.approx(value(theta), rel=1e-12)
    each_and_all(value, theta, g.vector, rtol=1e-6)
    out = core().trajectory_sensitivity(body.core_model(), G, body.forces.copy(), body.prescribed_displacement.copy(),
                                        DT, np.zeros((STEPS, 0)), [{"density": np.full(body.mesh.n_tets, 1.0)}],
                                        *damping, None, None, TIGHT, 50)
    _, dJ = objective(np.asarray(out["positions"]))
    forward = float(np.vdot(dJ, np.asarray(out["dx"])[0]))
    assert forward == pytest.approx(g.gradient["density"], rel=1e-7)

"""sf.control(..., dynamics=...): an open-loop cable schedule that brings a target to its goal at
a time T and holds it there. The objective's gradient by keyframe value against central
differences of re-simulated trajectories (tests/fdcheck.py); a schedule recovered for a goal
a known schedule reaches; an unreachable goal; bad input."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_gradient

import sorofem as sf
from sorofem.dynamics import Keyframes
from sorofem.inverse._control_dynamics import ScheduleProblem, dynamics_options

G = np.array([0.0, 0.0, -9.81])
DT, STEPS = 0.01, 40
DAMPING = (4.0, 0.002)
TIP = np.array([[0.4, 0.05, 0.05]])  # m, the tip face's centre at rest
TIGHT = 1e-11
MESH = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
TIP_POINT = sf.Target.points(TIP, TIP).bind(MESH)


def cantilever(tendon=False):
    """The 0.4 m cable cantilever on 8 x 2 x 2 cells: a spring cable near the top face (pulling
    lifts the tip against gravity), and with ``tendon`` a tendon near the side y = 0 driven by its
    pull; starts from its static equilibrium."""
    mesh = MESH
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    body.add_cable(sf.Cable.line((0.0, 0.05, 0.09), (1, 0, 0), 0.4, 10, stiffness=1e5))
    if tendon:
        body.add_cable(sf.Cable.line((0.0, 0.01, 0.05), (1, 0, 0), 0.38, 8, model="tendon", pull=0.0))
    rest = sf.solve_static(body, gravity=G, tolerance=TIGHT)
    return body, rest


def tip_at(positions, frame):
    return TIP_POINT.points(positions[frame])


def hold_objective(positions, goal, reach_frame):
    """The documented objective, written out: the mean over the frames from T to the end of
    1/2 |tip - goal|^2 (m^2)."""
    frames = range(reach_frame, positions.shape[0])
    return np.mean([0.5 * np.sum((tip_at(positions, i) - goal) ** 2) for i in frames])


def test_objective_gradient_by_keyframe_values_matches_central_differences():
    body, rest = cantilever(tendon=True)
    times = np.array([0.1, 0.2, 0.3])
    reach = 0.3
    goal = TIP + [-0.03, 0.01, 0.02]
    dynamics = dict(dt=DT, steps=STEPS, keyframe_times=times, reach_time=reach, damping=DAMPING, initial=rest)
    problem = ScheduleProblem(body, sf.Target.points(TIP, goal).bind(body.mesh), [0, 1],
                              dynamics_options(dynamics, body), G, TIGHT)
    values = np.array([[0.93, 0.004], [0.88, 0.008], [0.9, 0.006]])  # alpha, pull (m)
    value, gradient = problem.evaluate(values)
    assert gradient.shape == (3, 2)

    def simulated(v):
        v = v.reshape(3, 2)
        schedule = {0: Keyframes(np.column_stack([np.r_[0.0, times], np.r_[1.0, v[:, 0]]])),
                    1: Keyframes(np.column_stack([np.r_[0.0, times], np.r_[0.0, v[:, 1]]]))}
        traj = sf.simulate(body, DT, STEPS, actuation=schedule, gravity=G, damping=DAMPING, initial=rest,
                           tolerance=TIGHT, method="newton")
        return hold_objective(traj.positions, goal, round(reach / DT))

    assert value == pytest.approx(simulated(values.ravel()), rel=1e-10)
    # The alphas and the pulls (m) differ by two orders of magnitude: each kind on its own too.
    fd = check_gradient(simulated, values.ravel(), gradient.ravel(), step=1e-5, rtol=1e-5,
                        blocks=[[0, 2, 4], [1, 3, 5]])
    assert fd.passed, str(fd)


def test_a_keyframe_at_t0_is_optimised_too():
    body, rest = cantilever()
    dynamics = dict(dt=DT, steps=20, keyframe_times=[0.0, 0.1], reach_time=0.2, initial=rest, damping=DAMPING)
    goal = TIP + [0.0, 0.0, 0.03]
    problem = ScheduleProblem(body, sf.Target.points(TIP, goal).bind(body.mesh), [0],
                              dynamics_options(dynamics, body), G, TIGHT)
    values = np.array([[0.95], [0.9]])
    _, gradient = problem.evaluate(values)

    def simulated(v):
        traj = sf.simulate(body, DT, 20, actuation={0: Keyframes([[0.0, v[0]], [0.1, v[1]]])}, gravity=G,
                           damping=DAMPING, initial=rest, tolerance=TIGHT, method="newton")
        return hold_objective(traj.positions, goal, 20)

    fd = check_gradient(simulated, values.ravel(), gradient.ravel(), step=1e-5, rtol=1e-5)
    assert fd.passed, str(fd)
    assert abs(gradient[0, 0]) > 1e-3 * abs(gradient[1, 0])  # the t = 0 keyframe acts on the first steps


@pytest.fixture(scope="module")
def known():
    """A known schedule (ramp the spring cable to alpha = 0.92 by 0.2 s, hold) and its tip."""
    body, rest = cantilever()
    schedule = Keyframes([[0.0, 1.0], [0.1, 0.96], [0.2, 0.92]])
    traj = sf.simulate(body, DT, STEPS, actuation={0: schedule}, gravity=G, damping=DAMPING, initial=rest,
                       tolerance=TIGHT, method="newton")
    return body, rest, traj


def test_control_reaches_the_pose_of_a_known_schedule_at_the_end(known):
    """T = the last frame: the known schedule's final tip is reached exactly (J = 1/2 |r|^2 at T)."""
    body, rest, traj = known
    goal = tip_at(traj.positions, STEPS)
    plan = sf.control(body, sf.Target.points(TIP, goal), cables=[0], bounds=[(0.5, 1.0)], gravity=G,
                      solve_tolerance=TIGHT,
                      dynamics=dict(dt=DT, steps=STEPS, keyframe_times=[0.1, 0.2], reach_time=DT * STEPS,
                                    damping=DAMPING, initial=rest))
    assert isinstance(plan, sf.inverse.ScheduleResult)
    assert plan.reachable and plan.distance < 1e-6 and plan.swing == 0.0, plan.message
    assert plan.actuation.shape == (2, 1)
    assert plan.trajectory.positions.shape == (STEPS + 1, body.mesh.n_nodes, 3)
    assert plan.simulations > plan.iterations >= 1
    # The schedule drives sf.simulate as it is, and the body keeps its own command.
    again = sf.simulate(body, DT, STEPS, actuation=plan.schedule, gravity=G, damping=DAMPING, initial=rest,
                        tolerance=TIGHT, method="newton")
    np.testing.assert_allclose(again.positions, plan.trajectory.positions, atol=1e-12)
    assert body.actuations == [1.0]


def test_control_holds_the_pose_a_known_schedule_settles_to(known):
    """The goal is where the known schedule's tip comes to rest (the static equilibrium at its
    final alpha = 0.92, 7 cm above the start), to reach at T = 0.3 s and hold to 0.4 s. The known schedule still
    swings about it; the schedule found reaches it and keeps it within 1 mm, and its objective
    is a small fraction of the known one's."""
    body, rest, traj = known
    reach_frame = 30
    body.set_actuation(0, 0.92)
    settled = sf.solve_static(body, gravity=G, initial=rest, tolerance=TIGHT)
    body.set_actuation(0, 1.0)
    goal = tip_at(settled.positions[None], 0)
    j_known = hold_objective(traj.positions, goal, reach_frame)
    plan = sf.control(body, sf.Target.points(TIP, goal), cables=[0], bounds=[(0.5, 1.0)], gravity=G,
                      solve_tolerance=TIGHT,
                      dynamics=dict(dt=DT, steps=STEPS, keyframe_times=[0.1, 0.2, 0.3], reach_time=0.3,
                                    damping=DAMPING, initial=rest))
    assert plan.objective == pytest.approx(hold_objective(plan.trajectory.positions, goal, reach_frame), rel=1e-9)
    assert plan.objective < 0.01 * j_known
    assert plan.reachable and plan.distance < 1e-3 and plan.swing < 1e-3, plan.message
    assert plan.history[-1]["objective"] <= plan.history[0]["objective"]


def test_an_unreachable_goal_gives_the_closest_schedule():
    """A goal 10 cm ahead of the tip along +x: one cable cannot stretch the beam. Not reachable;
    the schedule found beats holding the static control's closest command from the first
    keyframe, and its tip at T is about as far from the goal as that static optimum."""
    body, rest = cantilever()
    goal = tip_at(rest.positions[None], 0) + [0.1, 0.0, 0.0]
    target = sf.Target.points(TIP, goal)
    static = sf.control(body, target, cables=[0], bounds=[(0.5, 1.0)], gravity=G)
    assert not static.reachable
    dynamics = dict(dt=DT, steps=STEPS, keyframe_times=[0.1, 0.2], reach_time=0.3, damping=DAMPING, initial=rest)
    plan = sf.control(body, target, cables=[0], bounds=[(0.5, 1.0)], gravity=G, dynamics=dynamics)
    assert not plan.reachable and "not reachable" in plan.message
    held = sf.simulate(body, DT, STEPS, actuation={0: Keyframes([[0.0, 1.0], [0.1, static.actuation[0]]])},
                       gravity=G, damping=DAMPING, initial=rest)
    assert plan.objective <= hold_objective(held.positions, goal, 30) * (1 + 1e-9)
    assert plan.distance == pytest.approx(static.distance, rel=0.2)


@pytest.mark.parametrize(("change", "match"), [
    ({"keyframe_times": [0.2, 0.1]}, r"dynamics\['keyframe_times'\]: expected strictly increasing times, got 0.1 s after 0.2 s"),
    ({"keyframe_times": [0.1, 0.5]}, r"dynamics\['keyframe_times'\]: expected times within the run, 0 to dt \* steps = 0.4 s, got 0.5 s"),
    ({"keyframe_times": []}, r"dynamics\['keyframe_times'\]: expected a non-empty list"),
    ({"damping": (-1.0, 0.0)}, r"dynamics\['damping'\]\[0\] \(alpha_M, 1/s\): expected a finite number >= 0, got float -1.0"),
    ({"damping": (1.0, -0.1)}, r"dynamics\['damping'\]\[1\] \(beta_K, s\)"),
    ({"dt": 0.0}, r"dynamics\['dt'\]: expected a finite positive number, got 0.0"),
    ({"dt": float("nan")}, r"dynamics\['dt'\]"),
    ({"steps": 0}, r"dynamics\['steps'\]"),
    ({"steps": 10**7}, r"dynamics\['steps'\]"),
    ({"reach_time": 0.255}, r"dynamics\['reach_time'\]: expected the time of a frame, a multiple of dt = 0.01 s in \[0.01, 0.4\] s"),
    ({"reach_time": 0.5}, r"dynamics\['reach_time'\]: expected the time of a frame"),
    ({"reach_time": 0.0}, r"dynamics\['reach_time'\]: expected the time of a frame"),
    ({"reach_time": 1.7e308}, r"dynamics\['reach_time'\]: expected the time of a frame"),
    ({"reach_time": "end"}, r"dynamics\['reach_time'\]: expected a time in s"),
    ({"initial": np.zeros((3, 3))}, r"dynamics\['initial'\]"),
    ({"swing_weight": 2.0}, r"dynamics: unknown keys \['swing_weight'\]"),
])
def test_bad_dynamics_are_named(change, match):
    body, rest = cantilever()
    dynamics = dict(dt=DT, steps=STEPS, keyframe_times=[0.1, 0.2], reach_time=0.3, initial=rest) | change
    with pytest.raises(sf.InputError, match=match):
        sf.control(body, sf.Target.points(TIP, TIP), cables=[0], bounds=[(0.5, 1.0)], gravity=G, dynamics=dynamics)


def test_bad_control_arguments_with_dynamics_are_named():
    body, rest = cantilever()
    target = sf.Target.points(TIP, TIP)
    dynamics = dict(dt=DT, steps=STEPS, keyframe_times=[0.1, 0.2], reach_time=0.3, initial=rest)
    with pytest.raises(sf.InputError, match=r"cables\[1\]: index 3 out of range: the body has 1 cable"):
        sf.control(body, target, cables=[0, 3], gravity=G, dynamics=dynamics)
    with pytest.raises(sf.InputError, match=r"dynamics: missing 'reach_time'"):
        sf.control(body, target, cables=[0], dynamics={k: v for k, v in dynamics.items() if k != "reach_time"})
    with pytest.raises(sf.InputError, match=r"dynamics: expected a dict"):
        sf.control(body, target, cables=[0], dynamics=[DT, STEPS])
    with pytest.raises(sf.InputError, match=r"x0: expected 1 finite commands \(one per cable\) or \(2, 1\)"):
        sf.control(body, target, cables=[0], x0=[[0.9, 0.8]], dynamics=dynamics)
    with pytest.raises(sf.InputError, match=r"method: a schedule \(dynamics=\) is optimised by 'l-bfgs-b'"):
        sf.control(body, target, cables=[0], method="nelder-mead", dynamics=dynamics)
    with pytest.raises(sf.InputError, match=r"initial: a schedule"):
        sf.control(body, target, cables=[0], initial=rest, dynamics=dynamics)
    with pytest.raises(sf.InputError, match=r"target: expected a sorofem.Target"):
        sf.control(body, "tip", cables=[0], dynamics=dynamics)
    body.add_obstacle(sf.Plane(point=(0, 0, -0.5), normal=(0, 0, 1)))
    with pytest.raises(sf.InputError, match=r"target: a contact force is not a target of a schedule"):
        sf.control(body, sf.Target.contact_force(0, 0.1), cables=[0], bounds=[(0.5, 1.0)], dynamics=dynamics)

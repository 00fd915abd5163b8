"""Self-contact through the Python API: a C-shaped body whose upper arm sags under gravity rests on
its lower arm with ``set_contact(self_contact=True)`` and passes through it without; the switch is
checked, and the scene key reaches the body. In dynamics the arm thrown onto the other one bounces
off it (momentum conserved, energy not created, no surface crossing at any step) and, damped,
settles on it at the static equilibrium; adjoint and forward sensitivities through self-contact
match re-solves (trajectory derivatives through self-contact: tests/test_trajectory_contact.py)."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_gradient, check_jacobian, random_direction

import sorofem as sf

SIZE = (0.2, 0.02, 0.08)  # m
CELLS = (8, 1, 4)
LOWER_TOP, UPPER_BOTTOM = 0.02, 0.06  # m: the slot between the arms
DENSITY = 1080.0  # kg/m^3
GRAVITY = (0.0, 0.0, -9.81)


def c_shape() -> sf.Mesh:
    """The box without the slot of the cells x > one cell, 1 <= layer <= 2 (open towards +x), and
    without the second half of the top layer: the upper arm is half as long as the lower one."""
    box = sf.Mesh.box(size=SIZE, cells=CELLS)
    centres = box.points[box.tets].mean(axis=1)
    h = np.array(SIZE) / np.array(CELLS)
    slot = (centres[:, 0] > h[0]) & (centres[:, 2] > LOWER_TOP) & (centres[:, 2] < UPPER_BOTTOM)
    beyond = (centres[:, 0] > SIZE[0] / 2) & (centres[:, 2] > UPPER_BOTTOM)
    tets = box.tets[~(slot | beyond)]
    used, inverse = np.unique(tets, return_inverse=True)
    return sf.Mesh(box.points[used], inverse.reshape(tets.shape))


def clamped_body(self_contact: bool) -> sf.Body:
    mesh = c_shape()
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=30e3, poisson_ratio=0.45, density=DENSITY))
    body.fix(np.flatnonzero(mesh.points[:, 2] < 1e-9))
    body.set_contact(self_contact=self_contact)
    return body


def lowest_of_upper_arm(body: sf.Body, positions: np.ndarray) -> float:
    rest = body.mesh.points
    arm = (rest[:, 2] >= UPPER_BOTTOM - 1e-12) & (rest[:, 0] > SIZE[0] / CELLS[0] + 1e-12)
    return float(positions[arm, 2].min())


def test_an_arm_rests_on_its_own_body_and_passes_through_it_without_self_contact():
    through = sf.solve_static(clamped_body(False), gravity=GRAVITY)
    assert through.contact is None
    sag = lowest_of_upper_arm(through.body, through.positions)
    assert sag < LOWER_TOP

    body = clamped_body(True)
    result = sf.solve_static(body, gravity=GRAVITY)
    contact = result.contact
    # Resting on the lower arm (whose top sinks a little under the load), apart from it.
    assert sag + 0.5 * (LOWER_TOP - sag) < lowest_of_upper_arm(body, result.positions) < LOWER_TOP + body.dhat
    assert contact.self_active > 0 and result.active_contacts == contact.self_active
    assert 0 < contact.self_min_distance < body.dhat
    assert np.all(contact.iterate_min_distances > 0)
    # Internal forces: they sum to zero, and the supports carry the whole weight.
    forces = result.contact_forces
    assert np.abs(forces).sum() > 0
    np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-10 * np.abs(forces).sum())
    weight = DENSITY * body.mesh.volumes.sum() * np.asarray(GRAVITY)
    np.testing.assert_allclose(result.reactions.sum(axis=0), -weight, atol=1e-8 * np.linalg.norm(weight))
    assert result.to_dict()["contact"]["self_contact"]["active_contacts"] == contact.self_active


def test_the_switch_is_checked_and_defaults_to_off():
    body = clamped_body(False)
    assert body.contact_settings["self_contact"] is False
    assert body.dhat is None
    with pytest.raises(sf.ParameterError, match="self_contact"):
        body.set_contact(self_contact="yes")
    body.set_contact(self_contact=True)
    assert body.dhat > 0


def test_the_scene_key_switches_self_contact_on(tmp_path):
    scene = tmp_path / "c.toml"
    scene.write_text("""
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [5, 1, 1] }

[material]
youngs_modulus = 1e5
poisson_ratio = 0.45

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[contact]
self_contact = true
adaptive_stiffness = false
""", encoding="utf-8")
    settings = sf.Scene.load(scene).body.contact_settings
    assert settings["self_contact"] is True and settings["adaptive_stiffness"] is False


# ---------------------------------------------------------------------------
# Dynamics and sensitivities


def surface_crossings(faces: np.ndarray, x: np.ndarray) -> int:
    """How many (surface edge, surface triangle) pairs sharing no vertex cross at positions ``x``
    (the edge strictly through the triangle's interior; Moller-Trumbore): an independent
    intersection check, which counts 20 for the arm passing through without self-contact."""
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    e, t = (a.ravel() for a in np.meshgrid(np.arange(len(edges)), np.arange(len(faces)), indexing="ij"))
    keep = ~(edges[e][:, :, None] == faces[t][:, None, :]).any(axis=(1, 2))
    e, t = e[keep], t[keep]
    p, d = x[edges[e, 0]], x[edges[e, 1]] - x[edges[e, 0]]
    a, e1, e2 = x[faces[t, 0]], x[faces[t, 1]] - x[faces[t, 0]], x[faces[t, 2]] - x[faces[t, 0]]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=det != 0.0)
    s = p - a
    q = np.cross(s, e1)
    u, v, w = (inv * np.einsum("ij,ij->i", *pair) for pair in ((s, h), (d, q), (e2, q)))
    return int(((det != 0.0) & (u > 0) & (v > 0) & (u + v < 1) & (w > 0) & (w < 1)).sum())


def nodal_masses(mesh: sf.Mesh) -> np.ndarray:
    """Lumped masses ``(n_nodes,)``, kg: a quarter of each tet's mass to each of its nodes (the
    column sums of the consistent mass matrix too)."""
    m = np.zeros(mesh.n_nodes)
    np.add.at(m, mesh.tets.ravel(), np.repeat(DENSITY * mesh.volumes / 4, 4))
    return m


def test_sagging_arm_passes_through_without_self_contact_by_the_crossing_count():
    """The intersection check of the dynamics test sees what it should: crossings when the arm
    passes through the lower one, none at rest or resting on it."""
    faces = c_shape().boundary_faces()
    assert surface_crossings(faces, c_shape().points) == 0
    assert surface_crossings(faces, sf.solve_static(clamped_body(False), gravity=GRAVITY).positions) > 0
    assert surface_crossings(faces, sf.solve_static(clamped_body(True), gravity=GRAVITY).positions) == 0


def test_a_free_arm_thrown_onto_the_other_bounces_off_conserving_momentum():
    """A free C-body (no support, no gravity) whose upper arm is thrown down at 1 m/s: the
    self-contact forces are internal, so implicit Euler keeps the total momentum ``sum m v``
    (velocities ``(x_n+1 - x_n) / dt``) exactly; the strain plus kinetic energy never exceeds the
    initial one (implicit Euler dissipates, the barrier's energy is >= 0), nor falls below the
    kinetic energy of the centre of mass; no surface edge crosses a triangle at any step."""
    mesh = c_shape()
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=30e3, poisson_ratio=0.45, density=DENSITY))
    body.set_contact(self_contact=True)
    rest = mesh.points
    arm = (rest[:, 2] >= UPPER_BOTTOM - 1e-12) & (rest[:, 0] > SIZE[0] / CELLS[0] + 1e-12)
    v0 = np.zeros_like(rest)
    v0[arm, 2] = -1.0
    dt = 2e-3
    traj = sf.simulate(body, dt=dt, steps=60, initial_velocity=v0, tolerance=1e-10)
    forces = np.abs(traj.contact_forces).sum(axis=(1, 2))
    assert forces.max() > 0 and forces[-1] == 0, "the arm should hit the other one and bounce off"
    # Contact forces are internal at every frame.
    np.testing.assert_allclose(traj.contact_forces.sum(axis=1), 0.0, atol=1e-10 * forces.max())
    m = nodal_masses(mesh)
    p0 = m @ v0
    momentum = np.einsum("i,fij->fj", m, np.diff(traj.positions, axis=0) / dt)
    np.testing.assert_allclose(momentum, np.broadcast_to(p0, momentum.shape), atol=1e-9 * np.linalg.norm(p0))
    model = body.core_model()
    energy = traj.kinetic_energy + np.array([model.strain_energy(x) for x in traj.positions])
    assert np.all(energy <= energy[0] * (1 + 1e-9))
    assert np.all(traj.kinetic_energy >= (p0 @ p0) / (2 * m.sum()) * (1 - 1e-9))
    faces = mesh.boundary_faces()
    assert [surface_crossings(faces, x) for x in traj.positions] == [0] * traj.n_frames
    assert np.all(traj.iterate_min_distances > 0)


def test_a_damped_arm_settles_on_the_other_at_the_static_equilibrium():
    """Released at rest under gravity with mass damping, the upper arm falls onto the lower one
    and stays there: the final state is the static self-contact equilibrium, and no frame
    intersects."""
    body = clamped_body(True)
    static = sf.solve_static(body, gravity=GRAVITY, tolerance=1e-10)
    traj = sf.simulate(body, dt=5e-3, steps=200, gravity=GRAVITY, damping=(20.0, 0.0), tolerance=1e-10,
                       save_every=10)
    assert traj.kinetic_energy[-1] < 1e-5 * traj.kinetic_energy.max()
    np.testing.assert_allclose(traj.final_positions, static.positions, atol=1e-5)
    assert lowest_of_upper_arm(body, traj.final_positions) < LOWER_TOP + body.dhat
    faces = body.mesh.boundary_faces()
    assert [surface_crossings(faces, x) for x in traj.positions] == [0] * traj.n_frames


@pytest.fixture(scope="module")
def resting():
    body = clamped_body(True)
    result = sf.solve_static(body, gravity=GRAVITY, tolerance=1e-11)
    assert result.contact.self_active > 0, "the arm should rest on the lower one"
    tip = np.flatnonzero(np.isclose(body.mesh.points[:, 0], SIZE[0] / 2) & (body.mesh.points[:, 2] > LOWER_TOP))
    goal = result.positions[tip] + [0.0, 0.0, 0.005]
    return body, result, sf.Target.nodes(tip, goal)


def test_adjoint_gradients_through_self_contact_match_finite_differences(resting):
    """d(1/2 |r|^2)/d(mu, lambda, rho) of the resting arm's tip by the adjoint against re-solves of
    the same body (its barrier stiffness fixed at its first solve)."""
    body, result, target = resting
    names = ["shear_modulus", "lame_lambda", "density"]
    g = sf.gradient(body, target, names, gravity=GRAVITY, initial=result, tolerance=1e-11)
    material = body.material
    theta = np.array([material.shear_modulus, material.lame_lambda, material.density])
    bound = target.bind(body.mesh)

    def misfit(values):
        body.material = sf.NeoHookean(shear_modulus=values[0], lame_lambda=values[1], density=values[2])
        try:
            return bound.misfit(sf.solve_static(body, gravity=GRAVITY, initial=result, tolerance=1e-11).positions)[0]
        finally:
            body.material = material

    fd = check_gradient(misfit, theta, np.array([g.gradient[n] for n in names]), step=1e-4, rtol=1e-5,
                        direction=random_direction(theta, seed=2), blocks=[[0], [1], [2]])
    assert fd.passed, str(fd)


def test_forward_sensitivities_through_self_contact_match_finite_differences(resting):
    """The Jacobian least squares builds from forward sensitivities, dr/ds (s the log parameters),
    against re-solves; and J^T r equals the adjoint gradient."""
    from sorofem.inverse._parameters import Parameters
    from sorofem.inverse._problem import Problem, scenarios

    body, result, target = resting
    p = Parameters(body, ["shear_modulus", "lame_lambda"])
    problem = Problem(body, p, scenarios(body, target, None, GRAVITY, sf.SolveOptions(1e-11, 50, 1)))
    try:
        s = p.to_s(p.current())
        r, J = problem.evaluate(s, "jacobian")
        _, grad = problem.evaluate(s, "gradient")
        np.testing.assert_allclose(J.T @ r, grad, rtol=1e-8)
        fd = check_jacobian(lambda x: problem.evaluate(x)[0], s, J, step=1e-5, rtol=1e-5, blocks=[[0], [1]])
        assert fd.passed, str(fd)
    finally:
        problem.restore()

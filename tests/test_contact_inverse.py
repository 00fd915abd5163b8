"""Inverse problems through contact (issue 17, item 4): a target on the force an obstacle exerts
on the body, its derivatives through frictionless contact checked by finite differences, a
cable-driven finger pressing on a table with a target force, and a material calibrated from
the shape of a cantilever resting on a table."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_gradient, check_jacobian, random_direction

import sorofem as sf
from sorofem.errors import InputError

TIGHT = 1e-11
LENGTH, SIDE = 0.1, 0.02  # m
TABLE_Z = -0.004  # m: 4 mm below the finger's underside
E, NU = 100e3, 0.3


def finger(youngs_modulus: float = E, poisson_ratio: float = NU) -> tuple[sf.Body, sf.Cable, sf.Plane]:
    """A 100 x 20 x 20 mm finger clamped at x = 0, a tendon along its underside that curls it
    down, and a frictionless table under its tip."""
    mesh = sf.Mesh.box(size=(LENGTH, SIDE, SIDE), cells=(10, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    x = np.linspace(0.0, LENGTH - 0.005, 10)
    tendon = sf.Cable(np.c_[x, np.full_like(x, SIDE / 2), np.full_like(x, 0.003)], model="tendon")
    body.add_cable(tendon)
    table = sf.Plane((0.0, 0.0, TABLE_Z), (0.0, 0.0, 1.0))
    body.add_obstacle(table)
    return body, tendon, table


def pressed(body: sf.Body, tendon: sf.Cable, pull: float) -> sf.StaticResult:
    """The finger pulled to ``pull`` (m) in a few steps, so that it lands on the table gently."""
    results = sf.actuate(body, tendon, pull, max_step=pull / 4, tolerance=TIGHT)
    return results[-1]


@pytest.fixture(scope="module")
def on_table():
    body, tendon, table = finger()
    result = pressed(body, tendon, 0.004)
    assert result.active_contacts > 0, "the finger should press on the table"
    return body, tendon, table, result


def test_a_contact_force_target_is_the_obstacle_force(on_table):
    body, _, table, result = on_table
    force = result.obstacle_forces[0]
    assert force[2] > 0
    vector = sf.Target.contact_force(table, force + [0.0, 0.0, 0.01]).bind(body.mesh, body=body)
    np.testing.assert_allclose(vector.residual(result.positions), [0.0, 0.0, -0.01], atol=1e-12)
    magnitude = sf.Target.contact_force(0, 0.5 * np.linalg.norm(force)).bind(body.mesh, body=body)
    assert magnitude.residual(result.positions)[0] == pytest.approx(0.5 * np.linalg.norm(force), rel=1e-12)


def test_the_contact_force_jacobian_matches_finite_differences(on_table):
    body, _, table, result = on_table
    x0 = result.positions
    for goal in ([0.0, 0.0, 0.1], 0.1):
        bound = sf.Target.contact_force(table, goal).bind(body.mesh, body=body)
        jacobian = bound.jacobian(x0)
        # Small steps keep every stencil on the same side of dhat.
        fd = check_jacobian(lambda x: bound.residual(x.reshape(-1, 3)), x0.reshape(-1), jacobian.toarray(),
                            step=1e-8, rtol=1e-6)
        assert fd.passed, str(fd)


def test_adjoint_gradients_through_contact_match_finite_differences(on_table):
    """d(1/2 |F - F*|^2)/dtheta by the adjoint (sf.gradient) against re-solves, for the material
    and for the tendon's pull: the static sensitivities hold the contact Hessian. The re-solves
    use the same body, whose barrier stiffness was fixed at its first solve (as in the inverse
    problems: a new body would pick its own from its material)."""
    body, tendon, table, result = on_table
    goal = 0.5 * float(np.linalg.norm(result.obstacle_forces[0]))
    target = sf.Target.contact_force(table, goal)
    g = sf.gradient(body, target, ["shear_modulus", "lame_lambda"], initial=result, tolerance=TIGHT)
    material = body.material
    theta = np.array([material.shear_modulus, material.lame_lambda])

    def misfit(values):
        body.material = sf.NeoHookean(shear_modulus=values[0], lame_lambda=values[1])
        try:
            r = sf.solve_static(body, initial=result, tolerance=TIGHT)
        finally:
            body.material = material
        return 0.5 * (np.linalg.norm(r.obstacle_forces[0]) - goal) ** 2

    fd = check_gradient(misfit, theta, np.array([g.gradient["shear_modulus"], g.gradient["lame_lambda"]]),
                        step=1e-4, rtol=1e-5, direction=random_direction(theta, seed=1))
    assert fd.passed, str(fd)

    g_pull = sf.gradient(body, target, ["cable_pull"], cables=[tendon], initial=result, tolerance=TIGHT)

    def misfit_pull(values):
        body.pull(tendon, displacement=float(values[0]))
        try:
            r = sf.solve_static(body, initial=result, tolerance=TIGHT)
        finally:
            body.pull(tendon, displacement=0.004)
        return 0.5 * (np.linalg.norm(r.obstacle_forces[0]) - goal) ** 2

    fd = check_gradient(misfit_pull, np.array([0.004]), np.atleast_1d(g_pull.gradient["cable_pull"]),
                        step=1e-3, rtol=1e-5)
    assert fd.passed, str(fd)


def test_control_presses_with_a_target_force(on_table):
    """The tendon pull that makes the table push back with 60 % of the force at 4 mm."""
    body, tendon, table, result = on_table
    goal = 0.6 * float(np.linalg.norm(result.obstacle_forces[0]))
    ctl = sf.control(body, sf.Target.contact_force(table, goal), cables=[tendon], bounds=[(0.0025, 0.0045)],
                     x0=[0.004], initial=result, tolerance=1e-6 * goal)
    reached = float(np.linalg.norm(ctl.result.obstacle_forces[0]))
    assert abs(reached - goal) <= 1e-6 * goal, (reached, goal, ctl.message)
    assert ctl.reachable and "force error" in ctl.message
    assert 0.0025 < ctl.actuation[0] < 0.004


def test_a_contact_force_target_needs_the_body_and_its_obstacle(on_table):
    body, _, _, _ = on_table
    with pytest.raises(InputError, match="body"):
        sf.Target.contact_force(0, 1.0).bind(body.mesh)
    with pytest.raises(InputError, match="obstacle"):
        sf.Target.contact_force(sf.Plane((0, 0, -1), (0, 0, 1)), 1.0).bind(body.mesh, body=body)
    with pytest.raises(InputError, match="obstacle"):
        sf.Target.contact_force(3, 1.0).bind(body.mesh, body=body)
    with pytest.raises(sf.ParameterError, match="force"):
        sf.Target.contact_force(0, -1.0)


def cantilever_on_table(mu: float, lam: float, stiffness: float | None = None) -> sf.Body:
    """A 0.3 m silicone cantilever whose tip sags onto a frictionless table under its weight
    (``stiffness``: the barrier's, J/m^4; default: from the material at the first solve)."""
    mesh = sf.Mesh.box(size=(0.3, 0.05, 0.05), cells=(12, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(shear_modulus=mu, lame_lambda=lam, density=1080.0))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    body.add_obstacle(sf.Plane((0.0, 0.0, -0.03), (0.0, 0.0, 1.0)))
    body.set_contact(stiffness=stiffness)
    return body


def test_estimate_calibrates_a_cantilever_resting_on_a_table():
    """Shear modulus and lambda from the shape of a cantilever whose tip rests on a table: the
    table's reaction depends on them too, and the exact sensitivities through the contact give
    Levenberg-Marquardt its quadratic convergence. Both bodies take the same barrier stiffness:
    by default each would fix its own from the material it first solves with."""
    truth = sf.NeoHookean(youngs_modulus=200e3, poisson_ratio=0.4, density=1080.0)
    g = (0.0, 0.0, -9.81)
    stiffness = sf.solve_static(cantilever_on_table(truth.shear_modulus, truth.lame_lambda), g).contact.stiffness
    reference = sf.solve_static(cantilever_on_table(truth.shear_modulus, truth.lame_lambda, stiffness), g,
                                tolerance=TIGHT)
    assert reference.active_contacts > 0, "the tip should rest on the table"
    target = sf.Target.nodes(np.arange(reference.mesh.n_nodes), reference.positions)
    body = cantilever_on_table(1.0, 1.0, stiffness)
    fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"],
                      x0=[0.7 * truth.shear_modulus, 1.3 * truth.lame_lambda], gravity=g)
    assert fit.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-6)
    assert fit.params["lame_lambda"] == pytest.approx(truth.lame_lambda, rel=1e-6)
    assert fit.converged and fit.residual < 1e-9
    assert fit.forward_solves <= 20
